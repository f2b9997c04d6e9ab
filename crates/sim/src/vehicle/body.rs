//! The two dynamics modes of a vehicle.
//!
//! - `Raycast`: one rigid chassis carrying the whole car's mass properties, held up and driven by
//!   rapier's `DynamicRayCastVehicleController` (one suspension ray per wheel). Wheel proxies
//!   (cylinders) ride along for contacts with obstacles but never touch the ground. Fast.
//! - `Multibody`: the URDF's links and joints as a rapier multibody (reduced coordinates), ball
//!   wheel colliders on the ground, velocity motors on the driven joints and position motors on
//!   the steering hinges. The reference for fidelity.
//!
//! Both follow the same command: a wheel speed `w` (rad/s) from the drive model and the two
//! front-wheel steering angles.

use super::spec::{TyreSpec, VehicleModel};
use crate::SimError;
use crate::world::{NearStatics, World, groups};
use rapier3d::control::{DynamicRayCastVehicleController, WheelTuning};
use rapier3d::prelude::*;
use rapier3d_urdf::{UrdfLoaderOptions, UrdfMultibodyOptions, UrdfRobot};
use serde::{Deserialize, Serialize};

/// Which physics represents the vehicle.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DynamicsMode {
    /// A rigid chassis on ray-cast wheels (rapier's ray-cast vehicle controller).
    #[default]
    Raycast,
    /// The URDF's joints as a multibody with joint motors.
    Multibody,
}

/// Time constant of the wheel-speed tracking in ray-cast mode, seconds: the tyre force brings
/// the ground speed to `w r` about as fast as a velocity motor would.
const TRACK_TAU_S: f32 = 0.03;
/// Velocity-motor damping of the driven joints in multibody mode (high: rapier's motors are soft).
const DRIVE_MOTOR_DAMPING: f32 = 1000.0;
/// Position-motor gains of the steering hinges in multibody mode.
const STEER_STIFFNESS: f32 = 2000.0;
const STEER_DAMPING: f32 = 50.0;
/// Suspension of the ray-cast wheels: stiffness per unit chassis mass (1/s^2) and travel.
const SUSPENSION_STIFFNESS: f32 = 400.0;
const SUSPENSION_REST_M: f32 = 0.03;

#[derive(Clone)]
pub(crate) enum Body {
    Raycast {
        chassis: RigidBodyHandle,
        controller: DynamicRayCastVehicleController,
        colliders: Vec<ColliderHandle>,
        /// Each collider's box in the chassis frame, and whether it may touch the ground.
        bounds: Vec<(Aabb, bool)>,
    },
    Multibody(Box<MultibodyCar>),
}

#[derive(Clone)]
pub(crate) struct MultibodyCar {
    template: UrdfRobot,
    joint_names: Vec<String>,
    base_idx: usize,
    bodies: Vec<RigidBodyHandle>,
    mprops: Vec<MassProperties>,
    colliders: Vec<ColliderHandle>,
    wheel_colliders: Vec<ColliderHandle>,
    drive: Vec<MultibodyJointHandle>,
    steer: Vec<(MultibodyJointHandle, i8)>,
}

/// Physical parameters that domain randomisation may change per episode.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BodyParams {
    /// Tyre friction coefficient.
    pub tyre_friction: f32,
    /// Factor on the total mass (and inertia).
    pub mass_scale: f32,
}

impl Body {
    pub(crate) fn new(
        world: &mut World,
        model: &VehicleModel,
        mode: DynamicsMode,
        pose: Pose,
        p: BodyParams,
        other_cars: bool,
    ) -> Result<Self, SimError> {
        match mode {
            DynamicsMode::Raycast => Ok(Self::new_raycast(world, model, pose, p, other_cars)),
            DynamicsMode::Multibody => Self::new_multibody(world, model, pose, p, other_cars),
        }
    }

