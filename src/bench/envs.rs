//! Speed figures of the envs as `key=value` lines: single-thread steps per second for every
//! id (random actions, resets included), the task layer's overhead over the bare simulator,
//! and VecEnv throughput on 1 and 2 threads.

use super::median;
use super::sim::wander;
use agvrl_envs::registry::scene_of;
use agvrl_envs::{ENV_IDS, Env, VecEnv, make};
use agvrl_sim::{SceneSource, Sim, SimConfig};
use anyhow::Context as _;
use std::hint::black_box;
use std::ops::Range;
use std::time::Instant;

/// The shipped search policy and its settings (read from the checkout the binary was built in).
const SHIPPED_SEARCH: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/assets/policies/search.agvrl");

fn action_elem(t: usize, k: usize) -> f32 {
    ((((t * 7919 + k * 104_729) % 2001) as f32) / 1000.0) - 1.0
}

fn actions(t: usize, n: usize, dim: usize) -> Vec<f32> {
    (0..n * dim).map(|k| action_elem(t, k)).collect()
}

fn timed_s(f: impl FnOnce()) -> f64 {
    let t0 = Instant::now();
    f();
    t0.elapsed().as_secs_f64()
}

/// Env figures. `quick` shortens the runs.
pub(super) fn run(quick: bool) -> Vec<String> {
    let reps = if quick { 3 } else { 7 };
    let steps = if quick { 200 } else { 2000 };
    let mut out = Vec::new();
    for id in ENV_IDS {
        let Ok(mut env) = make(id, &agvrl_envs::EnvConfig::default()) else {
            continue;
        };
        let _ = env.reset(Some(0));
        let env = std::slice::from_mut(&mut env);
        let mut t = 1;
        let mut run = |n: usize| {
            drive(env, 1, t..t + n);
            t += n;
        };
        run(steps / 5);
        // The same number of steps on the bare simulator (physics + one LiDAR scan), timed in
        // turn with the env's in every repetition so that both see the same machine.
        let mut sim = scene_of(id).and_then(|scene| {
            Sim::new(SimConfig {
                scene: SceneSource::Builtin(scene.into()),
                ..SimConfig::default()
            })
            .ok()
        });
        let mut x = 0.37;
        let (mut env_s, mut sim_s) = (Vec::new(), Vec::new());
        for _ in 0..reps {
            env_s.push(timed_s(|| run(steps)));
            if let Some(sim) = sim.as_mut() {
                let spawn = sim.default_spawn();
                sim_s.push(timed_s(|| {
                    for _ in 0..steps {
                        if sim.steps() > 150 || !sim.car(0).contacts().is_empty() {
                            let _ = sim.reset(spawn);
                        }
                        let _ = sim.step(wander(&mut x));
                        black_box(sim.lidar_scan(0));
                    }
                }));
            }
        }
        let rate = steps as f64 / median(env_s.clone());
        let mut line = format!("env={id} steps_per_s={rate:.0}");
        if !sim_s.is_empty() {
            let overhead = median(env_s.iter().zip(&sim_s).map(|(e, s)| e / s).collect());
            line.push_str(&format!(
                " sim_steps_per_s={:.0} task_overhead_pct={:.1}",
                steps as f64 / median(sim_s),
                100.0 * (overhead - 1.0)
            ));
        }
        out.push(format!("{line} reps={reps}"));
    }
    out.extend(races(steps, reps));
    out.extend(shipped_search(steps, reps));
    out.extend(camera_obs(steps, reps));
    for (id, n_envs) in [
        ("racing-oval", 8),
        ("racing-oval", 16),
        ("search-outdoor-50", 8),
        ("search-outdoor-50", 16),
        ("pendulum", 8),
    ] {
        out.extend(vec_figures(id, n_envs, steps, if quick { 3 } else { 9 }));
    }
    out
}

