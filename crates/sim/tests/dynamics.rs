//! Vehicle dynamics against closed forms (steady state, reverse, braking distance, Ackermann
//! radius), no tunnelling and no jitter, bit-identical trajectories, free flight as rapier moves
//! the car, the steering and substep settings.

use super::*;

const L_XTENTH: f64 = 0.330;

#[test]
fn full_throttle_reaches_model_steady_state_without_slip() {
    for mode in MODES {
        let mut s = sim(room(40.0, "ss").src(), mode);
        s.reset(PlanarPose {
            x_m: -30.0,
            y_m: 0.0,
            yaw_rad: 0.0,
        })
        .unwrap();
        run(
            &mut s,
            Control {
                throttle: 1.0,
                steering_rad: 0.0,
            },
            300,
        );
        let p = s.nominal_params().drive;
        let w_ss = p.steady_state(1.0);
        let w = s.car(0).wheel_speed_radps();
        assert!((w - w_ss).abs() / w_ss < 0.01, "{mode:?}: w {w} vs steady state {w_ss}");
        let v = s.car(0).forward_speed_mps() as f64;
        let wr = w * s.vehicle().drive_radius_m() as f64;
        assert!((v - wr).abs() / wr < 0.05, "{mode:?}: ground speed {v} vs w r {wr}");
        let top = s.vehicle().top_speed_mps() as f64;
        assert!(
            (v - top).abs() / top < 0.05,
            "{mode:?}: ground speed {v} vs top speed {top}"
        );
        let imu = s.car(0).imu();
        assert!(
            imu.lin_vel_b[1].abs() < 0.05 * v,
            "{mode:?}: sideways drift {}",
            imu.lin_vel_b[1]
        );
        assert!(
            s.car(0).pose2().y_m.abs() < 0.5,
            "{mode:?}: drifted to y = {}",
            s.car(0).pose2().y_m
        );
    }
}

#[test]
fn reverse_backs_the_car_at_the_models_steady_speed_on_the_mirrored_arc() {
    for mode in MODES {
        let mut s = sim(room(40.0, "rev").src(), mode);
        s.reset(PlanarPose {
            x_m: 30.0,
            y_m: 0.0,
            yaw_rad: 0.0,
        })
        .unwrap();
        let back = Control {
            throttle: -0.5,
            steering_rad: 0.0,
        };
        run(&mut s, back, 300);
        let w_ss = s.nominal_params().drive.steady_state(0.5);
        let w = s.car(0).wheel_speed_radps();
        assert!((w + w_ss).abs() / w_ss < 0.01, "{mode:?}: w {w} vs -{w_ss}");
        let v = s.car(0).forward_speed_mps() as f64;
        let wr = w * s.vehicle().drive_radius_m() as f64;
        assert!(
            (v - wr).abs() / wr.abs() < 0.05,
            "{mode:?}: ground speed {v} vs w r {wr}"
        );
        assert!(
            s.car(0).pose2().x_m < 30.0 - 5.0,
            "{mode:?}: backed only to x = {}",
            s.car(0).pose2().x_m
        );
        assert!(
            s.car(0).pose2().y_m.abs() < 0.5,
            "{mode:?}: drifted to y = {}",
            s.car(0).pose2().y_m
        );
    }
    // Reversing on left lock turns the car clockwise, on the forward arc's radius.
    let mut s = sim(room(40.0, "rev-arc").src(), DynamicsMode::Raycast);
    s.reset(PlanarPose {
        x_m: 0.0,
        y_m: 0.0,
        yaw_rad: 0.0,
    })
    .unwrap();
    let lock = s.vehicle().spec.steering.max_rad;
    run(
        &mut s,
        Control {
            throttle: -0.2,
            steering_rad: lock,
        },
        60,
    );
    let p = s.car(0).pose2();
    assert!(p.yaw_rad < -0.3 && p.x_m < -0.3, "{p:?}");
}

#[test]
fn braking_stops_the_car_within_the_closed_form_distance() {
    let a = 3.0;
    for mode in MODES {
        let mut s = Sim::new(SimConfig {
            scene: room(40.0, "brake").src(),
            settings: SimSettings {
                dynamics: mode,
                brake_mps2: a,
                ..Default::default()
            },
        })
        .unwrap();
        s.reset(PlanarPose {
            x_m: -30.0,
            y_m: 0.0,
            yaw_rad: 0.0,
        })
        .unwrap();
        let full = Control {
            throttle: 1.0,
            steering_rad: 0.0,
        };
        run(&mut s, full, 240);
        let v0 = s.car(0).forward_speed_mps() as f64;
        let x0 = s.car(0).pose2().x_m as f64;
        run(&mut s, Control::default(), 90);
        let d = s.car(0).pose2().x_m as f64 - x0;
        // v0^2 / 2a, plus up to one control period at v0 before the first braked step and
        // the speed tracking's lag.
        let expect = v0 * v0 / (2.0 * a);
        assert!(s.car(0).forward_speed_mps().abs() < 0.02, "{mode:?}: still moving");
        assert!(
            d > 0.9 * expect && d < expect + v0 * (1.0 / 30.0 + 0.05),
            "{mode:?}: stopped in {d:.3} m from {v0:.2} m/s, closed form {expect:.3} m"
        );
    }
}

