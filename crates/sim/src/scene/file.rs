//! The scene file format (`assets/scenes/<id>.toml`): ground, boundary walls, an optional oval
//! track, decals and placed object models; units are in the field names.

use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use rapier3d::prelude::{Pose, Rotation, Vector};
use serde::{Deserialize, Serialize};
use std::f32::consts::PI;

/// Which procedural generator a scene belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SceneKind {
    /// Rocks and trees.
    Outdoor,
    /// Buildings, roads and parked cars.
    Urban,
    /// A closed race track.
    Track,
}

/// A scene file (`assets/scenes/<id>.toml`). Units are in the field names.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    /// Scene id.
    pub name: String,
    /// Generator family.
    pub kind: SceneKind,
    /// The ground box (top face at z = 0).
    pub ground: GroundSpec,
    /// Four walls around the map.
    pub boundary: Option<BoundarySpec>,
    /// AutoVRL's fixed spawn.
    pub spawn: SpawnSpec,
    /// An oval race track.
    pub track: Option<TrackSpec>,
    /// Visual-only ground markings.
    #[serde(default, rename = "decal")]
    pub decals: Vec<Decal>,
    /// Placed object models.
    #[serde(default, rename = "object")]
    pub objects: Vec<Placement>,
}

/// The ground.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct GroundSpec {
    /// Extent along x and y, metres, centred at the origin.
    pub size_m: [f32; 2],
    /// Friction coefficient (multiplied with the tyre's).
    pub friction: f32,
    /// RGB in [0, 1].
    pub color: [f32; 3],
}

/// Four boundary walls.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct BoundarySpec {
    /// Inner faces at x = +-inner_half_m and y = +-inner_half_m, metres.
    pub inner_half_m: f32,
    /// Wall thickness, metres.
    pub thickness_m: f32,
    /// Wall height, metres.
    pub height_m: f32,
    /// RGB in [0, 1].
    pub color: [f32; 3],
}

/// A vehicle pose on the ground.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SpawnSpec {
    /// x, metres.
    pub x_m: f32,
    /// y, metres.
    pub y_m: f32,
    /// Heading, degrees counter-clockwise from +x.
    pub yaw_deg: f32,
}

/// An oval (stadium) track: straights along y joined by semicircles centred at (0, +-straight/2).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TrackSpec {
    /// Length of each straight, metres.
    pub straight_m: f32,
    /// Radius of the inner wall's lane-side face, metres.
    pub inner_radius_m: f32,
    /// Radius of the outer wall's lane-side face, metres.
    pub outer_radius_m: f32,
    /// Wall height, metres.
    pub wall_height_m: f32,
    /// Wall thickness, metres.
    pub wall_thickness_m: f32,
    /// Angle covered by one straight segment of a curved wall, degrees.
    pub segment_deg: f32,
    /// RGB in [0, 1].
    pub color: [f32; 3],
}

impl TrackSpec {
    /// Walls as boxes: (half extents, pose).
    pub fn wall_boxes(&self) -> Vec<(Vector, Pose)> {
        let t = self.wall_thickness_m;
        let hz = self.wall_height_m / 2.0;
        let h = self.straight_m / 2.0;
        let mut out = Vec::new();
        for sx in [-1.0f32, 1.0] {
            out.push((
                Vector::new(t / 2.0, h, hz),
                Pose::translation(sx * (self.inner_radius_m - t / 2.0), 0.0, hz),
            ));
            out.push((
                Vector::new(t / 2.0, h, hz),
                Pose::translation(sx * (self.outer_radius_m + t / 2.0), 0.0, hz),
            ));
        }
        let n = (180.0 / self.segment_deg).round().max(1.0) as usize;
        let step = PI / n as f32;
        for (cy, a0) in [(h, 0.0f32), (-h, PI)] {
            for i in 0..n {
                let mid = a0 + (i as f32 + 0.5) * step;
                let (s, c) = mid.sin_cos();
                for (face_r, side) in [(self.inner_radius_m, -1.0f32), (self.outer_radius_m, 1.0)] {
                    let half_len = face_r * (step / 2.0).tan() + t / 2.0;
                    let rc = face_r + side * t / 2.0;
                    let rot = Rotation::from_rotation_z(mid);
                    out.push((
                        Vector::new(t / 2.0, half_len, hz),
                        Pose::from_parts(Vector::new(rc * c, cy + rc * s, hz), rot),
                    ));
                }
            }
        }
        out
    }
}

