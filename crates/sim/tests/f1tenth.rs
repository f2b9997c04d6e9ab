//! The F1TENTH car (assets/vehicles/f1tenth.toml) against closed forms and f1tenth_gym's
//! single-track model.

use super::*;

/// f1tenth_gym's wheelbase lf + lr, metres.
const L_F1TENTH: f64 = 0.3302;

/// The F1TENTH car at 40 Hz (configs/f1tenth.toml's period and substeps) in a 60 m room.
fn f1tenth_sim(name: &str, mode: DynamicsMode) -> (Sim, Room) {
    f1tenth_sim_braking(name, mode, 0.0)
}

/// As [`f1tenth_sim`], with a drive that brakes at `brake_mps2`.
fn f1tenth_sim_braking(name: &str, mode: DynamicsMode, brake_mps2: f64) -> (Sim, Room) {
    let r = room(30.0, name);
    let s = Sim::new(SimConfig {
        scene: r.src(),
        settings: SimSettings {
            vehicle: "f1tenth".into(),
            dynamics: mode,
            control_period_s: 0.025,
            substeps: 3,
            brake_mps2,
            ..Default::default()
        },
    })
    .unwrap();
    (s, r)
}

/// The throttle whose steady wheel speed gives `v` m/s.
fn throttle_for(s: &Sim, v: f64) -> f64 {
    let d = s.nominal_params().drive;
    let w = v / s.vehicle().drive_radius_m() as f64;
    (w * (d.c_d * w + d.c_r)) / d.c_t
}

/// Settle on the arc for `settle` periods, then the mean speed and yaw rate over `measure`.
fn circle(s: &mut Sim, v: f64, delta: f64, settle: usize, measure: usize) -> (f64, f64) {
    let c = Control {
        throttle: throttle_for(s, v),
        steering_rad: delta,
    };
    run(s, c, settle);
    let (mut v_sum, mut w_sum) = (0.0, 0.0);
    for _ in 0..measure {
        s.step(c).unwrap();
        assert!(s.car(0).contacts().is_empty(), "the circle met a wall");
        v_sum += s.car(0).forward_speed_mps() as f64;
        w_sum += s.car(0).yaw_rate_radps() as f64;
    }
    (v_sum / measure as f64, w_sum / measure as f64)
}

#[test]
fn the_f1tenth_car_has_f1tenth_gyms_geometry_mass_and_drive() {
    let (s, _r) = f1tenth_sim("f1t-spec", DynamicsMode::Raycast);
    let m = s.vehicle();
    assert!((m.wheelbase_m as f64 - L_F1TENTH).abs() < 1e-5, "{}", m.wheelbase_m);
    assert!((m.mass_kg - 3.74).abs() < 1e-4, "{}", m.mass_kg);
    let com = m.mass_props.local_com;
    assert!(
        (com.x - 0.17145).abs() < 1e-4 && (com.z - 0.024).abs() < 1e-4,
        "{com:?}"
    );
    let iz = m.mass_props.reconstruct_inertia_matrix().z_axis.z;
    assert!((iz - 0.04712).abs() < 1e-4, "I_z {iz}");
    assert_eq!(m.spec.steering.max_rad, 0.4189);
    // Launch at a_max = 9.51 m/s^2, top speed 10 m/s.
    let a0 = m.spec.drive.c_t * m.drive_radius_m() as f64;
    assert!((a0 - 9.51).abs() < 1e-3, "a0 {a0}");
    assert!((m.top_speed_mps() - 10.0).abs() < 0.01, "{}", m.top_speed_mps());
    assert!(
        s.car(0).contacts().is_empty(),
        "the car at rest touches something: {:?}",
        s.car(0).contacts()
    );
}

/// Ray-cast mode only: in multibody mode this car does not drive off at a low throttle (its
/// 0.05 m wheels' velocity motors on a 3.74 kg car stall: v = 0), a gap of that mode.
#[test]
fn low_speed_turning_radius_is_wheelbase_over_tan_delta() {
    for delta in [0.25f64, -0.4] {
        let (mut s, _r) = f1tenth_sim("f1t-turn", DynamicsMode::Raycast);
        let (v, w) = circle(&mut s, 0.5, delta, 200, 80);
        let r = v / w;
        let expect = L_F1TENTH / delta.tan();
        assert!(
            (r - expect).abs() / expect.abs() < 0.05,
            "delta {delta}: radius {r} vs {expect}"
        );
    }
}

