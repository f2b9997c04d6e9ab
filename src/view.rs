//! `agvrl view`: drive one episode (a policy or random actions) into the rerun viewer or an
//! .rrd file.

use crate::episode::{RandomActions, drive, make_sim_env};
use crate::viz::{self, Recorder, Sink};
use agvrl_envs::{Env, EnvConfig};
use agvrl_run::PolicySettings;
use anyhow::{Context, Result, bail};
use clap::Args;
use std::path::PathBuf;

#[derive(Args)]
pub struct ViewArgs {
    /// Environment id (see `agvrl envs`; default: the policy's).
    #[arg(long, required_unless_present_any = ["run", "policy", "bag"])]
    pub env: Option<String>,
    /// Drive with this policy file (default: uniform random actions), with its own settings
    /// (see `agvrl eval --policy`).
    #[arg(long)]
    pub policy: Option<PathBuf>,
    /// Override one of the policy's settings, KEY=VALUE as `agvrl train --set`.
    #[arg(long, value_name = "KEY=VALUE")]
    pub set: Vec<String>,
    /// Race on the track of a ROS map file (its YAML; a centre-line CSV beside it, or traced):
    /// `--set env_config.track=PATH`, loaded into the run config and policy file.
    #[arg(long, value_name = "MAP.yaml")]
    pub track: Option<PathBuf>,
    /// Take env, env settings and policy from a run directory.
    #[arg(long, conflicts_with_all = ["env"])]
    pub run: Option<PathBuf>,
    /// Seed of the episode (spawn, random actions).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Episode length limit, control steps (default: the env's).
    #[arg(long)]
    pub steps: Option<u64>,
    /// Write the recording here (default: view-<env>.rrd).
    #[arg(long, value_name = "FILE.rrd", conflicts_with = "spawn_viewer")]
    pub rerun: Option<PathBuf>,
    /// Stream to a rerun viewer started from `rerun` on your PATH instead of a file.
    #[arg(long)]
    pub spawn_viewer: bool,
    /// Mount the vehicle camera (160x120, 80 degrees) and record its RGB, depth and
    /// segmentation images.
    #[arg(long)]
    pub camera: bool,
    /// Draw a recorded bag instead of driving (`agvrl-drive --record`, `agvrl eval --record`,
    /// or a car log with MCAP storage): pose, path, LiDAR, depth image, commands and events
    /// (default file: view-bag.rrd).
    #[arg(long, value_name = "DIR", conflicts_with_all = ["env", "policy", "run", "camera", "steps"])]
    pub bag: Option<PathBuf>,
}

/// Drive one episode (policy or random actions) into rerun.
pub fn view(a: ViewArgs) -> Result<()> {
    if let Some(dir) = &a.bag {
        let sink = viz::sink_of(a.rerun.as_deref(), a.spawn_viewer)
            .unwrap_or_else(|| Sink::File(PathBuf::from("view-bag.rrd")));
        let (file, v) = viz::bag(sink, dir)?;
        if let Some(d) = &v.damage {
            eprintln!("warning: {d}; drew the intact part");
        }
        println!("bag={}", dir.display());
        println!("scans={}", v.scans);
        println!("poses={}", v.poses);
        println!("images={}", v.images);
        println!("ticks={}", v.ticks);
        println!("skipped={}", v.skipped);
        if let Some(p) = file {
            println!("rrd={}", p.display());
            eprintln!("open it with: rerun {}", p.display());
        }
        return Ok(());
    }
    let (env_id, mut env_cfg, src) = if a.run.is_some() || a.policy.is_some() {
        let sets = [a.set.clone(), a.track.iter().map(|p| agvrl_run::track_set(p)).collect()].concat();
        let src = PolicySettings::resolve(a.run.as_deref(), a.policy.as_deref(), &sets)?;
        (src.env_id(a.env.as_deref())?, src.eval_env_config(), Some(src))
    } else {
        if let Some(s) = a.set.first() {
            bail!("--set {s}: random actions have no settings to override; give --policy or --run");
        }
        let cfg = EnvConfig {
            track: a.track.clone().map(agvrl_envs::TrackSetting::Path),
            ..EnvConfig::default()
        };
        (a.env.clone().unwrap_or_default(), cfg, None)
    };
    if let Some(n) = a.steps {
        env_cfg.max_steps = n;
    }
    if a.camera && env_cfg.sim.camera.is_none() {
        env_cfg.sim.camera = Some(Default::default());
    }
    let mut env = make_sim_env(&env_id, &env_cfg)?.with_context(|| format!("{env_id} has no vehicle to view"))?;
    let policy_path = src.as_ref().map(|s| s.policy.clone());
    let mut policy = match src {
        Some(mut s) => {
            let pol = s.load_policy()?;
            pol.check_spaces(&env.observation_space(), &env.action_space())
                .context("the policy does not fit this env")?;
            Some(pol)
        }
        None => None,
    };
    let sink = viz::sink_of(a.rerun.as_deref(), a.spawn_viewer)
        .unwrap_or_else(|| Sink::File(PathBuf::from(format!("view-{env_id}.rrd"))));
    let mut rec = Recorder::new(sink, &format!("{env_id} view"), env_cfg.sim.camera.as_ref())?;
    let space = env.action_space();
    let mut rng = RandomActions::new(a.seed);
    let mut act = |o: &[f32]| -> Result<Vec<f32>> {
        match &mut policy {
            Some(p) => Ok(p.act(o, true)?),
            None => Ok(rng.sample(&space.low, &space.high)),
        }
    };
    let (ret, last) = drive(&mut env, a.seed, 0, &mut act, &mut |v| rec.step(v))?;
    println!("env={env_id}");
    println!(
        "policy={}",
        policy_path.map_or("random".into(), |p| p.display().to_string())
    );
    println!("steps={}", env.elapsed());
    println!("return={ret:.2}");
    println!("terminated={}", last.terminated);
    if let Some(p) = rec.finish()? {
        println!("rrd={}", p.display());
        eprintln!("open it with: rerun {}", p.display());
    }
    Ok(())
}