    fn new_raycast(world: &mut World, model: &VehicleModel, pose: Pose, p: BodyParams, other_cars: bool) -> Self {
        let mp = scale_mass(model.mass_props, p.mass_scale);
        let chassis = world.pw.insert_body(
            RigidBodyBuilder::dynamic()
                .pose(pose)
                .additional_mass_properties(mp)
                .can_sleep(false),
        );
        let mut colliders = Vec::new();
        let mut bounds = Vec::new();
        for s in &model.body_shapes {
            bounds.push((s.shape.compute_aabb(&s.pose), true));
            colliders.push(
                world.pw.insert_collider(
                    ColliderBuilder::new(s.shape.clone())
                        .position(s.pose)
                        .density(0.0)
                        .friction(0.5)
                        .collision_groups(groups::vehicle(other_cars)),
                    Some(chassis),
                ),
            );
        }
        for w in &model.wheels {
            let rot = Rotation::from_rotation_x(std::f32::consts::FRAC_PI_2);
            let shape = Cylinder::new(w.width_m / 2.0, w.radius_m);
            bounds.push((shape.compute_aabb(&Pose::from_parts(w.center_b, rot)), false));
            colliders.push(
                world.pw.insert_collider(
                    ColliderBuilder::cylinder(w.width_m / 2.0, w.radius_m)
                        .position(Pose::from_parts(w.center_b, rot))
                        .density(0.0)
                        .friction(0.5)
                        .collision_groups(groups::vehicle_no_ground(other_cars)),
                    Some(chassis),
                ),
            );
        }
        let mut controller = DynamicRayCastVehicleController::new(chassis);
        controller.index_up_axis = 2;
        controller.index_forward_axis = 0;
        let n = model.wheels.len() as f32;
        let tuning = WheelTuning {
            suspension_stiffness: SUSPENSION_STIFFNESS,
            // Critically damped per wheel: c = 2 sqrt(k / n_wheels) in per-unit-mass terms.
            suspension_compression: 2.0 * (SUSPENSION_STIFFNESS / n).sqrt(),
            suspension_damping: 2.0 * (SUSPENSION_STIFFNESS / n).sqrt(),
            max_suspension_travel: SUSPENSION_REST_M,
            // Tyres with cornering stiffness take over the side force (`tyre_side_impulses`).
            side_friction_stiffness: if model.spec.tyre.is_some() { 0.0 } else { 1.0 },
            friction_slip: p.tyre_friction,
            max_suspension_force: 1.0e4,
        };
        // Rest compression under a 1/n share of the weight, so the wheel centre sits where the
        // URDF puts it.
        let sag = crate::world::GRAVITY_MPS2 / (n * SUSPENSION_STIFFNESS);
        for w in &model.wheels {
            let hard_point = w.center_b + Vector::Z * (SUSPENSION_REST_M - sag);
            controller.add_wheel(
                hard_point,
                -Vector::Z,
                -Vector::Y,
                SUSPENSION_REST_M,
                w.radius_m,
                &tuning,
            );
        }
        Body::Raycast {
            chassis,
            controller,
            colliders,
            bounds,
        }
    }