#[test]
fn brake_rejects_a_negative_rate() {
    let e = Sim::new(SimConfig {
        settings: SimSettings {
            brake_mps2: -1.0,
            ..Default::default()
        },
        ..SimConfig::default()
    });
    assert!(e.err().is_some_and(|e| e.to_string().contains("brake_mps2")));
}

#[test]
fn low_speed_turning_radius_matches_ackermann_geometry() {
    for mode in MODES {
        for delta in [0.2f64, -0.3] {
            let mut s = sim(room(40.0, "turn").src(), mode);
            // T = 0.15 gives w = 10 rad/s, 0.5 m/s.
            run(
                &mut s,
                Control {
                    throttle: 0.15,
                    steering_rad: delta,
                },
                240,
            );
            let (mut v_sum, mut w_sum) = (0.0, 0.0);
            for _ in 0..60 {
                s.step(Control {
                    throttle: 0.15,
                    steering_rad: delta,
                })
                .unwrap();
                v_sum += s.car(0).forward_speed_mps() as f64;
                w_sum += s.car(0).yaw_rate_radps() as f64;
            }
            let r = v_sum / w_sum;
            let expect = L_XTENTH / delta.tan();
            assert!(
                (r - expect).abs() / expect.abs() < 0.10,
                "{mode:?} delta {delta}: radius {r} vs {expect}"
            );
        }
    }
}

#[test]
fn no_tunnelling_through_a_wall_at_top_speed() {
    for mode in MODES {
        let mut s = sim(room(6.0, "wall").src(), mode);
        s.reset(PlanarPose {
            x_m: -5.0,
            y_m: 0.0,
            yaw_rad: 0.0,
        })
        .unwrap();
        let mut touched = false;
        for _ in 0..400 {
            s.step(Control {
                throttle: 1.0,
                steering_rad: 0.0,
            })
            .unwrap();
            touched |= !s.car(0).contacts().is_empty();
            // Wall face at x = 6; the front of the car is ~0.42 m ahead of the base.
            assert!(
                s.car(0).pose2().x_m < 6.0,
                "{mode:?}: passed the wall, x = {}",
                s.car(0).pose2().x_m
            );
        }
        assert!(touched, "{mode:?}: driving into the wall must report a contact");
    }
}

#[test]
fn swept_collision_checks_run_only_where_a_substep_could_skip_a_wall() {
    // At 1.79 m/s and 1/120 s substeps the car moves 1.5 cm (3 cm with the margin): the
    // built-in scenes' obstacles (7 cm and up) and a 50 cm wall are thicker, a 2 cm wall
    // is not.
    for id in SCENE_IDS {
        let s = sim(SceneSource::Builtin(id.to_string()), DynamicsMode::Raycast);
        assert!(!s.continuous_collision(), "{id}");
    }
    assert!(!sim(room(6.0, "thick").src(), DynamicsMode::Raycast).continuous_collision());
    for mode in MODES {
        let mut s = sim(walled_room(6.0, 0.02, "thin").src(), mode);
        assert!(s.continuous_collision(), "{mode:?}");
        s.reset(PlanarPose {
            x_m: -5.0,
            y_m: 0.0,
            yaw_rad: 0.0,
        })
        .unwrap();
        for _ in 0..400 {
            s.step(Control {
                throttle: 1.0,
                steering_rad: 0.0,
            })
            .unwrap();
            assert!(
                s.car(0).pose2().x_m < 6.0,
                "{mode:?}: passed the thin wall, x = {}",
                s.car(0).pose2().x_m
            );
        }
    }
}

#[test]
fn no_jitter_at_rest() {
    for mode in MODES {
        let mut s = sim(room(10.0, "rest").src(), mode);
        run(&mut s, Control::default(), 60);
        let p0 = s.car(0).pose2();
        run(&mut s, Control::default(), 60);
        let p1 = s.car(0).pose2();
        let moved = ((p1.x_m - p0.x_m).powi(2) + (p1.y_m - p0.y_m).powi(2)).sqrt();
        assert!(moved < 1e-3, "{mode:?}: moved {moved} m at rest");
        assert!(
            Vector::from_array(s.car(0).linvel_w()).length() < 1e-2,
            "{mode:?}: speed {} at rest",
            Vector::from_array(s.car(0).linvel_w()).length()
        );
    }
}

