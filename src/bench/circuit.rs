//! Racing speed on a real circuit, the unit f1tenth_gym is compared in (docs/speed.md,
//! tools/f110-bench.sh): a generated 400 m circuit 2.2 m wide (an F1TENTH-sized track, no
//! outside files), a LiDAR of 1,081 beams over 270 degrees and 30 m on every car, 1, 2 and 8
//! cars in one world at the default control rate (30 Hz), every car scanning once a control
//! period. Like f1tenth_gym's anchor (anchors/f110/bench_f110.py) every car gets one constant
//! control (2 m/s, 0.02 rad) and all cars go back to their start poses, 3 m apart along the
//! centre line, when any car touches something.

use super::median;
use super::sim::median_s;
use agvrl_sim::sensors::LidarConfig;
use agvrl_sim::{CircuitSettings, Control, MapTrack, PlanarPose, SceneSource, Sim, SimConfig, SimSettings};
use std::hint::black_box;
use std::time::Instant;

/// The circuit's seed: `agvrl circuit --seed 7 --set length_m=[400,400] --set
/// width_m=[2.2,2.2]` writes the same circuit as a map (tools/f110-bench.sh does).
pub const SEED: u64 = 7;
/// Lap length and width of the circuit, metres.
pub const LAP_M: f32 = 400.0;
pub const WIDTH_M: f32 = 2.2;
/// Car counts, as f1tenth_gym's side is run.
const CARS: [usize; 3] = [1, 2, 8];
/// Start poses this far apart along the centre line, metres (bench_f110.py's SPACING).
const SPACING_M: f32 = 3.0;
/// The constant control of every car (bench_f110.py's SPEED and STEER).
const SPEED_MPS: f64 = 2.0;
const STEER_RAD: f64 = 0.02;

/// The circuit the figures are taken on.
pub fn track() -> Option<MapTrack> {
    let settings = CircuitSettings {
        length_m: [LAP_M, LAP_M],
        width_m: [WIDTH_M, WIDTH_M],
        ..Default::default()
    };
    MapTrack::generated(SEED, &settings).ok().map(|(t, _)| t)
}

/// F1TENTH's LiDAR (Hokuyo UST-10LX as f1tenth_gym's 1,080 beams, plus the centre beam).
fn lidar() -> LidarConfig {
    LidarConfig {
        n_rays: 1081,
        fov_deg: 270.0,
        range_min_m: 0.05,
        range_max_m: 30.0,
    }
}

/// `n` poses `SPACING_M` apart along the centre line from its first point, heading along it.
fn start_poses(line: &[[f32; 2]], n: usize) -> Vec<PlanarPose> {
    let mut out = Vec::with_capacity(n);
    let (mut s, mut k) = (0.0f32, 0usize);
    for i in 0..n {
        let want = i as f32 * SPACING_M;
        while k + 2 < line.len() {
            let seg = (line[k + 1][0] - line[k][0]).hypot(line[k + 1][1] - line[k][1]);
            if s + seg > want {
                break;
            }
            s += seg;
            k += 1;
        }
        let (a, b) = (line[k], line[k + 1]);
        let len = (b[0] - a[0]).hypot(b[1] - a[1]).max(1e-6);
        let t = ((want - s) / len).clamp(0.0, 1.0);
        out.push(PlanarPose {
            x_m: a[0] + t * (b[0] - a[0]),
            y_m: a[1] + t * (b[1] - a[1]),
            yaw_rad: (b[1] - a[1]).atan2(b[0] - a[0]),
        });
    }
    out
}

