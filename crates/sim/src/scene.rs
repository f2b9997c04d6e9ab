//! Scenes: a TOML file (ground, boundary walls, an optional oval track, decals and placed object
//! models), the objects it places, and a seeded procedural generator per scene kind.

use crate::SimError;
use crate::assets::AssetSource;
use crate::urdf::{ShapeSpec, UrdfModel};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use rapier3d::prelude::*;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
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
    /// The track's plain geometry (progress along the centre line).
    pub fn oval(&self) -> crate::msg::OvalTrack {
        crate::msg::OvalTrack {
            straight_m: self.straight_m,
            inner_radius_m: self.inner_radius_m,
            outer_radius_m: self.outer_radius_m,
        }
    }

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

/// A static object of a built scene: one fixed body with one or more colliders.
#[derive(Clone)]
pub struct SceneObject {
    /// Object id: what LiDAR and segmentation report. Ids are dense from 0.
    pub id: u32,
    /// Model name, or `boundary` / `track`.
    pub model: String,
    /// Semantic class.
    pub class: String,
    /// Collision shapes in the world frame.
    pub shapes: Vec<ShapeSpec>,
}

/// A scene ready to be inserted into a world.
#[derive(Clone)]
pub struct Scene {
    /// The description it came from.
    pub file: SceneFile,
    /// Every static object (walls included), id = index.
    pub objects: Vec<SceneObject>,
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

/// Ids of the built-in scenes.
pub const SCENE_IDS: &[&str] = &["outdoor-20", "outdoor-50", "urban-20", "urban-50", "oval"];

impl Scene {
    /// Load a built-in scene by id.
    pub fn builtin(src: &AssetSource, id: &str) -> Result<Self, SimError> {
        let rel = format!("scenes/{id}.toml");
        if src.read(&rel).is_err() {
            return Err(SimError::Invalid {
                context: "scene".into(),
                msg: format!(
                    "unknown scene '{id}'; built-in scenes: {}",
                    src.list("scenes", "toml").join(", ")
                ),
            });
        }
        Self::load(src, &rel)
    }

    /// Load the scene TOML at `rel`; object models come from `objects/` of the built-in assets.
    pub fn load(src: &AssetSource, rel: &str) -> Result<Self, SimError> {
        let text = src.read(rel)?;
        let file: SceneFile = toml::from_str(&text).map_err(|e| SimError::Toml {
            path: src.display_path(rel),
            msg: e.to_string(),
        })?;
        Self::build(
            file,
            &AssetSource::builtin(),
            &src.display_path(rel).display().to_string(),
        )
    }

