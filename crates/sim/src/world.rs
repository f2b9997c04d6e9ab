//! The physics world: rapier with gravity along -z, fixed substeps, the scene's static colliders,
//! and the collision groups that keep the vehicle out of its own sensors.

use crate::scene::Scene;
use rapier3d::prelude::*;

/// Gravity, m/s^2 (REP 103: z up).
pub const GRAVITY_MPS2: f32 = 9.81;

/// Collision groups.
pub mod groups {
    use rapier3d::prelude::*;
    /// The ground.
    pub const GROUND: Group = Group::GROUP_1;
    /// Static scene objects and walls.
    pub const OBSTACLE: Group = Group::GROUP_2;
    /// The vehicle's colliders.
    pub const VEHICLE: Group = Group::GROUP_3;

    /// Groups of a vehicle collider that may touch the ground.
    pub fn vehicle() -> InteractionGroups {
        InteractionGroups::new(VEHICLE, GROUND.union(OBSTACLE), InteractionTestMode::And)
    }
    /// Groups of a vehicle collider that must not touch the ground (ray-cast wheel proxies).
    pub fn vehicle_no_ground() -> InteractionGroups {
        InteractionGroups::new(VEHICLE, OBSTACLE, InteractionTestMode::And)
    }
    /// Groups for queries that see everything but the vehicle.
    pub fn sensors() -> InteractionGroups {
        InteractionGroups::new(Group::ALL, GROUND.union(OBSTACLE), InteractionTestMode::And)
    }
}

/// Collider `user_data` for the ground: scene object ids are stored as `id + 1`.
pub const GROUND_USER_DATA: u128 = 0;

/// One static collider, for sensors that skip the broad phase.
#[derive(Clone)]
pub struct StaticEntry {
    /// World-frame bounding box.
    pub aabb: Aabb,
    /// Shape.
    pub shape: SharedShape,
    /// World pose.
    pub pose: Pose,
    /// Scene object id (`None`: the ground).
    pub object_id: Option<u32>,
    /// RGB in [0, 1].
    pub color: [f32; 3],
    /// The shape prepared for closed-form ray casts.
    pub fast: crate::sensors::fast_ray::FastRay,
}

/// Every static collider of the scene with its box (the scene never moves).
#[derive(Clone, Default)]
pub struct StaticIndex {
    /// The entries, ground first.
    pub entries: Vec<StaticEntry>,
}

/// The rapier state plus the static index.
pub struct World {
    /// rapier's bundle of sets and pipelines.
    pub pw: PhysicsWorld,
    /// Static colliders for sensors.
    pub statics: StaticIndex,
    /// The ground's collider.
    pub ground: ColliderHandle,
    /// A tree of the static colliders alone (ground and obstacles), built once: the wheels'
    /// suspension rays only ever hit those, and walking it instead of rapier's broad phase
    /// (which also holds the moving car) takes 6 % off an oval step.
    pub statics_bvh: BroadPhaseBvh,
}

impl World {
    /// A world holding `scene`, stepping `substep_s` seconds per physics step.
    pub fn new(scene: &Scene, substep_s: f32) -> Self {
        let mut pw = PhysicsWorld {
            gravity: Vector::new(0.0, 0.0, -GRAVITY_MPS2),
            ..PhysicsWorld::default()
        };
        pw.integration_parameters.dt = substep_s;
        let [gx, gy] = scene.file.ground.size_m;
        let ground_body = pw.insert_body(RigidBodyBuilder::fixed());
        let ground = pw.insert_collider(
            ColliderBuilder::cuboid(gx / 2.0, gy / 2.0, 0.05)
                .translation(Vector::new(0.0, 0.0, -0.05))
                .friction(scene.file.ground.friction)
                .friction_combine_rule(CoefficientCombineRule::Multiply)
                .collision_groups(InteractionGroups::new(
                    groups::GROUND,
                    Group::ALL,
                    InteractionTestMode::And,
                ))
                .user_data(GROUND_USER_DATA),
            Some(ground_body),
        );
        let mut statics = StaticIndex::default();
        let gco = &pw.colliders[ground];
        statics.entries.push(StaticEntry {
            aabb: gco.compute_aabb(),
            shape: gco.shared_shape().clone(),
            pose: *gco.position(),
            object_id: None,
            color: scene.file.ground.color,
            fast: crate::sensors::fast_ray::FastRay::new(gco.shared_shape(), gco.position()),
        });
        for obj in &scene.objects {
            let body = pw.insert_body(RigidBodyBuilder::fixed());
            for s in &obj.shapes {
                let h = pw.insert_collider(
                    ColliderBuilder::new(s.shape.clone())
                        .position(s.pose)
                        .friction(0.5)
                        .collision_groups(InteractionGroups::new(
                            groups::OBSTACLE,
                            Group::ALL,
                            InteractionTestMode::And,
                        ))
                        .user_data(obj.id as u128 + 1),
                    Some(body),
                );
                let co = &pw.colliders[h];
                statics.entries.push(StaticEntry {
                    aabb: co.compute_aabb(),
                    shape: co.shared_shape().clone(),
                    pose: *co.position(),
                    object_id: Some(obj.id),
                    color: s.color,
                    fast: crate::sensors::fast_ray::FastRay::new(co.shared_shape(), co.position()),
                });
            }
        }
        let mut statics_bvh = BroadPhaseBvh::new();
        for (h, co) in pw.colliders.iter() {
            if co.parent().is_some_and(|b| pw.bodies[b].is_fixed()) {
                statics_bvh.set_aabb(&pw.integration_parameters, h, co.compute_aabb());
            }
        }
        Self {
            pw,
            statics,
            ground,
            statics_bvh,
        }
    }

