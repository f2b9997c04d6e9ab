//! Several cars in one world: contact with momentum kept and no tunnelling, each car's LiDAR and
//! camera see the others, free flight exact per car, a parked car, one to eight cars.

use super::*;
use agvrl_sim::sensors::{CameraConfig, LidarConfig, camera::class};

/// Rear face of XTENTH-CAR's computer stack in the base frame (tools/gen_vehicles.py: centre
/// 0.02, length 0.18), the part of the car a LiDAR at 0.27 m meets from behind; its side
/// faces stand 0.09 m off the centre line.
const STACK_REAR_X: f32 = 0.02 - 0.09;
const STACK_HALF_WIDTH: f32 = 0.09;

fn cars(scene: SceneSource, n: usize, settings: SimSettings) -> Sim {
    Sim::with_cars(SimConfig { scene, settings }, n).unwrap()
}

fn at(x_m: f32, y_m: f32, yaw_rad: f32) -> PlanarPose {
    PlanarPose { x_m, y_m, yaw_rad }
}

fn speed_x(s: &Sim, i: usize) -> f32 {
    s.car(i).linvel_w()[0]
}

/// Two cars head-on at top speed, the second twice as heavy, in both dynamics modes: they
/// never pass through each other, both report the contact at a point between them, and over
/// the impact the momentum one car loses is what the other gains, up to what the tyres can
/// push meanwhile (the drive's largest force times the impact's length); rapier's contacts
/// are inelastic, so both end at the common speed (m1 v1 + m2 v2) / (m1 + m2).
#[test]
fn two_cars_driven_into_each_other_exchange_momentum_and_never_pass_through() {
    let settings = SimSettings {
        control_period_s: 1.0 / 240.0,
        substeps: 1,
        ..Default::default()
    };
    for mode in MODES {
        let mut s = cars(
            room(12.0, "duel").src(),
            2,
            SimSettings {
                dynamics: mode,
                ..settings.clone()
            },
        );
        let heavy = VehicleParams {
            mass_scale: 2.0,
            ..s.nominal_params()
        };
        s.set_params_of(1, heavy);
        let m = [s.vehicle().mass_kg, 2.0 * s.vehicle().mass_kg];
        let top = s.vehicle().top_speed_mps();
        let model = s.vehicle().clone();
        let drive_n = model.wheels.iter().filter(|w| w.driven).count() as f32 * model.spec.drive.max_torque_nm as f32
            / model.drive_radius_m();
        // Car 1 faces car 0 from 16 m: both reach top speed before they meet.
        s.reset_cars(&[at(-8.0, 0.0, 0.0), at(8.0, 0.0, std::f32::consts::PI)])
            .unwrap();
        let full = Control {
            throttle: 1.0,
            steering_rad: 0.0,
        };
        let (mut impact, mut before) = (None, (0.0f32, 0.0f32));
        for step in 0..4000 {
            let v = (speed_x(&s, 0), speed_x(&s, 1));
            s.step_cars(&[full, full]).unwrap();
            let (a, b) = (s.car(0).car_contacts(), s.car(1).car_contacts());
            // The fronts (bumpers 0.415 m ahead of the base) may overlap by the contact's
            // penetration at most.
            let gap = s.car(1).pose2().x_m - s.car(0).pose2().x_m - 2.0 * 0.415;
            assert!(
                gap > -0.02,
                "{mode:?}: the cars pass through each other, gap {gap} at step {step}"
            );
            if impact.is_none() && !a.is_empty() {
                assert_eq!(b.len(), 1, "{mode:?}: car 1 must report the contact too");
                assert_eq!((a[0].other, b[0].other), (1, 0));
                let x = a[0].point_w[0];
                assert!(
                    x > s.car(0).pose2().x_m && x < s.car(1).pose2().x_m,
                    "{mode:?}: contact point x {x} lies between the cars"
                );
                impact = Some(step);
                before = v;
            }
        }
        let step = impact.unwrap_or_else(|| panic!("{mode:?}: the cars never touched"));
        assert!(
            before.0 > 0.95 * top && -before.1 > 0.95 * top,
            "{mode:?}: speeds {before:?} at impact, top speed {top}"
        );
        // Replay up to the impact, then until the closing speed is gone.
        s.reset_cars(&[at(-8.0, 0.0, 0.0), at(8.0, 0.0, std::f32::consts::PI)])
            .unwrap();
        for _ in 0..step {
            s.step_cars(&[full, full]).unwrap();
        }
        let mut steps = 0;
        while speed_x(&s, 0) - speed_x(&s, 1) > 0.1 * (before.0 - before.1) {
            s.step_cars(&[full, full]).unwrap();
            steps += 1;
            assert!(steps < 50, "{mode:?}: the impact did not stop the closing speed");
        }
        // The base's speed stands for the whole car's: the wheels move with it along x.
        let after = (speed_x(&s, 0), speed_x(&s, 1));
        let tyres = 2.0 * drive_n * steps as f32 * settings.control_period_s as f32;
        let p0 = m[0] * before.0 + m[1] * before.1;
        let dp = m[0] * after.0 + m[1] * after.1 - p0;
        assert!(
            tyres < 0.25 * m[0] * before.0,
            "{mode:?}: the bound ({tyres} N s over {steps} steps) must be small against the momentum ({} N s)",
            m[0] * before.0
        );
        assert!(
            dp.abs() <= tyres,
            "{mode:?}: total momentum changed by {dp} N s in the impact (tyres: {tyres}); speeds {before:?} -> {after:?}"
        );
        let common = p0 / (m[0] + m[1]);
        for v in [after.0, after.1] {
            assert!(
                (v - common).abs() <= 0.1 * (before.0 - before.1) + tyres / m[0],
                "{mode:?}: speeds {after:?} after the impact, inelastic closed form {common}"
            );
        }
    }
}