    fn new_multibody(
        world: &mut World,
        model: &VehicleModel,
        pose: Pose,
        p: BodyParams,
        other_cars: bool,
    ) -> Result<Self, SimError> {
        let options = UrdfLoaderOptions {
            create_colliders_from_collision_shapes: true,
            apply_imported_mass_props: true,
            enable_joint_collisions: false,
            collider_blueprint: ColliderBuilder::default()
                .density(0.0)
                .friction(0.5)
                .friction_combine_rule(CoefficientCombineRule::Multiply)
                .collision_groups(groups::vehicle(other_cars)),
            ..UrdfLoaderOptions::default()
        };
        let mut template = UrdfRobot::from_robot(&model.urdf.robot, options, std::path::Path::new("."));
        let robot = &model.urdf.robot;
        // Ball wheels: cylinders roll badly on rapier's contact manifolds.
        for link in &mut template.links {
            let name = &robot.links[link.urdf_link_index].name;
            if let Some(w) = model.wheels.iter().find(|w| &w.link == name) {
                for c in &mut link.colliders {
                    let local = c
                        .collider
                        .position_wrt_parent()
                        .copied()
                        .unwrap_or(*c.collider.position());
                    c.collider.set_shape(SharedShape::ball(w.radius_m));
                    c.collider
                        .set_position_wrt_parent(Pose::from_translation(local.translation));
                    c.collider.set_friction(p.tyre_friction);
                }
            }
        }
        let joint_names: Vec<String> = template
            .joints
            .iter()
            .map(|j| robot.joints[j.urdf_joint_index].name.clone())
            .collect();
        let base_idx = template
            .links
            .iter()
            .position(|l| robot.links[l.urdf_link_index].name == model.urdf.root)
            .ok_or_else(|| SimError::Invalid {
                context: model.urdf.rel_path.clone(),
                msg: "root link has no body".into(),
            })?;
        let mut car = MultibodyCar {
            template,
            joint_names,
            base_idx,
            bodies: vec![],
            mprops: vec![],
            colliders: vec![],
            wheel_colliders: vec![],
            drive: vec![],
            steer: vec![],
        };
        car.insert(world, model, pose)?;
        Ok(Body::Multibody(Box::new(car)))
    }

    /// World pose of the base frame.
    pub(crate) fn base(&self) -> RigidBodyHandle {
        match self {
            Body::Raycast { chassis, .. } => *chassis,
            Body::Multibody(c) => c.bodies[c.base_idx],
        }
    }

    pub(crate) fn is_raycast(&self) -> bool {
        matches!(self, Body::Raycast { .. })
    }

    pub(crate) fn colliders(&self) -> &[ColliderHandle] {
        match self {
            Body::Raycast { colliders, .. } => colliders,
            Body::Multibody(c) => &c.colliders,
        }
    }

    /// Whether the next `period_s` seconds can skip rapier's pipeline (see [`free_flight`]):
    /// only the chassis moves, and no contact with the scene can start on the way. The car's
    /// boxes, widened by twice the distance its farthest point can travel plus rapier's contact
    /// prediction distance and a margin, must stay clear of every obstacle's box and of the
    /// ground. Returns that widened box (other cars' boxes must stay clear of it too), or
    /// `None` when the car may touch the scene. A parked car moves nowhere and answers its
    /// own box.
    pub(crate) fn free_reach(&self, world: &World, period_s: f32, parked: bool) -> Option<Aabb> {
        let Body::Raycast { chassis, bounds, .. } = self else {
            return None;
        };
        let rb = &world.pw.bodies[*chassis];
        let pose = *rb.position();
        let com = rb.mass_properties().local_mprops.local_com;
        let mut car = Aabb::new_invalid();
        let mut lowest = f32::INFINITY;
        let mut radius = 0.0f32;
        for (local, touches_ground) in bounds {
            let b = local.transform_by(&pose);
            car.merge(&b);
            if *touches_ground {
                lowest = lowest.min(b.mins.z);
            }
            radius = radius.max((local.mins - com).abs().max(local.maxs - com).abs().length());
        }
        let prediction = world.pw.integration_parameters.prediction_distance();
        if parked {
            return Some(car.loosened(prediction + FREE_MARGIN_M));
        }
        let (v, w) = (rb.linvel(), rb.angvel());
        let gap = 2.0 * (v.length() + w.length() * radius) * period_s + prediction + FREE_MARGIN_M;
        // Only a climb or a roll or pitch brings the chassis nearer the ground.
        let drop = 2.0 * (v.z.abs() + w.truncate().length() * radius) * period_s + prediction + GROUND_MARGIN_M;
        let reach = car.loosened(gap);
        // A wall's own box, not only its bounding box: a long wall along a diagonal straight has
        // a bounding box over the whole track beside it.
        let reach_box = Cuboid::new(reach.half_extents());
        let reach_pose = Pose::from_translation(reach.center());
        let clear = world.statics.entries.iter().all(|e| match e.object_id {
            None => lowest - drop > e.aabb.maxs.z,
            Some(_) => {
                !e.aabb.intersects(&reach)
                    || !rapier3d::parry::query::intersection_test(&reach_pose, &reach_box, &e.pose, e.shape.as_ref())
                        .map(|i| i.intersecting)
                        .unwrap_or(true)
            }
        });
        clear.then_some(reach)
    }

