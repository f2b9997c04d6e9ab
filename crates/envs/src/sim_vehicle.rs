//! `SimVehicle`: the `Vehicle` seam over agvrl-sim, with seeded spawns and per-episode domain
//! randomisation.

use crate::api::{Control, EnvError, MapInfo, SensorFrame, Vehicle};
use agvrl_sim::{PlanarPose, SceneSource, Sim, SimConfig, VehicleParams};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use serde::{Deserialize, Serialize};

/// Where episodes start.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SpawnMode {
    /// Seeded, uniformly over free space (on a track: anywhere on the centre line, facing the
    /// racing direction, with a small lateral and heading jitter).
    #[default]
    Random,
    /// AutoVRL's fixed spawn of the scene.
    Fixed,
    /// Seeded over free space, facing an obstacle between [`RECOVERY_SPAWN_M`]'s bounds within
    /// the spawn view: every episode starts with a recovery (turn away or reverse). Random's
    /// rule where no such pose turns up.
    NearObstacle,
    /// On a track: on the start line (the centre line's start), facing the racing direction,
    /// with Random's lateral and heading jitter, as a race starts. Elsewhere: Random.
    Line,
}

/// Nearest return within the spawn view of a [`SpawnMode::NearObstacle`] start, metres: beyond
/// the search task's 0.6 m termination, within a braking car's reach.
pub const RECOVERY_SPAWN_M: std::ops::Range<f32> = 0.7..1.5;

/// Per-episode domain randomisation: each factor is drawn uniformly in `[1 - x, 1 + x]`, the
/// steering offset in `[-x, x]` rad. All zero: off.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Randomisation {
    /// Relative spread of tyre friction.
    pub friction: f64,
    /// Relative spread of mass.
    pub mass: f64,
    /// Relative spread of C_T.
    pub c_t: f64,
    /// Relative spread of C_d.
    pub c_d: f64,
    /// Relative spread of C_r.
    pub c_r: f64,
    /// Largest steering offset, rad.
    pub steering_offset_rad: f64,
}

impl Randomisation {
    /// The `sim2real` preset: friction +-20 %, mass +-10 %, C_T +-10 %, C_d and C_r +-20 %,
    /// steering offset up to 0.02 rad (about 1 degree of servo trim).
    pub fn sim2real() -> Self {
        Self {
            friction: 0.2,
            mass: 0.1,
            c_t: 0.1,
            c_d: 0.2,
            c_r: 0.2,
            steering_offset_rad: 0.02,
        }
    }

    pub(crate) fn draw(&self, nominal: VehicleParams, rng: &mut StdRng) -> VehicleParams {
        let mut f = |x: f64| {
            if x > 0.0 {
                rng.random_range(1.0 - x..1.0 + x)
            } else {
                1.0
            }
        };
        let mut p = nominal;
        p.tyre_friction *= f(self.friction) as f32;
        p.mass_scale *= f(self.mass) as f32;
        p.drive.c_t *= f(self.c_t);
        p.drive.c_d *= f(self.c_d);
        p.drive.c_r *= f(self.c_r);
        p.steering_offset_rad = if self.steering_offset_rad > 0.0 {
            rng.random_range(-self.steering_offset_rad..self.steering_offset_rad)
        } else {
            0.0
        };
        p
    }
}

/// Clearance kept between a random spawn and any obstacle, metres.
const SPAWN_CLEARANCE_M: f32 = 1.2;
/// Free range the LiDAR sees ahead of a random spawn in an open map, metres...
pub const SPAWN_VIEW_M: f32 = 2.0;
/// ...within this half-angle of straight ahead (AutoVRL's 90 degree fan), whatever the
/// LiDAR's own field of view, so every LiDAR setup draws the same spawns.
const SPAWN_VIEW_HALF_RAD: f32 = std::f32::consts::FRAC_PI_4;
/// Coverage grid cell, metres.
const CELL_M: f32 = 0.5;

/// The simulated vehicle.
pub struct SimVehicle {
    sim: Sim,
    spawn: SpawnMode,
    randomisation: Randomisation,
    map: MapInfo,
    rng: StdRng,
    new_layout_each_episode: bool,
}