/// The F1TENTH car's wheels turn at f1tenth_gym's sv_max, 3.2 rad/s: full lock from
/// straight takes 0.131 s, 0.08 rad per 40 Hz period, and back the same way.
#[test]
fn the_f1tenth_cars_steering_turns_at_3_2_rad_per_s() {
    let (mut s, _r) = f1tenth_sim("f1t-steer-rate", DynamicsMode::Raycast);
    let lock = 0.4189f64;
    let per_period = 3.2 * 0.025;
    let mut expect = 0.0f64;
    for (target, periods) in [(lock, 8), (-lock, 12)] {
        for k in 0..periods {
            s.step(Control {
                throttle: 0.0,
                steering_rad: target,
            })
            .unwrap();
            expect += (target - expect).clamp(-per_period, per_period);
            let got = s.car(0).control().steering_rad;
            assert!(
                (got - expect).abs() < 1e-9,
                "to {target}, period {k}: {got} vs {expect}"
            );
            let m = s.vehicle();
            let split = agvrl_sim::vehicle::ackermann_split(got, m.wheelbase_m as f64, m.front_track_m as f64, true);
            assert_eq!(
                s.car(0).wheel_angles_rad(),
                split,
                "period {k}: the wheels stand at the angle reached"
            );
        }
        assert!((expect - target).abs() < 1e-12, "reached {expect}, not {target}");
    }
}

/// Sideslip of the base frame (the rear axle) in its own frame, rad.
fn sideslip(s: &Sim) -> f64 {
    let q = rp(&s.car(0).pose()).rotation;
    let v = Vector::from_array(s.car(0).linvel_w());
    (v.dot(q * Vector::Y) as f64).atan2(v.dot(q * Vector::X) as f64)
}

/// Asked to turn tighter than its grip allows (full lock at 3-7 m/s, 2.2-5.8 times mu g on
/// the kinematic circle), the car corners at the friction limit and runs wide (understeer),
/// as a car with slip-angle tyres and its weight a little forward does: lateral acceleration
/// 0.8-1.0 mu g, the rear axle's sideslip under 15 degrees. Rapier's own side friction, which
/// has no slip angle, spun it instead (sideslip above 90 degrees at 3 m/s).
#[test]
fn beyond_its_grip_the_f1tenth_car_runs_wide_and_does_not_spin() {
    let mu_g = 1.0489 * 9.81;
    let (mut s, _r) = f1tenth_sim("f1t-limit", DynamicsMode::Raycast);
    for v_set in [3.0, 5.0, 7.0] {
        s.reset(PlanarPose {
            x_m: -20.0,
            y_m: 0.0,
            yaw_rad: 0.0,
        })
        .unwrap();
        let th = throttle_for(&s, v_set);
        run(
            &mut s,
            Control {
                throttle: th,
                steering_rad: 0.0,
            },
            200,
        );
        let c = Control {
            throttle: th,
            steering_rad: 0.4189,
        };
        let mut worst_slip = 0.0f64;
        let (mut a_sum, mut n) = (0.0, 0);
        for k in 0..160 {
            s.step(c).unwrap();
            assert!(s.car(0).contacts().is_empty(), "{v_set} m/s: the car met a wall");
            worst_slip = worst_slip.max(sideslip(&s).abs());
            if k >= 80 {
                a_sum += s.car(0).forward_speed_mps() as f64 * s.car(0).yaw_rate_radps() as f64;
                n += 1;
            }
        }
        let a = a_sum / n as f64;
        assert!(
            worst_slip < 15f64.to_radians(),
            "{v_set} m/s: sideslip {:.1} degrees",
            worst_slip.to_degrees()
        );
        assert!(
            (0.8 * mu_g..=1.0 * mu_g).contains(&a),
            "{v_set} m/s: lateral acceleration {a:.2} m/s^2 against mu g {mu_g:.2}"
        );
    }
}

/// f1tenth_gym's single-track model braking from 9 m/s at 6 m/s^2 with its front wheels
/// at 0.01 rad: heading change to the stop, rad (`python3 tools/parity/f1tenth_st_yaw.py`).
const GYM_BRAKING_TURN: f64 = 0.6180;