    /// Hold the car where it stands for the rest of the episode (a crashed car in a race): its
    /// chassis becomes a fixed body that others still hit. `reset` restores the dynamic body
    /// from the pristine copy.
    /// A multibody car stays dynamic (rapier's multibodies keep their links' types): its
    /// drive motors hold the wheels still instead.
    pub(crate) fn park(&self, world: &mut World) {
        if let Body::Raycast { chassis, .. } = self
            && let Some(rb) = world.pw.bodies.get_mut(*chassis)
        {
            rb.set_linvel(Vector::ZERO, false);
            rb.set_angvel(Vector::ZERO, false);
            rb.set_body_type(RigidBodyType::Fixed, true);
        }
    }

    /// Put the car at `pose`, at rest, with parameters `p` (no bodies are rebuilt).
    pub(crate) fn reset(
        &mut self,
        world: &mut World,
        model: &VehicleModel,
        pose: Pose,
        p: BodyParams,
    ) -> Result<(), SimError> {
        match self {
            Body::Raycast {
                chassis, controller, ..
            } => {
                let rb = &mut world.pw.bodies[*chassis];
                rb.set_additional_mass_properties(scale_mass(model.mass_props, p.mass_scale), true);
                rb.set_position(pose, true);
                rb.set_linvel(Vector::ZERO, true);
                rb.set_angvel(Vector::ZERO, true);
                for w in controller.wheels_mut() {
                    w.engine_force = 0.0;
                    w.steering = 0.0;
                }
                Ok(())
            }
            Body::Multibody(car) => car.teleport(world, model, pose, p),
        }
    }

    /// Apply the command for one physics substep: the ray-cast wheels' impulses, or the
    /// multibody's motor targets. The world then advances by one rapier step, or by
    /// [`Body::fly`] when no contact can start.
    pub(crate) fn drive(
        &mut self,
        world: &mut World,
        near: &mut NearStatics,
        model: &VehicleModel,
        w_radps: f32,
        steer: (f32, f32),
        p: BodyParams,
    ) {
        match self {
            Body::Raycast {
                chassis, controller, ..
            } => {
                let rb = &world.pw.bodies[*chassis];
                let fwd = rb.position().rotation * Vector::X;
                let v = rb.linvel().dot(fwd);
                let r = model.drive_radius_m();
                let n_driven = model.wheels.iter().filter(|w| w.driven).count().max(1) as f32;
                let f_max = model.spec.drive.max_torque_nm as f32 / r;
                let f_total = rb.mass() * (w_radps * r - v) / TRACK_TAU_S;
                let f_wheel = (f_total / n_driven).clamp(-f_max, f_max);
                let shares = model.spec.tyre.map(|_| {
                    load_shares(
                        controller,
                        model,
                        f_total.clamp(-f_max * n_driven, f_max * n_driven),
                        p.tyre_friction,
                    )
                });
                for (i, (wheel, geom)) in controller.wheels_mut().iter_mut().zip(&model.wheels).enumerate() {
                    wheel.engine_force = match (&shares, geom.driven) {
                        (_, false) => 0.0,
                        (Some(f), true) => f[i],
                        (None, true) => f_wheel,
                    };
                    wheel.steering = match geom.steer_side {
                        1 => steer.0,
                        -1 => steer.1,
                        _ => 0.0,
                    };
                    wheel.friction_slip = p.tyre_friction;
                }
                let dt = world.pw.integration_parameters.dt;
                let at = rb.position().translation;
                let filter = QueryFilter::default().groups(groups::sensors());
                let pw = &mut world.pw;
                // Every suspension ray starts and ends this close to the chassis origin.
                let reach = controller
                    .wheels()
                    .iter()
                    .map(|w| w.chassis_connection_point_cs.length() + w.suspension_rest_length + w.radius)
                    .fold(0.0f32, f32::max);
                let near = near.around(&pw.integration_parameters, at, reach);
                let q = near.as_query_pipeline_mut(
                    pw.narrow_phase.query_dispatcher(),
                    &mut pw.bodies,
                    &mut pw.colliders,
                    filter,
                );
                controller.update_vehicle(dt, q);
                if let Some(tyre) = model.spec.tyre {
                    tyre_side_impulses(&mut world.pw, *chassis, controller, model, tyre, p.tyre_friction, dt);
                }
            }
            Body::Multibody(car) => {
                let max_t = model.spec.drive.max_torque_nm as f32;
                for &h in &car.drive {
                    if let Some((mb, link)) = world.pw.multibody_joints.get_mut(h)
                        && let Some(l) = mb.link_mut(link)
                    {
                        l.joint
                            .data
                            .set_motor_velocity(JointAxis::AngX, w_radps, DRIVE_MOTOR_DAMPING);
                        l.joint.data.set_motor_max_force(JointAxis::AngX, max_t);
                    }
                }
                for &(h, side) in &car.steer {
                    if let Some((mb, link)) = world.pw.multibody_joints.get_mut(h)
                        && let Some(l) = mb.link_mut(link)
                    {
                        let target = if side > 0 { steer.0 } else { steer.1 };
                        l.joint
                            .data
                            .set_motor_position(JointAxis::AngX, target, STEER_STIFFNESS, STEER_DAMPING);
                    }
                }
            }
        }
    }