/// A LiDAR at 0.27 m meets the other car's computer stack at the distance its box gives,
/// from behind and from the side, names the car, and the clearance to the static scene
/// leaves it out; the camera's depth on its optical axis meets the same face.
#[test]
fn a_cars_lidar_and_camera_see_the_other_car_at_the_analytic_distance() {
    let settings = SimSettings {
        lidar: LidarConfig {
            n_rays: 101,
            ..LidarConfig::default()
        },
        camera: Some(CameraConfig {
            width: 161,
            height: 121,
            fov_deg: 60.0,
            near_m: 0.01,
            far_m: 100.0,
            depth_only: false,
        }),
        ..Default::default()
    };
    for (yaw1, face) in [(0.0, STACK_REAR_X), (std::f32::consts::FRAC_PI_2, -STACK_HALF_WIDTH)] {
        let mut s = cars(room(10.0, "seen").src(), 2, settings.clone());
        s.reset_cars(&[at(-1.0, 0.0, 0.0), at(2.0, -0.02 * (yaw1 != 0.0) as i32 as f32, yaw1)])
            .unwrap();
        for _ in 0..30 {
            s.step_cars(&[Control::default(), Control::default()]).unwrap();
        }
        let scan = s.lidar_scan(0);
        let lidar = rp(&s.car(0).pose()) * s.vehicle().lidar_b;
        let other = rp(&s.car(1).pose());
        // The face's world x (the other car stands level, a rotation about z only).
        let face_w = (other * Vector::new(face, 0.0, 0.0)).x;
        let face_w = if yaw1 == 0.0 {
            face_w
        } else {
            other.translation.x + face
        };
        let want = face_w - lidar.translation.x;
        assert_eq!(scan.car.len(), 101);
        assert_eq!(scan.car[50], Some(1), "yaw {yaw1}: the middle ray meets car 1");
        assert!(
            (scan.ranges[50] - want).abs() < 2e-3,
            "yaw {yaw1}: range {} against {want}",
            scan.ranges[50]
        );
        assert!(scan.min_static_range() > 5.0, "the walls stand 9 m away");
        let f = s.car(0).camera_frame().unwrap();
        let cam = s.car(0).camera_pose().unwrap();
        let k = 60 * 161 + 80;
        let depth = f.frame.depth_m[k];
        assert!(
            (depth - (face_w - cam.position_m[0])).abs() < 2e-3,
            "yaw {yaw1}: camera depth {depth} against {}",
            face_w - cam.position_m[0]
        );
        assert_eq!(f.classes[k], class::CAR);
        // A car alone in the world sees nothing there.
        let mut alone = Sim::new(SimConfig {
            scene: room(10.0, "alone").src(),
            settings: settings.clone(),
        })
        .unwrap();
        alone.reset(at(-1.0, 0.0, 0.0)).unwrap();
        let scan = alone.lidar_scan(0);
        assert!(scan.car.is_empty() && scan.ranges[50] > 9.0);
    }
}

