//! The racing rules: one setting for the end limit, the track's defaults, the progress reward,
//! the stall and time limits.

use super::*;
use agvrl_envs::sim_vehicle::{Randomisation, SimVehicle, SpawnMode};
use agvrl_envs::task::{RacingReward, RacingRules, RacingRulesSetting};
use agvrl_envs::{Vehicle, registry};

/// How far the car reaches to its left of the base, metres: its body and its wheels (balls
/// of the wheel's radius on the ground).
fn left_reach_m(model: &agvrl_sim::vehicle::VehicleModel) -> f32 {
    let body = model.body_bounds_m().map_or(f32::NEG_INFINITY, |(_, hi)| hi[1]);
    let wheels = model
        .wheels
        .iter()
        .map(|w| w.center_b.y + w.radius_m)
        .fold(f32::NEG_INFINITY, f32::max);
    body.max(wheels)
}

/// On the oval's +x straight the car heads -y, its left towards the outer wall's face at
/// x = 5 m. Set down `gap_m` from that face (negative: into it), one control period on.
fn outcome_beside_the_wall(rules: RacingRules, gap_m: f32) -> agvrl_envs::task::Outcome {
    let sim = agvrl_sim::SimConfig::default();
    let mut v = SimVehicle::new(sim, SpawnMode::Fixed, Randomisation::default()).unwrap();
    let reach = left_reach_m(v.sim().vehicle());
    let mut task = Racing::new(
        RacingConfig {
            rules,
            ..RacingConfig::default()
        },
        0.36,
    );
    let first = v.reset(0).unwrap();
    task.reset(&first, v.map());
    let pose = agvrl_sim::PlanarPose {
        x_m: 5.0 - reach - gap_m,
        y_m: 0.0,
        yaw_rad: -std::f32::consts::FRAC_PI_2,
    };
    v.sim_mut().reset(pose).unwrap();
    v.actuate(Control::default()).unwrap();
    let frame = v.sense().unwrap();
    task.evaluate(&frame, v.map())
}

#[test]
fn the_contact_rule_fires_at_the_analytic_pose_against_a_wall() {
    let contact_only = RacingRules {
        end_below_m: 0.0,
        ..RacingRules::map_track()
    };
    // Contact counts within the physics' contact distance (rapier's prediction distance).
    let at = agvrl_sim::contact_distance_m();
    let clear = outcome_beside_the_wall(contact_only, at + 0.003);
    assert_eq!(clear.termination, None, "3 mm beyond the contact distance drives on");
    let touching = outcome_beside_the_wall(contact_only, at - 0.003);
    assert_eq!(touching.termination, Some(TerminationCause::Contact));
    assert_eq!(touching.terms.collision, contact_only.crash_penalty);
    // The paper's 0.8 m limit ends the same clear pose before any contact.
    let paper = outcome_beside_the_wall(RacingRules::oval(), at + 0.003);
    assert_eq!(paper.termination, Some(TerminationCause::TooClose));
    assert_eq!(paper.terms.total(), -50.0);
}

