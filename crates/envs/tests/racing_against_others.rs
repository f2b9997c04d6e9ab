//! Races of several cars: seeded grids, fault for contacts, crashed cars, passes and the figures
//! counting them, the position and rear-end terms, races on generated circuits, cars driven by
//! controls, the safety filter keeping a car off the one ahead.

use super::*;
use agvrl_envs::api::{MultiStep, Track};
use std::path::Path;

fn track(name: &str) -> TrackSetting {
    TrackSetting::Path(Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../../assets/tracks/{name}.yaml")))
}

fn race(track_name: Option<&str>, cars: usize, max_steps: u64) -> RaceEnv {
    let cfg = EnvConfig {
        track: track_name.map(track),
        race: Some(RaceSettings {
            cars,
            ..RaceSettings::default()
        }),
        max_steps,
        ..EnvConfig::default()
    };
    make_race("racing-duel", &cfg).unwrap()
}

/// Pure pursuit of the line `offset_m` left of the centre line, from the simulator's pose:
/// the steering action.
fn steer_along(env: &RaceEnv, i: usize, offset_m: f32) -> f32 {
    let t: &Track = env.track();
    let p = env.sim().car(i).pose2();
    let s = t.centreline_s(p.x_m, p.y_m);
    let ([cx, cy], [dx, dy]) = t.centreline_at(s + 1.2);
    let (tx, ty) = (cx - offset_m * dy, cy + offset_m * dx);
    let alpha = (ty - p.y_m).atan2(tx - p.x_m) - p.yaw_rad;
    let alpha = alpha.sin().atan2(alpha.cos());
    ((2.0 * 0.33 * alpha.sin() / 1.2).atan() / 0.36).clamp(-1.0, 1.0)
}

fn distances(st: &MultiStep) -> Vec<f64> {
    st.agents
        .iter()
        .map(|a| a.as_ref().unwrap().info.race.as_ref().unwrap().distance_m)
        .collect()
}

/// The same seed and actions give the same race, bit for bit; the grid stands behind the
/// start line, a row per 0.8 m, and its order is drawn per race.
#[test]
fn a_race_is_seeded_and_draws_its_grid_order_per_race() {
    let mut env = race(None, 3, 60);
    assert_eq!(env.n_agents(), 3);
    let run = |env: &mut RaceEnv, seed| {
        let obs = env.reset(Some(seed)).unwrap();
        let mut steps = vec![];
        for k in 0..60 {
            let a: Vec<Vec<f32>> = (0..3)
                .map(|i| vec![0.2 * i as f32, 0.1 * (k % 3) as f32 - 0.1])
                .collect();
            steps.push(env.step(&a).unwrap());
        }
        (obs, steps)
    };
    let (a, b) = (run(&mut env, 7), run(&mut env, 7));
    assert_eq!(a, b, "same seed, same race");
    let last = a.1.last().unwrap();
    assert!(last.over(), "the time limit ends every car's episode at once");
    assert!(last.agents.iter().all(|s| s.as_ref().unwrap().truncated));
    let mut orders = std::collections::BTreeSet::new();
    for seed in 0..12 {
        env.reset(Some(seed)).unwrap();
        let st = env.step(&vec![vec![-1.0, 0.0]; 3]).unwrap();
        let mut d = distances(&st);
        assert!(
            d.iter().all(|x| *x < 0.0),
            "the grid stands behind the start line: {d:?}"
        );
        let order: Vec<usize> = {
            let mut o: Vec<usize> = (0..3).collect();
            o.sort_by(|&x, &y| d[y].total_cmp(&d[x]));
            o
        };
        d.sort_by(f64::total_cmp);
        assert!(
            (d[1] - d[0] - 0.8).abs() < 0.05 && (d[2] - d[1] - 0.8).abs() < 0.05,
            "rows 0.8 m apart: {d:?}"
        );
        orders.insert(order);
    }
    assert!(orders.len() >= 4, "grid orders drawn: {orders:?}");
}

/// On the oval (single file: the lane leaves no room for two columns) the car behind
/// drives into the stopped car ahead: both count the contact, the one whose front hit is
/// at fault and pays for it, and a car close by ends nobody's episode.
#[test]
fn a_car_that_drives_into_the_one_ahead_is_at_fault_and_pays_for_it() {
    let mut env = race(None, 2, 200);
    env.reset(Some(3)).unwrap();
    let st = env.step(&vec![vec![-1.0, 0.0]; 2]).unwrap();
    let d = distances(&st);
    let (front, back) = if d[0] > d[1] { (0, 1) } else { (1, 0) };
    let (mut paid, mut front_paid, mut last) = (0.0, 0.0, None);
    for _ in 0..199 {
        let mut a = vec![vec![-1.0, 0.0]; 2];
        a[back] = vec![1.0, steer_along(&env, back, 0.0)];
        let st = env.step(&a).unwrap();
        paid += st.agents[back].as_ref().unwrap().info.reward_terms.car_contact;
        front_paid += st.agents[front].as_ref().unwrap().info.reward_terms.car_contact;
        assert!(
            st.agents.iter().all(|s| !s.as_ref().unwrap().terminated),
            "no one crashed"
        );
        last = Some(st);
    }
    let s = last.unwrap().summary.expect("the race ended at its time limit");
    assert!(s.contacts[back] >= 1 && s.contacts[front] >= 1, "{s:?}");
    assert_eq!((s.at_fault[back] >= 1, s.at_fault[front]), (true, 0), "{s:?}");
    assert!(paid < 0.0 && front_paid == 0.0, "back paid {paid}, front {front_paid}");
    assert!(s.time_lost_s[back] > 0.0, "{s:?}");
}

/// Behind the safety filter set for racing (0.3 m clearance, 0.5 s of scan points, brakes), the
/// car sent at full throttle straight at the stopped one 2 m ahead never hits it with its front:
/// the filter sees a car as it sees a wall, and stops short of it.
#[test]
fn behind_the_safety_filter_a_car_sent_at_the_one_ahead_stops_short_of_it() {
    let cfg = EnvConfig {
        race: Some(RaceSettings {
            cars: 2,
            start_behind_share: 1.0,
            ..RaceSettings::default()
        }),
        max_steps: 200,
        // The map-track rules (contact ends an episode), under which races on circuits run.
        racing: Some(agvrl_envs::task::RacingRulesSetting {
            end_below_m: Some(0.0),
            ..Default::default()
        }),
        sim: agvrl_sim::SimSettings {
            brake_mps2: 4.0,
            ..Default::default()
        },
        safety_filter: agvrl_envs::task::SafetyFilterConfig {
            enabled: true,
            clearance_m: 0.3,
            memory_s: 0.5,
            ..Default::default()
        },
        ..EnvConfig::default()
    };
    let mut env = make_race("racing-duel", &cfg).unwrap();
    // The filter drives car 0's controls (the learner's, in training and in `agvrl race`),
    // which starts 2 m behind.
    let (front, back) = (1, 0);
    env.reset(Some(0)).unwrap();
    let d = distances(&env.step(&vec![vec![-1.0, 0.0]; 2]).unwrap());
    assert!(d[front] - d[back] > 1.5, "{d:?}");
    let mut last = None;
    for _ in 0..199 {
        // Full throttle, steered at the other car's middle.
        let (p, q) = (env.sim().car(back).pose2(), env.sim().car(front).pose2());
        let alpha = (q.y_m - p.y_m).atan2(q.x_m - p.x_m) - p.yaw_rad;
        let steer = (alpha.sin().atan2(alpha.cos()) / 0.36).clamp(-1.0, 1.0);
        let mut a = vec![vec![-1.0, 0.0]; 2];
        a[back] = vec![1.0, steer];
        let st = env.step(&a).unwrap();
        let over = st.summary.is_some();
        last = Some(st);
        if over {
            break;
        }
    }
    let s = last.unwrap().summary.expect("the race ended");
    let end = &s.distance_m;
    assert_eq!((s.at_fault[back], s.crashed[back]), (0, false), "{s:?}");
    // It closed in before it stopped, rather than standing still from the start.
    assert!(end[back] - d[back] > 0.5, "the car behind moved from {d:?} to {end:?}");
}

/// A car steered into the wall crashes: its episode ends with the crash penalty, it stands
/// where it stopped while the race goes on, and it finishes last.
#[test]
fn a_crashed_car_stays_where_it_stopped_until_the_race_ends() {
    let mut env = race(Some("bean"), 2, 300);
    env.reset(Some(1)).unwrap();
    let mut crashed_at = None;
    for k in 0..300 {
        let a = vec![vec![0.0, 1.0], vec![0.0, steer_along(&env, 1, 0.0)]];
        let st = env.step(&a).unwrap();
        match crashed_at {
            None => {
                let s0 = st.agents[0].as_ref().unwrap();
                if s0.terminated {
                    let rules = agvrl_envs::task::RacingRules::map_track();
                    assert_eq!(s0.info.reward_terms.collision, rules.crash_penalty);
                    assert!(s0.info.race.as_ref().unwrap().crashed);
                    crashed_at = Some((k, env.sim().car(0).pose()));
                }
            }
            Some((_, pose)) => {
                assert!(st.agents[0].is_none(), "a crashed car drops out");
                assert_eq!(env.sim().car(0).pose(), pose, "and stays put");
            }
        }
        if let Some(s) = st.summary {
            assert_eq!(k, 299);
            assert!(s.crashed[0] && !s.crashed[1]);
            assert_eq!(s.order, vec![1, 0]);
            return;
        }
    }
    panic!("car 0 crashed at {crashed_at:?} and the race never ended");
}

/// On the wide sweepers track two cars start side by side; the one behind, faster on
/// its own line, passes the other without touching it: one encounter and one pass, and it
/// leads (the slower car's encounter, once passed, ends without a pass).
#[test]
fn a_faster_car_on_its_own_line_passes() {
    let mut env = race(Some("sweepers"), 2, 600);
    env.reset(Some(2)).unwrap();
    let st = env.step(&vec![vec![-1.0, 0.0]; 2]).unwrap();
    let d = distances(&st);
    let (front, back) = if d[0] > d[1] { (0, 1) } else { (1, 0) };
    // Each car keeps to its grid column's side.
    let side = |env: &RaceEnv, i: usize| {
        let t = env.track();
        let p = env.sim().car(i).pose2();
        let s = t.centreline_s(p.x_m, p.y_m);
        let ([cx, cy], [dx, dy]) = t.centreline_at(s);
        if (p.x_m - cx) * -dy + (p.y_m - cy) * dx > 0.0 {
            0.3
        } else {
            -0.3
        }
    };
    let (sf, sb) = (side(&env, front), side(&env, back));
    assert!(sf != sb, "two columns on a 3 m track");
    let mut summary = None;
    for _ in 0..599 {
        let mut a = vec![vec![]; 2];
        a[front] = vec![-0.3, steer_along(&env, front, sf)];
        a[back] = vec![1.0, steer_along(&env, back, sb)];
        let st = env.step(&a).unwrap();
        assert!(st.agents.iter().all(|s| !s.as_ref().unwrap().terminated));
        summary = st.summary;
    }
    let s = summary.unwrap();
    assert_eq!((s.passes[back], s.passes[front]), (1, 0), "{s:?}");
    assert_eq!(s.encounters[back], 1, "{s:?}");
    assert_eq!((s.start_place[front], s.start_place[back]), (1, 2), "{s:?}");
    assert_eq!(s.order[0], back);
    assert_eq!(s.contacts, vec![0, 0]);
}

/// A race on `track_name` whose every start puts car 0 two metres behind car 1.
fn race_behind(track_name: Option<&str>, max_steps: u64) -> RaceEnv {
    let cfg = EnvConfig {
        track: track_name.map(track),
        race: Some(RaceSettings {
            cars: 2,
            start_behind_share: 1.0,
            ..RaceSettings::default()
        }),
        max_steps,
        ..EnvConfig::default()
    };
    make_race("racing-duel", &cfg).unwrap()
}

/// A start behind puts car 0 two metres behind car 1 along the centre line wherever the
/// lap draws it, across the start line too, and the gap stays continuous as both drive
/// over the line: distances count from one place, not from each car's wrapped arc.
#[test]
fn relative_progress_across_the_lap_line_is_continuous() {
    let mut env = race_behind(None, 400);
    let lap = env.track().lap_length_m() as f64;
    let mut straddled = 0;
    for seed in 0..200 {
        env.reset(Some(seed)).unwrap();
        let st = env.step(&[vec![-1.0, 0.0], vec![-1.0, 0.0]]).unwrap();
        let d = distances(&st);
        assert!((d[1] - d[0] - 2.0).abs() < 0.05, "seed {seed}: {d:?}");
        let arc = |i: usize| {
            let p = env.sim().car(i).pose2();
            env.track().centreline_s(p.x_m, p.y_m) as f64
        };
        if arc(0) > lap - 2.0 && arc(1) < 2.0 {
            straddled += 1;
            let mut last = d[1] - d[0];
            for _ in 0..60 {
                let a: Vec<Vec<f32>> = (0..2).map(|i| vec![0.6, steer_along(&env, i, 0.0)]).collect();
                let gap = {
                    let d = distances(&env.step(&a).unwrap());
                    d[1] - d[0]
                };
                assert!((gap - last).abs() < 0.3, "seed {seed}: gap {last} -> {gap}");
                last = gap;
            }
        }
    }
    assert!(straddled > 0, "no start across the line in 200 races: no test");
}

/// Car 0 starts behind car 1 on the wide sweepers and passes it on a line 0.5 m to its side:
/// one encounter, one pass. On a line 0.35 m to the side its front hits car 1's rear corner
/// and it scrapes by: ahead within two seconds of the contact its front caused, an at-fault
/// incident and no pass.
#[test]
fn a_pass_counts_but_not_one_made_right_after_ramming_the_car_ahead() {
    for ram in [false, true] {
        let mut env = race_behind(Some("sweepers"), 300);
        env.reset(Some(4)).unwrap();
        let mut summary = None;
        // Rammed: a line that takes its front into car 1's rear corner and scrapes by.
        let line = if ram { 0.35 } else { 0.5 };
        for _ in 0..300 {
            let a = vec![
                vec![1.0, steer_along(&env, 0, line)],
                vec![-0.2, steer_along(&env, 1, 0.0)],
            ];
            let st = env.step(&a).unwrap();
            summary = st.summary;
        }
        let s = summary.unwrap();
        assert_eq!(s.start_place, vec![2, 1], "ram {ram}: {s:?}");
        assert_eq!(s.order[0], 0, "ram {ram}: car 0 ends ahead: {s:?}");
        assert!(s.encounters[0] >= 1, "ram {ram}: {s:?}");
        if ram {
            assert!(s.at_fault[0] >= 1 && s.at_fault[1] == 0 && !s.crashed[1], "{s:?}");
            assert_eq!(s.passes[0], 0, "a pass right after ramming: {s:?}");
            assert!(s.at_fault_incidents(0) >= 1);
        } else {
            assert_eq!(s.contacts, vec![0, 0], "{s:?}");
            assert_eq!(s.passes, vec![1, 0], "{s:?}");
        }
    }
}

/// Run the sweepers race of `a_pass_counts_but_not_one_made_right_after_ramming_the_car_ahead`
/// (car 0 on a line `line` m to the side, from 2 m behind) with `settings`; gives the
/// summary and each car's summed reward terms (position, car contact).
fn scripted_pass(line: f32, settings: RaceSettings) -> (RaceSummary, [(f64, f64); 2]) {
    let cfg = EnvConfig {
        track: Some(track("sweepers")),
        race: Some(RaceSettings {
            cars: 2,
            start_behind_share: 1.0,
            ..settings
        }),
        max_steps: 300,
        ..EnvConfig::default()
    };
    let mut env = make_race("racing-duel", &cfg).unwrap();
    env.reset(Some(4)).unwrap();
    let mut sums = [(0.0, 0.0); 2];
    loop {
        let a = vec![
            vec![1.0, steer_along(&env, 0, line)],
            vec![-0.2, steer_along(&env, 1, 0.0)],
        ];
        let st = env.step(&a).unwrap();
        for (i, a) in st.agents.iter().enumerate() {
            if let Some(a) = a {
                sums[i].0 += a.info.reward_terms.position;
                sums[i].1 += a.info.reward_terms.car_contact;
            }
        }
        if let Some(s) = st.summary {
            return (s, sums);
        }
    }
}

/// The position term sums to the clamped gap's change over the race (window 5 m behind to
/// 10 m ahead): car 0, from 2 m behind to G ahead, gains min(G, 10) + 2; car 1, passed by
/// more than 5 m, loses 5 + 2.
#[test]
fn the_position_term_pays_the_ground_gained_within_its_window() {
    let settings = RaceSettings {
        position_per_m: 1.0,
        ..RaceSettings::default()
    };
    let (s, sums) = scripted_pass(0.5, settings);
    let gap = s.distance_m[0] - s.distance_m[1];
    assert!(gap > 5.0 && !s.crashed[1], "{s:?}");
    let gained = gap.min(10.0) + 2.0;
    assert!(
        (sums[0].0 - gained).abs() < 0.06,
        "car 0 gained {} of {gained}",
        sums[0].0
    );
    assert!((sums[1].0 + 7.0).abs() < 0.06, "car 1 lost {}", sums[1].0);
    let (_, off) = scripted_pass(0.5, RaceSettings::default());
    assert_eq!((off[0].0, off[1].0), (0.0, 0.0), "off by default");
}

/// The rear-end charge falls on the car whose front hit, once per contact, by its closing
/// speed: the rammed race costs car 0 more with it, and car 1 nothing.
#[test]
fn the_rear_end_charge_falls_on_the_car_that_hit() {
    let charged = RaceSettings {
        rear_end_per_mps: -1.0,
        ..RaceSettings::default()
    };
    let (s, with) = scripted_pass(0.35, charged);
    let (_, without) = scripted_pass(0.35, RaceSettings::default());
    assert!(s.at_fault[0] >= 1 && s.at_fault[1] == 0, "{s:?}");
    let charge = with[0].1 - without[0].1;
    assert!(charge < -0.1, "car 0's rear-end charge {charge}");
    assert_eq!(with[1].1, without[1].1, "car 1 caused nothing");
}

/// `layout_seed` races on racing-circuit's generated circuit of that seed; `circuit`
/// without it draws a new circuit for every race, held-out races from the other half of
/// the seed space.
#[test]
fn races_run_on_generated_circuits() {
    let lap_of = |cfg: &EnvConfig| {
        let mut car = make_sim_car("racing-circuit", cfg).unwrap();
        car.reset(0).unwrap();
        car.map().unwrap().track.as_ref().unwrap().lap_length_m()
    };
    let pinned = EnvConfig {
        layout_seed: Some(5),
        ..EnvConfig::default()
    };
    let mut env = make_race("racing-duel", &pinned).unwrap();
    env.reset(Some(0)).unwrap();
    let first = env.track().lap_length_m();
    assert_eq!(first, lap_of(&pinned), "the circuit of layout_seed 5");
    env.reset(Some(1)).unwrap();
    assert_eq!(env.track().lap_length_m(), first, "pinned: the same circuit every race");
    let laps = |held_out: bool| -> std::collections::BTreeSet<u32> {
        let drawn = EnvConfig {
            circuit: Some(Default::default()),
            held_out,
            ..EnvConfig::default()
        };
        let mut env = make_race("racing-duel", &drawn).unwrap();
        (0..4)
            .map(|seed| {
                env.reset(Some(seed)).unwrap();
                env.track().lap_length_m().to_bits()
            })
            .collect()
    };
    let (train, held_out) = (laps(false), laps(true));
    assert_eq!(train.len(), 4, "a new circuit every race");
    assert!(train.is_disjoint(&held_out), "held-out races meet other circuits");
}

#[test]
fn a_race_takes_one_to_eight_cars_and_is_no_single_agent_env() {
    let e = make("racing-duel", &EnvConfig::default()).err().unwrap().to_string();
    assert!(e.contains("make_multi"), "{e}");
    for cars in [0, 9] {
        let cfg = EnvConfig {
            race: Some(RaceSettings {
                cars,
                ..RaceSettings::default()
            }),
            ..EnvConfig::default()
        };
        let e = make_multi("racing-duel", &cfg).err().unwrap().to_string();
        assert!(e.contains("cars must be 1 to 8"), "{e}");
    }
    let e = make_multi("racing-oval", &EnvConfig::default())
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("racing-duel"), "{e}");
    let mut env = make_multi("racing-duel", &EnvConfig::default()).unwrap();
    assert!(matches!(
        env.step(&[vec![0.0, 0.0], vec![0.0, 0.0]]),
        Err(EnvError::NeedsReset)
    ));
    env.reset(Some(0)).unwrap();
    let e = env
        .step(&[vec![f32::NAN, 0.0], vec![0.0, 0.0]])
        .unwrap_err()
        .to_string();
    assert!(e.contains("env 0") && e.contains("not finite"), "{e}");
}

