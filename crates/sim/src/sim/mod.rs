//! `Sim`: one or more vehicles in one scene, stepped one control period at a time. The
//! settings types are in `settings.rs`, the control period's step (actuation, substeps,
//! velocities) in `step.rs`; this file builds the world, resets it and reads it.

mod car;
mod settings;
mod step;

pub use car::CarView;
pub(crate) use car::pose3;

pub use settings::{PlanarPose, SceneSource, SimConfig, SimSettings, VehicleParams, VehicleSource, contact_distance_m};

use crate::SimError;
use crate::assets::AssetSource;
use crate::msg::{LaserScan, Pose3};
use crate::scene::{MapTrack, Scene};
use crate::sensors::Lidar;
use crate::sensors::fast_ray::FastRay;
use crate::sensors::imu::ImuState;
use crate::vehicle::body::Body;
use crate::vehicle::{BodyParams, Control, DriveModel, VehicleModel};
use crate::world::{Movers, NearStatics, StaticEntry, World};
use rapier3d::prelude::*;

/// One vehicle of the world: its body and the state its actuation and sensors keep.
#[derive(Clone)]
struct Car {
    body: Body,
    params: VehicleParams,
    lidar: Lidar,
    imu: ImuState,
    wheel_speed: f64,
    control: Control,
    /// The centre steering angle the wheels turn towards, and where they stand, rad (the two
    /// differ only for a vehicle with a steering rate limit).
    steer_target_rad: f64,
    steer_rad: f64,
    wheel_angles: (f64, f64),
    vel_w: (Vector, Vector),
    /// The static colliders around the car, for its suspension rays.
    near: NearStatics,
    /// Held where it stands until the next reset (see [`Sim::park`]).
    parked: bool,
}

/// Another car touched in the last physics step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CarContact {
    /// The other car's index.
    pub other: usize,
    /// The deepest contact point, world frame, metres.
    pub point_w: [f32; 3],
}

/// The simulator: one scene and one or more vehicles of one model.
pub struct Sim {
    cfg: SimConfig,
    world: World,
    scene: Scene,
    /// What the generator drew, when the scene is a generated circuit.
    circuit: Option<crate::CircuitInfo>,
    model: VehicleModel,
    nominal: VehicleParams,
    cars: Vec<Car>,
    camera: crate::sensors::Camera,
    time_s: f64,
    steps: u64,
    pristine: (crate::world::WorldSnapshot, Vec<Body>),
    /// Control steps taken without rapier's pipeline since the simulator was built.
    free_steps: u64,
    /// Every car's shapes where they stand, for the sensors (empty with one car).
    shapes: Movers,
}

/// Most cars one world holds.
pub const MAX_CARS: usize = 8;

impl Sim {
    /// Build the world once: scene, vehicle at the scene's spawn, sensors.
    pub fn new(cfg: SimConfig) -> Result<Self, SimError> {
        Self::with_cars(cfg, 1)
    }