#[test]
fn the_oval_keeps_the_papers_rules_and_map_tracks_take_rules_a_narrow_track_admits() {
    let oval = registry::spec("racing-oval").unwrap();
    assert_eq!(
        registry::racing_rules(oval, &EnvConfig::default()).unwrap(),
        RacingRules::oval()
    );
    let yaml = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/tracks/bean.yaml");
    let on_map = EnvConfig {
        track: Some(TrackSetting::Path(yaml)),
        ..EnvConfig::default()
    };
    let rules = registry::racing_rules(oval, &on_map).unwrap();
    assert_eq!(rules, RacingRules::map_track());
    assert_eq!((rules.end_below_m, rules.reward), (0.0, RacingReward::Progress));
    let circuit = registry::spec(registry::CIRCUIT_ENV).unwrap();
    assert_eq!(
        registry::racing_rules(circuit, &EnvConfig::default()).unwrap(),
        RacingRules::map_track()
    );
    // One key set, the others the track's.
    let set = EnvConfig {
        racing: Some(RacingRulesSetting {
            end_below_m: Some(0.3),
            ..Default::default()
        }),
        ..on_map.clone()
    };
    let r = registry::racing_rules(oval, &set).unwrap();
    assert_eq!(r.end_below_m, 0.3);
    assert_eq!(r.reward, RacingReward::Progress);
    // Bad values and a racing setting on a search env are named.
    for bad in [
        RacingRulesSetting {
            end_below_m: Some(-0.1),
            ..Default::default()
        },
        RacingRulesSetting {
            crash_penalty: Some(5.0),
            ..Default::default()
        },
        RacingRulesSetting {
            stall_after_s: Some(f64::NAN),
            ..Default::default()
        },
    ] {
        let cfg = EnvConfig {
            racing: Some(bad),
            ..EnvConfig::default()
        };
        let e = make("racing-oval", &cfg).err().unwrap().to_string();
        assert!(e.contains("racing."), "{e}");
    }
    let cfg = EnvConfig {
        racing: Some(RacingRulesSetting::default()),
        ..EnvConfig::default()
    };
    let e = make("search-urban-20", &cfg).err().unwrap().to_string();
    assert!(e.contains("not a racing env"), "{e}");
    // The default config writes no racing table: a policy file's settings stay as they were.
    let text = toml::to_string(&EnvConfig::default()).unwrap();
    assert!(!text.contains("racing"), "{text}");
}

/// Under the progress form a step pays for the ground gained: over a lap of the oval the
/// progress terms add up to the lap's length times the rate.
#[test]
fn progress_pays_per_metre_along_the_centre_line() {
    let cfg = EnvConfig {
        spawn: SpawnMode::Fixed,
        racing: Some(RacingRulesSetting {
            reward: Some(RacingReward::Progress),
            progress_per_m: Some(2.0),
            ..Default::default()
        }),
        ..EnvConfig::default()
    };
    let mut env = make("racing-oval", &cfg).unwrap();
    env.reset(Some(0)).unwrap();
    let (mut paid, mut last) = (0.0, None);
    // 2 s from the fixed spawn, 3 m before the straight's end: straight ahead.
    for _ in 0..60 {
        let st = env.step(&[1.0, 0.0]).unwrap();
        assert!(!st.done(), "{st:?}");
        assert_eq!(st.info.reward_terms.throttle, 0.0);
        paid += st.info.reward_terms.progress;
        last = st.info.racing.clone();
    }
    let laps = last.unwrap().progress_laps;
    let lap_m = 2.0 * 14.0 + 2.0 * std::f64::consts::PI * 4.0;
    assert!(laps > 0.02, "the car moved: {laps} laps");
    assert!((paid - 2.0 * laps * lap_m).abs() < 1e-3, "paid {paid} for {laps} laps");
}