/// Races of 1, 2, 4 and 8 cars on the shipped map-file tracks (read from the working
/// directory): world steps per second with every car acting at random (sensors, tasks and race
/// bookkeeping included) from the grid, a new race whenever a car crashes; `per_car` is
/// cars x world steps/s over the lone car's. The four races are timed in turn in every
/// repetition, so that all see the same machine.
fn races(steps: usize, reps: usize) -> Vec<String> {
    use agvrl_envs::MultiEnv as _;
    let mut out = Vec::new();
    for track in ["bean", "sweepers"] {
        let yaml = std::path::PathBuf::from(format!("assets/tracks/{track}.yaml"));
        let mut envs = Vec::new();
        for cars in [1usize, 2, 4, 8] {
            let cfg = agvrl_envs::EnvConfig {
                track: Some(agvrl_envs::TrackSetting::Path(yaml.clone())),
                race: Some(agvrl_envs::RaceSettings {
                    cars,
                    ..Default::default()
                }),
                ..Default::default()
            };
            match agvrl_envs::make_race("racing-duel", &cfg) {
                Ok(mut e) => {
                    let _ = e.reset(Some(0));
                    envs.push((cars, e, 0usize, 0u64, Vec::new()));
                }
                Err(e) => out.push(format!(
                    "race=track-{track} cars={cars} error={}",
                    e.to_string().replace(' ', "_")
                )),
            }
        }
        let drive = |cars: usize, env: &mut agvrl_envs::RaceEnv, t: &mut usize, races: &mut u64, n: usize| {
            for _ in 0..n {
                *t += 1;
                let a: Vec<Vec<f32>> = (0..cars)
                    .map(|k| vec![action_elem(*t, 2 * k), action_elem(*t, 2 * k + 1)])
                    .collect();
                let again = match env.step(&a) {
                    Ok(st) => st.agents.iter().any(|s| s.as_ref().is_none_or(|s| s.done())),
                    Err(_) => true,
                };
                if again {
                    *races += 1;
                    let _ = env.reset(Some(*races));
                }
            }
        };
        for (cars, env, t, races, _) in envs.iter_mut() {
            drive(*cars, env, t, races, steps / 5);
        }
        for _ in 0..reps {
            for (cars, env, t, races, times) in envs.iter_mut() {
                times.push(timed_s(|| drive(*cars, env, t, races, steps)));
            }
        }
        let mut lone = None;
        for (cars, env, t, races, times) in envs {
            let rate = steps as f64 / median(times);
            let base = *lone.get_or_insert(rate);
            out.push(format!(
                "race=track-{track} cars={cars} world_steps_per_s={rate:.0} per_car={:.2} free_flight_pct={:.1} races={races} reps={reps}",
                cars as f64 * rate / base,
                100.0 * env.sim().free_flight_steps() as f64 / (t as f64).max(1.0)
            ));
        }
    }
    out
}

/// The shipped search policy driving its own car (270 degree LiDAR, reverse, the safety filter
/// and its back-out; and the bare policy, filter off), deterministic actions, one thread, policy
/// inference included: what the search evaluation steps. The filter checks paths against the
/// points it remembers, so these steps cost more than the bare task's, most where walls stand
/// close.
fn shipped_search(steps: usize, reps: usize) -> Vec<String> {
    let path = std::path::Path::new(SHIPPED_SEARCH);
    let loaded = (|| -> anyhow::Result<_> {
        let policy = agvrl_rl::Policy::load(path)?;
        let src = agvrl_run::PolicySettings::of_policy(path, policy.data(), &[])?;
        let cfg = src
            .run
            .with_context(|| format!("{} carries no settings", path.display()))?;
        Ok((policy, cfg))
    })();
    let (mut policy, cfg) = match loaded {
        Ok(x) => x,
        Err(e) => return vec![format!("settings=shipped_search error=\"{e}\"")],
    };
    let mut out = Vec::new();
    for (id, filter) in [
        ("search-urban-20", true),
        ("search-outdoor-50", true),
        ("search-urban-20", false),
    ] {
        let mut env_cfg = cfg.eval_env_config();
        env_cfg.safety_filter.enabled = filter;
        let Ok(mut env) = make(id, &env_cfg) else {
            continue;
        };
        let Ok((mut obs, _)) = env.reset(Some(0)) else { continue };
        let mut run = |n: usize| {
            for _ in 0..n {
                let Ok(a) = policy.act(&obs, true) else { return };
                obs = match env.step(&a) {
                    Ok(st) if !st.done() => st.obs,
                    _ => env.reset(None).map(|r| r.0).unwrap_or_default(),
                };
            }
        };
        run(steps / 5);
        let t = (0..reps).map(|_| timed_s(|| run(steps))).collect();
        out.push(format!(
            "env={id} settings=shipped_search filter={} policy=shipped steps_per_s={:.0} reps={reps}",
            if filter { "on" } else { "off" },
            steps as f64 / median(t)
        ));
    }
    out
}

