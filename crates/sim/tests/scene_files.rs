//! Scenes: every built-in scene loads, spawns clear and drives, AutoVRL's object counts, the oval's
//! lane width, seeded procedural layouts and subjects, and `clearance_at` against the walls of a
//! room.

use super::*;

#[test]
fn every_scene_loads_spawns_clear_and_drives_five_seconds() {
    for mode in MODES {
        for id in SCENE_IDS {
            let mut s = sim(SceneSource::Builtin(id.to_string()), mode);
            s.step(Control::default()).unwrap();
            assert!(
                s.car(0).contacts().is_empty(),
                "{mode:?} {id}: contact at spawn {:?}",
                s.car(0).contacts()
            );
            let mut x = 0.77f64;
            for _ in 0..150 {
                x = (x * 3.8 * (1.0 - x)).clamp(0.0, 1.0);
                s.step(Control {
                    throttle: x,
                    steering_rad: 0.36 * (2.0 * x - 1.0),
                })
                .unwrap();
                let p = s.car(0).pose();
                assert!(p.is_finite(), "{mode:?} {id}: non-finite pose");
                assert!(!s.car(0).flipped(), "{mode:?} {id}: flipped");
                assert!(p.position_m[2].abs() < 0.5, "{mode:?} {id}: z = {}", p.position_m[2]);
            }
        }
    }
}

#[test]
fn scenes_hold_autovrls_object_counts() {
    let src = AssetSource::builtin();
    let count = |id: &str, class: &str| {
        Scene::builtin(&src, id)
            .unwrap()
            .objects
            .iter()
            .filter(|o| o.class == class)
            .count()
    };
    assert_eq!((count("outdoor-20", "rock"), count("outdoor-20", "tree")), (7, 4));
    assert_eq!((count("outdoor-50", "rock"), count("outdoor-50", "tree")), (48, 25));
    assert_eq!((count("urban-20", "building"), count("urban-20", "car")), (5, 2));
    assert_eq!((count("urban-50", "building"), count("urban-50", "car")), (10, 6));
}

#[test]
fn oval_lane_is_two_metres_wide_on_straights_and_curves() {
    let mut s = sim(SceneSource::Builtin("oval".into()), DynamicsMode::Raycast);
    // On the straights the walls sit 1 m to each side of the centre line, so the rays at
    // +-45 degrees off the heading meet them at sqrt(2) m.
    for (x, y, yaw) in [
        (4.0f32, 0.0f32, -std::f32::consts::FRAC_PI_2),
        (-4.0, 2.0, std::f32::consts::FRAC_PI_2),
    ] {
        let pose = Pose::from_parts(Vector::new(x, y, 0.3), Rotation::from_rotation_z(yaw));
        let scan = s.lidar_scan_at(&mp(&pose));
        for r in [scan.ranges[0], scan.ranges[99]] {
            assert!((r - std::f32::consts::SQRT_2).abs() < 0.01, "({x},{y}): {r}");
        }
    }
}

#[test]
fn procedural_layouts_are_seeded_and_keep_the_spawn_clear() {
    for kind in [SceneKind::Outdoor, SceneKind::Urban, SceneKind::Track] {
        let a = Scene::procedural(kind, 7, 20.0, 2.0).unwrap();
        let b = Scene::procedural(kind, 7, 20.0, 2.0).unwrap();
        let c = Scene::procedural(kind, 8, 20.0, 2.0).unwrap();
        assert_eq!(a.file, b.file, "{kind:?}: same seed, same layout");
        assert_ne!(a.file, c.file, "{kind:?}: another seed, another layout");
        let mut s = Sim::new(SimConfig {
            scene: SceneSource::Procedural {
                kind,
                seed: 7,
                half_m: 20.0,
            },
            ..SimConfig::default()
        })
        .unwrap();
        let sp = s.default_spawn();
        assert!(s.free_at(sp.x_m, sp.y_m, 0.5), "{kind:?}: spawn not clear");
        s.step(Control::default()).unwrap();
        assert!(s.car(0).contacts().is_empty());
    }
}

#[test]
fn subjects_are_seeded_and_stand_clear() {
    let src = AssetSource::builtin();
    let base = Scene::builtin(&src, "urban-20").unwrap().file;
    let a = base.clone().with_subjects(4, 1, 3.0);
    let b = base.clone().with_subjects(4, 1, 3.0);
    let c = base.clone().with_subjects(4, 2, 3.0);
    assert_eq!(a, b);
    assert_ne!(a, c);
    let subjects: Vec<_> = a.objects.iter().filter(|o| o.model == "subject").collect();
    assert_eq!(subjects.len(), 4);
    for s in subjects {
        assert!((s.x_m.powi(2) + s.y_m.powi(2)).sqrt() >= 3.0, "too close to the spawn");
    }
    // They load as solid `person` objects the car can collide with.
    let scene = Scene::build(a, &src, "test").unwrap();
    assert_eq!(scene.objects.iter().filter(|o| o.class == "person").count(), 4);
}

/// `clearance_at` is the distance to the nearest wall: in a square room with inner faces at
/// +-2 m, 2 m less the larger coordinate; capped at its bound; and `free_at` agrees on either
/// side of it.
#[test]
fn clearance_at_is_the_distance_to_the_nearest_wall() {
    let r = room(2.0, "clearance");
    let s = sim(r.src(), DynamicsMode::Raycast);
    for (x, y) in [(0.0f32, 0.0f32), (1.5, 0.2), (-0.3, -1.9), (1.2, 1.4)] {
        let expected = 2.0 - x.abs().max(y.abs());
        let c = s.clearance_at(x, y, 10.0);
        assert!((c - expected).abs() < 1e-4, "({x}, {y}): {c}, expected {expected}");
        assert!(
            s.free_at(x, y, c - 0.01) && !s.free_at(x, y, c + 0.01),
            "({x}, {y}): {c}"
        );
        assert_eq!(s.clearance_at(x, y, 0.5 * expected), 0.5 * expected);
    }
}
