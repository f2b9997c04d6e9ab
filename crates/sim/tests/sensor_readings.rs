//! Sensor readings against closed forms: LiDAR ranges in a box room, the vehicle never in its own
//! scan, misses at range_max, the IMU at rest, GPS against the integrated IMU velocity and its
//! geodetic fix.

use super::*;

const LIDAR_MOUNT: [f32; 3] = [0.16, 0.0, 0.22];

/// Closed-form range from (ox, oy) along world bearing `a` to the walls of a square room.
fn room_range(half: f32, ox: f32, oy: f32, a: f32) -> f32 {
    let (dx, dy) = (a.cos(), a.sin());
    let mut t = f32::INFINITY;
    for (d, o) in [(dx, ox), (dy, oy)] {
        if d > 1e-9 {
            t = t.min((half - o) / d);
        } else if d < -1e-9 {
            t = t.min((-half - o) / d);
        }
    }
    t
}

#[test]
fn lidar_ranges_match_closed_form_away_from_the_origin() {
    let half = 4.0;
    for mode in MODES {
        for (x, y, yaw) in [(1.3f32, -0.7f32, 0.4f32), (-2.0, 1.5, 2.5), (0.5, 2.0, -1.2)] {
            let mut s = sim(room(half, "lidar").src(), mode);
            s.reset(PlanarPose {
                x_m: x,
                y_m: y,
                yaw_rad: yaw,
            })
            .unwrap();
            run(&mut s, Control::default(), 30);
            let g = s.car(0).gps();
            let yaw_now = g.rpy_rad[2] as f32;
            let (c, sn) = (yaw_now.cos(), yaw_now.sin());
            let ox = g.position_m[0] as f32 + c * LIDAR_MOUNT[0] - sn * LIDAR_MOUNT[1];
            let oy = g.position_m[1] as f32 + sn * LIDAR_MOUNT[0] + c * LIDAR_MOUNT[1];
            let scan = s.lidar_scan(0);
            assert_eq!(scan.ranges.len(), 100);
            for (i, r) in scan.ranges.iter().enumerate() {
                let a = yaw_now + scan.angle_min + i as f32 * scan.angle_increment;
                let want = room_range(half, ox, oy, a);
                assert!(
                    (r - want).abs() < 0.01,
                    "{mode:?} pose ({x},{y},{yaw}) ray {i}: {r} vs {want}"
                );
                assert!(scan.hit[i]);
                assert_eq!(scan.object_id[i], Some(0), "the boundary is object 0");
            }
            // The fan is centred on the heading and spans 90 degrees.
            assert!((scan.angle_min + std::f32::consts::FRAC_PI_4).abs() < 1e-6);
            let last = scan.angle_min + 99.0 * scan.angle_increment;
            assert!((last - std::f32::consts::FRAC_PI_4).abs() < 1e-5);
        }
    }
}

#[test]
fn the_vehicle_never_sees_itself() {
    for mode in MODES {
        let walls = room(20.0, "self");
        let cfg = SimConfig {
            scene: walls.src(),
            settings: SimSettings {
                dynamics: mode,
                lidar: sensors::LidarConfig {
                    n_rays: 720,
                    fov_deg: 360.0,
                    range_min_m: 0.0,
                    range_max_m: 3.0,
                },
                ..Default::default()
            },
        };
        let mut s = Sim::new(cfg).unwrap();
        for _ in 0..90 {
            s.step(Control::default()).unwrap();
            let scan = s.lidar_scan(0);
            assert!(
                scan.hit.iter().all(|h| !h),
                "{mode:?}: a ray hit something in an empty room"
            );
            assert!(scan.ranges.iter().all(|r| *r == 3.0));
        }
    }
}

#[test]
fn lidar_misses_read_range_max_and_ranges_stay_in_bounds() {
    let mut s = sim(SceneSource::Builtin("outdoor-50".into()), DynamicsMode::Raycast);
    let mut x = 0.123f64;
    for _ in 0..200 {
        x = (x * 3.9 * (1.0 - x)).clamp(0.0, 1.0);
        s.step(Control {
            throttle: x,
            steering_rad: 0.3 * (2.0 * x - 1.0),
        })
        .unwrap();
        let scan = s.lidar_scan(0);
        for (r, h) in scan.ranges.iter().zip(&scan.hit) {
            assert!(*r >= scan.range_min && *r <= scan.range_max);
            if !h {
                assert_eq!(*r, scan.range_max);
            }
        }
    }
}

#[test]
fn imu_at_rest_reads_gravity_and_no_rates() {
    for mode in MODES {
        let mut s = sim(room(10.0, "imu").src(), mode);
        s.reset(PlanarPose {
            x_m: 1.0,
            y_m: 2.0,
            yaw_rad: 1.0,
        })
        .unwrap();
        run(&mut s, Control::default(), 90);
        let imu = s.car(0).imu();
        assert!((imu.lin_acc_b[2] - 9.81).abs() < 0.05, "{mode:?}: {:?}", imu.lin_acc_b);
        assert!(
            imu.lin_acc_b[0].abs() < 0.05 && imu.lin_acc_b[1].abs() < 0.05,
            "{mode:?}: {:?}",
            imu.lin_acc_b
        );
        for w in imu.ang_vel_b {
            assert!(w.abs() < 1e-2, "{mode:?}: rates {:?}", imu.ang_vel_b);
        }
    }
}

#[test]
fn gps_displacement_equals_integrated_imu_velocity() {
    for mode in MODES {
        let mut s = sim(room(20.0, "gps").src(), mode);
        run(
            &mut s,
            Control {
                throttle: 0.6,
                steering_rad: 0.0,
            },
            30,
        );
        let g0 = s.car(0).gps().position_m;
        let dt = s.config().settings.control_period_s;
        let mut v_prev = s.car(0).imu().lin_vel_w;
        let mut integ = [0.0f64; 3];
        for _ in 0..60 {
            s.step(Control {
                throttle: 0.8,
                steering_rad: 0.25,
            })
            .unwrap();
            let v = s.car(0).imu().lin_vel_w;
            for k in 0..3 {
                integ[k] += 0.5 * (v[k] + v_prev[k]) * dt;
            }
            v_prev = v;
        }
        let g1 = s.car(0).gps().position_m;
        let disp = [g1[0] - g0[0], g1[1] - g0[1]];
        let err = ((disp[0] - integ[0]).powi(2) + (disp[1] - integ[1]).powi(2)).sqrt();
        let len = (disp[0].powi(2) + disp[1].powi(2)).sqrt();
        assert!(len > 1.0 && err < 0.03 * len, "{mode:?}: gps {disp:?} vs imu {integ:?}");
    }
}

#[test]
fn gps_geodetic_fix_moves_north_with_y() {
    let walls = room(20.0, "geo");
    let cfg = SimConfig {
        scene: walls.src(),
        settings: SimSettings {
            gps: sensors::GpsConfig {
                origin: Some(msg::Geodetic {
                    latitude_deg: 35.0,
                    longitude_deg: -85.0,
                    altitude_m: 200.0,
                }),
            },
            ..Default::default()
        },
    };
    let mut s = Sim::new(cfg).unwrap();
    s.reset(PlanarPose {
        x_m: 0.0,
        y_m: 10.0,
        yaw_rad: 0.0,
    })
    .unwrap();
    let g = s.car(0).gps().geodetic.unwrap();
    // 10 m north is 10 / 6378137 rad of latitude.
    assert!((g.latitude_deg - 35.0 - (10.0f64 / 6_378_137.0).to_degrees()).abs() < 1e-6);
    assert!((g.longitude_deg + 85.0).abs() < 1e-9);
}
