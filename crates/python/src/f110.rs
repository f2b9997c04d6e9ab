//! `F110Sim`: the simulator under `agvrl.f110.F110Env` (f1tenth_gym's interface). Several cars
//! of one vehicle in one world on a map_server track (`Sim::with_cars`, so cars collide for
//! real), a LiDAR of f1tenth_gym's beams, and its action: a steering angle and a speed, the speed
//! held by the classical racers' speed controller (`CarLimits::throttle`). Lap counting, `done`
//! and the observation dict are Python's (python/agvrl/f110.py).

use crate::guard;
use agvrl_envs::drivers::CarLimits;
use agvrl_sim::sensors::LidarConfig;
use agvrl_sim::{Control, MapTrack, PlanarPose, SceneSource, Sim, SimConfig, SimError, SimSettings};
use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray1, PyArray2, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use std::path::PathBuf;
use std::sync::Mutex;

/// f1tenth_gym's LiDAR (`RaceCar` and `ScanSimulator2D` defaults): beams, field of view (rad),
/// range (m).
const BEAMS: usize = 1080;
const FOV_RAD: f32 = 4.7;
const RANGE_M: f32 = 30.0;
/// The longest physics substep a control period is split into, seconds (agvrl's default:
/// 1/30 s in 4 substeps).
const SUBSTEP_S: f64 = 1.0 / 120.0;

/// `(scans (N, beams), poses (N, 3) [x, y, theta], velocities (N, 3) [vx, vy, yaw rate],
/// collisions (N,) 0/1, time_s)`.
type State<'py> = (
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray1<f64>>,
    f64,
);

struct Inner {
    sim: Sim,
    limits: CarLimits,
    /// The speed controller's proportional gain, throttle per m/s.
    speed_gain: f64,
    /// Whether each car has touched a wall or another car since the last reset.
    collided: Vec<bool>,
    ready: bool,
}

/// The raw numbers of one observation (built without the GIL).
struct Raw {
    scans: Vec<f64>,
    poses: Vec<f64>,
    vels: Vec<f64>,
    collisions: Vec<f64>,
    time_s: f64,
}

fn sim_err(e: SimError) -> PyErr {
    match e {
        SimError::Invalid { .. } => PyValueError::new_err(e.to_string()),
        _ => PyRuntimeError::new_err(e.to_string()),
    }
}

impl Inner {
    fn raw(&mut self) -> Raw {
        let n = self.sim.n_cars();
        let mut raw = Raw {
            scans: Vec::with_capacity(n * BEAMS),
            poses: Vec::with_capacity(3 * n),
            vels: Vec::with_capacity(3 * n),
            collisions: Vec::with_capacity(n),
            time_s: self.sim.time_s(),
        };
        for i in 0..n {
            raw.scans
                .extend(self.sim.lidar_scan(i).ranges.iter().map(|&r| f64::from(r)));
            let p = self.sim.car(i).pose2();
            raw.poses
                .extend([f64::from(p.x_m), f64::from(p.y_m), f64::from(p.yaw_rad)]);
            // Body-frame velocity (forward, leftward) and the yaw rate.
            let imu = self.sim.car(i).imu();
            raw.vels.extend([imu.lin_vel_b[0], imu.lin_vel_b[1], imu.ang_vel_w[2]]);
            self.collided[i] |= !self.sim.car(i).contacts().is_empty() || !self.sim.car(i).car_contacts().is_empty();
            raw.collisions.push(f64::from(u8::from(self.collided[i])));
        }
        raw
    }
}

fn state<'py>(py: Python<'py>, r: Raw) -> PyResult<State<'py>> {
    let n = r.collisions.len();
    let shaped = |v: Vec<f64>, cols: usize| {
        Array2::from_shape_vec((n, cols), v)
            .map(|a| a.into_pyarray(py))
            .map_err(|e| PyRuntimeError::new_err(e.to_string()))
    };
    Ok((
        shaped(r.scans, BEAMS)?,
        shaped(r.poses, 3)?,
        shaped(r.vels, 3)?,
        PyArray1::from_vec(py, r.collisions),
        r.time_s,
    ))
}