/// Braking from 9 m/s at 6 m/s^2 (`brake_mps2`, configs/f1tenth.toml's) with the wheels at
/// 0.01 rad, from running straight: the car stops in v^2 / 2a along its path within 5 %, and
/// turns in as f1tenth_gym's single-track model does (35 degrees, within 20 %), three times
/// the 12 degrees of a car rolling on the wheels' arc: braking moves load onto the front
/// wheels, whose side force grows while the rear's shrinks. The drive force is shared by the
/// wheels' loads, as the grip is.
#[test]
fn braking_hard_the_f1tenth_car_turns_in_as_f1tenth_gyms_model_does() {
    let (v0, a, delta) = (9.0f64, 6.0f64, 0.01f64);
    let (mut s, _r) = f1tenth_sim_braking("f1t-brake", DynamicsMode::Raycast, a);
    s.reset(PlanarPose {
        x_m: -25.0,
        y_m: 0.0,
        yaw_rad: 0.0,
    })
    .unwrap();
    let th = throttle_for(&s, v0);
    run(
        &mut s,
        Control {
            throttle: th,
            steering_rad: 0.0,
        },
        240,
    );
    let v_start = s.car(0).forward_speed_mps() as f64;
    assert!((v_start - v0).abs() < 0.2, "speed before braking {v_start}");
    let yaw0 = s.car(0).pose2().yaw_rad as f64;
    let c = Control {
        throttle: 0.0,
        steering_rad: delta,
    };
    let mut path = 0.0;
    for _ in 0..200 {
        let v = Vector::from_array(s.car(0).linvel_w()).length() as f64;
        if v < 0.05 {
            break;
        }
        s.step(c).unwrap();
        assert!(s.car(0).contacts().is_empty(), "the car met a wall");
        path += 0.5 * (v + Vector::from_array(s.car(0).linvel_w()).length() as f64) * 0.025;
    }
    let stop = v_start * v_start / (2.0 * a);
    assert!(
        (path - stop).abs() / stop < 0.05,
        "stopped in {path:.2} m, v^2/2a {stop:.2} m"
    );
    let turned = s.car(0).pose2().yaw_rad as f64 - yaw0;
    assert!(
        (turned - GYM_BRAKING_TURN).abs() / GYM_BRAKING_TURN < 0.2,
        "turned {:.1} degrees, f1tenth_gym {:.1}",
        turned.to_degrees(),
        GYM_BRAKING_TURN.to_degrees()
    );
}

/// Golden yaw rates of f1tenth_gym's single-track model (`vehicle_dynamics_st` integrated,
/// and the closed-form steady state, which agree to 4 digits): (speed m/s, front wheel angle
/// rad, yaw rate rad/s) from `python3 tools/parity/f1tenth_st_yaw.py`.
const GYM_YAW: [(f64, f64, f64); 3] = [(3.0, 0.04, 0.3378), (6.0, 0.04, 0.5575), (5.0, 0.1, 1.2504)];

/// In steady cornering agvrl's car turns within 10 % of f1tenth_gym's at every case, 0.05 g
/// to 0.65 g: its tyres are the single-track model's (`[tyre]`, mu C_S F_z alpha), so it
/// understeers as f1tenth_gym's does (understeer gradient (1/C_Sf - 1/C_Sr) / mu = 0.0273
/// rad per g) and not as the kinematic v tan(delta) / L, which is 8-22 % above these.
#[test]
fn steady_cornering_yaw_rate_against_f1tenth_gyms_single_track_model() {
    let (mut s, _r) = f1tenth_sim("f1t-corner", DynamicsMode::Raycast);
    for (v_set, delta, gym) in GYM_YAW {
        s.reset(PlanarPose {
            x_m: 0.0,
            y_m: -8.0,
            yaw_rad: 0.0,
        })
        .unwrap();
        let (v, w) = circle(&mut s, v_set, delta, 400, 80);
        assert!((v - v_set).abs() / v_set < 0.03, "speed {v} vs {v_set}");
        // Scaled to the set speed: both models' yaw rates are near proportional to it here.
        let w = w * v_set / v;
        let gap = (w - gym) / gym;
        assert!(
            gap.abs() < 0.10,
            "{v_set} m/s, delta {delta}: yaw rate {w} vs f1tenth_gym {gym} ({gap:+.3})"
        );
    }
}