    /// Advance a ray-cast car by one rapier step without rapier's pipeline (see
    /// [`free_flight`]); only called when [`Body::free_reach`] allowed it.
    pub(crate) fn fly(&self, world: &mut World) {
        if let Body::Raycast { chassis, .. } = self {
            free_flight(&mut world.pw, *chassis);
        }
    }
}

/// The drive force `f_total` (within the motor's limit) shared among the driven wheels in
/// proportion to their load at the last substep, each within its tyre's friction `mu F_z`, for
/// tyres with cornering stiffness: braking and driving load the wheels alike, so none runs out
/// of grip first and leaves its axle without side force (with an even share, hard braking
/// unloads the rear wheels past their grip and the car spins on a straight). Without load yet
/// (the first substep, or in the air) the share is even.
fn load_shares(controller: &DynamicRayCastVehicleController, model: &VehicleModel, f_total: f32, mu: f32) -> Vec<f32> {
    let wheels = controller.wheels();
    let load = |i: usize| {
        let w = &wheels[i];
        if model.wheels[i].driven && w.raycast_info().is_in_contact {
            w.wheel_suspension_force.min(w.max_suspension_force)
        } else {
            0.0
        }
    };
    let total: f32 = (0..wheels.len()).map(load).sum();
    let n_driven = model.wheels.iter().filter(|w| w.driven).count().max(1) as f32;
    (0..wheels.len())
        .map(|i| {
            if total > 0.0 {
                let fz = load(i);
                (f_total * fz / total).clamp(-mu * fz, mu * fz)
            } else {
                f_total / n_driven
            }
        })
        .collect()
}

/// Share of a side force's roll moment that reaches the chassis: rapier's default for its own
/// side friction (`Wheel::roll_influence`), which applies the force this far from the centre of
/// mass's height towards the ground.
const ROLL_INFLUENCE: f32 = 0.1;

