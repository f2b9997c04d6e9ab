//! The safety filter in the envs: random actions behind it never crash, a car that reverses, the
//! safe reward's filter term, corrected actions and advising filters, refused settings.

use super::*;
use agvrl_envs::task::SafetyFilterConfig;
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};

fn filtered(enabled: bool) -> EnvConfig {
    EnvConfig {
        sim: agvrl_sim::SimSettings {
            brake_mps2: 3.0,
            ..Default::default()
        },
        safety_filter: SafetyFilterConfig {
            enabled,
            ..SafetyFilterConfig::default()
        },
        ..quick_cfg()
    }
}

/// Episodes of uniform random actions; returns (terminations, interventions).
fn random_episodes(id: &str, cfg: &EnvConfig, episodes: u64) -> (usize, u64) {
    let mut env = make(id, cfg).unwrap();
    let mut rng = StdRng::seed_from_u64(7);
    let (mut ended, mut interventions) = (0, 0);
    for k in 0..episodes {
        env.reset(Some(k)).unwrap();
        loop {
            let st = env
                .step(&[rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0)])
                .unwrap();
            if st.done() {
                ended += st.terminated as usize;
                interventions += st.info.search.map_or(0, |s| s.filter_interventions);
                break;
            }
        }
    }
    (ended, interventions)
}

#[test]
fn random_actions_behind_the_filter_never_crash_where_they_crash_without_it() {
    for id in ["search-outdoor-20", "search-urban-20"] {
        let cfg = EnvConfig {
            max_steps: 600,
            ..filtered(false)
        };
        let (raw, _) = random_episodes(id, &cfg, 4);
        assert!(
            raw >= 2,
            "{id}: random actions should crash without the filter ({raw} of 4)"
        );
        let cfg = EnvConfig {
            max_steps: 600,
            ..filtered(true)
        };
        let (ended, interventions) = random_episodes(id, &cfg, 4);
        assert_eq!(ended, 0, "{id}: a filtered episode terminated");
        assert!(interventions > 0, "{id}: the filter never acted");
    }
}

#[test]
fn a_car_with_reverse_and_back_out_behind_the_filter_reverses_and_never_crashes() {
    for id in ["search-outdoor-20", "search-urban-20"] {
        let cfg = EnvConfig {
            max_steps: 600,
            action_mapping: agvrl_envs::task::ActionMapping::ScaledReverse,
            safety_filter: SafetyFilterConfig {
                backout_m: 0.6,
                ..filtered(true).safety_filter
            },
            ..filtered(true)
        };
        let mut env = make(id, &cfg).unwrap();
        let mut rng = StdRng::seed_from_u64(11);
        let mut slowest = 0.0f32;
        for k in 0..4 {
            env.reset(Some(k)).unwrap();
            for t in 0.. {
                // Two seconds forward, one second in reverse, random steering.
                let a0 = if t % 90 < 60 { 0.8 } else { -1.0 };
                let a = [a0, rng.random_range(-1.0..1.0)];
                let st = env.step(&a).unwrap();
                // Speed (halved) is the fourth value from the end of the default observation.
                slowest = slowest.min(2.0 * st.obs[st.obs.len() - 4]);
                assert!(!st.terminated, "{id}: {:?}", st.info.termination);
                if st.done() {
                    break;
                }
            }
        }
        assert!(slowest < -0.1, "{id}: never reversed (slowest {slowest} m/s)");
    }
}

