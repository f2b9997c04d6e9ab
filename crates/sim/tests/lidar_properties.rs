//! Generated LiDAR settings and poses in generated box rooms.

use super::*;
use proptest::prelude::*;

/// Distance from `o` along the unit vector `d` to the first inner wall face of a room
/// with faces at +-`half` (vertical planes, so a tilted ray is exact too).
fn to_wall(half: f32, o: Vector, d: Vector) -> f32 {
    let mut t = f32::INFINITY;
    for (dc, oc) in [(d.x, o.x), (d.y, o.y)] {
        if dc > 1e-9 {
            t = t.min((half - oc) / dc);
        } else if dc < -1e-9 {
            t = t.min((-half - oc) / dc);
        }
    }
    t
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(128))]

    /// Every range lies in [range_min, range_max] and never beyond the nearest wall;
    /// a ray whose wall lies within range returns it (to 1 cm).
    #[test]
    fn ranges_lie_within_the_limits_and_never_pass_the_nearest_wall(
        half in 1.5f32..8.0,
        n_rays in 1usize..200,
        fov_deg in 1.0f32..=360.0,
        range_min_m in 0.0f32..0.4,
        range_max_m in 0.5f32..15.0,
        poses in prop::collection::vec((-1.0f32..1.0, -1.0f32..1.0, -3.2f32..3.2, 0.1f32..0.9, -0.05f32..0.05), 1..8),
    ) {
        let walls = room(half, "lidar-props");
        let mut s = Sim::new(SimConfig {
            scene: walls.src(),
            settings: SimSettings {
                lidar: sensors::LidarConfig { n_rays, fov_deg, range_min_m, range_max_m },
                ..Default::default()
            },
        })
        .unwrap();
        for (fx, fy, yaw, z, pitch) in poses {
            // Anywhere at least 0.45 m inside the walls, tilted a little.
            let inner = half - 0.45;
            let rot = Rotation::from_rotation_z(yaw) * Rotation::from_rotation_y(pitch);
            let pose = Pose::from_parts(Vector::new(fx * inner, fy * inner, z), rot);
            let scan = s.lidar_scan_at(&mp(&pose));
            prop_assert_eq!(scan.ranges.len(), n_rays);
            for (i, &r) in scan.ranges.iter().enumerate() {
                prop_assert!(r >= range_min_m && r <= range_max_m, "ray {i}: {r}");
                let a = scan.angle_min + i as f32 * scan.angle_increment;
                let d = rot * Vector::new(a.cos(), a.sin(), 0.0);
                let want = to_wall(half, pose.translation, d);
                // Pitched, a ray may meet the ground first or pass over the 1 m walls.
                let ground = if d.z < -1e-6 { -pose.translation.z / d.z } else { f32::INFINITY };
                let meets_wall = pose.translation.z + want * d.z < 1.0 - 1e-3;
                if meets_wall {
                    prop_assert!(r <= want + 1e-3, "ray {i}: {r} beyond the wall at {want}");
                }
                if meets_wall && want < range_max_m && want < ground {
                    prop_assert!(scan.hit[i], "ray {i}: the wall at {want} is in range");
                    prop_assert!((r - want).abs() < 0.01, "ray {i}: {r} vs {want}");
                }
            }
        }
    }
}