    /// Half the thickness of the thinnest obstacle (parry's `ccd_thickness`: a box's smallest
    /// half extent), metres; infinite without obstacles.
    pub fn thinnest_obstacle_m(&self) -> f32 {
        self.statics
            .entries
            .iter()
            .filter(|e| e.object_id.is_some())
            .map(|e| e.shape.ccd_thickness())
            .fold(f32::INFINITY, f32::min)
    }

    /// Turn rapier's continuous collision detection (swept motion clamping) on or off.
    pub fn set_continuous_collision(&mut self, on: bool) {
        self.pw.integration_parameters.max_ccd_substeps = usize::from(on);
    }

    /// Whether continuous collision detection runs.
    pub fn continuous_collision(&self) -> bool {
        self.pw.integration_parameters.max_ccd_substeps > 0
    }

    /// Scene object id behind a collider (`None` for the ground and the vehicle).
    pub fn object_id(&self, h: ColliderHandle) -> Option<u32> {
        let co = self.pw.colliders.get(h)?;
        if co.collision_groups().memberships.contains(groups::OBSTACLE) && co.user_data > 0 {
            Some((co.user_data - 1) as u32)
        } else {
            None
        }
    }
}

/// A copy of the rapier state, restored at every reset so episodes replay bit for bit (contact
/// caches, islands and the broad phase would otherwise remember earlier episodes).
#[derive(Clone)]
pub struct WorldSnapshot {
    bodies: RigidBodySet,
    colliders: ColliderSet,
    impulse_joints: ImpulseJointSet,
    multibody_joints: MultibodyJointSet,
    islands: IslandManager,
    broad_phase: BroadPhaseBvh,
    narrow_phase: NarrowPhase,
    ccd_solver: CCDSolver,
}

impl World {
    /// Copy the rapier state.
    pub fn snapshot(&self) -> WorldSnapshot {
        let pw = &self.pw;
        WorldSnapshot {
            bodies: pw.bodies.clone(),
            colliders: pw.colliders.clone(),
            impulse_joints: pw.impulse_joints.clone(),
            multibody_joints: pw.multibody_joints.clone(),
            islands: pw.islands.clone(),
            broad_phase: pw.broad_phase.clone(),
            narrow_phase: pw.narrow_phase.clone(),
            ccd_solver: pw.ccd_solver.clone(),
        }
    }

    /// Put the rapier state back to `snap`, with fresh solver workspaces.
    pub fn restore(&mut self, snap: &WorldSnapshot) {
        let pw = &mut self.pw;
        pw.bodies.clone_from(&snap.bodies);
        pw.colliders.clone_from(&snap.colliders);
        pw.impulse_joints.clone_from(&snap.impulse_joints);
        pw.multibody_joints.clone_from(&snap.multibody_joints);
        pw.islands.clone_from(&snap.islands);
        pw.broad_phase.clone_from(&snap.broad_phase);
        pw.narrow_phase.clone_from(&snap.narrow_phase);
        pw.ccd_solver.clone_from(&snap.ccd_solver);
        pw.physics_pipeline = PhysicsPipeline::new();
        pw.collision_pipeline = CollisionPipeline::new();
    }
}