/// Side impulses of tyres with cornering stiffness, after rapier's suspension and drive
/// impulses of one substep: f1tenth_gym's linear tyre, `mu C_S F_z alpha` per wheel with the
/// wheel's load `F_z` from its suspension, limited by the friction circle `mu F_z` less the drive
/// force, and never more than stops the contact's side velocity (the wheels share that), which
/// keeps the explicit step stable at a standstill, where `alpha` is large for any side velocity.
fn tyre_side_impulses(
    pw: &mut PhysicsWorld,
    chassis: RigidBodyHandle,
    controller: &DynamicRayCastVehicleController,
    model: &VehicleModel,
    tyre: TyreSpec,
    mu: f32,
    dt: f32,
) {
    let rb = &pw.bodies[chassis];
    let wheels = controller.wheels();
    let on_ground = wheels.iter().filter(|w| w.raycast_info().is_in_contact).count();
    if on_ground == 0 {
        return;
    }
    let up = rb.position().rotation * Vector::Z;
    let com = rb.center_of_mass();
    let inv_m = rb.mass_properties().local_mprops.inv_mass;
    let inv_i = rb.mass_properties().effective_world_inv_inertia;
    let mut impulses = Vec::with_capacity(wheels.len());
    for (w, geom) in wheels.iter().zip(&model.wheels) {
        let info = w.raycast_info();
        if !info.is_in_contact {
            continue;
        }
        let n = info.contact_normal_ws;
        let axle = (w.axle() - n * w.axle().dot(n)).normalize_or_zero();
        let fwd = n.cross(axle).normalize_or_zero();
        let at = info.contact_point_ws;
        let v = rb.velocity_at_point(at);
        let (vx, vy) = (v.dot(fwd), v.dot(axle));
        let fz = w.wheel_suspension_force.min(w.max_suspension_force);
        let c = if geom.steer_side != 0 {
            tyre.cornering_stiffness_front
        } else {
            tyre.cornering_stiffness_rear
        } as f32;
        let alpha = vy.atan2(vx.abs());
        let fx = w.forward_impulse / dt;
        let room = ((mu * fz).powi(2) - fx * fx).max(0.0).sqrt();
        let r_axle = (at - com).cross(axle);
        let k = inv_m + r_axle.dot(inv_i * r_axle);
        let stop = vy.abs() / (k * on_ground as f32);
        let j = ((mu * c * fz * alpha.abs()).min(room) * dt).min(stop);
        let at = at - up * (up.dot(at - com) * (1.0 - ROLL_INFLUENCE));
        impulses.push((axle * (-vy.signum() * j), at));
    }
    let rb = &mut pw.bodies[chassis];
    for (j, at) in impulses {
        rb.apply_impulse_at_point(j, at, false);
    }
}

/// Clearance kept beyond rapier's contact prediction distance before a step may skip rapier,
/// metres: rapier recycles contact points up to 5 cm, and 5 cm also covers the car's speed
/// changing by up to 3 m/s within a control period (90 m/s^2) beyond the doubled travel.
const FREE_MARGIN_M: f32 = 0.05;
/// The same beneath the chassis, metres: the ground is flat and the chassis rides 5 cm above it.
const GROUND_MARGIN_M: f32 = 0.01;