/// `rows` as an (n, cols) f64 table, checked finite.
fn table(a: &PyReadonlyArray2<'_, f64>, n: usize, cols: usize, what: &str) -> PyResult<Vec<f64>> {
    if a.shape() != [n, cols] {
        return Err(PyValueError::new_err(format!(
            "{what} must have shape ({n}, {cols}), got {:?}",
            a.shape()
        )));
    }
    let v = a.as_array().iter().copied().collect::<Vec<f64>>();
    if !v.iter().all(|x| x.is_finite()) {
        return Err(PyValueError::new_err(format!("{what} must be finite")));
    }
    Ok(v)
}

/// Several cars on a map track, driven by (steering angle, speed) (`agvrl.f110` wraps it).
#[pyclass(module = "agvrl._core")]
pub struct F110Sim {
    inner: Mutex<Inner>,
    n: usize,
    timestep: f64,
    substeps: u32,
    steer_max: f64,
    top_speed: f64,
    vehicle: String,
}

#[pymethods]
impl F110Sim {
    /// `F110Sim(map_yaml, num_agents, timestep, vehicle, brake_mps2, speed_gain)`: the control
    /// period is `timestep`, split into physics substeps of at most 1/120 s.
    #[new]
    #[pyo3(signature = (map_yaml, num_agents=1, timestep=0.01, vehicle=None, brake_mps2=3.0, speed_gain=1.0))]
    fn new(
        map_yaml: PathBuf,
        num_agents: usize,
        timestep: f64,
        vehicle: Option<String>,
        brake_mps2: f64,
        speed_gain: f64,
    ) -> PyResult<Self> {
        guard(|| {
            if !(1..=agvrl_sim::MAX_CARS).contains(&num_agents) {
                return Err(PyValueError::new_err(format!(
                    "num_agents must be 1 to {}, got {num_agents}",
                    agvrl_sim::MAX_CARS
                )));
            }
            if !(timestep.is_finite() && timestep > 0.0 && timestep <= 0.1) {
                return Err(PyValueError::new_err(format!(
                    "timestep must be in (0, 0.1] seconds, got {timestep}"
                )));
            }
            for (k, v) in [("brake_mps2", brake_mps2), ("speed_gain", speed_gain)] {
                if !(v.is_finite() && v >= 0.0) {
                    return Err(PyValueError::new_err(format!("{k} must be finite and >= 0, got {v}")));
                }
            }
            let track = MapTrack::load(&map_yaml).map_err(sim_err)?;
            let substeps = ((timestep / SUBSTEP_S) - 1e-9).ceil().max(1.0) as u32;
            let settings = SimSettings {
                vehicle: vehicle.unwrap_or_else(|| SimSettings::default().vehicle),
                control_period_s: timestep,
                substeps,
                brake_mps2,
                lidar: LidarConfig {
                    n_rays: BEAMS,
                    fov_deg: FOV_RAD.to_degrees(),
                    range_min_m: 0.0,
                    range_max_m: RANGE_M,
                },
                ..SimSettings::default()
            };
            let vehicle = settings.vehicle.clone();
            let sim = Sim::with_cars(
                SimConfig {
                    scene: SceneSource::Map(Box::new(track)),
                    settings,
                },
                num_agents,
            )
            .map_err(sim_err)?;
            let limits = CarLimits::of(sim.vehicle(), brake_mps2);
            limits.validate().map_err(|e| PyValueError::new_err(e.to_string()))?;
            let (steer_max, top_speed) = (limits.max_steering_rad, limits.top_speed_mps);
            Ok(Self {
                inner: Mutex::new(Inner {
                    sim,
                    limits,
                    speed_gain,
                    collided: vec![false; num_agents],
                    ready: false,
                }),
                n: num_agents,
                timestep,
                substeps,
                steer_max,
                top_speed,
                vehicle,
            })
        })
    }

