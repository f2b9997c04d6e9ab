//! `agvrl policy`: print the settings a policy file drives with, or write a copy of it with
//! other settings embedded (the weights unchanged).

use agvrl_envs::make;
use agvrl_rl::PolicyData;
use agvrl_run::{PolicySettings, RunConfig};
use anyhow::{Context, Result, bail};
use clap::Args;
use std::path::PathBuf;

#[derive(Args)]
pub struct PolicyArgs {
    /// The policy file.
    pub file: PathBuf,
    /// Embed the settings of this run TOML (env id, env settings) instead of the policy's own.
    #[arg(long, value_name = "RUN.toml", requires = "out")]
    pub settings: Option<PathBuf>,
    /// Override one setting, KEY=VALUE as `agvrl train --set`.
    #[arg(long, value_name = "KEY=VALUE")]
    pub set: Vec<String>,
    /// Write the policy with the resulting settings embedded here (may be FILE itself; written
    /// atomically). Without it the settings are only printed.
    #[arg(long, value_name = "FILE.agvrl")]
    pub out: Option<PathBuf>,
}

pub fn policy(a: PolicyArgs) -> Result<()> {
    let mut data = PolicyData::load(&a.file)?;
    let (cfg, source) = match &a.settings {
        Some(path) => (Some(RunConfig::load_with(path, &a.set)?), path.display().to_string()),
        None => {
            let src = PolicySettings::of_policy(&a.file, &data, &a.set)?;
            (src.run, src.source.to_string())
        }
    };
    println!("policy={}", a.file.display());
    println!("algorithm={}", data.algorithm);
    println!("observation_dim={}", data.observation_space.dim());
    println!("action_dim={}", data.action_space.dim());
    println!("settings={source}");
    let Some(cfg) = cfg else {
        if a.out.is_some() {
            bail!(
                "{} carries no settings to embed: give --settings RUN.toml",
                a.file.display()
            );
        }
        return Ok(());
    };
    if let Some(out) = &a.out {
        // The settings must build an env this policy fits, or the file could never drive.
        let env = make(&cfg.env, &cfg.drive_env_config())?;
        agvrl_rl::Policy::new(data.clone(), &agvrl_rl::default_device())
            .check_spaces(&env.observation_space(), &env.action_space())
            .with_context(|| format!("the policy does not fit {} with these settings", cfg.env))?;
        data.settings_toml = Some(cfg.to_toml()?);
        data.save(out)?;
        println!("written={}", out.display());
    }
    print!("\n{}", cfg.to_toml()?);
    Ok(())
}