/// A car driven by the controls its task would make races as it does by actions, bit for
/// bit (`agvrl-drive --serve-sim racing-duel` drives car 0 that way); a control that is not
/// finite is refused.
#[test]
fn a_car_driven_by_controls_races_as_it_does_by_actions() {
    let (mut by_action, mut by_control) = (race(None, 2, 200), race(None, 2, 200));
    by_action.reset(Some(3)).unwrap();
    by_control.reset(Some(3)).unwrap();
    for k in 0..200 {
        let actions: Vec<Vec<f32>> = (0..2)
            .map(|i| vec![0.4 + 0.2 * i as f32, steer_along(&by_action, i, 0.3 - 0.6 * i as f32)])
            .collect();
        let a = by_action.step(&actions).unwrap();
        let inputs = vec![
            CarInput::Control(by_action.sim().car(0).control()),
            CarInput::Action(&actions[1]),
        ];
        let c = by_control.step_inputs(&inputs).unwrap();
        assert_eq!(a, c, "step {k}");
        if k == 0 {
            assert!(by_action.sim().car(0).control().throttle > 0.0);
        }
    }
    by_control.reset(Some(3)).unwrap();
    let e = by_control
        .step_inputs(&[
            CarInput::Control(Control {
                throttle: f64::NAN,
                steering_rad: 0.0,
            }),
            CarInput::Action(&[0.0, 0.0]),
        ])
        .unwrap_err()
        .to_string();
    assert!(e.contains("car 0") && e.contains("not finite"), "{e}");
}

