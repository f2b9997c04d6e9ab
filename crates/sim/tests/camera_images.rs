//! Camera images: exact depth of a wall, objects at the edges of the field of view, the camera
//! riding on the car without seeing it, a depth-only frame, the view and projection matrices
//! against PyBullet's.

use super::*;
use agvrl_sim::sensors::CameraConfig;
use agvrl_sim::sensors::camera::{class, compute_projection_matrix_fov, compute_view_matrix};

fn cam_sim(scene: SceneSource, w: u32, h: u32, fov: f32) -> Sim {
    let camera = Some(CameraConfig {
        width: w,
        height: h,
        fov_deg: fov,
        near_m: 0.01,
        far_m: 100.0,
        depth_only: false,
    });
    Sim::new(SimConfig {
        scene,
        settings: SimSettings {
            camera,
            ..Default::default()
        },
    })
    .unwrap()
}

#[test]
fn depth_of_a_wall_facing_the_camera_is_exact_at_every_pixel() {
    let s = cam_sim(room(5.0, "cam-depth").src(), 64, 48, 10.0);
    let pose = Pose::from_parts(Vector::new(1.0, 0.3, 0.5), Rotation::IDENTITY);
    let f = s.render_at(&mp(&pose));
    assert_eq!(f.frame.depth_m.len(), 64 * 48);
    for (i, z) in f.frame.depth_m.iter().enumerate() {
        assert!((z - 4.0).abs() < 0.01, "pixel {i}: depth {z}");
        assert_eq!(f.frame.segmentation[i], 1, "the boundary is object 0 (id + 1 = 1)");
        assert_eq!(f.classes[i], class::WALL);
    }
}

/// A depth camera renders what the full render's depth buffer holds, bit for bit, and
/// nothing else.
#[test]
fn a_depth_only_frame_is_the_full_frames_depth() {
    let full = cam_sim(SceneSource::Builtin("urban-50".into()), 64, 48, 70.0);
    let mut settings = full.config().settings.clone();
    settings.camera.as_mut().unwrap().depth_only = true;
    let depth = Sim::new(SimConfig {
        scene: SceneSource::Builtin("urban-50".into()),
        settings,
    })
    .unwrap();
    for (x, y, yaw) in [(0.0, 0.0, 0.0), (3.0, -4.0, 2.0), (-10.0, 6.0, -1.0)] {
        let pose = Pose::from_parts(Vector::new(x, y, 0.3), Rotation::from_rotation_z(yaw));
        let (a, b) = (full.render_at(&mp(&pose)), depth.render_at(&mp(&pose)));
        assert_eq!(a.frame.depth_m, b.frame.depth_m);
        assert!(a.frame.depth_m.iter().any(|z| *z < 20.0));
        assert!(b.frame.rgb.is_empty() && b.frame.segmentation.is_empty() && b.classes.is_empty());
        assert_eq!((b.frame.width, b.frame.height), (64, 48));
    }
}

#[test]
fn objects_at_the_edge_of_the_field_of_view_land_on_the_edge_columns() {
    let d = tmpdir("cam-edge");
    let (w, h, fov) = (64u32, 48u32, 30.0f32);
    let tan_x = (fov.to_radians() / 2.0).tan() * w as f32 / h as f32;
    // Bearing of the centre of the first and last columns.
    let edge = tan_x * (1.0 - 1.0 / w as f32);
    let dist = 4.0;
    std::fs::write(
        d.path().join("edge.toml"),
        format!(
            "name = \"edge\"\nkind = \"outdoor\"\n[ground]\nsize_m = [30.0, 30.0]\nfriction = 1.0\ncolor = [0.5, 0.5, 0.5]\n\
             [spawn]\nx_m = -5.0\ny_m = 0.0\nyaw_deg = 0.0\n\
             [[object]]\nmodel = \"building\"\nx_m = {dist}\ny_m = {l}\nscale = [0.04, 0.04, 3.0]\n\
             [[object]]\nmodel = \"building\"\nx_m = {dist}\ny_m = {r}\nscale = [0.04, 0.04, 3.0]\n",
            l = edge * dist,
            r = -edge * dist
        ),
    )
    .unwrap();
    let s = cam_sim(SceneSource::File(d.path().join("edge.toml")), w, h, fov);
    let f = s.render_at(&mp(&Pose::from_parts(Vector::new(0.0, 0.0, 1.0), Rotation::IDENTITY)));
    let at = |u: usize, v: usize| f.frame.segmentation[v * w as usize + u];
    let v = h as usize / 2;
    // Left edge (+y) shows object 0, right edge object 1; the middle sees past both.
    assert_eq!(at(0, v), 1);
    assert_eq!(at(w as usize - 1, v), 2);
    assert_eq!(at(w as usize / 2, v), 0);
    assert_eq!(at(3, v), 0, "the poles are thin: three columns in they are gone");
    assert_eq!(f.classes[v * w as usize], class::BUILDING);
    // Upper rows see sky, lower rows ground.
    assert_eq!(f.classes[w as usize / 2], class::SKY);
    assert_eq!(f.classes[(h as usize - 1) * w as usize + w as usize / 2], class::GROUND);
}