/// With several cars, control periods that skip rapier's pipeline move every car as rapier
/// does, to the bit, until a contact; cars apart fly free, cars near each other do not.
#[test]
fn free_flight_stays_exact_per_car_with_several_cars() {
    let make = |free_flight| {
        cars(
            room(8.0, "pack").src(),
            3,
            SimSettings {
                free_flight,
                ..Default::default()
            },
        )
    };
    let (mut a, mut b) = (make(true), make(false));
    let start = [at(-4.0, 0.0, 0.0), at(-4.0, 2.0, 0.3), at(-5.0, -2.0, -0.3)];
    let (mut x, mut compared, mut episodes) = (0.23f64, 0, 0);
    let touching = |s: &Sim| (0..3).any(|i| !s.car(i).contacts().is_empty() || !s.car(i).car_contacts().is_empty());
    for _ in 0..1500 {
        if a.steps() > 200 || touching(&a) || touching(&b) {
            a.reset_cars(&start).unwrap();
            b.reset_cars(&start).unwrap();
            episodes += 1;
        }
        let controls: Vec<Control> = (0..3)
            .map(|_| {
                x = (x * 3.9 * (1.0 - x)).clamp(1e-6, 1.0 - 1e-6);
                Control {
                    throttle: 0.5 + 0.5 * x,
                    steering_rad: 0.36 * (2.0 * x - 1.0),
                }
            })
            .collect();
        a.step_cars(&controls).unwrap();
        b.step_cars(&controls).unwrap();
        if !touching(&a) && !touching(&b) {
            for i in 0..3 {
                assert!(
                    a.car(i).pose() == b.car(i).pose() && a.car(i).linvel_w() == b.car(i).linvel_w(),
                    "car {i}, step {} of episode {episodes}",
                    a.steps()
                );
            }
            compared += 1;
        }
    }
    assert_eq!(b.free_flight_steps(), 0);
    assert!(
        a.free_flight_steps() > 600 && compared > 1200 && episodes >= 5,
        "{} free steps, {compared} compared, {episodes} episodes",
        a.free_flight_steps()
    );
    // Two cars side by side, 10 cm apart, never skip the pipeline.
    let mut c = make(true);
    c.reset_cars(&[at(0.0, 0.0, 0.0), at(0.0, 0.36, 0.0), at(-5.0, -5.0, 0.0)])
        .unwrap();
    let slow = Control {
        throttle: 0.2,
        steering_rad: 0.0,
    };
    for _ in 0..20 {
        c.step_cars(&[slow, slow, slow]).unwrap();
    }
    assert_eq!(c.free_flight_steps(), 0, "cars 10 cm apart must go through rapier");
}

/// A parked car stops where it stands, stays put when another car drives into it, and
/// the next reset frees it.
#[test]
fn a_parked_car_stays_an_obstacle_until_the_reset() {
    let mut s = cars(room(8.0, "parked").src(), 2, SimSettings::default());
    s.reset_cars(&[at(-4.0, 0.0, 0.0), at(0.0, 0.0, 0.0)]).unwrap();
    let full = Control {
        throttle: 1.0,
        steering_rad: 0.0,
    };
    for _ in 0..20 {
        s.step_cars(&[Control::default(), full]).unwrap();
    }
    s.park(1);
    let held = s.car(1).pose();
    let mut touched = false;
    for _ in 0..300 {
        s.step_cars(&[full, full]).unwrap();
        touched |= s.car(0).car_contacts().iter().any(|c| c.other == 1);
        assert_eq!(s.car(1).pose(), held, "a parked car does not move");
    }
    assert!(touched, "car 0 drove into the parked car");
    assert!(s.car(0).pose2().x_m < held.position_m[0], "and did not pass it");
    s.reset_cars(&[at(-4.0, 0.0, 0.0), at(0.0, 0.0, 0.0)]).unwrap();
    assert!(!s.car(1).parked());
    for _ in 0..60 {
        s.step_cars(&[Control::default(), full]).unwrap();
    }
    assert!(s.car(1).pose2().x_m > 0.5, "after the reset car 1 drives again");
}

#[test]
fn a_world_holds_one_to_eight_cars_and_one_control_each() {
    for n in [0, 9] {
        let e = Sim::with_cars(SimConfig::default(), n)
            .err()
            .expect("refused")
            .to_string();
        assert!(e.contains("1 to 8 cars"), "{e}");
    }
    let mut s = Sim::with_cars(SimConfig::default(), 2).unwrap();
    let e = s.step(Control::default()).unwrap_err().to_string();
    assert!(e.contains("1 controls for a world of 2 cars"), "{e}");
}