/// One rapier step of a lone dynamic body that has no contact and no joint, without rapier's
/// pipeline (broad phase, narrow phase, islands and a staged solver cost about 30k instructions
/// a step for one free body). These are the operations rapier's solver applies to such a body,
/// in its order: gravity and the gyroscopic correction per internal substep, the speed caps,
/// the linearised pose integration, then damping (rapier 0.36's staged solver; the test
/// `free_flight_moves_the_car_as_rapier_does_to_the_bit_up_to_a_contact` drives every scene
/// both ways and pins it). The colliders and the broad phase catch up at the next rapier step
/// through the body's position change.
fn free_flight(pw: &mut PhysicsWorld, chassis: RigidBodyHandle) {
    let params = pw.integration_parameters;
    let gravity = pw.gravity;
    let rb = &mut pw.bodies[chassis];
    let mp = rb.mass_properties();
    let lm = &mp.local_mprops;
    let n = params.num_solver_iterations;
    let h = params.dt / n as f32;
    let force = rb.user_force() + gravity * mp.effective_mass() * rb.gravity_scale();
    let incr_lin = force * mp.effective_inv_mass * h;
    let incr_ang = mp.effective_world_inv_inertia * rb.user_torque() * h;
    let gyro = rb.gyroscopic_forces_enabled();
    let (principal_frame, principal_inertia, inv_principal_inertia) = (
        lm.principal_inertia_local_frame,
        lm.principal_inertia(),
        lm.inv_principal_inertia,
    );
    let local_com = lm.local_com;
    let com_pose = rb.position().prepend_translation(local_com);
    let (mut trans, mut rot) = (com_pose.translation, com_pose.rotation);
    let (mut lin, mut ang) = (rb.linvel(), rb.angvel());
    let max_lin = params.max_linear_velocity();
    let max_ang = std::f64::consts::FRAC_PI_4 as f32 * params.inv_dt();
    for _ in 0..n {
        lin += incr_lin;
        ang += incr_ang;
        if gyro {
            ang = gyroscopic_corrected_angvel(ang, rot * principal_frame, principal_inertia, inv_principal_inertia, h);
        }
        if max_lin != f32::MAX {
            let l = lin.length();
            if l > max_lin {
                lin *= max_lin / l;
            }
        }
        // The chassis does not allow fast rotation (rapier's default).
        let a = ang.length();
        if a > max_ang {
            ang *= max_ang / a;
        }
        let hang = ang * (h * 0.5);
        rot = (Rotation::from_xyzw(hang.x, hang.y, hang.z, 1.0) * rot).normalize();
        trans += lin * h;
    }
    let one = 1.0f32;
    lin *= one / (one + params.dt * rb.linear_damping());
    ang *= one / (one + params.dt * rb.angular_damping());
    let next = Pose::from_parts(trans, rot).prepend_translation(-local_com);
    rb.set_linvel(lin, false);
    rb.set_angvel(ang, false);
    rb.set_position(next, false);
}

/// rapier's explicit gyroscopic correction that keeps the angular momentum's norm.
fn gyroscopic_corrected_angvel(
    angvel: Vector,
    principal_axes: Rotation,
    principal_inertia: Vector,
    inv_principal_inertia: Vector,
    dt: f32,
) -> Vector {
    let w = principal_axes.inverse() * angvel;
    let curr_momentum = principal_inertia * w;
    let explicit_gyro_momentum = -w.cross(curr_momentum) * dt;
    let total_momentum = curr_momentum + explicit_gyro_momentum;
    let total_momentum_sqnorm = total_momentum.length_squared();
    if total_momentum_sqnorm != 0.0 {
        let capped_momentum = total_momentum * (curr_momentum.length_squared() / total_momentum_sqnorm).sqrt();
        principal_axes * (inv_principal_inertia * capped_momentum)
    } else {
        angvel
    }
}

impl MultibodyCar {
    fn insert(&mut self, world: &mut World, model: &VehicleModel, pose: Pose) -> Result<(), SimError> {
        let mut robot = self.template.clone();
        robot.append_transform(&pose);
        let pw = &mut world.pw;
        let handles = robot.insert_using_multibody_joints(
            &mut pw.bodies,
            &mut pw.colliders,
            &mut pw.multibody_joints,
            UrdfMultibodyOptions::DISABLE_SELF_CONTACTS,
        );
        self.bodies = handles.links.iter().map(|l| l.body).collect();
        let robot = &model.urdf.robot;
        self.mprops = self
            .template
            .links
            .iter()
            .map(|l| {
                model
                    .link_mprops
                    .get(&robot.links[l.urdf_link_index].name)
                    .copied()
                    .unwrap_or_default()
            })
            .collect();
        let wheel_links: Vec<usize> = self
            .template
            .links
            .iter()
            .enumerate()
            .filter(|(_, l)| {
                model
                    .wheels
                    .iter()
                    .any(|w| w.link == model.urdf.robot.links[l.urdf_link_index].name)
            })
            .map(|(i, _)| i)
            .collect();
        self.wheel_colliders = wheel_links
            .iter()
            .flat_map(|&i| handles.links[i].colliders.iter().map(|c| c.handle))
            .collect();
        self.colliders = handles
            .links
            .iter()
            .flat_map(|l| l.colliders.iter().map(|c| c.handle))
            .collect();
        let find = |name: &str| -> Result<MultibodyJointHandle, SimError> {
            self.joint_names
                .iter()
                .position(|n| n == name)
                .and_then(|i| handles.joints[i].joint)
                .ok_or_else(|| SimError::Invalid {
                    context: model.urdf.rel_path.clone(),
                    msg: format!("joint '{name}' did not become a multibody joint"),
                })
        };
        self.drive = model
            .wheels
            .iter()
            .filter(|w| w.driven)
            .map(|w| find(&w.joint))
            .collect::<Result<_, _>>()?;
        self.steer = model
            .wheels
            .iter()
            .filter_map(|w| w.steer_joint.as_ref().map(|s| (s, w.steer_side)))
            .map(|(s, side)| find(s).map(|h| (h, side)))
            .collect::<Result<_, _>>()?;
        // Multibodies add 0.1 of damping to free angular axes; a car must roll freely.
        if let Some(&h) = self.drive.first()
            && let Some((mb, _)) = pw.multibody_joints.get_mut(h)
        {
            mb.damping_mut().fill(0.0);
        }
        for &b in &self.bodies {
            if let Some(rb) = pw.bodies.get_mut(b) {
                rb.set_linear_damping(0.0);
                rb.set_angular_damping(0.0);
            }
            // The loader inserts joints without waking: put every link in an active island.
            pw.wake_up(b, true);
        }
        Ok(())
    }