/// The camera-only racing observation (configs/racing-camera.toml: a 64x48 depth image, no
/// LiDAR in the observation) against the LiDAR one on the same car, one thread, timed in turn
/// in every repetition: `camera_obs_us` is the extra time per step (render and observation).
fn camera_obs(steps: usize, reps: usize) -> Vec<String> {
    const CONFIG: &str = include_str!("../../configs/racing-camera.toml");
    let run = || -> anyhow::Result<String> {
        let cam = agvrl_run::RunConfig::from_toml(CONFIG, "configs/racing-camera.toml")?.env_config;
        let mut envs = [
            make("racing-oval", &cam)?,
            make("racing-oval", &agvrl_envs::EnvConfig::default())?,
        ];
        let (mut cam_s, mut lidar_s, mut t) = (Vec::new(), Vec::new(), 1);
        for e in envs.iter_mut() {
            e.reset(Some(0))?;
        }
        for r in 0..=reps {
            let c = timed_s(|| drive(&mut envs[..1], 1, t..t + steps));
            let l = timed_s(|| drive(&mut envs[1..], 1, t..t + steps));
            t += steps;
            if r > 0 {
                cam_s.push(c);
                lidar_s.push(l);
            }
        }
        let per_step = |v: Vec<f64>| median(v) * 1e6 / steps as f64;
        let (c, l) = (per_step(cam_s), per_step(lidar_s));
        Ok(format!(
            "camera_obs_us={:.0} env=racing-oval image=depth-64x48 camera_env_step_us={c:.0} lidar_env_step_us={l:.0} threads=1 reps={reps}",
            c - l
        ))
    };
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build();
    match one.map_err(anyhow::Error::from).and_then(|p| p.install(run)) {
        Ok(line) => vec![line],
        Err(e) => vec![format!("camera_obs_error=\"{e}\"")],
    }
}

/// `n` fresh envs of `id`, reset with seeds `0..n`.
fn envs_of(id: &str, n: usize) -> Option<Vec<Box<dyn Env>>> {
    (0..n)
        .map(|i| {
            let mut e = make(id, &agvrl_envs::EnvConfig::default()).ok()?;
            e.reset(Some(i as u64)).ok()?;
            Some(e)
        })
        .collect()
}

/// Step `envs` through `rounds` on the calling thread, env `i` with VecEnv's actions for env
/// `i % period`, resetting ended episodes as VecEnv does.
fn drive(envs: &mut [Box<dyn Env>], period: usize, rounds: Range<usize>) {
    let mut a = Vec::new();
    let dim = envs.first().map_or(0, |e| e.action_space().dim());
    for t in rounds {
        for (i, e) in envs.iter_mut().enumerate() {
            a.clear();
            a.extend((0..dim).map(|j| action_elem(t, (i % period) * dim + j)));
            match e.step(&a) {
                Ok(st) if st.done() => {
                    let _ = e.reset(None);
                }
                Ok(st) => {
                    black_box(st);
                }
                Err(_) => {
                    let _ = e.reset(None);
                }
            }
        }
    }
}