#[test]
fn same_actions_give_bit_identical_trajectories() {
    for mode in MODES {
        let traj = || {
            let mut s = sim(SceneSource::Builtin("outdoor-20".into()), mode);
            let mut out = Vec::new();
            let mut x = 0.3f64;
            for _ in 0..150 {
                x = (x * 3.7 * (1.0 - x)).clamp(0.0, 1.0);
                s.step(Control {
                    throttle: x,
                    steering_rad: 0.36 * (2.0 * x - 1.0),
                })
                .unwrap();
                let p = s.car(0).pose();
                out.push((p.position_m, p.orientation_xyzw, s.lidar_scan(0).ranges));
            }
            out
        };
        assert!(traj() == traj(), "{mode:?}: two runs differ");
        // And within one simulator: a reset forgets the earlier episode entirely.
        let mut s = sim(SceneSource::Builtin("outdoor-20".into()), mode);
        let mut replay = || {
            s.reset(PlanarPose {
                x_m: 1.0,
                y_m: -2.0,
                yaw_rad: 0.7,
            })
            .unwrap();
            let mut out = Vec::new();
            let mut x = 0.3f64;
            for _ in 0..200 {
                x = (x * 3.7 * (1.0 - x)).clamp(0.0, 1.0);
                s.step(Control {
                    throttle: x,
                    steering_rad: 0.36 * (2.0 * x - 1.0),
                })
                .unwrap();
                out.push(s.car(0).pose().position_m);
            }
            out
        };
        let (a, b) = (replay(), replay());
        assert!(a == b, "{mode:?}: replay after reset differs");
    }
}

/// Control periods that cannot meet a contact skip rapier's pipeline. The car must move as
/// it does through rapier to the bit, on every scene, up to each contact (where episodes
/// restart, as in the tasks); the skipping must really happen.
#[test]
fn free_flight_moves_the_car_as_rapier_does_to_the_bit_up_to_a_contact() {
    // The built-in scenes, and a small room of 2 cm walls where swept collision checks run.
    let thin = walled_room(2.5, 0.02, "free-flight");
    let mut scenes: Vec<(String, SceneSource)> = SCENE_IDS
        .iter()
        .map(|id| (id.to_string(), SceneSource::Builtin(id.to_string())))
        .collect();
    scenes.push(("thin walls".into(), thin.src()));
    for (id, scene) in scenes {
        let make = |free_flight| {
            Sim::new(SimConfig {
                scene: scene.clone(),
                settings: SimSettings {
                    free_flight,
                    ..Default::default()
                },
            })
            .unwrap()
        };
        let (mut a, mut b) = (make(true), make(false));
        assert_eq!(a.continuous_collision(), id == "thin walls", "{id}");
        let spawn = a.default_spawn();
        let (mut x, mut compared, mut episodes) = (0.31f64, 0, 0);
        for _ in 0..1200 {
            if a.steps() > 150 || !a.car(0).contacts().is_empty() || !b.car(0).contacts().is_empty() {
                a.reset(spawn).unwrap();
                b.reset(spawn).unwrap();
                episodes += 1;
            }
            x = (x * 3.9 * (1.0 - x)).clamp(1e-6, 1.0 - 1e-6);
            let c = Control {
                throttle: 0.4 + 0.6 * x,
                steering_rad: 0.36 * (2.0 * x - 1.0),
            };
            a.step(c).unwrap();
            b.step(c).unwrap();
            if a.car(0).contacts().is_empty() && b.car(0).contacts().is_empty() {
                let (pa, pb) = (a.car(0).pose(), b.car(0).pose());
                assert!(
                    pa == pb
                        && a.car(0).linvel_w() == b.car(0).linvel_w()
                        && a.car(0).angvel_w() == b.car(0).angvel_w(),
                    "{id}: step {} of episode {episodes} differs: {pa:?} against {pb:?}",
                    a.steps()
                );
                compared += 1;
            }
        }
        assert_eq!(b.free_flight_steps(), 0, "{id}: free flight was off");
        assert!(
            a.free_flight_steps() > 900 && compared > 1100 && episodes >= 7,
            "{id}: {} free steps, {compared} compared, {episodes} episodes",
            a.free_flight_steps()
        );
    }
}

#[test]
fn ackermann_can_be_switched_to_autovrl_equal_angles() {
    let mut s = Sim::new(SimConfig {
        settings: SimSettings {
            ackermann: Some(false),
            ..Default::default()
        },
        ..SimConfig::default()
    })
    .unwrap();
    s.step(Control {
        throttle: 0.0,
        steering_rad: 0.3,
    })
    .unwrap();
    assert_eq!(s.car(0).wheel_angles_rad(), (0.3, 0.3));
    let mut s = Sim::new(SimConfig::default()).unwrap();
    s.step(Control {
        throttle: 0.0,
        steering_rad: 0.3,
    })
    .unwrap();
    let (l, r) = s.car(0).wheel_angles_rad();
    assert!(l > 0.3 && r < 0.3, "inner (left) wheel steers more: {l} {r}");
    s.step(Control {
        throttle: 0.0,
        steering_rad: 5.0,
    })
    .unwrap();
    assert_eq!(
        s.car(0).control().steering_rad,
        0.36,
        "steering limit from the vehicle file"
    );
}

#[test]
fn substeps_longer_than_a_sixtieth_are_rejected() {
    let e = Sim::new(SimConfig {
        settings: SimSettings {
            substeps: 1,
            ..Default::default()
        },
        ..SimConfig::default()
    })
    .err()
    .expect("must fail");
    assert!(e.to_string().contains("1/60"), "{e}");
}