/// Free cells, track and subjects of a built world.
pub(crate) fn map_of(sim: &Sim) -> MapInfo {
    let half = sim.scene().half_extent_m();
    let oval = sim.scene().file.track.as_ref().map(|t| crate::api::OvalTrack {
        straight_m: t.straight_m,
        inner_radius_m: t.inner_radius_m,
        outer_radius_m: t.outer_radius_m,
    });
    let mut free_cells = Vec::new();
    // Only search reads free cells, and a map-file or generated track rebuilt every episode
    // would pay for a grid over its whole extent: tracks with a centre line get none.
    let (nx, ny) = match sim.scene().centreline {
        Some(_) => (0, 0),
        None => ((2.0 * half[0] / CELL_M) as i32, (2.0 * half[1] / CELL_M) as i32),
    };
    for i in 0..nx {
        for j in 0..ny {
            let (x, y) = (
                -half[0] + (i as f32 + 0.5) * CELL_M,
                -half[1] + (j as f32 + 0.5) * CELL_M,
            );
            let on_track = oval
                .map(|t| t.lateral_offset_m(x, y).abs() < 0.5 * (t.outer_radius_m - t.inner_radius_m))
                .unwrap_or(true);
            if on_track && sim.free_at(x, y, 0.5 * CELL_M) {
                free_cells.push([x, y]);
            }
        }
    }
    let subjects = sim
        .scene()
        .objects
        .iter()
        .filter(|o| o.class == "person")
        .map(|o| o.id)
        .collect();
    let track = match (oval, &sim.scene().centreline) {
        (Some(t), _) => Some(crate::api::Track::Oval(t)),
        (None, Some(c)) => Some(crate::api::Track::Path(
            crate::api::PathTrack::new(c.clone())
                .with_clearance(centreline_clearance(sim, c))
                .expect("one clearance per point"),
        )),
        (None, None) => None,
    };
    MapInfo {
        half_extent_m: half,
        track,
        free_cells,
        cell_m: CELL_M,
        subjects,
    }
}

/// Largest clearance measured at a centre-line point, metres: far wider than any lane a car
/// races on, and a bound that keeps the first point's search short.
const MAX_CLEARANCE_M: f32 = 10.0;

/// Distance from each point of the closed centre line `c` to the nearest wall, metres (at most
/// [`MAX_CLEARANCE_M`]). A point's clearance is at most its predecessor's plus the step between
/// them, so each search starts from that bound.
fn centreline_clearance(sim: &Sim, c: &[[f32; 2]]) -> Vec<f32> {
    let mut out: Vec<f32> = Vec::with_capacity(c.len());
    for (i, p) in c.iter().enumerate() {
        let bound = match i.checked_sub(1) {
            Some(j) => {
                let q = c[j];
                (out[j] + (p[0] - q[0]).hypot(p[1] - q[1]) + 1e-3).min(MAX_CLEARANCE_M)
            }
            None => MAX_CLEARANCE_M,
        };
        out.push(sim.clearance_at(p[0], p[1], bound));
    }
    out
}

impl SimVehicle {
    /// Build the simulation once; episodes only move the vehicle.
    pub fn new(cfg: SimConfig, spawn: SpawnMode, randomisation: Randomisation) -> Result<Self, EnvError> {
        let sim = Sim::new(cfg)?;
        Ok(Self {
            map: map_of(&sim),
            sim,
            spawn,
            randomisation,
            rng: StdRng::seed_from_u64(0),
            new_layout_each_episode: false,
        })
    }

    /// On a procedural scene, draw a new layout of the same kind and size at every reset, from
    /// the episode seed (in its half of the seed space, see [`crate::heldout`]).
    pub fn with_new_layout_each_episode(mut self, on: bool) -> Self {
        self.new_layout_each_episode = on;
        self
    }

    /// Rebuild the world on the layout of `episode_seed` when layouts change per episode.
    fn relayout(&mut self, episode_seed: u64) -> Result<(), EnvError> {
        if !self.new_layout_each_episode {
            return Ok(());
        }
        let seed = crate::heldout::layout_of_episode(episode_seed);
        let scene = match &self.sim.config().scene {
            SceneSource::Procedural { kind, half_m, .. } => SceneSource::Procedural {
                kind: *kind,
                seed,
                half_m: *half_m,
            },
            SceneSource::Circuit { settings, .. } => SceneSource::Circuit {
                seed,
                settings: *settings,
            },
            _ => return Ok(()),
        };
        let cfg = SimConfig {
            scene,
            ..self.sim.config().clone()
        };
        self.sim = Sim::new(cfg)?;
        self.map = map_of(&self.sim);
        Ok(())
    }

    /// The simulator (read-only).
    pub fn sim(&self) -> &Sim {
        &self.sim
    }

    /// The simulator.
    pub fn sim_mut(&mut self) -> &mut Sim {
        &mut self.sim
    }

    fn random_pose(&mut self) -> PlanarPose {
        if let Some(t) = &self.map.track {
            let s = match self.spawn {
                SpawnMode::Line => 0.0,
                _ => self.rng.random_range(0.0..t.lap_length_m()),
            };
            let ([x, y], [dx, dy]) = t.centreline_at(s);
            let lateral = self.rng.random_range(-0.2..0.2f32);
            let yaw = dy.atan2(dx) + self.rng.random_range(-0.15..0.15f32);
            // Normal pointing to the outer wall: the direction turned right (clockwise lap).
            return PlanarPose {
                x_m: x + lateral * dy,
                y_m: y - lateral * dx,
                yaw_rad: yaw,
            };
        }
        let half = self.map.half_extent_m;
        for _ in 0..1000 {
            let x = self
                .rng
                .random_range(-half[0] + SPAWN_CLEARANCE_M..half[0] - SPAWN_CLEARANCE_M);
            let y = self
                .rng
                .random_range(-half[1] + SPAWN_CLEARANCE_M..half[1] - SPAWN_CLEARANCE_M);
            if self.sim.free_at(x, y, SPAWN_CLEARANCE_M) {
                let yaw = self.rng.random_range(-std::f32::consts::PI..std::f32::consts::PI);
                return PlanarPose {
                    x_m: x,
                    y_m: y,
                    yaw_rad: yaw,
                };
            }
        }
        self.sim.default_spawn()
    }