    /// Number of cars.
    #[getter]
    fn num_agents(&self) -> usize {
        self.n
    }

    /// The control period, seconds: one `step` advances the world this much.
    #[getter]
    fn timestep(&self) -> f64 {
        self.timestep
    }

    /// Physics substeps per control period.
    #[getter]
    fn substeps(&self) -> u32 {
        self.substeps
    }

    /// The steering limit, rad (steering commands are clamped to +-this).
    #[getter]
    fn steer_max(&self) -> f64 {
        self.steer_max
    }

    /// The car's top speed on flat ground at full throttle, m/s.
    #[getter]
    fn top_speed(&self) -> f64 {
        self.top_speed
    }

    /// The vehicle setting (a built-in name or a vehicle TOML).
    #[getter]
    fn vehicle(&self) -> &str {
        &self.vehicle
    }

    /// LiDAR beams, field of view (rad) and range (m).
    #[getter]
    fn lidar(&self) -> (usize, f32, f32) {
        (BEAMS, FOV_RAD, RANGE_M)
    }

    /// Put the cars at `poses` ((N, 3): x, y, theta), at rest; the state there (no step taken).
    fn reset<'py>(&self, py: Python<'py>, poses: PyReadonlyArray2<'py, f64>) -> PyResult<State<'py>> {
        guard(|| {
            let p = table(&poses, self.n, 3, "poses")?;
            let poses: Vec<PlanarPose> = p
                .chunks(3)
                .map(|r| PlanarPose {
                    x_m: r[0] as f32,
                    y_m: r[1] as f32,
                    yaw_rad: r[2] as f32,
                })
                .collect();
            let raw = py.detach(|| {
                guard(|| {
                    let mut g = crate::lock(&self.inner)?;
                    g.sim.reset_cars(&poses).map_err(sim_err)?;
                    g.collided.iter_mut().for_each(|c| *c = false);
                    g.ready = true;
                    Ok(g.raw())
                })
            })?;
            state(py, raw)
        })
    }

    /// One control period with `actions` ((N, 2): steering angle in rad, speed in m/s).
    fn step<'py>(&self, py: Python<'py>, actions: PyReadonlyArray2<'py, f64>) -> PyResult<State<'py>> {
        guard(|| {
            let a = table(&actions, self.n, 2, "actions")?;
            let raw = py.detach(|| {
                guard(|| {
                    let mut g = crate::lock(&self.inner)?;
                    if !g.ready {
                        return Err(PyRuntimeError::new_err("call reset(poses) before step"));
                    }
                    let controls: Vec<Control> = a
                        .chunks(2)
                        .enumerate()
                        .map(|(i, r)| {
                            let measured = f64::from(g.sim.car(i).forward_speed_mps());
                            Control {
                                throttle: speed_throttle(&g.limits, g.speed_gain, r[1], measured),
                                steering_rad: r[0].clamp(-self.steer_max, self.steer_max),
                            }
                        })
                        .collect();
                    g.sim.step_cars(&controls).map_err(sim_err)?;
                    Ok(g.raw())
                })
            })?;
            state(py, raw)
        })
    }
}

/// The throttle that holds `target_mps` (the classical racers' controller: the drive's
/// steady-state throttle plus `gain` per m/s of error, braking through the ESC's `brake_mps2`);
/// a negative target reverses with the same controller mirrored.
fn speed_throttle(limits: &CarLimits, gain: f64, target_mps: f64, measured_mps: f64) -> f64 {
    if target_mps >= 0.0 {
        limits.throttle(target_mps, Some(measured_mps), gain)
    } else {
        -limits.throttle(-target_mps, Some(-measured_mps), gain)
    }
}