    /// Build a world holding `n_cars` vehicles (1 to [`MAX_CARS`]) with real contact between
    /// them; each car's sensors see the others. Car 0 stands at the scene's spawn, the others
    /// above it until the first [`Sim::reset_cars`].
    pub fn with_cars(cfg: SimConfig, n_cars: usize) -> Result<Self, SimError> {
        let invalid = |msg: String| SimError::Invalid {
            context: "sim config".into(),
            msg,
        };
        let set = &cfg.settings;
        if !(set.control_period_s > 0.0 && set.control_period_s.is_finite()) || set.substeps == 0 {
            return Err(invalid("control_period_s must be positive and substeps >= 1".into()));
        }
        if set.control_period_s / set.substeps as f64 > 1.0 / 60.0 + 1e-9 {
            return Err(invalid(format!(
                "physics substep {:.4} s is longer than 1/60 s: raise substeps",
                set.control_period_s / set.substeps as f64
            )));
        }
        if !(set.brake_mps2 >= 0.0 && set.brake_mps2.is_finite()) {
            return Err(invalid(format!(
                "brake_mps2 must be finite and >= 0, got {}",
                set.brake_mps2
            )));
        }
        if !(1..=MAX_CARS).contains(&n_cars) {
            return Err(invalid(format!("a world holds 1 to {MAX_CARS} cars, not {n_cars}")));
        }
        set.lidar.validate().map_err(|e| invalid(e.message))?;
        if let Some(c) = &set.camera {
            c.validate().map_err(|e| invalid(e.message))?;
        }
        let assets = AssetSource::builtin();
        let mut circuit = None;
        let mut scene = match &cfg.scene {
            SceneSource::Builtin(id) => Scene::builtin(&assets, id)?,
            SceneSource::File(path) => {
                let (src, name) = AssetSource::for_file(path);
                Scene::load(&src, &name)?
            }
            SceneSource::Procedural { kind, seed, half_m } => Scene::procedural(*kind, *seed, *half_m, 2.0)?,
            SceneSource::Map(t) => Scene::from_map(t)?,
            SceneSource::Circuit { seed, settings } => {
                let (track, info) = MapTrack::generated(*seed, settings)?;
                circuit = Some(info);
                Scene::from_map(&track)?
            }
        };
        if set.subjects > 0 && scene.centreline.is_some() {
            return Err(invalid(
                "subjects are search targets; a race track (map file or circuit) has none".into(),
            ));
        }
        if set.subjects > 0 {
            let file = scene.file.clone().with_subjects(set.subjects, set.subject_seed, 3.0);
            scene = Scene::build(file, &assets, "scene with subjects")?;
        }
        let model = set.vehicle_model()?;
        let substep_s = (set.control_period_s / set.substeps as f64) as f32;
        let mut world = World::new(&scene, substep_s);
        // Swept collision checks cost a fifth of a step; they are needed only where one substep's
        // motion could carry the car through an obstacle without an overlap at either end. The
        // car's farthest point moves at most about twice its top speed (turning, a randomised
        // drive); an obstacle thicker than that is always seen overlapping (or, earlier, by a
        // speculative contact).
        let reach_m = 2.0 * model.top_speed_mps() * substep_s;
        world.set_continuous_collision(reach_m > 2.0 * world.thinnest_obstacle_m());
        let d = model.spec.drive;
        let nominal = VehicleParams {
            drive: DriveModel {
                c_t: d.c_t,
                c_d: d.c_d,
                c_r: d.c_r,
                brake: set.brake_mps2 / model.drive_radius_m() as f64,
            },
            tyre_friction: model.spec.tyre_friction,
            mass_scale: 1.0,
            steering_offset_rad: 0.0,
        };
        let spawn = scene.file.spawn;
        let pose2 = PlanarPose {
            x_m: spawn.x_m,
            y_m: spawn.y_m,
            yaw_rad: spawn.yaw_deg.to_radians(),
        };
        let others = n_cars > 1;
        let mut cars = Vec::with_capacity(n_cars);
        for k in 0..n_cars {
            // Stacked a metre apart until the first reset puts them on the ground.
            let mut pose = spawn_pose(&model, pose2);
            pose.translation.z += k as f32;
            let body = Body::new(&mut world, &model, set.dynamics, pose, body_params(&nominal), others)?;
            cars.push(Car {
                body,
                params: nominal,
                lidar: Lidar::new(set.lidar.clone()),
                imu: ImuState::default(),
                wheel_speed: 0.0,
                control: Control::default(),
                steer_target_rad: 0.0,
                steer_rad: 0.0,
                wheel_angles: (0.0, 0.0),
                vel_w: (Vector::ZERO, Vector::ZERO),
                near: NearStatics::new(&world.pw),
                parked: false,
            });
        }
        let camera = crate::sensors::Camera::new(set.camera.clone().unwrap_or_default(), &scene, &world.statics);
        // One physics step first, so the snapshot holds a built broad phase: the wheel rays of
        // the first substep after every reset then see the ground.
        world.pw.step();
        let pristine = (world.snapshot(), cars.iter().map(|c| c.body.clone()).collect());
        let mut sim = Self {
            cfg,
            world,
            scene,
            circuit,
            model,
            nominal,
            cars,
            camera,
            time_s: 0.0,
            steps: 0,
            pristine,
            free_steps: 0,
            shapes: Movers::default(),
        };
        let poses: Vec<PlanarPose> = (0..n_cars)
            .map(|k| PlanarPose {
                x_m: pose2.x_m - 1.0 * k as f32,
                ..pose2
            })
            .collect();
        sim.reset_cars(&poses)?;
        Ok(sim)
    }

    /// The configuration.
    pub fn config(&self) -> &SimConfig {
        &self.cfg
    }

