//! Speed figures of the envs as `key=value` lines: single-thread steps per second for every
//! id (random actions, resets included), the task layer's overhead over the bare simulator,
//! and VecEnv throughput on 1 and 2 threads.

use crate::registry::scene_of;
use crate::{ENV_IDS, Env, VecEnv, make};
use agvrl_sim::bench::{median_s, wander};
use agvrl_sim::{SceneSource, Sim, SimConfig};
use std::hint::black_box;

fn actions(t: usize, n: usize, dim: usize) -> Vec<f32> {
    (0..n * dim)
        .map(|k| ((((t * 7919 + k * 104_729) % 2001) as f32) / 1000.0) - 1.0)
        .collect()
}

fn env_rate(env: &mut dyn Env, steps: usize, reps: usize) -> f64 {
    let dim = env.action_space().dim();
    let _ = env.reset(Some(0));
    let mut t = 0;
    let mut run = |n: usize| {
        for _ in 0..n {
            t += 1;
            let a = actions(t, 1, dim);
            match env.step(&a) {
                Ok(st) if st.done() => {
                    let _ = env.reset(None);
                }
                Ok(st) => {
                    black_box(st);
                }
                Err(_) => {
                    let _ = env.reset(None);
                }
            }
        }
    };
    run(steps / 5);
    steps as f64 / median_s(reps, || run(steps))
}

/// Env figures. `quick` shortens the runs.
pub fn run(quick: bool) -> Vec<String> {
    let reps = if quick { 3 } else { 5 };
    let steps = if quick { 200 } else { 2000 };
    let mut out = Vec::new();
    for id in ENV_IDS {
        let Ok(mut env) = make(id, &crate::EnvConfig::default()) else {
            continue;
        };
        let rate = env_rate(env.as_mut(), steps, reps);
        let mut line = format!("env={id} steps_per_s={rate:.0}");
        if let Some(scene) = scene_of(id) {
            // The same steps on the bare simulator (physics + one LiDAR scan).
            let mut sim = Sim::new(SimConfig {
                scene: SceneSource::Builtin(scene.into()),
                ..SimConfig::default()
            })
            .ok();
            if let Some(sim) = sim.as_mut() {
                let spawn = sim.default_spawn();
                let mut x = 0.37;
                let sim_rate = steps as f64
                    / median_s(reps, || {
                        for _ in 0..steps {
                            if sim.steps() > 150 || !sim.contacts().is_empty() {
                                let _ = sim.reset(spawn);
                            }
                            let _ = sim.step(wander(&mut x));
                            black_box(sim.lidar_scan());
                        }
                    });
                line.push_str(&format!(
                    " sim_steps_per_s={sim_rate:.0} task_overhead_pct={:.1}",
                    100.0 * (sim_rate / rate - 1.0)
                ));
            }
        }
        out.push(format!("{line} reps={reps}"));
    }
    for (id, n_envs) in [
        ("racing-oval", 8),
        ("racing-oval", 16),
        ("search-outdoor-50", 8),
        ("search-outdoor-50", 16),
        ("pendulum", 8),
    ] {
        let mut rates = Vec::new();
        for threads in [1, 2] {
            let Ok(envs) = (0..n_envs)
                .map(|_| make(id, &crate::EnvConfig::default()))
                .collect::<Result<Vec<_>, _>>()
            else {
                continue;
            };
            let Ok(mut v) = VecEnv::new(envs, threads) else {
                continue;
            };
            let dim = v.action_space().dim();
            let _ = v.reset(Some(0));
            // Whole rounds, at least 2,000 env steps: the speed-up is a ratio of medians.
            let rounds = steps.max(2000) / n_envs;
            let mut t = 0;
            let s = median_s(reps, || {
                for _ in 0..rounds {
                    t += 1;
                    black_box(v.step(&actions(t, n_envs, dim)).ok());
                }
            });
            let rate = (rounds * n_envs) as f64 / s;
            rates.push(rate);
            out.push(format!(
                "env={id} n_envs={n_envs} threads={threads} vec_steps_per_s={rate:.0} reps={reps}"
            ));
        }
        if let [one, two] = rates[..] {
            out.push(format!(
                "env={id} n_envs={n_envs} vec_speedup_2_threads={:.2}",
                two / one
            ));
        }
    }
    out
}