#[test]
fn the_safe_reward_charges_its_filter_term_on_exactly_the_steps_the_filter_acted() {
    let cfg = EnvConfig {
        search_reward: agvrl_envs::task::SearchReward::Safe,
        safe_reward: agvrl_envs::task::SafeShaping {
            filter: -0.5,
            ..Default::default()
        },
        max_steps: 400,
        ..filtered(true)
    };
    let mut env = make("search-urban-20", &cfg).unwrap();
    let mut rng = StdRng::seed_from_u64(3);
    env.reset(Some(0)).unwrap();
    let (mut last, mut charged) = (0, 0);
    loop {
        let st = env
            .step(&[rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0)])
            .unwrap();
        let n = st.info.search.as_ref().unwrap().filter_interventions;
        let expect = if n > last { -0.5 } else { 0.0 };
        assert_eq!(st.info.reward_terms.filter, expect, "interventions {last} -> {n}");
        charged += (n > last) as u64;
        last = n;
        if st.done() {
            break;
        }
    }
    assert!(charged > 0, "the filter never acted");
}

#[test]
fn corrected_steps_report_the_action_of_the_control_sent_and_an_advising_filter_sends_the_policy_s() {
    // Random forward actions through an acting and an advising filter: both report a
    // correction (an action in the box, not the proposed one) on exactly the steps the
    // filter changed; behind the acting one the car never crashes, behind the advising one
    // the policy's actions drive and it does.
    for advisory in [false, true] {
        let cfg = EnvConfig {
            max_steps: 400,
            action_mapping: agvrl_envs::task::ActionMapping::ScaledReverse,
            safety_filter: SafetyFilterConfig {
                advisory,
                ..filtered(true).safety_filter
            },
            ..filtered(true)
        };
        let mut env = make("search-urban-20", &cfg).unwrap();
        let mut rng = StdRng::seed_from_u64(5);
        env.reset(Some(0)).unwrap();
        let (mut corrected, mut last) = (0, 0);
        loop {
            let a = [rng.random_range(0.5..1.0), rng.random_range(-1.0..1.0)];
            let st = env.step(&a).unwrap();
            let n = st.info.search.as_ref().unwrap().filter_interventions;
            assert_eq!(
                st.info.corrected_action.is_some(),
                n > last,
                "step with {n} interventions"
            );
            if let Some(c) = &st.info.corrected_action {
                corrected += 1;
                assert_eq!(c.len(), 2);
                assert!(c.iter().all(|v| (-1.0..=1.0).contains(v)), "{c:?}");
                assert_ne!(c.as_slice(), &a[..], "a correction differs from the proposal");
            }
            last = n;
            if st.done() {
                assert_eq!(
                    st.terminated, advisory,
                    "advisory {advisory}: {:?}",
                    st.info.termination
                );
                break;
            }
        }
        assert!(corrected > 0, "advisory {advisory}: the filter never acted");
    }
}

#[test]
fn a_car_sent_straight_at_a_wall_stops_short_of_it() {
    // The oval's outer wall ahead, full throttle, no steering: the filter brakes or steers
    // away, and the LiDAR never comes within the racing task's 0.8 m.
    let cfg = EnvConfig {
        spawn: SpawnMode::Fixed,
        safety_filter: SafetyFilterConfig {
            clearance_m: 0.9,
            ..filtered(true).safety_filter
        },
        ..filtered(true)
    };
    let mut env = make("racing-oval", &cfg).unwrap();
    env.reset(Some(0)).unwrap();
    for t in 0..600 {
        let st = env.step(&[1.0, 0.0]).unwrap();
        assert!(!st.terminated, "terminated at step {t}: {:?}", st.info.termination);
        if st.truncated {
            break;
        }
    }
}

#[test]
fn a_filter_on_a_coasting_drive_is_refused() {
    let mut cfg = filtered(true);
    cfg.sim.brake_mps2 = 0.0;
    let err = make("search-outdoor-20", &cfg)
        .err()
        .expect("a coasting car cannot be filtered");
    assert!(err.to_string().contains("brake_mps2"), "{err}");
    // Racing ends at 0.8 m: the default 0.75 m clearance would plan into terminations.
    let err = make("racing-oval", &filtered(true))
        .err()
        .expect("clearance under the termination range");
    assert!(err.to_string().contains("clearance_m"), "{err}");
}