/// A flat ground marking, visual only.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Decal {
    /// Semantic class (`road`, `lane_marking`).
    pub class: String,
    /// Centre x, metres.
    pub x_m: f32,
    /// Centre y, metres.
    pub y_m: f32,
    /// Extent along its own x and y, metres.
    pub size_m: [f32; 2],
    /// Rotation about z, degrees.
    #[serde(default)]
    pub yaw_deg: f32,
    /// RGB in [0, 1].
    pub color: [f32; 3],
}

/// An object model placed in a scene.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Placement {
    /// Model name: `assets/objects/<model>.urdf`.
    pub model: String,
    /// x, metres.
    pub x_m: f32,
    /// y, metres.
    pub y_m: f32,
    /// Rotation about z, degrees.
    #[serde(default)]
    pub yaw_deg: f32,
    /// Per-axis scale of geometry and origins.
    #[serde(default = "unit_scale")]
    pub scale: [f32; 3],
}

fn unit_scale() -> [f32; 3] {
    [1.0; 3]
}

impl SceneFile {
    /// Add `n` human-sized subjects (model `subject`), seeded: each stands 1.0-1.6 m from a tree
    /// trunk or 0.6-1.2 m outside a building's wall, clear of every other object and at least
    /// `spawn_clearance_m` from the spawn. Fewer are placed when the scene has no room.
    pub fn with_subjects(mut self, n: usize, seed: u64, spawn_clearance_m: f32) -> Self {
        let mut rng = StdRng::seed_from_u64(seed ^ 0x5eed_5b1e);
        // Footprints (centre, half extents) of what is there, to keep subjects clear of it.
        let mut taken: Vec<([f32; 2], [f32; 2])> = self
            .objects
            .iter()
            .map(|o| {
                let half = match o.model.as_str() {
                    "tree" => [0.35, 0.35],
                    "rock_1" => [1.4, 1.4],
                    "rock_2" => [0.9, 0.9],
                    "building" => [o.scale[0] / 2.0, o.scale[1] / 2.0],
                    "car_1" | "car_2" => [2.6 * o.scale[0], 2.6 * o.scale[0]],
                    _ => [0.5, 0.5],
                };
                ([o.x_m, o.y_m], half)
            })
            .collect();
        let anchors: Vec<Placement> = self
            .objects
            .iter()
            .filter(|o| o.model == "tree" || o.model == "building")
            .cloned()
            .collect();
        let limit = match &self.boundary {
            Some(b) => b.inner_half_m - 0.5,
            None => self.ground.size_m[0].min(self.ground.size_m[1]) / 2.0 - 0.5,
        };
        let mut placed = 0;
        for _ in 0..(200 * n) {
            if placed == n || anchors.is_empty() {
                break;
            }
            let a = &anchors[rng.random_range(0..anchors.len())];
            let (x, y) = if a.model == "tree" {
                let (r, ang) = (rng.random_range(1.0..1.6f32), rng.random_range(-PI..PI));
                (a.x_m + r * ang.cos(), a.y_m + r * ang.sin())
            } else {
                let (hx, hy) = (a.scale[0] / 2.0, a.scale[1] / 2.0);
                let gap = rng.random_range(0.6..1.2f32);
                match rng.random_range(0..4) {
                    0 => (a.x_m + hx + gap, a.y_m + rng.random_range(-hy..hy)),
                    1 => (a.x_m - hx - gap, a.y_m + rng.random_range(-hy..hy)),
                    2 => (a.x_m + rng.random_range(-hx..hx), a.y_m + hy + gap),
                    _ => (a.x_m + rng.random_range(-hx..hx), a.y_m - hy - gap),
                }
            };
            let clear = |c: [f32; 2], h: [f32; 2]| (x - c[0]).abs() > h[0] + 0.4 || (y - c[1]).abs() > h[1] + 0.4;
            let spawn_d = ((x - self.spawn.x_m).powi(2) + (y - self.spawn.y_m).powi(2)).sqrt();
            if x.abs() > limit
                || y.abs() > limit
                || spawn_d < spawn_clearance_m
                || !taken.iter().all(|(c, h)| clear(*c, *h))
            {
                continue;
            }
            taken.push(([x, y], [0.2, 0.2]));
            self.objects.push(Placement {
                model: "subject".into(),
                x_m: x,
                y_m: y,
                yaw_deg: rng.random_range(-180.0..180.0),
                scale: [1.0; 3],
            });
            placed += 1;
        }
        self
    }
}