/// The throttle whose steady wheel speed drives the car at `mps` (bisection).
fn throttle_for(sim: &Sim, mps: f64) -> f64 {
    let drive = sim.nominal_params().drive;
    let r = sim.vehicle().drive_radius_m() as f64;
    let (mut lo, mut hi) = (0.0, 1.0);
    for _ in 0..50 {
        let mid = 0.5 * (lo + hi);
        if drive.steady_state(mid) * r < mps {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// One world of `cars` cars on the circuit, its start poses and controls, steps and resets.
struct Race {
    cars: usize,
    sim: Sim,
    poses: Vec<PlanarPose>,
    controls: Vec<Control>,
    resets: u64,
    /// Control steps driven (the share of them that skipped rapier: `free_flight_pct`).
    stepped: u64,
    times: Vec<f64>,
}

impl Race {
    fn drive(&mut self, n: usize) {
        self.stepped += n as u64;
        for _ in 0..n {
            let _ = self.sim.step_cars(&self.controls);
            let mut hit = false;
            for i in 0..self.cars {
                black_box(self.sim.lidar_scan(i));
                hit |= !self.sim.car(i).contacts().is_empty() || self.sim.car(i).flipped();
            }
            if hit {
                self.resets += 1;
                let _ = self.sim.reset_cars(&self.poses);
            }
        }
    }
}

/// The circuit figures, one line per car count. `quick` shortens the runs.
pub(super) fn run(quick: bool) -> Vec<String> {
    let reps = if quick { 3 } else { 7 };
    let steps = if quick { 60 } else { 600 };
    let Some(track) = track() else {
        return vec![format!("circuit=circuit-{SEED} error=generation_failed")];
    };
    let lap_m = track.lap_length_m();
    let settings = SimSettings {
        lidar: lidar(),
        ..Default::default()
    };
    let dt = settings.control_period_s;
    let mut races = Vec::new();
    let mut out = Vec::new();
    for cars in CARS {
        let cfg = SimConfig {
            scene: SceneSource::Map(Box::new(track.clone())),
            settings: settings.clone(),
        };
        let mut sim = match Sim::with_cars(cfg, cars) {
            Ok(s) => s,
            Err(e) => {
                out.push(format!(
                    "circuit=circuit-{SEED} cars={cars} error={}",
                    e.to_string().replace(' ', "_")
                ));
                continue;
            }
        };
        let poses = start_poses(&track.centreline, cars);
        if sim.reset_cars(&poses).is_err() {
            out.push(format!("circuit=circuit-{SEED} cars={cars} error=reset_failed"));
            continue;
        }
        let throttle = throttle_for(&sim, SPEED_MPS);
        let controls = vec![
            Control {
                throttle,
                steering_rad: STEER_RAD,
            };
            cars
        ];
        races.push(Race {
            cars,
            sim,
            poses,
            controls,
            resets: 0,
            stepped: 0,
            times: Vec::new(),
        });
    }
    for r in races.iter_mut() {
        r.drive(steps / 5);
    }
    // Every car count timed in turn in each repetition, so that all see the same machine.
    for _ in 0..reps {
        for r in races.iter_mut() {
            let t0 = Instant::now();
            r.drive(steps);
            r.times.push(t0.elapsed().as_secs_f64());
        }
    }
    for mut r in races {
        let wall = median(std::mem::take(&mut r.times));
        // One scan alone, from the first start pose (where the time of a step goes).
        let _ = r.sim.reset_cars(&r.poses);
        let scan_s = median_s(reps, || {
            for _ in 0..50 {
                black_box(r.sim.lidar_scan(0));
            }
        }) / 50.0;
        let c = r.cars;
        out.push(format!(
            "circuit=circuit-{SEED} lap_m={lap_m:.1} width_m={WIDTH_M} cars={c} beams=1081 fov_deg=270 control_hz={:.0} \
             circuit_cars{c}_sim_s_per_wall_s={:.1} circuit_cars{c}_scans_per_s={:.0} world_steps_per_s={:.0} \
             lidar_scan_us={:.1} free_flight_pct={:.1} resets={} reps={reps}",
            1.0 / dt,
            steps as f64 * dt / wall,
            (c * steps) as f64 / wall,
            steps as f64 / wall,
            scan_s * 1e6,
            100.0 * r.sim.free_flight_steps() as f64 / r.stepped.max(1) as f64,
            r.resets
        ));
    }
    out
}
