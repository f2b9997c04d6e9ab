//! The run configuration: one TOML file says which env, which algorithm and which settings.

use agvrl_envs::EnvConfig;
use agvrl_rl::{PpoConfig, SacConfig};
use anyhow::{Context, Result, bail};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The default job, also embedded so the binary works outside a checkout.
pub const DEFAULT_TOML: &str = include_str!("../configs/default.toml");

/// A training run.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct RunConfig {
    /// Env id.
    pub env: String,
    /// `ppo` or `sac`.
    pub algo: String,
    /// Environment steps to train.
    pub steps: u64,
    /// Seed of everything.
    pub seed: u64,
    /// Parallel envs.
    pub n_envs: usize,
    /// Threads stepping the envs.
    pub threads: usize,
    /// How many of the `n_envs` training envs drive on seeded procedural layouts of the env's
    /// kind and size instead of its built-in map (layout randomisation; evaluation always uses
    /// the map of `env_config`).
    pub procedural_layouts: usize,
    /// Deterministic episodes evaluated after training.
    pub eval_episodes: usize,
    /// Time limit of evaluation episodes, control steps (default: the training limit).
    pub eval_max_steps: Option<u64>,
    /// Env settings.
    pub env_config: EnvConfig,
    /// PPO settings (used when algo = "ppo").
    pub ppo: PpoConfig,
    /// SAC settings (used when algo = "sac").
    pub sac: SacConfig,
}

impl Default for RunConfig {
    fn default() -> Self {
        Self {
            env: "racing-oval".into(),
            algo: "ppo".into(),
            steps: 100_000,
            seed: 0,
            n_envs: 8,
            threads: 2,
            procedural_layouts: 0,
            eval_episodes: 3,
            eval_max_steps: None,
            env_config: EnvConfig::default(),
            ppo: PpoConfig::default(),
            sac: SacConfig::default(),
        }
    }
}

impl RunConfig {
    /// Parse a run TOML; `origin` names it in errors.
    pub fn from_toml(text: &str, origin: &str) -> Result<Self> {
        let cfg: RunConfig = toml::from_str(text).map_err(|e| anyhow::anyhow!("{origin}: {}", e.message().trim()))?;
        cfg.validate().with_context(|| origin.to_string())?;
        Ok(cfg)
    }

    /// Load a run TOML file.
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
        Self::from_toml(&text, &path.display().to_string())
    }

    /// Check values a typo would break.
    pub fn validate(&self) -> Result<()> {
        if !agvrl_envs::ENV_IDS.contains(&self.env.as_str()) {
            bail!(
                "unknown env id '{}'; valid ids: {}",
                self.env,
                agvrl_envs::ENV_IDS.join(", ")
            );
        }
        if self.algo != "ppo" && self.algo != "sac" {
            bail!("unknown algo '{}'; use ppo or sac", self.algo);
        }
        if self.n_envs == 0 || self.threads == 0 || self.steps == 0 {
            bail!("steps, n_envs and threads must be at least 1");
        }
        if self.procedural_layouts > self.n_envs {
            bail!(
                "procedural_layouts ({}) cannot exceed n_envs ({})",
                self.procedural_layouts,
                self.n_envs
            );
        }
        Ok(())
    }

    /// The fully resolved TOML (every default written out).
    pub fn to_toml(&self) -> Result<String> {
        Ok(toml::to_string_pretty(self)?)
    }

    /// Env settings of training env `i`: the last `procedural_layouts` envs get a layout seed
    /// drawn from the run's seed and their index.
    pub fn train_env_config(&self, i: usize) -> EnvConfig {
        let mut cfg = self.env_config.clone();
        if i + self.procedural_layouts >= self.n_envs {
            cfg.layout_seed = Some(self.seed.wrapping_mul(1_000_003).wrapping_add(i as u64));
        }
        cfg
    }

    /// Env settings for evaluation episodes.
    pub fn eval_env_config(&self) -> EnvConfig {
        EnvConfig {
            max_steps: self.eval_max_steps.unwrap_or(self.env_config.max_steps),
            ..self.env_config.clone()
        }
    }
}