#[test]
fn the_camera_rides_on_the_vehicle_and_does_not_see_it() {
    let s = cam_sim(SceneSource::Builtin("oval".into()), 80, 60, 80.0);
    let f = s.car(0).camera_frame().expect("xtenth_car has a camera link");
    assert_eq!((f.frame.width, f.frame.height), (80, 60));
    // Looking down the straight from the centre line: walls left and right, track ahead,
    // and no pixel closer than the ground in front of the bumper.
    assert!(f.classes.contains(&class::WALL));
    assert!(
        f.frame.depth_m.iter().all(|z| *z > 0.1),
        "the car's own body is not in view"
    );
    let same = cam_sim(SceneSource::Builtin("oval".into()), 80, 60, 80.0)
        .car(0)
        .camera_frame()
        .unwrap();
    assert_eq!(f, same, "rendering is deterministic");
}

/// All 16 entries of both matrices against PyBullet's own `computeViewMatrix` and
/// `computeProjectionMatrixFOV` (pybullet 3.2.7, `tools/parity/pybullet_camera_matrices.py`,
/// its output pasted). Flat column-major as PyBullet returns them: entry `c * 4 + r` is row
/// `r`, column `c`, so each line of four below is one column.
#[test]
fn view_and_projection_matrices_match_pybullet() {
    #[rustfmt::skip]
    let views = [
        // Straight down with y up.
        (
            [1.0, 2.0, 3.0],
            [1.0, 2.0, 0.0],
            [0.0, 1.0, 0.0],
            [
                1.0, 0.0, -0.0, 0.0,
                -0.0, 1.0, -0.0, 0.0,
                0.0, 0.0, 1.0, 0.0,
                -1.0, -2.0, -3.0, 1.0,
            ],
        ),
        // Oblique, z up as on a car: no entry is trivially 0 or 1.
        (
            [0.3, -1.2, 0.8],
            [2.0, 0.5, 0.1],
            [0.0, 0.0, 1.0],
            [
                0.70710677, 0.19767386, -0.6789146, 0.0,
                -0.70710677, 0.19767386, -0.6789146, 0.0,
                0.0, 0.9601302, 0.27955306, 0.0,
                -1.0606601, -0.5901977, -0.83466566, 1.0,
            ],
        ),
    ];
    #[rustfmt::skip]
    let projections = [
        (
            [90.0, 2.0, 0.1, 10.0],
            [
                0.49999997, 0.0, 0.0, 0.0,
                0.0, 0.99999994, 0.0, 0.0,
                0.0, 0.0, -1.020202, -1.0,
                0.0, 0.0, -0.20202021, 0.0,
            ],
        ),
        // agvrl's default camera (80 deg, 0.01 to 100 m) at 4:3.
        (
            [80.0, 4.0 / 3.0, 0.01, 100.0],
            [
                0.8938151, 0.0, 0.0, 0.0,
                0.0, 1.1917535, 0.0, 0.0,
                0.0, 0.0, -1.0002, -1.0,
                0.0, 0.0, -0.020002, 0.0,
            ],
        ),
    ];
    let same = |ours: [f32; 16], pybullet: [f32; 16], what: &str| {
        for (k, (a, b)) in ours.iter().zip(&pybullet).enumerate() {
            assert!(
                (a - b).abs() <= 1e-6 * b.abs().max(1.0),
                "{what}: entry {k} (row {}, column {}): {a} vs PyBullet's {b}",
                k % 4,
                k / 4
            );
        }
    };
    for (eye, target, up, want) in views {
        same(
            compute_view_matrix(eye, target, up),
            want,
            &format!("view from {eye:?}"),
        );
    }
    for ([fov, aspect, near, far], want) in projections {
        same(
            compute_projection_matrix_fov(fov, aspect, near, far),
            want,
            &format!("projection fov {fov}"),
        );
    }
}
