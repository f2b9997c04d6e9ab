//! Scenes: a TOML file (ground, boundary walls, an optional oval track, decals and placed object
//! models; `file.rs`), the objects it places, built into colliders here, and a seeded procedural
//! generator per scene kind (`procedural.rs`). Race tracks come from map files (`map_track.rs`)
//! or are generated as seeded circuits (`circuit.rs`); both build through [`Scene::from_map`].

mod circuit;
mod file;
mod map_track;
mod procedural;

pub use circuit::{CircuitInfo, CircuitSettings, write_map};
pub use file::{BoundarySpec, Decal, GroundSpec, Placement, SceneFile, SceneKind, SpawnSpec, TrackSpec};
pub use map_track::{MapTrack, SIMPLIFY_PX};

use crate::SimError;
use crate::assets::AssetSource;
use crate::urdf::{ShapeSpec, UrdfModel};
use rapier3d::prelude::*;
use serde::Deserialize;
use std::collections::HashMap;

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
    /// The closed centre line of a map-file track in racing order, metres (the oval's is in
    /// `file.track`).
    pub centreline: Option<Vec<[f32; 2]>>,
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
        Ok(Self {
            file,
            objects,
            centreline: None,
        })
    }

    /// A map-file track: its walls on a ground that holds them all, the vehicle spawning on the
    /// centre line's first point, heading to the next.
    pub fn from_map(t: &MapTrack) -> Result<Self, SimError> {
        t.validate().map_err(|msg| SimError::Invalid {
            context: format!("track {}", t.name),
            msg,
        })?;
        // The ground is centred at the origin: it reaches the farthest wall each way, and 2 m on.
        let mut reach = [0.0f32; 2];
        let shapes = t
            .walls
            .iter()
            .map(|&[x, y, hx, hy, yaw]| {
                let r = hx.hypot(hy);
                reach = [reach[0].max(x.abs() + r), reach[1].max(y.abs() + r)];
                let hz = t.wall_height_m / 2.0;
                ShapeSpec {
                    shape: SharedShape::cuboid(hx, hy, hz),
                    pose: Pose::from_parts(Vector::new(x, y, hz), Rotation::from_rotation_z(yaw)),
                    link: "wall".into(),
                    color: [0.8, 0.1, 0.1],
                }
            })
            .collect();
        let c = &t.centreline;
        let file = SceneFile {
            name: t.name.clone(),
            kind: SceneKind::Track,
            ground: GroundSpec {
                size_m: [2.0 * (reach[0] + 2.0), 2.0 * (reach[1] + 2.0)],
                friction: 1.0,
                color: [0.5, 0.5, 0.5],
            },
            boundary: None,
            spawn: SpawnSpec {
                x_m: c[0][0],
                y_m: c[0][1],
                yaw_deg: (c[1][1] - c[0][1]).atan2(c[1][0] - c[0][0]).to_degrees(),
            },
            track: None,
            decals: Vec::new(),
            objects: Vec::new(),
        };
        Ok(Self {
            file,
            objects: vec![SceneObject {
                id: 0,
                model: "track".into(),
                class: "wall".into(),
                shapes,
            }],
            centreline: Some(t.centreline.clone()),
        })
    }

    /// Half extents (x, y) of the drivable map, metres: inside the boundary walls, or the ground.
    pub fn half_extent_m(&self) -> [f32; 2] {
        match &self.file.boundary {
            Some(b) => [b.inner_half_m, b.inner_half_m],
            None => [self.file.ground.size_m[0] / 2.0, self.file.ground.size_m[1] / 2.0],
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CatalogEntry {
    class: String,
}