/// With `critic_sees_opponents`, each car's critic values hold the other car's gap along the
/// centre line (over 10 m), lateral offset and speed differences and whether it races: 2 m
/// ahead on the centre line wherever along the lap the start is drawn, and the car ahead sees
/// the one behind 2 m behind; without the setting there are none. (The gap is the difference
/// of the distances raced, which `relative_progress_across_the_lap_line_is_continuous` pins.)
#[test]
fn the_critic_sees_the_other_cars_gap_offset_and_speed() {
    let cfg = |on: bool| EnvConfig {
        race: Some(RaceSettings {
            cars: 2,
            start_behind_share: 1.0,
            critic_sees_opponents: on,
            ..RaceSettings::default()
        }),
        max_steps: 400,
        ..EnvConfig::default()
    };
    assert_eq!(make_race("racing-duel", &cfg(false)).unwrap().critic_obs_dim(), 0);
    let mut env = make_race("racing-duel", &cfg(true)).unwrap();
    assert_eq!(env.critic_obs_dim(), 4);
    for seed in 0..40 {
        env.reset(Some(seed)).unwrap();
        let (c0, c1) = (env.critic_obs_of(0), env.critic_obs_of(1));
        assert_eq!(c0.len(), 4);
        assert!(
            (c0[0] - 0.2).abs() < 0.005 && (c1[0] + 0.2).abs() < 0.005,
            "seed {seed}: {c0:?} {c1:?}"
        );
        assert!(
            c0[1].abs() < 0.01 && c0[2] == 0.0 && c0[3] == 1.0,
            "seed {seed}: {c0:?}"
        );
    }
    // Car 1 drives on 0.4 m right of the centre line while car 0 waits: the gap grows, the
    // offset and the speed difference show.
    for _ in 0..150 {
        env.step(&[vec![-1.0, 0.0], vec![0.6, steer_along(&env, 1, -0.4)]])
            .unwrap();
    }
    let c0 = env.critic_obs_of(0);
    let v1 = env.sim().car(1).forward_speed_mps();
    assert!(c0[0] > 0.3, "{c0:?}");
    assert!((c0[1].abs() - 0.4).abs() < 0.15, "{c0:?}");
    assert!((c0[2] - v1 / 2.0).abs() < 0.05 && v1 > 0.5, "{c0:?} {v1}");
}