    /// Build the objects of `file`, reading models from `objects/` of `models`.
    pub fn build(file: SceneFile, models: &AssetSource, context: &str) -> Result<Self, SimError> {
        let invalid = |msg: String| SimError::Invalid {
            context: context.to_string(),
            msg,
        };
        let [gx, gy] = file.ground.size_m;
        if !(gx > 0.0 && gy > 0.0 && file.ground.friction >= 0.0) {
            return Err(invalid("ground.size_m must be positive and friction >= 0".into()));
        }
        let catalog: HashMap<String, CatalogEntry> = {
            let text = models.read("objects/catalog.toml")?;
            toml::from_str(&text).map_err(|e| SimError::Toml {
                path: models.display_path("objects/catalog.toml"),
                msg: e.to_string(),
            })?
        };
        let mut objects = Vec::new();
        if let Some(b) = &file.boundary {
            if !(b.inner_half_m > 0.0 && b.thickness_m > 0.0 && b.height_m > 0.0) {
                return Err(invalid("boundary sizes must be positive".into()));
            }
            let (h, t, hz) = (b.inner_half_m, b.thickness_m, b.height_m / 2.0);
            let long = h + t;
            let mut shapes = Vec::new();
            for (he, pos) in [
                (Vector::new(t / 2.0, long, hz), Vector::new(h + t / 2.0, 0.0, hz)),
                (Vector::new(t / 2.0, long, hz), Vector::new(-h - t / 2.0, 0.0, hz)),
                (Vector::new(long, t / 2.0, hz), Vector::new(0.0, h + t / 2.0, hz)),
                (Vector::new(long, t / 2.0, hz), Vector::new(0.0, -h - t / 2.0, hz)),
            ] {
                shapes.push(ShapeSpec {
                    shape: SharedShape::cuboid(he.x, he.y, he.z),
                    pose: Pose::from_translation(pos),
                    link: "wall".into(),
                    color: b.color,
                });
            }
            objects.push(SceneObject {
                id: 0,
                model: "boundary".into(),
                class: "wall".into(),
                shapes,
            });
        }
        if let Some(t) = &file.track {
            if !(t.straight_m >= 0.0
                && t.inner_radius_m > 0.0
                && t.outer_radius_m > t.inner_radius_m
                && t.segment_deg > 0.0)
            {
                return Err(invalid(
                    "track needs straight_m >= 0 and 0 < inner_radius_m < outer_radius_m".into(),
                ));
            }
            let shapes = t
                .wall_boxes()
                .into_iter()
                .map(|(he, pose)| ShapeSpec {
                    shape: SharedShape::cuboid(he.x, he.y, he.z),
                    pose,
                    link: "wall".into(),
                    color: t.color,
                })
                .collect();
            objects.push(SceneObject {
                id: 0,
                model: "track".into(),
                class: "wall".into(),
                shapes,
            });
        }
        let mut cache: HashMap<String, UrdfModel> = HashMap::new();
        for (i, p) in file.objects.iter().enumerate() {
            if p.scale.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
                return Err(invalid(format!(
                    "object {} ('{}'): scale must be positive",
                    i + 1,
                    p.model
                )));
            }
            let entry = catalog.get(&p.model).ok_or_else(|| {
                let mut known: Vec<&String> = catalog.keys().collect();
                known.sort();
                invalid(format!(
                    "object {} names unknown model '{}'; known models: {}",
                    i + 1,
                    p.model,
                    known.iter().map(|s| s.as_str()).collect::<Vec<_>>().join(", ")
                ))
            })?;
            if !cache.contains_key(&p.model) {
                cache.insert(
                    p.model.clone(),
                    UrdfModel::read(models, &format!("objects/{}.urdf", p.model))?,
                );
            }
            let model = &cache[&p.model];
            let scale = Vector::from_array(p.scale);
            let place = Pose::from_parts(
                Vector::new(p.x_m, p.y_m, 0.0),
                Rotation::from_rotation_z(p.yaw_deg.to_radians()),
            );
            let shapes = model
                .collision_shapes(models, scale, |_| true)?
                .into_iter()
                .map(|s| ShapeSpec {
                    pose: place * s.pose,
                    ..s
                })
                .collect();
            objects.push(SceneObject {
                id: 0,
                model: p.model.clone(),
                class: entry.class.clone(),
                shapes,
            });
        }
        for (i, o) in objects.iter_mut().enumerate() {
            o.id = i as u32;
        }
        Ok(Self { file, objects })
    }

    /// Half extents (x, y) of the drivable map, metres: inside the boundary walls, or the ground.
    pub fn half_extent_m(&self) -> [f32; 2] {
        match &self.file.boundary {
            Some(b) => [b.inner_half_m, b.inner_half_m],
            None => [self.file.ground.size_m[0] / 2.0, self.file.ground.size_m[1] / 2.0],
        }
    }

