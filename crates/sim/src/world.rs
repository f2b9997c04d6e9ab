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

    /// Groups of a vehicle collider that may touch the ground (and other cars, when the world
    /// holds several).
    pub fn vehicle(other_cars: bool) -> InteractionGroups {
        let with = if other_cars { VEHICLE } else { Group::NONE };
        InteractionGroups::new(VEHICLE, GROUND.union(OBSTACLE).union(with), InteractionTestMode::And)
    }
    /// Groups of a vehicle collider that must not touch the ground (ray-cast wheel proxies).
    pub fn vehicle_no_ground(other_cars: bool) -> InteractionGroups {
        let with = if other_cars { VEHICLE } else { Group::NONE };
        InteractionGroups::new(VEHICLE, OBSTACLE.union(with), InteractionTestMode::And)
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

/// Every car's shapes where they stand now, for the sensors of a world of several cars (a
/// handful of shapes a car: sensors test them all, after the static scene, but their own).
#[derive(Clone, Default)]
pub struct Movers {
    /// The shapes; `object_id` is `None`.
    pub entries: Vec<StaticEntry>,
    /// The car each entry belongs to.
    pub car: Vec<u32>,
}

impl Movers {
    /// The entries a sensor of car `own` sees (all but its own), with their index.
    pub fn seen(&self, own: Option<u32>) -> impl Iterator<Item = (usize, &StaticEntry)> {
        self.entries
            .iter()
            .enumerate()
            .filter(move |(i, _)| Some(self.car[*i]) != own)
    }
}

/// The rapier state plus the static index.
pub struct World {
    /// rapier's bundle of sets and pipelines.
    pub pw: PhysicsWorld,
    /// Static colliders for sensors.
    pub statics: StaticIndex,
    /// The ground's collider.
    pub ground: ColliderHandle,
}

/// A tree of the static colliders (ground and obstacles) around one car, for its wheels'
/// suspension rays: they only ever hit those, and a tree of the few colliders near the car
/// is walked in a fraction of the time of a tree of the whole scene.
#[derive(Clone)]
pub(crate) struct NearStatics {
    /// Every static collider with its box.
    all: Vec<(ColliderHandle, Aabb)>,
    bvh: BroadPhaseBvh,
    /// Where the tree was built and the half size of its box; `None` until first used.
    built: Option<(Vector, f32)>,
}

impl NearStatics {
    /// How far the car may move before the tree is rebuilt, metres.
    const SLACK_M: f32 = 0.5;

    pub(crate) fn new(pw: &PhysicsWorld) -> Self {
        let all = pw
            .colliders
            .iter()
            .filter(|(_, co)| co.parent().is_some_and(|b| pw.bodies[b].is_fixed()))
            .map(|(h, co)| (h, co.compute_aabb()))
            .collect();
        Self {
            all,
            bvh: BroadPhaseBvh::new(),
            built: None,
        }
    }

    /// The tree, holding every static collider that a segment starting within `reach_m` of
    /// `at` and ending within `reach_m` of it can meet.
    pub(crate) fn around(&mut self, params: &IntegrationParameters, at: Vector, reach_m: f32) -> &BroadPhaseBvh {
        let fresh = self
            .built
            .is_some_and(|(c, half)| half >= reach_m + Self::SLACK_M && (at - c).abs().max_element() <= Self::SLACK_M);
        if !fresh {
            let half = reach_m + Self::SLACK_M;
            let region = Aabb::new(at - Vector::splat(half), at + Vector::splat(half));
            self.bvh = BroadPhaseBvh::new();
            for (h, aabb) in &self.all {
                if aabb.intersects(&region) {
                    self.bvh.set_aabb(params, *h, *aabb);
                }
            }
            self.built = Some((at, half));
        }
        &self.bvh
    }
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
        Self { pw, statics, ground }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::assets::AssetSource;

    /// Rays that start and end within the reach of the point the near tree was asked about hit
    /// what they hit in a tree of the whole scene, to the bit; the tree is rebuilt as the point
    /// wanders off.
    #[test]
    fn the_near_tree_answers_rays_within_reach_like_the_whole_scene() {
        for id in ["urban-20", "oval"] {
            let scene = Scene::builtin(&AssetSource::builtin(), id).unwrap();
            let mut w = World::new(&scene, 1.0 / 120.0);
            let mut near_tree = NearStatics::new(&w.pw);
            let mut full = BroadPhaseBvh::new();
            for (h, aabb) in &near_tree.all {
                full.set_aabb(&w.pw.integration_parameters, *h, *aabb);
            }
            let filter = QueryFilter::default().groups(groups::sensors());
            let [hx, hy] = scene.half_extent_m();
            let reach = 0.6f32;
            let (mut hits, mut rebuilds, mut last) = (0, 0, None);
            let mut x = 0.37f64;
            let mut next = || {
                x = (x * 3.97 * (1.0 - x)).clamp(1e-6, 1.0 - 1e-6);
                x as f32
            };
            // A walk across the map, with rays in every direction (the ground, walls, boxes).
            let mut at = Vector::new(-hx * 0.9, -hy * 0.9, 0.1);
            for _ in 0..3000 {
                at += Vector::new(0.05 + 0.1 * next(), 0.05 + 0.1 * next(), 0.0);
                if at.x > hx || at.y > hy {
                    at = Vector::new(-hx * 0.9 + 2.0 * hx * next() * 0.9, -hy * 0.9, 0.1);
                }
                let a = Vector::new(next() - 0.5, next() - 0.5, next() - 0.8).normalize() * reach * next();
                let b = Vector::new(next() - 0.5, next() - 0.5, next() - 0.8).normalize() * reach * next();
                let ray = Ray::new(at + a, b - a);
                let pw = &mut w.pw;
                let near = near_tree.around(&pw.integration_parameters, at, reach);
                let got = near
                    .as_query_pipeline(pw.narrow_phase.query_dispatcher(), &pw.bodies, &pw.colliders, filter)
                    .cast_ray_and_get_normal(&ray, 1.0, true);
                let want = full
                    .as_query_pipeline(pw.narrow_phase.query_dispatcher(), &pw.bodies, &pw.colliders, filter)
                    .cast_ray_and_get_normal(&ray, 1.0, true);
                // A ray starting inside overlapping solids may name either of them (at 0).
                let key = |h: Option<(ColliderHandle, RayIntersection)>| {
                    h.map(|(c, i)| {
                        let inside = i.time_of_impact == 0.0;
                        let c = if inside { None } else { Some(c) };
                        let n = if inside {
                            [0; 3]
                        } else {
                            i.normal.to_array().map(f32::to_bits)
                        };
                        (c, i.time_of_impact.to_bits(), n)
                    })
                };
                assert_eq!(
                    key(got),
                    key(want),
                    "{id}: ray from {:?} along {:?}",
                    ray.origin,
                    ray.dir
                );
                hits += usize::from(want.is_some_and(|(c, _)| c != w.ground));
                if near_tree.built != last {
                    rebuilds += 1;
                    last = near_tree.built;
                }
            }
            assert!(hits > 20, "{id}: only {hits} rays met an obstacle");
            assert!(rebuilds > 20, "{id}: the tree was rebuilt {rebuilds} times");
        }
    }
}