/// With `pass_advice_margin_m`, a car closing on a stopped one ahead while running to its
/// left is advised, as its corrected action, to steer further left (the side it is on, where
/// the lane has room), and only once within the advice's horizon; the advice is never applied:
/// the race runs the same, step for step, without it.
#[test]
fn passing_advice_steers_a_closing_car_away_from_the_one_ahead_and_is_never_applied() {
    let run = |margin_m: f32| {
        let cfg = EnvConfig {
            race: Some(RaceSettings {
                cars: 2,
                start_behind_share: 1.0,
                pass_advice_margin_m: margin_m,
                ..RaceSettings::default()
            }),
            max_steps: 120,
            racing: Some(agvrl_envs::task::RacingRulesSetting {
                end_below_m: Some(0.0),
                ..Default::default()
            }),
            ..EnvConfig::default()
        };
        let mut env = make_race("racing-duel", &cfg).unwrap();
        env.reset(Some(0)).unwrap();
        let mut steps = vec![];
        for _ in 0..120 {
            // Car 0 (2 m behind) at full throttle along a line 0.2 m left of the centre line,
            // where car 1 stands.
            let a = vec![vec![1.0, steer_along(&env, 0, 0.2)], vec![-1.0, 0.0]];
            let gap_m = {
                let (p, q) = (env.sim().car(0).pose2(), env.sim().car(1).pose2());
                ((q.x_m - p.x_m).powi(2) + (q.y_m - p.y_m).powi(2)).sqrt()
            };
            let speed = env.sim().car(0).forward_speed_mps();
            let st = env.step(&a).unwrap();
            let over = st.over();
            steps.push((a[0].clone(), gap_m, speed, st));
            if over {
                break;
            }
        }
        steps
    };
    let (advised, plain) = (run(0.25), run(0.0));
    assert_eq!(advised.len(), plain.len());
    for (x, y) in advised.iter().zip(&plain) {
        let (sx, sy) = (x.3.agents[0].as_ref().unwrap(), y.3.agents[0].as_ref().unwrap());
        assert_eq!(
            (&sx.obs, sx.reward),
            (&sy.obs, sy.reward),
            "the advice changed the race"
        );
        assert_eq!(sy.info.corrected_action, None, "no advice when it is off");
    }
    let first = advised
        .iter()
        .position(|(_, _, _, st)| st.agents[0].as_ref().unwrap().info.corrected_action.is_some())
        .expect("advice while closing in");
    let (a, gap_m, speed, st) = &advised[first];
    let c = st.agents[0].as_ref().unwrap().info.corrected_action.clone().unwrap();
    assert!(first > 0, "not from the start, 2 m behind");
    // Base to base: within a car's length (0.6 m at most) and a horizon's travel.
    let reach = 0.6 + agvrl_envs::pass_advice::HORIZON_S * speed;
    assert!(*gap_m < reach, "advised {gap_m} m behind at {speed} m/s");
    assert_eq!(c[0], a[0], "room to the left: steer, keep the throttle");
    assert!(
        c[1] > a[1] + 0.05,
        "steer left, away from the car ahead: {a:?} -> {c:?}"
    );
}

