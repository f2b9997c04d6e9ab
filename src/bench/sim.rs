//! Speed figures of the simulator as `key=value` lines (medians over repetitions after a
//! warm-up, single thread). `agvrl bench` prints them.

use agvrl_sim::{Control, DynamicsMode, PlanarPose, SCENE_IDS, SceneSource, Sim, SimConfig};
use std::hint::black_box;
use std::time::Instant;

/// Median of `reps` timings (seconds) of `f`.
pub(super) fn median_s(reps: usize, mut f: impl FnMut()) -> f64 {
    let t: Vec<f64> = (0..reps)
        .map(|_| {
            let t0 = Instant::now();
            f();
            t0.elapsed().as_secs_f64()
        })
        .collect();
    agvrl_run::stats::median(&t)
}

/// A deterministic pseudo-random control sequence (logistic map), so every run drives the same.
pub(super) fn wander(x: &mut f64) -> Control {
    *x = (*x * 3.9 * (1.0 - *x)).clamp(1e-6, 1.0 - 1e-6);
    Control {
        throttle: 0.4 + 0.6 * *x,
        steering_rad: 0.36 * (2.0 * *x - 1.0),
    }
}

/// Simulator figures per scene and dynamics mode. `quick` shortens the runs (CI smoke test).
pub(super) fn run(quick: bool) -> Vec<String> {
    let reps = if quick { 3 } else { 7 };
    let steps = if quick { 100 } else { 1000 };
    let mut out = Vec::new();
    // The built-in scenes, and the shipped map-file tracks (from the working directory).
    let mut scenes: Vec<(String, SceneSource)> = SCENE_IDS
        .iter()
        .map(|id| (id.to_string(), SceneSource::Builtin(id.to_string())))
        .collect();
    for t in ["bean", "sweepers"] {
        match agvrl_sim::MapTrack::load(std::path::Path::new(&format!("assets/tracks/{t}.yaml"))) {
            Ok(m) => scenes.push((format!("track-{t}"), SceneSource::Map(Box::new(m)))),
            Err(_) => out.push(format!("scene=track-{t} error=assets/tracks/{t}.yaml_not_found")),
        }
    }
    for mode in [DynamicsMode::Raycast, DynamicsMode::Multibody] {
        for (id, scene) in &scenes {
            let cfg = SimConfig {
                scene: scene.clone(),
                settings: agvrl_sim::SimSettings {
                    dynamics: mode,
                    ..Default::default()
                },
            };
            let load_s = median_s(reps.min(3), || {
                black_box(Sim::new(cfg.clone()).ok());
            });
            let Ok(mut sim) = Sim::new(cfg.clone()) else {
                out.push(format!("scene={id} mode={} error=load_failed", mode_name(mode)));
                continue;
            };
            let spawn = sim.default_spawn();
            let mut x = 0.31;
            let mut stepped = 0u64;
            // Episodes restart when the car strays, so every scene is timed while driving.
            let mut drive = |sim: &mut Sim, n: usize, scan: bool| {
                stepped += n as u64;
                for _ in 0..n {
                    if sim.steps() > 150 || !sim.car(0).contacts().is_empty() {
                        let _ = sim.reset(spawn);
                    }
                    let _ = sim.step(wander(&mut x));
                    if scan {
                        black_box(sim.lidar_scan(0));
                    }
                }
            };
            drive(&mut sim, steps / 5, true);
            let step_s = median_s(reps, || drive(&mut sim, steps, true)) / steps as f64;
            let phys_s =
                median_s(reps, || drive(&mut sim, steps, false)) / steps as f64 / sim.config().settings.substeps as f64;
            let scan_s = median_s(reps, || {
                for _ in 0..steps {
                    black_box(sim.lidar_scan(0));
                }
            }) / steps as f64;
            let reset_s = median_s(reps, || {
                for _ in 0..100 {
                    let _ = sim.reset(PlanarPose { ..spawn });
                }
            }) / 100.0;
            // Share of the control steps that skipped rapier's pipeline (SimSettings::free_flight).
            let free_pct = 100.0 * sim.free_flight_steps() as f64 / stepped.max(1) as f64;
            out.push(format!(
                "scene={id} mode={} physics_step_us={:.1} lidar_scan_us={:.1} sim_steps_per_s={:.0} free_flight_pct={free_pct:.1} scene_load_ms={:.1} reset_us={:.2} reps={reps}",
                mode_name(mode),
                phys_s * 1e6,
                scan_s * 1e6,
                1.0 / step_s,
                load_s * 1e3,
                reset_s * 1e6
            ));
        }
    }
    out
}

/// Camera figures: RGB + depth + segmentation per frame, milliseconds, at two resolutions.
pub(super) fn camera(quick: bool) -> Vec<String> {
    let reps = if quick { 3 } else { 9 };
    let mut out = Vec::new();
    for id in ["oval", "outdoor-50", "urban-50"] {
        for (w, h) in [(160u32, 120u32), (400, 400)] {
            let camera = Some(agvrl_sim::sensors::CameraConfig {
                width: w,
                height: h,
                ..Default::default()
            });
            let cfg = SimConfig {
                scene: SceneSource::Builtin(id.to_string()),
                settings: agvrl_sim::SimSettings {
                    camera,
                    ..Default::default()
                },
            };
            let Ok(sim) = Sim::new(cfg) else { continue };
            black_box(sim.car(0).camera_frame());
            let s = median_s(reps, || {
                black_box(sim.car(0).camera_frame());
            });
            out.push(format!(
                "scene={id} camera_ms={:.2} res={w}x{h} threads={} reps={reps}",
                s * 1e3,
                rayon::current_num_threads()
            ));
        }
    }
    out
}

fn mode_name(m: DynamicsMode) -> &'static str {
    match m {
        DynamicsMode::Raycast => "raycast",
        DynamicsMode::Multibody => "multibody",
    }
}
