//! agvrl-drive: run a trained policy on a vehicle at a fixed rate, with a watchdog.
//!
//! `agvrl-drive --run runs/<dir> --vehicle sim` drives the simulated car with the run's policy
//! and env settings; each tick prints one `key=value` line.

use agvrl_deploy::{DriveConfig, DriveLoop};
use agvrl_envs::{EnvConfig, make_task, make_vehicle};
use agvrl_rl::Policy;
use anyhow::{Context, Result, bail};
use clap::Parser;
use serde::Deserialize;
use std::path::PathBuf;

#[derive(Parser)]
#[command(
    name = "agvrl-drive",
    version,
    about = "Drive a trained agvrl policy on the simulator (or, later, a ROS 2 car) at a fixed rate, with a watchdog."
)]
struct Args {
    /// A run directory from `agvrl train` (its policy.agvrl and config.toml).
    #[arg(long, conflicts_with = "policy")]
    run: Option<PathBuf>,
    /// A policy file (with --env and the default env settings).
    #[arg(long)]
    policy: Option<PathBuf>,
    /// Environment id whose task to run (default: the run's).
    #[arg(long)]
    env: Option<String>,
    /// Which vehicle: sim (ros2 is not built yet).
    #[arg(long, default_value = "sim")]
    vehicle: String,
    /// Control rate, Hz.
    #[arg(long, default_value_t = 30.0)]
    rate_hz: f64,
    /// Ticks to run (0: until interrupted).
    #[arg(long, default_value_t = 900)]
    steps: u64,
    /// Hold the rate with the wall clock.
    #[arg(long)]
    realtime: bool,
    /// Seed of the vehicle's reset.
    #[arg(long, default_value_t = 0)]
    seed: u64,
}

#[derive(Deserialize)]
struct RunFile {
    env: String,
    #[serde(default)]
    env_config: EnvConfig,
}

fn main() {
    if let Err(e) = run() {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

fn run() -> Result<()> {
    let a = Args::parse();
    let (policy_path, mut env, cfg) = match (&a.run, &a.policy) {
        (Some(dir), _) => {
            let text = std::fs::read_to_string(dir.join("config.toml"))
                .with_context(|| format!("{} is not a run directory", dir.display()))?;
            let r: RunFile = toml::from_str(&text)
                .map_err(|e| anyhow::anyhow!("{}: {}", dir.join("config.toml").display(), e.message().trim()))?;
            (dir.join("policy.agvrl"), r.env, r.env_config)
        }
        (None, Some(p)) => (p.clone(), "racing-oval".to_string(), EnvConfig::default()),
        (None, None) => bail!("give --run DIR or --policy FILE"),
    };
    if let Some(e) = &a.env {
        env = e.clone();
    }
    if a.vehicle != "sim" {
        bail!("--vehicle '{}': only 'sim' is built so far", a.vehicle);
    }
    if !(a.rate_hz > 0.0 && a.rate_hz.is_finite()) {
        bail!("--rate-hz must be positive");
    }
    let policy = Policy::load(&policy_path).with_context(|| format!("loading {}", policy_path.display()))?;
    let vehicle = make_vehicle(&env, &cfg)?;
    let task = make_task(&env, &cfg, vehicle.steering_limit_rad())?;
    let drive = DriveConfig {
        rate_hz: a.rate_hz,
        realtime: a.realtime,
        ..DriveConfig::default()
    };
    let mut lp = DriveLoop::new(vehicle, task, policy, drive, a.seed)?;
    let mut k = 0u64;
    while a.steps == 0 || k < a.steps {
        let t = lp.tick()?;
        k += 1;
        let ev = t.event.as_ref().map(|e| format!(" event={e:?}")).unwrap_or_default();
        println!(
            "tick={} stamp_s={:.3} throttle={:.3} steering_rad={:.3} infer_us={:.1}{ev}",
            t.index, t.stamp_s, t.control.throttle, t.control.steering_rad, t.infer_us
        );
    }
    Ok(())
}