/// A car that stands still ends its episode truncated after the stall limit, not before;
/// the lap time limit ends a drive after its share of a lap at top speed.
#[test]
fn a_stalled_car_is_truncated_after_the_stall_limit() {
    let stall = |s: f64| EnvConfig {
        spawn: SpawnMode::Fixed,
        max_steps: 10_000,
        racing: Some(RacingRulesSetting {
            stall_after_s: Some(s),
            ..Default::default()
        }),
        ..EnvConfig::default()
    };
    let mut env = make("racing-oval", &stall(2.0)).unwrap();
    let dt = env.dt_s();
    env.reset(Some(0)).unwrap();
    let mut steps = 0;
    loop {
        steps += 1;
        // Scaled mapping: action -1 is zero throttle.
        let st = env.step(&[-1.0, 0.0]).unwrap();
        if st.done() {
            assert!(st.truncated && !st.terminated, "{st:?}");
            break;
        }
        assert!(steps < 1000);
    }
    let ended_s = steps as f64 * dt;
    assert!((ended_s - 2.0).abs() < 0.5 * dt, "ended after {ended_s} s");
    // The time limit: 0.1 laps of 53.1 m at 1.79 m/s is about 2.97 s.
    let cfg = EnvConfig {
        racing: Some(RacingRulesSetting {
            time_limit_laps: Some(0.1),
            ..Default::default()
        }),
        ..stall(0.0)
    };
    let mut env = make("racing-oval", &cfg).unwrap();
    env.reset(Some(0)).unwrap();
    let mut steps = 0;
    loop {
        let st = env.step(&[-1.0, 0.0]).unwrap();
        if st.done() {
            assert!(st.truncated && !st.terminated, "{st:?}");
            break;
        }
        steps += 1;
        assert!(steps < 1000);
    }
    let top = agvrl_sim::SimSettings::default()
        .vehicle_model()
        .unwrap()
        .top_speed_mps() as f64;
    let limit_s = 0.1 * (2.0 * 14.0 + 2.0 * std::f64::consts::PI * 4.0) / top;
    let ended_s = (steps + 1) as f64 * dt;
    assert!(
        (ended_s - limit_s).abs() <= dt,
        "ended after {ended_s} s, limit {limit_s} s"
    );
}

/// The stall clock stands still while the safety filter brakes the car: a car that drives at a
/// wall and is held short of it by the filter is not stalled, while the same car driving at the
/// same wall behind a filter that only advises (nothing is braked on its behalf) crashes, and a car
/// that holds itself still is stalled at the limit (above).
#[test]
fn a_car_the_filter_holds_short_of_a_wall_is_not_stalled() {
    let run = |advisory: bool| {
        let sim = agvrl_sim::SimConfig {
            settings: agvrl_sim::SimSettings {
                brake_mps2: 4.0,
                ..Default::default()
            },
            ..agvrl_sim::SimConfig::default()
        };
        let mut v = SimVehicle::new(sim, SpawnMode::Fixed, Randomisation::default()).unwrap();
        let rules = RacingRules {
            stall_after_s: 1.0,
            ..RacingRules::map_track()
        };
        let common = agvrl_envs::task::CommonConfig {
            safety_filter: agvrl_envs::task::SafetyFilterConfig {
                enabled: true,
                advisory,
                ..Default::default()
            }
            .on_drive(4.0),
            ..Default::default()
        };
        let limit = v.steering_limit_rad();
        let mut task = Racing::new(
            RacingConfig {
                rules,
                common,
                ..RacingConfig::default()
            },
            limit,
        );
        v.reset(0).unwrap();
        // On the oval's +x straight, facing the outer wall (x = 5 m) head on, 0.3 m short of it.
        let front = v.sim().vehicle().body_bounds_m().map_or(0.0, |(_, hi)| hi[0]);
        let pose = agvrl_sim::PlanarPose {
            x_m: 5.0 - front - 0.3,
            y_m: 0.0,
            yaw_rad: 0.0,
        };
        v.sim_mut().reset(pose).unwrap();
        v.actuate(Control::default()).unwrap();
        let mut frame = v.sense().unwrap();
        task.reset(&frame, v.map());
        let dt = v.control_period_s();
        // Full throttle, straight on, for three times the stall limit.
        for step in 1..=(3.0 / dt) as usize {
            let c = task.control(&[1.0, 0.0], limit, &frame);
            v.actuate(c).unwrap();
            frame = v.sense().unwrap();
            let out = task.evaluate(&frame, v.map());
            if out.termination.is_some() || out.truncate {
                return Some((step as f64 * dt, out));
            }
            assert!(advisory || task.intervention() == agvrl_envs::task::Intervention::Braked);
        }
        None
    };
    let held = run(false);
    assert!(held.is_none(), "a car the filter holds was ended: {held:?}");
    let (ended_s, out) = run(true).expect("driving at the wall ends the episode");
    assert_eq!(
        out.termination,
        Some(TerminationCause::Contact),
        "after {ended_s} s: {out:?}"
    );
}