/// A passer takes a car sent along the line of a slower one ahead around it, from the
/// simulator's places or from its own scan, and holds the line until past: no contact, a pass.
/// Without it the same actions run into the car ahead.
#[test]
fn a_passer_takes_a_car_sent_at_a_slower_one_around_it() {
    use agvrl_envs::passer::PasserSource;
    let run = |passer: PasserSource| {
        let cfg = EnvConfig {
            track: Some(track("sweepers")),
            race: Some(RaceSettings {
                cars: 2,
                start_behind_share: 1.0,
                passer,
                ..RaceSettings::default()
            }),
            max_steps: 450,
            racing: Some(agvrl_envs::task::RacingRulesSetting {
                end_below_m: Some(0.0),
                ..Default::default()
            }),
            ..EnvConfig::default()
        };
        let mut env = make_race("racing-duel", &cfg).unwrap();
        env.reset(Some(0)).unwrap();
        loop {
            // Car 0, 2 m behind, at full throttle after car 1 at half throttle, both along the
            // centre line.
            let a = vec![
                vec![1.0, steer_along(&env, 0, 0.0)],
                vec![0.5, steer_along(&env, 1, 0.0)],
            ];
            if let Some(s) = env.step(&a).unwrap().summary {
                return s;
            }
        }
    };
    let plain = run(PasserSource::Off);
    assert!(plain.contacts[0] >= 1 && plain.at_fault[0] >= 1, "{plain:?}");
    for source in [PasserSource::Truth, PasserSource::Scan] {
        let s = run(source);
        assert_eq!(s.contacts, vec![0, 0], "{source:?}: {s:?}");
        assert_eq!((s.encounters[0], s.passes[0]), (1, 1), "{source:?}: {s:?}");
        assert!(!s.crashed[0], "{source:?}: {s:?}");
    }
}

