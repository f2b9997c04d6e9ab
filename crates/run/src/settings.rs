//! What a `--policy FILE` or `--run DIR` argument means: the one resolver that eval, view,
//! agvrl-drive and Python share.
//!
//! A policy's settings (its env id and env settings, as a run TOML) are, in this order:
//! embedded in the policy file (format 3 on), the `FILE.toml` beside it (formats 1 and 2, as
//! `assets/policies` shipped them), or the `config.toml` of the run directory it was written
//! into. `--set KEY=VALUE` overrides any of them.

use crate::config::RunConfig;
use crate::dir::{Run, files};
use crate::error::{Result, RunError};
use agvrl_envs::EnvConfig;
use agvrl_rl::{Policy, PolicyData};
use std::fmt;
use std::path::{Path, PathBuf};

/// Where a policy's settings came from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum SettingsSource {
    /// Embedded in this policy file.
    Embedded(PathBuf),
    /// This TOML beside the policy file.
    Beside(PathBuf),
    /// This run directory's `config.toml`.
    RunDir(PathBuf),
    /// The policy carries none.
    None,
}

impl fmt::Display for SettingsSource {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Embedded(p) => write!(f, "{} (embedded)", p.display()),
            Self::Beside(p) | Self::RunDir(p) => write!(f, "{}", p.display()),
            Self::None => f.write_str("default"),
        }
    }
}

/// A policy file and the settings it drives with.
#[derive(Clone, Debug)]
pub struct PolicySettings {
    /// The policy file.
    pub policy: PathBuf,
    /// Its run config (`--set` applied), or `None` when it carries none.
    pub run: Option<RunConfig>,
    /// Where `run` came from.
    pub source: SettingsSource,
    /// The policy file's contents when resolving read them (`--policy`), so the policy is not
    /// read twice.
    data: Option<PolicyData>,
}

impl PolicySettings {
    /// Resolve `--run DIR` (its config and, unless `policy` is given too, its policy file) or
    /// `--policy FILE`, with `sets` (`KEY=VALUE`, as `agvrl train --set`) on top.
    pub fn resolve(run: Option<&Path>, policy: Option<&Path>, sets: &[String]) -> Result<Self> {
        if let Some(dir) = run {
            let opened = Run::open(dir)?;
            let path = opened.file(files::CONFIG);
            return Ok(Self {
                policy: policy.map_or_else(|| opened.file(files::POLICY), Path::to_path_buf),
                run: Some(RunConfig::load_with(&path, sets)?),
                source: SettingsSource::RunDir(path),
                data: None,
            });
        }
        let Some(policy) = policy else {
            return Err(RunError::Config("give --run DIR or --policy FILE".into()));
        };
        let data = PolicyData::load(policy)?;
        let mut settings = Self::of_policy(policy, &data, sets)?;
        settings.data = Some(data);
        Ok(settings)
    }

    /// Settings with no policy behind them (a scripted driver's evaluation): `run`, named by
    /// `name` where a policy file's path would stand.
    pub fn without_policy(name: &str, run: RunConfig) -> Self {
        Self {
            policy: PathBuf::from(name),
            run: Some(run),
            source: SettingsSource::None,
            data: None,
        }
    }

    /// The policy on the default CPU device (from the contents resolving read, else the file).
    pub fn load_policy(&mut self) -> Result<Policy> {
        let data = match self.data.take() {
            Some(d) => d,
            None => PolicyData::load(&self.policy)?,
        };
        Ok(Policy::new(data, &agvrl_rl::default_device()))
    }

    /// The settings of `data`, read from `policy` (see the module's rules).
    pub fn of_policy(policy: &Path, data: &PolicyData, sets: &[String]) -> Result<Self> {
        let (run, source) = if let Some(text) = &data.settings_toml {
            let origin = format!("{} (embedded settings)", policy.display());
            (
                Some(RunConfig::from_toml_with(text, &origin, sets)?),
                SettingsSource::Embedded(policy.to_path_buf()),
            )
        } else if let Some(side) = Some(policy.with_extension("toml")).filter(|p| p.is_file()) {
            (Some(RunConfig::load_with(&side, sets)?), SettingsSource::Beside(side))
        } else if let Some(dir) = Run::of_policy(policy) {
            let path = dir.join(files::CONFIG);
            (Some(RunConfig::load_with(&path, sets)?), SettingsSource::RunDir(path))
        } else if let Some(s) = sets.first() {
            return Err(RunError::Config(format!(
                "--set {s}: {} carries no settings to override (none embedded, no TOML beside \
                 it); embed some with `agvrl policy {} --settings RUN.toml --out FILE`",
                policy.display(),
                policy.display()
            )));
        } else {
            (None, SettingsSource::None)
        };
        Ok(Self {
            policy: policy.to_path_buf(),
            run,
            source,
            data: None,
        })
    }

    /// The env to drive: `over` (`--env`), else the settings' env (a race's policy drives
    /// alone: [`RunConfig::eval_env_id`]).
    pub fn env_id(&self, over: Option<&str>) -> Result<String> {
        match (over, &self.run) {
            (Some(id), _) => Ok(id.to_string()),
            (None, Some(run)) => Ok(run.eval_env_id().to_string()),
            (None, None) => Err(RunError::Config(format!(
                "--env is needed: {} carries no settings naming its env",
                self.policy.display()
            ))),
        }
    }

    /// Env settings for evaluation episodes (see [`RunConfig::eval_env_config`]); the defaults
    /// when the policy carries none.
    pub fn eval_env_config(&self) -> EnvConfig {
        self.run
            .as_ref()
            .map_or_else(EnvConfig::default, RunConfig::eval_env_config)
    }

    /// Env settings for driving a car (see [`RunConfig::drive_env_config`]); the defaults when
    /// the policy carries none.
    pub fn drive_env_config(&self) -> EnvConfig {
        self.run
            .as_ref()
            .map_or_else(EnvConfig::default, RunConfig::drive_env_config)
    }
}
