//! `agvrl bench`: speed figures as `key=value` lines, each the median of several repetitions
//! after a warm-up. The code lives here, not in the library crates, so their public APIs hold
//! only what users drive.

mod circuit;
mod deploy;
mod envs;
mod rl;
mod sim;

use anyhow::Result;

/// The upper median of timings (the order statistic every figure reports).
fn median(v: Vec<f64>) -> f64 {
    agvrl_run::stats::median(&v)
}

/// A part of `agvrl bench`.
#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum BenchPart {
    /// The simulator: physics, LiDAR, camera, racing on a generated circuit.
    Sim,
    /// Racing on a generated 400 m circuit alone (1,081-beam LiDAR, 1, 2 and 8 cars): the
    /// figures tools/f110-bench.sh sets beside f1tenth_gym's.
    Circuit,
    /// Envs and VecEnv.
    Envs,
    /// The learners' updates and inference.
    Rl,
    /// The drive loop, agvrl-drive and the ROS 2 loopback.
    Deploy,
    /// The learning checks alone.
    Learning,
}

/// Print the figures of `agvrl bench`: every part, or `only` one; the learner figures on `backend`.
pub fn run(quick: bool, learning: bool, only: Option<BenchPart>, backend: agvrl_rl::CpuBackend) -> Result<()> {
    let want = |part: BenchPart| only.is_none_or(|o| o == part);
    println!(
        "build=release quick={quick} threads_available={}",
        std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1)
    );
    if want(BenchPart::Sim) {
        for l in sim::run(quick).into_iter().chain(sim::camera(quick)) {
            println!("{l}");
        }
    }
    if want(BenchPart::Sim) || only == Some(BenchPart::Circuit) {
        for l in circuit::run(quick) {
            println!("{l}");
        }
    }
    if want(BenchPart::Envs) {
        for l in envs::run(quick) {
            println!("{l}");
        }
    }
    if want(BenchPart::Rl) {
        for l in rl::run_on(backend, quick)? {
            println!("{l}");
        }
    }
    if want(BenchPart::Deploy) {
        for (k, v) in deploy::run(quick) {
            println!("{k}={v}");
        }
    }
    if learning || only == Some(BenchPart::Learning) {
        // Scored as Stable-Baselines3's side (`pendulum_parity.py`): 200-step deterministic
        // episodes from the 100 shared start states, 5 seeds.
        type Run = Box<dyn Fn(u64) -> agvrl_rl::Result<f64>>;
        let runs: [(&str, u64, Run); 3] = [
            ("sac", 20_000, Box::new(|s| agvrl_rl::learning::sac_parity(s, 20_000))),
            (
                "ppo_zoo",
                100_000,
                Box::new(|s| agvrl_rl::learning::ppo_parity(true, s, 100_000, &mut |_| {})),
            ),
            (
                "ppo_zoo_gaussian",
                100_000,
                Box::new(|s| agvrl_rl::learning::ppo_parity(false, s, 100_000, &mut |_| {})),
            ),
        ];
        for (algo, steps, run) in runs {
            let mut sum = 0.0;
            for seed in 0..5 {
                let r = run(seed)?;
                sum += r;
                println!("learning={algo} env=pendulum steps={steps} seed={seed} mean_return={r:.2}");
            }
            println!("learning={algo} env=pendulum seeds=5 mean_return={:.2}", sum / 5.0);
        }
    }
    Ok(())
}