    /// The scene.
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// The generated circuit's figures (length, width, tightest radius), when the scene is one.
    pub fn circuit(&self) -> Option<&crate::CircuitInfo> {
        self.circuit.as_ref()
    }

    /// The vehicle model.
    pub fn vehicle(&self) -> &VehicleModel {
        &self.model
    }

    /// The vehicle's nominal parameters (from its spec).
    pub fn nominal_params(&self) -> VehicleParams {
        self.nominal
    }

    /// Change parameters (domain randomisation); they take effect at the next `reset`.
    pub fn set_params(&mut self, p: VehicleParams) {
        self.set_params_of(0, p);
    }

    /// Change car `i`'s parameters; they take effect at the next reset.
    pub fn set_params_of(&mut self, i: usize, p: VehicleParams) {
        self.cars[i].params = p;
    }

    /// The number of cars in the world.
    pub fn n_cars(&self) -> usize {
        self.cars.len()
    }

    /// AutoVRL's fixed spawn of this scene.
    pub fn default_spawn(&self) -> PlanarPose {
        let s = self.scene.file.spawn;
        PlanarPose {
            x_m: s.x_m,
            y_m: s.y_m,
            yaw_rad: s.yaw_deg.to_radians(),
        }
    }

    /// Put the vehicle at `pose` on the ground, at rest, wheel speed 0 (no scene reload).
    pub fn reset(&mut self, pose: PlanarPose) -> Result<(), SimError> {
        self.reset_cars(&[pose])
    }

    /// Put every car at its pose (one per car), at rest, wheel speed 0.
    pub fn reset_cars(&mut self, poses: &[PlanarPose]) -> Result<(), SimError> {
        self.check_count(poses.len(), "poses")?;
        self.world.restore(&self.pristine.0);
        for (car, (pose, pristine)) in self.cars.iter_mut().zip(poses.iter().zip(&self.pristine.1)) {
            let p = spawn_pose(&self.model, *pose);
            car.body.clone_from(pristine);
            car.body
                .reset(&mut self.world, &self.model, p, body_params(&car.params))?;
            car.wheel_speed = 0.0;
            car.control = Control::default();
            car.steer_target_rad = 0.0;
            car.steer_rad = 0.0;
            car.wheel_angles = (0.0, 0.0);
            car.vel_w = (Vector::ZERO, Vector::ZERO);
            car.imu.reset();
            car.parked = false;
        }
        self.time_s = 0.0;
        self.steps = 0;
        self.place_shapes();
        Ok(())
    }

    fn check_count(&self, n: usize, what: &str) -> Result<(), SimError> {
        if n == self.cars.len() {
            return Ok(());
        }
        Err(SimError::Invalid {
            context: "sim".into(),
            msg: format!("{n} {what} for a world of {} cars", self.cars.len()),
        })
    }

    /// Hold car `i` where it stands until the next reset: it stops at once and stays an
    /// obstacle (a crashed car in a race). Its controls are ignored meanwhile.
    pub fn park(&mut self, i: usize) {
        let car = &mut self.cars[i];
        car.body.park(&mut self.world);
        car.parked = true;
        car.wheel_speed = 0.0;
        car.control = Control::default();
        car.vel_w = (Vector::ZERO, Vector::ZERO);
    }

    /// Control steps that skipped rapier's pipeline (see `SimSettings::free_flight`) since the
    /// simulator was built.
    pub fn free_flight_steps(&self) -> u64 {
        self.free_steps
    }

    /// Simulated time since reset, seconds.
    pub fn time_s(&self) -> f64 {
        self.time_s
    }