/// The passer's tracker finds the car ahead in the scan of the car behind, and times it:
/// its place along the track within 0.1 m, its offset within 0.1 m, its speed along the
/// centre line within 0.1 m/s.
#[test]
fn a_passers_tracker_follows_the_car_ahead_in_the_scan() {
    use agvrl_envs::passer::ScanTracker;
    let mut env = race_behind(Some("sweepers"), 300);
    env.reset(Some(1)).unwrap();
    let mut tracker = ScanTracker::default();
    let mut checked = 0;
    // Car 1's place along the centre line, and when.
    let mut places: Vec<(f64, f32)> = Vec::new();
    for k in 0..300 {
        // Car 1 0.3 m left of the centre line, car 0 on it, both at half throttle; checked
        // from 5 s on, at a steady speed.
        let a = vec![
            vec![0.5, steer_along(&env, 0, 0.0)],
            vec![0.5, steer_along(&env, 1, 0.3)],
        ];
        env.step(&a).unwrap();
        let t = env.track();
        let (p, q) = (env.sim().car(0).pose2(), env.sim().car(1).pose2());
        let seen = tracker.update(
            t,
            p,
            env.sim().car(0).forward_speed_mps(),
            env.frame_of(0).scan.as_ref(),
            env.sim().time_s(),
            1.0,
        );
        places.push((env.sim().time_s(), t.centreline_s(q.x_m, q.y_m)));
        if k < 150 {
            continue;
        }
        let seen = seen.expect("the car ahead is in the scan");
        let ahead = t.centreline_s(q.x_m, q.y_m) - t.centreline_s(p.x_m, p.y_m);
        let offset = t.offset_right_m(q.x_m, q.y_m);
        // Its speed along the centre line over the last half second.
        let (t0, s0) = places[places.len() - 16];
        let (t1, s1) = places[places.len() - 1];
        let lap = t.lap_length_m();
        let speed = (s1 - s0).rem_euclid(lap) / (t1 - t0) as f32;
        assert!(
            (seen.ahead_m - ahead).abs() < 0.1,
            "step {k}: {seen:?} against {ahead} m ahead"
        );
        assert!(
            (seen.offset_m - offset).abs() < 0.1,
            "step {k}: {seen:?} against offset {offset}"
        );
        assert!(
            (seen.speed_mps - speed).abs() < 0.1,
            "step {k}: {seen:?} against {speed} m/s"
        );
        checked += 1;
    }
    assert_eq!(checked, 150);
}

