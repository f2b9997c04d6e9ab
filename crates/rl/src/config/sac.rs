//! SAC hyperparameters.

use crate::error::{Result, RlError};
use serde::{Deserialize, Serialize};

/// The entropy coefficient: learned (`"auto"`, or `"auto_0.1"` to start from 0.1) or fixed.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum EntCoef {
    /// A fixed coefficient.
    Fixed(f64),
    /// `"auto"` or `"auto_<initial value>"`.
    Auto(String),
}

impl EntCoef {
    /// `Some(initial value)` when learned, `None` when fixed.
    pub fn auto_init(&self) -> Result<Option<f64>> {
        match self {
            EntCoef::Fixed(_) => Ok(None),
            EntCoef::Auto(s) if s == "auto" => Ok(Some(1.0)),
            EntCoef::Auto(s) => s
                .strip_prefix("auto_")
                .and_then(|v| v.parse::<f64>().ok())
                .filter(|v| *v > 0.0)
                .map(|v| Ok(Some(v)))
                .unwrap_or_else(|| {
                    Err(RlError::Config(format!(
                        "ent_coef '{s}': use a number, \"auto\" or \"auto_<init>\""
                    )))
                }),
        }
    }
}

/// Soft Actor-Critic hyperparameters. `Default` is Stable-Baselines3's (`sac/sac.py`
/// `SAC.__init__`, `sac/policies.py`); a TOML table overrides any subset, with rl-zoo3's key
/// names.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SacConfig {
    /// Adam learning rate of actor, critics and entropy coefficient (3e-4).
    pub learning_rate: f64,
    /// Replay buffer capacity, transitions (1,000,000).
    pub buffer_size: usize,
    /// Env steps of uniform random actions before learning starts (100).
    pub learning_starts: u64,
    /// Minibatch size (256).
    pub batch_size: usize,
    /// Polyak coefficient of the target critics (0.005).
    pub tau: f64,
    /// Discount factor (0.99).
    pub gamma: f64,
    /// Train every this many vector steps (1).
    pub train_freq: u64,
    /// Gradient steps per training round; -1 (the default): one per env step collected in the
    /// round (`train_freq` x n_envs, SB3's `gradient_steps = -1`), so SAC keeps one gradient
    /// step per env step however many envs feed it. With one env this is SB3's default of 1.
    pub gradient_steps: i64,
    /// Entropy coefficient ("auto": learned, starting at 1.0).
    pub ent_coef: EntCoef,
    /// Update the target critics every this many gradient steps (1).
    pub target_update_interval: u64,
    /// Target entropy for the learned coefficient, nats (None: `-dim(action)`).
    pub target_entropy: Option<f64>,
    /// Hidden widths of actor and critics ([256, 256], ReLU).
    pub net_arch: Vec<usize>,
    /// Running observation normalisation (off, as SB3 without `VecNormalize`).
    pub normalize_obs: bool,
    /// The last `C*H*W` observation values are an image, encoded by a NatureCNN for the actor
    /// and another shared by the twin critics (SB3's SAC default, no sharing between actor and
    /// critic); left out of `normalize_obs` (None).
    pub image: Option<crate::cnn::ImageSpec>,
}

impl Default for SacConfig {
    fn default() -> Self {
        Self {
            learning_rate: 3e-4,
            buffer_size: 1_000_000,
            learning_starts: 100,
            batch_size: 256,
            tau: 0.005,
            gamma: 0.99,
            train_freq: 1,
            gradient_steps: -1,
            ent_coef: EntCoef::Auto("auto".into()),
            target_update_interval: 1,
            target_entropy: None,
            net_arch: vec![256, 256],
            normalize_obs: false,
            image: None,
        }
    }
}

impl SacConfig {
    /// Defaults overridden by the keys of a TOML table.
    pub fn from_toml(s: &str) -> Result<Self> {
        let c: Self = toml::from_str(s).map_err(|e| RlError::Config(format!("SAC config: {e}")))?;
        c.validate()?;
        Ok(c)
    }

    /// The configuration as TOML (what a run saves as `config.resolved.toml`).
    pub fn to_toml(&self) -> Result<String> {
        toml::to_string(self).map_err(|e| RlError::Config(format!("SAC config to TOML: {e}")))
    }

    /// Gradient steps taken every `train_freq` vector steps of `n_envs` envs.
    pub fn gradient_steps_per_round(&self, n_envs: usize) -> u64 {
        match u64::try_from(self.gradient_steps) {
            Ok(n) => n,
            Err(_) => self.train_freq * n_envs as u64,
        }
    }

    /// Reject values the learner cannot run with.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: &str| Err(RlError::Config(format!("SAC: {m}")));
        if self.learning_rate.is_nan() || self.learning_rate <= 0.0 {
            return bad("learning_rate must be > 0");
        }
        if self.batch_size == 0 || self.buffer_size == 0 {
            return bad("batch_size and buffer_size must be > 0");
        }
        if !(0.0..=1.0).contains(&self.tau) || !(0.0..=1.0).contains(&self.gamma) {
            return bad("tau and gamma must lie in [0, 1]");
        }
        if self.train_freq == 0 || self.target_update_interval == 0 {
            return bad("train_freq and target_update_interval must be >= 1");
        }
        if self.gradient_steps == 0 || self.gradient_steps < -1 {
            return bad("gradient_steps must be >= 1, or -1 for one per env step collected");
        }
        if self.net_arch.is_empty() || self.net_arch.contains(&0) {
            return bad("net_arch needs at least one non-zero width");
        }
        if let Some(image) = &self.image {
            image.conv_shapes()?;
        }
        self.ent_coef.auto_init().map(|_| ())
    }
}
