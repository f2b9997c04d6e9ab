//! agvrl: train autonomous ground vehicle policies with deep RL, evaluate them, look at what the
//! car sees, and measure speed. `cargo run --release` with no arguments trains the default
//! racing policy (configs/default.toml).

mod config;
// Without rerun, nothing reads what only recordings use.
#[cfg_attr(not(feature = "rerun"), allow(dead_code))]
mod episode;
mod plots;
mod probe;
mod runs;
#[cfg_attr(not(feature = "rerun"), allow(dead_code))]
mod sink;
mod train;
#[cfg_attr(not(feature = "rerun"), path = "viz_off.rs")]
mod viz;

use anyhow::Result;
use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(name = "agvrl", version, about = "Train autonomous ground vehicle policies with deep RL and run them on a real car.", long_about = None)]
struct Cli {
    #[command(subcommand)]
    cmd: Option<Cmd>,
}

#[derive(Subcommand)]
enum Cmd {
    /// Train a policy and leave a run directory under runs/ (or --out).
    Train(train::TrainArgs),
    /// Evaluate a trained run with deterministic actions; prints key=value lines.
    Eval(train::EvalArgs),
    /// Drive one episode (a policy, or random actions) into the rerun viewer or an .rrd file.
    View(train::ViewArgs),
    /// List the environment ids with their observation and action spaces.
    Envs,
    /// Print what the car senses at a pose (LiDAR scan, GPS, IMU) as JSON.
    Probe(probe::ProbeArgs),
    /// Measure speed: simulator, envs, learners; prints key=value lines.
    Bench {
        /// Short runs (a smoke test, not for reporting).
        #[arg(long)]
        quick: bool,
        /// Also run the learning checks (SAC and PPO on pendulum, 3 seeds; tens of minutes).
        #[arg(long)]
        learning: bool,
        /// Only this part: sim, envs, rl or deploy.
        #[arg(long)]
        only: Option<String>,
    },
}

fn main() {
    if let Err(e) = run() {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

fn run() -> Result<()> {
    let cli = Cli::parse();
    match cli.cmd {
        None => train::train(train::TrainArgs::default()),
        Some(Cmd::Train(a)) => train::train(a),
        Some(Cmd::Eval(a)) => train::eval(a),
        Some(Cmd::View(a)) => train::view(a),
        Some(Cmd::Envs) => envs(),
        Some(Cmd::Probe(a)) => probe::probe(a),
        Some(Cmd::Bench { quick, learning, only }) => bench(quick, learning, only.as_deref()),
    }
}

fn envs() -> Result<()> {
    for id in agvrl_envs::ENV_IDS {
        let env = agvrl_envs::make(id, &agvrl_envs::EnvConfig::default())?;
        let (o, a) = (env.observation_space(), env.action_space());
        let fmt = |s: &agvrl_envs::BoxSpace| {
            let lo = s.low.iter().cloned().fold(f32::INFINITY, f32::min);
            let hi = s.high.iter().cloned().fold(f32::NEG_INFINITY, f32::max);
            format!("Box({}) in [{lo}, {hi}]", s.dim())
        };
        println!("{id:<20} obs={:<28} act={}  dt={:.4}s", fmt(&o), fmt(&a), env.dt_s());
    }
    Ok(())
}

fn bench(quick: bool, learning: bool, only: Option<&str>) -> Result<()> {
    let want = |part: &str| only.is_none_or(|o| o == part);
    if let Some(o) = only {
        anyhow::ensure!(
            ["sim", "envs", "rl", "deploy"].contains(&o),
            "--only takes sim, envs, rl or deploy, not '{o}'"
        );
    }
    println!(
        "build=release quick={quick} threads_available={}",
        std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1)
    );
    if want("sim") {
        for l in agvrl_sim::bench::run(quick)
            .into_iter()
            .chain(agvrl_sim::bench::camera(quick))
        {
            println!("{l}");
        }
    }
    if want("envs") {
        for l in agvrl_envs::bench::run(quick) {
            println!("{l}");
        }
    }
    if want("rl") {
        for l in agvrl_rl::bench::run(quick)? {
            println!("{l}");
        }
    }
    if want("deploy") {
        for (k, v) in agvrl_deploy::bench::run(quick) {
            println!("{k}={v}");
        }
    }
    if learning {
        for seed in 0..3 {
            let r = agvrl_rl::learning::pendulum_sac(seed, 20_000)?;
            println!("learning=sac env=pendulum steps=20000 seed={seed} mean_return={r:.1}");
        }
        for seed in 0..3 {
            let r = agvrl_rl::learning::pendulum_ppo(seed, 100_000)?;
            println!("learning=ppo env=pendulum steps=100000 seed={seed} mean_return={r:.1}");
        }
    }
    Ok(())
}