/// A car's scan carries ranges alone; the passer places its rays on the map from the car's
/// pose and the LiDAR's mount. Those places are where the simulator's rays ended, within
/// 2 cm, for the car behind with the other car in its scan on the sweepers.
#[test]
fn scan_rays_placed_from_the_pose_land_where_the_simulators_rays_ended() {
    use agvrl_envs::passer::scan_points_w;
    let mut env = race_behind(Some("sweepers"), 300);
    env.reset(Some(1)).unwrap();
    let mount = env.sim().vehicle().lidar_mount();
    let mut checked = 0;
    for k in 0..60 {
        let a = vec![
            vec![0.6, steer_along(&env, 0, 0.0)],
            vec![0.5, steer_along(&env, 1, 0.3)],
        ];
        env.step(&a).unwrap();
        if k % 20 != 19 {
            continue;
        }
        let f = env.frame_of(0);
        let (scan, gps) = (f.scan.as_ref().unwrap(), f.gps.as_ref().unwrap());
        let pose = agvrl_sim::PlanarPose {
            x_m: gps.position_m[0] as f32,
            y_m: gps.position_m[1] as f32,
            yaw_rad: gps.rpy_rad[2] as f32,
        };
        let placed = scan_points_w(scan, pose, &mount);
        assert_eq!(placed.len(), scan.points_w.len());
        for (i, (p, q)) in placed.iter().zip(&scan.points_w).enumerate() {
            if !scan.hit_at(i) || scan.ranges[i] <= scan.range_min {
                continue;
            }
            let d = (p[0] - q[0]).hypot(p[1] - q[1]);
            assert!(d < 0.02, "step {k}, ray {i}: {p:?} against {q:?} ({d} m)");
            checked += 1;
        }
    }
    assert!(checked > 100, "{checked} rays checked");
}