    /// A random layout of the given kind: `outdoor` / `urban` on a square map of inner half
    /// size `half_m`, or an oval track; objects keep `clearance_m` from the spawn at the origin.
    pub fn procedural(kind: SceneKind, seed: u64, half_m: f32, clearance_m: f32) -> Result<Self, SimError> {
        let mut rng = StdRng::seed_from_u64(seed);
        let mut file = SceneFile {
            name: format!("{}-procedural-{seed}", kind_name(kind)),
            kind,
            ground: GroundSpec {
                size_m: [2.0 * half_m + 1.0; 2],
                friction: 1.0,
                color: [0.36, 0.5, 0.26],
            },
            boundary: Some(BoundarySpec {
                inner_half_m: half_m,
                thickness_m: 0.5,
                height_m: 1.0,
                color: [0.6, 0.6, 0.6],
            }),
            spawn: SpawnSpec {
                x_m: 0.0,
                y_m: 0.0,
                yaw_deg: 0.0,
            },
            track: None,
            decals: vec![],
            objects: vec![],
        };
        let area = (2.0 * half_m).powi(2);
        let place = |rng: &mut StdRng, n: usize, models: &[(&str, f32)], objects: &mut Vec<Placement>, spacing: f32| {
            let mut taken: Vec<(f32, f32, f32)> = Vec::new();
            let mut tries = 0;
            while taken.len() < n && tries < 10_000 {
                tries += 1;
                let (model, radius) = models[rng.random_range(0..models.len())];
                let x = rng.random_range(-half_m + radius..half_m - radius);
                let y = rng.random_range(-half_m + radius..half_m - radius);
                if (x * x + y * y).sqrt() < clearance_m + radius
                    || taken
                        .iter()
                        .any(|(tx, ty, tr)| ((x - tx).powi(2) + (y - ty).powi(2)).sqrt() < radius + tr + spacing)
                {
                    continue;
                }
                taken.push((x, y, radius));
                objects.push(Placement {
                    model: model.into(),
                    x_m: x,
                    y_m: y,
                    yaw_deg: rng.random_range(-180.0..180.0),
                    scale: [1.0; 3],
                });
            }
        };
        match kind {
            SceneKind::Outdoor => {
                // AutoVRL's densities: 11 objects on 400 m^2, 73 on 2500 m^2.
                let n = (area * 0.028).round() as usize;
                place(
                    &mut rng,
                    n,
                    &[("tree", 0.6), ("rock_1", 1.7), ("rock_2", 1.1)],
                    &mut file.objects,
                    1.2,
                );
            }
            SceneKind::Urban => {
                let road_half = (half_m * 0.3).clamp(3.0, 7.5);
                file.decals.push(Decal {
                    class: "road".into(),
                    x_m: 0.0,
                    y_m: 0.0,
                    size_m: [2.0 * half_m, 2.0 * road_half],
                    yaw_deg: 0.0,
                    color: [0.25, 0.25, 0.27],
                });
                let n = (area / 45.0).round() as usize;
                let mut taken: Vec<[f32; 4]> = Vec::new();
                let mut tries = 0;
                while taken.len() < n && tries < 10_000 {
                    tries += 1;
                    let (sx, sy) = (rng.random_range(4.0..10.0f32), rng.random_range(3.0..8.0f32));
                    let x = rng.random_range(-half_m + sx / 2.0..half_m - sx / 2.0);
                    let side = if rng.random::<bool>() { 1.0 } else { -1.0 };
                    let y_lo = road_half + 1.0 + sy / 2.0;
                    if y_lo >= half_m - sy / 2.0 {
                        continue;
                    }
                    let y = side * rng.random_range(y_lo..half_m - sy / 2.0);
                    let r = [
                        x - sx / 2.0 - 1.0,
                        x + sx / 2.0 + 1.0,
                        y - sy / 2.0 - 1.0,
                        y + sy / 2.0 + 1.0,
                    ];
                    if taken
                        .iter()
                        .any(|t| r[0] < t[1] && r[1] > t[0] && r[2] < t[3] && r[3] > t[2])
                    {
                        continue;
                    }
                    taken.push(r);
                    file.objects.push(Placement {
                        model: "building".into(),
                        x_m: x,
                        y_m: y,
                        yaw_deg: 0.0,
                        scale: [sx, sy, rng.random_range(3.0..14.0)],
                    });
                }
                // Parked cars along the road edges, away from the spawn.
                let n_cars = (half_m / 4.0).round() as usize;
                let mut placed = 0;
                let mut tries = 0;
                while placed < n_cars && tries < 1_000 {
                    tries += 1;
                    let x = rng.random_range(-half_m + 3.0..half_m - 3.0);
                    if x.abs() < clearance_m + 3.0 {
                        continue;
                    }
                    let y = if rng.random::<bool>() {
                        road_half - 1.2
                    } else {
                        -road_half + 1.2
                    };
                    if file
                        .objects
                        .iter()
                        .any(|o| o.model.starts_with("car") && (o.x_m - x).abs() < 6.0 && (o.y_m - y).abs() < 1.0)
                    {
                        continue;
                    }
                    let model = if rng.random::<bool>() { "car_1" } else { "car_2" };
                    file.objects.push(Placement {
                        model: model.into(),
                        x_m: x,
                        y_m: y,
                        yaw_deg: 0.0,
                        scale: [1.0; 3],
                    });
                    placed += 1;
                }
            }
            SceneKind::Track => {
                let straight = rng.random_range(6.0..20.0f32);
                let inner = rng.random_range(2.5..4.0f32);
                file.boundary = None;
                file.ground.size_m = [2.0 * (inner + 4.0) + 2.0, straight + 2.0 * (inner + 4.0) + 2.0];
                file.ground.color = [0.5, 0.5, 0.5];
                file.spawn = SpawnSpec {
                    x_m: inner + 1.0,
                    y_m: 0.0,
                    yaw_deg: -90.0,
                };
                file.track = Some(TrackSpec {
                    straight_m: straight,
                    inner_radius_m: inner,
                    outer_radius_m: inner + 2.0,
                    wall_height_m: 0.75,
                    wall_thickness_m: 0.1,
                    segment_deg: 10.0,
                    color: [0.8, 0.1, 0.1],
                });
            }
        }
        Self::build(file, &AssetSource::builtin(), "procedural scene")
    }
}

fn kind_name(k: SceneKind) -> &'static str {
    match k {
        SceneKind::Outdoor => "outdoor",
        SceneKind::Urban => "urban",
        SceneKind::Track => "track",
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CatalogEntry {
    class: String,
}