/// VecEnv on 1 and 2 threads, and beside it the ceiling of this machine: two threads that never
/// synchronise against one thread doing the same work. The four runs alternate in every
/// repetition and each speed-up is the median of per-repetition ratios, so a neighbour's load
/// that comes and goes hits both sides of a ratio alike. Copies of an env share its seed and
/// actions and so drive the same episodes: a step's cost depends on the episode's phase (a fast
/// car costs ~40 % more than one just spawned), and each ratio compares equal work.
/// `vec_efficiency` is the share of the ceiling VecEnv keeps (its per-step barrier and result
/// assembly cost the rest).
fn vec_figures(id: &str, n_envs: usize, steps: usize, reps: usize) -> Vec<String> {
    // The ceiling's threads each step a copy of the first half of the envs, the single thread
    // both copies: equal work on each side and the same memory as VecEnv's.
    let half = (n_envs / 2).max(1);
    let (Some(e1), Some(e2), Some(mut f1), Some(f1b), Some(mut f2), Some(mut f3)) = (
        envs_of(id, n_envs),
        envs_of(id, n_envs),
        envs_of(id, half),
        envs_of(id, half),
        envs_of(id, half),
        envs_of(id, half),
    ) else {
        return Vec::new();
    };
    let (Ok(mut v1), Ok(mut v2)) = (VecEnv::new(e1, 1), VecEnv::new(e2, 2)) else {
        return Vec::new();
    };
    f1.extend(f1b);
    let dim = v1.action_space().dim();
    let _ = v1.reset(Some(0));
    let _ = v2.reset(Some(0));
    // Whole rounds, at least 2,000 env steps per run.
    let rounds = steps.max(2000) / n_envs;
    let acts: Vec<Vec<f32>> = (0..rounds).map(|t| actions(t, n_envs, dim)).collect();
    let mut t = [Vec::new(), Vec::new(), Vec::new(), Vec::new()];
    for rep in 0..=reps {
        let s = [
            timed_s(|| {
                for a in &acts {
                    black_box(v1.step(a).ok());
                }
            }),
            timed_s(|| {
                for a in &acts {
                    black_box(v2.step(a).ok());
                }
            }),
            timed_s(|| drive(&mut f1, half, 0..rounds)),
            timed_s(|| {
                std::thread::scope(|sc| {
                    sc.spawn(|| drive(&mut f3, half, 0..rounds));
                    drive(&mut f2, half, 0..rounds);
                });
            }),
        ];
        // The first repetition warms caches and the worker thread up.
        if rep > 0 {
            for (v, x) in t.iter_mut().zip(s) {
                v.push(x);
            }
        }
    }
    let ratio = |a: usize, b: usize| median(t[a].iter().zip(&t[b]).map(|(x, y)| x / y).collect());
    let (vec_speedup, free_speedup) = (ratio(0, 1), ratio(2, 3));
    let steps_run = (rounds * n_envs) as f64;
    vec![
        format!(
            "env={id} n_envs={n_envs} threads=1 vec_steps_per_s={:.0} reps={reps}",
            steps_run / median(t[0].clone())
        ),
        format!(
            "env={id} n_envs={n_envs} threads=2 vec_steps_per_s={:.0} reps={reps}",
            steps_run / median(t[1].clone())
        ),
        format!(
            "env={id} n_envs={n_envs} vec_speedup_2_threads={vec_speedup:.2} \
             free_speedup_2_threads={free_speedup:.2} vec_efficiency={:.2}",
            vec_speedup / free_speedup
        ),
    ]
}

#[cfg(test)]
mod tests {
    use super::vec_figures;

    #[test]
    fn vec_figures_report_rates_speedups_and_efficiency() {
        let lines = vec_figures("pendulum", 4, 200, 2);
        assert_eq!(lines.len(), 3, "{lines:?}");
        let value = |key: &str| -> f64 {
            let kv = lines
                .iter()
                .flat_map(|l| l.split(' '))
                .find(|kv| kv.starts_with(&format!("{key}=")))
                .unwrap_or_else(|| panic!("no {key} in {lines:?}"));
            kv[key.len() + 1..].parse().unwrap()
        };
        for key in ["vec_speedup_2_threads", "free_speedup_2_threads", "vec_efficiency"] {
            let v = value(key);
            assert!(v.is_finite() && v > 0.0, "{key}={v}");
        }
        let eff = value("vec_efficiency");
        let (v, f) = (value("vec_speedup_2_threads"), value("free_speedup_2_threads"));
        // All three are printed to 2 decimals: allow their rounding, carried through v / f.
        let tol = 0.005 + 0.005 / f + 0.005 * v / (f * f) + 1e-9;
        assert!((eff - v / f).abs() <= tol, "{eff} vs {v} / {f}");
        assert!(lines[0].contains("threads=1 vec_steps_per_s=") && lines[1].contains("threads=2"));
    }
}