    /// Control steps since reset.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// Car `i` of the world, read-only (its pose, velocities, readings, contacts).
    pub fn car(&self, i: usize) -> CarView<'_> {
        assert!(i < self.cars.len(), "car {i} of a world of {} cars", self.cars.len());
        CarView { sim: self, i }
    }

    /// World pose of car `i`'s base frame.
    fn base_pose(&self, i: usize) -> Pose {
        *self.world.pw.bodies[self.cars[i].body.base()].position()
    }

    /// Scene objects car `i` touched in the last physics step.
    fn contacts(&self, i: usize) -> Vec<u32> {
        if self.steps == 0 {
            return Vec::new();
        }
        let mut out: Vec<u32> = self
            .touched(i)
            .filter_map(|(other, _)| self.world.object_id(other))
            .collect();
        out.sort_unstable();
        out.dedup();
        out
    }

    /// The colliders car `i` touches in the last physics step (an active contact), each with
    /// the pair.
    fn touched(&self, i: usize) -> impl Iterator<Item = (ColliderHandle, &ContactPair)> + '_ {
        self.cars[i].body.colliders().iter().flat_map(move |&h| {
            self.world
                .pw
                .narrow_phase
                .contact_pairs_with(h)
                .filter(|p| p.has_any_active_contact())
                .map(move |p| (if p.collider1 == h { p.collider2 } else { p.collider1 }, p))
        })
    }

    /// The other cars car `i` touched in the last physics step, each once, with the deepest
    /// contact point.
    fn car_contacts(&self, i: usize) -> Vec<CarContact> {
        let mut out: Vec<(f32, CarContact)> = Vec::new();
        if self.steps == 0 || self.cars.len() < 2 {
            return Vec::new();
        }
        let owner = |h: ColliderHandle| self.cars.iter().position(|c| c.body.colliders().contains(&h));
        for (other, pair) in self.touched(i) {
            let Some(j) = owner(other).filter(|&j| j != i) else {
                continue;
            };
            let Some((_, pt)) = pair.find_deepest_contact() else {
                continue;
            };
            let Some(co1) = self.world.pw.colliders.get(pair.collider1) else {
                continue;
            };
            let p = *co1.position() * pt.local_p1;
            let c = CarContact {
                other: j,
                point_w: p.to_array(),
            };
            match out.iter_mut().find(|(_, k)| k.other == j) {
                Some(slot) if pt.dist < slot.0 => *slot = (pt.dist, c),
                Some(_) => {}
                None => out.push((pt.dist, c)),
            }
        }
        out.sort_by_key(|(_, c)| c.other);
        out.into_iter().map(|(_, c)| c).collect()
    }

    /// Car `i`'s camera pose, when the vehicle has a camera link.
    fn camera_pose(&self, i: usize) -> Option<Pose> {
        self.model.camera_b.map(|c| self.base_pose(i) * c)
    }

    /// Car `i`'s LiDAR scan: the scene and the other cars.
    pub fn lidar_scan(&mut self, i: usize) -> LaserScan {
        let pose = self.base_pose(i) * self.model.lidar_b;
        let car = &mut self.cars[i];
        car.lidar
            .scan_with(&self.world.statics, &self.shapes, Some(i as u32), &pose)
    }

    /// A LiDAR scan as if car 0's LiDAR link were at `pose_w` (probing; the car does not move).
    pub fn lidar_scan_at(&mut self, pose_w: &Pose3) -> LaserScan {
        self.cars[0].lidar.scan(&self.world.statics, &car::pose_of(pose_w))
    }

    /// Car `i`'s camera frame: the scene and the other cars.
    fn camera_frame(&self, i: usize) -> Option<crate::sensors::camera::RenderedFrame> {
        self.cfg.settings.camera.as_ref()?;
        let pose = self.camera_pose(i)?;
        Some(
            self.camera
                .render_with(&self.world.statics, &self.shapes, Some(i as u32), &pose),
        )
    }

    /// Render the camera (configured, or the default 160x120) as if it stood at `pose_w`
    /// (looking along its x axis, z up).
    pub fn render_at(&self, pose_w: &Pose3) -> crate::sensors::camera::RenderedFrame {
        self.camera.render(&self.world.statics, &car::pose_of(pose_w))
    }

    /// Place every car's collision shapes where the car stands now (worlds of several cars).
    fn place_shapes(&mut self) {
        let m = &mut self.shapes;
        m.entries.clear();
        m.car.clear();
        if self.cars.len() < 2 {
            return;
        }
        let color = self.model.body_shapes.first().map_or([0.5; 3], |s| s.color);
        for (j, car) in self.cars.iter().enumerate() {
            let base = *self.world.pw.bodies[car.body.base()].position();
            for &h in car.body.colliders() {
                let co = &self.world.pw.colliders[h];
                // With free flight the colliders keep the pose of the last rapier step: place
                // each from its body's pose now.
                let pose = match co.parent() {
                    Some(b) if b == car.body.base() => {
                        base * co.position_wrt_parent().copied().unwrap_or(Pose::IDENTITY)
                    }
                    Some(b) => {
                        *self.world.pw.bodies[b].position()
                            * co.position_wrt_parent().copied().unwrap_or(Pose::IDENTITY)
                    }
                    None => *co.position(),
                };
                let shape = co.shared_shape().clone();
                m.entries.push(StaticEntry {
                    aabb: aabb_of(&shape, &pose),
                    fast: FastRay::new(&shape, &pose),
                    shape,
                    pose,
                    object_id: None,
                    color,
                });
                m.car.push(j as u32);
            }
        }
    }

    /// Whether a vertical cylinder of `radius_m` standing at (x, y) from the ground to 1 m
    /// touches no scene object (spawn and coverage checks). Tests the static scene directly, so
    /// the answer does not depend on the broad phase's state.
    pub fn free_at(&self, x: f32, y: f32, radius_m: f32) -> bool {
        let shape = Cylinder::new(0.45, radius_m);
        let pose = Pose::from_parts(
            Vector::new(x, y, 0.55),
            Rotation::from_rotation_x(std::f32::consts::FRAC_PI_2),
        );
        let aabb = Aabb::new(
            Vector::new(x - radius_m, y - radius_m, 0.1),
            Vector::new(x + radius_m, y + radius_m, 1.0),
        );
        !self.world.statics.entries.iter().any(|e| {
            e.object_id.is_some()
                && e.aabb.intersects(&aabb)
                && rapier3d::parry::query::intersection_test(&pose, &shape, &e.pose, e.shape.as_ref())
                    .map(|i| i.intersecting)
                    .unwrap_or(true)
        })
    }

    /// Distance from (x, y) to the nearest scene object, metres, measured as [`Sim::free_at`]
    /// tests (from a vertical line from 0.1 m to 1 m above the ground), so `free_at` with a
    /// smaller radius is free; `max_m` when nothing is nearer (a known upper bound, such as a
    /// neighbour's clearance plus the step to it, makes the search cheaper).
    pub fn clearance_at(&self, x: f32, y: f32, max_m: f32) -> f32 {
        let line = rapier3d::parry::shape::Segment::new(Vector::new(0.0, 0.0, -0.45), Vector::new(0.0, 0.0, 0.45));
        let pose = Pose::from_parts(Vector::new(x, y, 0.55), Rotation::IDENTITY);
        let mut best = max_m;
        for e in &self.world.statics.entries {
            if e.object_id.is_none() || e.aabb.maxs.z < 0.1 || e.aabb.mins.z > 1.0 {
                continue;
            }
            // The box's horizontal distance bounds the shape's from below.
            let dx = (e.aabb.mins.x - x).max(x - e.aabb.maxs.x).max(0.0);
            let dy = (e.aabb.mins.y - y).max(y - e.aabb.maxs.y).max(0.0);
            if dx.hypot(dy) >= best {
                continue;
            }
            let d = rapier3d::parry::query::distance(&pose, &line, &e.pose, e.shape.as_ref())
                .map(|d| d.distance)
                .unwrap_or(0.0);
            best = best.min(d);
        }
        best
    }

    /// Whether continuous collision detection runs (see `SimSettings`'s thin-wall check).
    pub fn continuous_collision(&self) -> bool {
        self.world.continuous_collision()
    }
}

/// A shape's world box; a cylinder's in closed form (parry finds it by support points).
fn aabb_of(shape: &SharedShape, pose: &Pose) -> Aabb {
    match shape.as_cylinder() {
        Some(c) => {
            let a = pose.rotation * Vector::Y;
            let half = (a.abs() * c.half_height) + (Vector::ONE - a * a).max(Vector::ZERO).sqrt() * c.radius;
            Aabb::new(pose.translation - half, pose.translation + half)
        }
        None => shape.compute_aabb(pose),
    }
}

fn body_params(p: &VehicleParams) -> BodyParams {
    BodyParams {
        tyre_friction: p.tyre_friction,
        mass_scale: p.mass_scale,
    }
}

fn spawn_pose(model: &VehicleModel, p: PlanarPose) -> Pose {
    // A hair above the ground so the first contact is not a penetration.
    Pose::from_parts(
        Vector::new(p.x_m, p.y_m, model.rest_height_m() + 0.002),
        Rotation::from_rotation_z(p.yaw_rad),
    )
}
