//! Seeded procedural scenes of each kind (outdoor, urban), built like scene files.

use super::{BoundarySpec, Decal, GroundSpec, Placement, Scene, SceneFile, SceneKind, SpawnSpec, TrackSpec};
use crate::SimError;
use crate::assets::AssetSource;
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};

impl Scene {
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