    fn frame(&mut self) -> SensorFrame {
        SensorFrame {
            stamp_s: self.sim.time_s(),
            scan: Some(self.sim.lidar_scan(0)),
            imu: Some(self.sim.car(0).imu()),
            gps: Some(self.sim.car(0).gps()),
            image: self.sim.car(0).camera_frame().map(|f| f.frame),
            contact: Some(!self.sim.car(0).contacts().is_empty()),
            applied: self.sim.car(0).control(),
        }
    }
}

impl Vehicle for SimVehicle {
    fn reset(&mut self, seed: u64) -> Result<SensorFrame, EnvError> {
        self.relayout(seed)?;
        self.rng = StdRng::seed_from_u64(seed);
        let params = self.randomisation.draw(self.sim.nominal_params(), &mut self.rng);
        self.sim.set_params(params);
        match self.spawn {
            SpawnMode::Random | SpawnMode::Line => {
                // A car spawned facing a rock it cannot steer around loses the episode before
                // the policy acts: in open maps the LiDAR fan must see this much free space.
                for attempt in 0.. {
                    let pose = self.random_pose();
                    self.sim.reset(pose)?;
                    if self.map.track.is_some()
                        || attempt == 100
                        || self.sim.lidar_scan(0).min_range_within(SPAWN_VIEW_HALF_RAD) >= SPAWN_VIEW_M
                    {
                        break;
                    }
                }
            }
            SpawnMode::Fixed => self.sim.reset(self.sim.default_spawn())?,
            SpawnMode::NearObstacle => {
                let mut open = None;
                for _ in 0..1000 {
                    let pose = self.random_pose();
                    self.sim.reset(pose)?;
                    let near = self.sim.lidar_scan(0).min_range_within(SPAWN_VIEW_HALF_RAD);
                    if RECOVERY_SPAWN_M.contains(&near) {
                        return Ok(self.frame());
                    }
                    if open.is_none() && near >= SPAWN_VIEW_M {
                        open = Some(pose);
                    }
                }
                if let Some(pose) = open {
                    self.sim.reset(pose)?;
                }
            }
        }
        Ok(self.frame())
    }

    fn actuate(&mut self, control: Control) -> Result<(), EnvError> {
        self.sim.step(control)?;
        Ok(())
    }

    fn sense(&mut self) -> Result<SensorFrame, EnvError> {
        Ok(self.frame())
    }

    fn control_period_s(&self) -> f64 {
        self.sim.config().settings.control_period_s
    }

    fn steering_limit_rad(&self) -> f64 {
        self.sim.vehicle().spec.steering.max_rad
    }

    fn map(&self) -> Option<&MapInfo> {
        Some(&self.map)
    }
}

/// A simulated car as the registry builds it: the simulator, behind sensor noise and latency
/// when the config asks for them. Viewers and plots reach the simulator through
/// [`SimCar::sim`]; a task only ever sees the [`Vehicle`] seam.
pub enum SimCar {
    /// Exact sensors, immediate commands.
    Exact(Box<SimVehicle>),
    /// Noisy sensors and delayed commands.
    Noisy(Box<crate::wrappers::Noisy<SimVehicle>>),
}

impl SimCar {
    /// The simulated vehicle under any noise layer.
    pub fn sim_vehicle(&self) -> &SimVehicle {
        match self {
            Self::Exact(v) => v,
            Self::Noisy(n) => n.inner(),
        }
    }

    /// The simulator (read-only).
    pub fn sim(&self) -> &Sim {
        self.sim_vehicle().sim()
    }

    fn vehicle_mut(&mut self) -> &mut dyn Vehicle {
        match self {
            Self::Exact(v) => v.as_mut(),
            Self::Noisy(n) => n.as_mut(),
        }
    }

    fn vehicle(&self) -> &dyn Vehicle {
        match self {
            Self::Exact(v) => v.as_ref(),
            Self::Noisy(n) => n.as_ref(),
        }
    }
}

impl Vehicle for SimCar {
    fn reset(&mut self, seed: u64) -> Result<SensorFrame, EnvError> {
        self.vehicle_mut().reset(seed)
    }
    fn actuate(&mut self, control: Control) -> Result<(), EnvError> {
        self.vehicle_mut().actuate(control)
    }
    fn sense(&mut self) -> Result<SensorFrame, EnvError> {
        self.vehicle_mut().sense()
    }
    fn control_period_s(&self) -> f64 {
        self.vehicle().control_period_s()
    }
    fn steering_limit_rad(&self) -> f64 {
        self.vehicle().steering_limit_rad()
    }
    fn map(&self) -> Option<&MapInfo> {
        self.vehicle().map()
    }
}