    /// Move the multibody to `pose` with every joint at zero and at rest. Removing and
    /// re-inserting a multibody leaves rapier's multibody set stale, so reset works in place.
    fn teleport(&mut self, world: &mut World, model: &VehicleModel, pose: Pose, p: BodyParams) -> Result<(), SimError> {
        let pw = &mut world.pw;
        for (&b, mp) in self.bodies.iter().zip(&self.mprops) {
            if let Some(rb) = pw.bodies.get_mut(b) {
                rb.set_additional_mass_properties(scale_mass(*mp, p.mass_scale), false);
                rb.set_linvel(Vector::ZERO, false);
                rb.set_angvel(Vector::ZERO, false);
            }
        }
        for &c in &self.wheel_colliders {
            if let Some(co) = pw.colliders.get_mut(c) {
                co.set_friction(p.tyre_friction);
            }
        }
        let root = self.bodies[self.base_idx];
        pw.bodies[root].set_position(pose, true);
        let h = *self.drive.first().ok_or_else(|| SimError::Invalid {
            context: model.urdf.rel_path.clone(),
            msg: "no driven wheel".into(),
        })?;
        let (mb, _) = pw.multibody_joints.get_mut(h).ok_or_else(|| SimError::Invalid {
            context: model.urdf.rel_path.clone(),
            msg: "multibody lost".into(),
        })?;
        let mut disp = vec![0.0; mb.ndofs()];
        for link in mb.links().filter(|l| !l.is_root()) {
            let n = link.joint().ndofs();
            let coords = link.joint().coords();
            // Revolute joints keep their angle in the first angular slot of `coords`.
            let locked = link.joint().data.locked_axes.bits();
            let mut k = 0;
            for (axis, c) in coords.iter().enumerate() {
                if locked & (1 << axis) == 0 && k < n {
                    disp[link.assembly_id() + k] = -c;
                    k += 1;
                }
            }
        }
        mb.apply_displacements(&disp);
        mb.generalized_velocity_mut().fill(0.0);
        mb.forward_kinematics(&pw.bodies, true);
        let poses: Vec<(RigidBodyHandle, Pose)> = mb
            .links()
            .map(|l| (l.rigid_body_handle(), *l.local_to_world()))
            .collect();
        for (b, pose) in poses {
            pw.bodies[b].set_position(pose, true);
            pw.wake_up(b, true);
        }
        Ok(())
    }
}

fn scale_mass(mp: MassProperties, s: f32) -> MassProperties {
    if s == 1.0 {
        return mp;
    }
    MassProperties::with_principal_inertia_frame(
        mp.local_com,
        mp.mass() * s,
        mp.principal_inertia() * s,
        mp.principal_inertia_local_frame,
    )
}
