//! Episodes: termination and truncation, spawns, layouts and held-out halves (procedural maps, and
//! racing-circuit's generated circuits: a new one every episode, training and evaluation circuits
//! from disjoint halves of the seed space), the pendulum's closed form, search coverage, the oval's
//! progress and counted laps.

use super::*;
use agvrl_envs::registry::CIRCUIT_ENV;

#[test]
fn driving_into_a_wall_terminates_and_is_not_truncated() {
    let cfg = EnvConfig {
        spawn: SpawnMode::Fixed,
        ..quick_cfg()
    };
    let mut env = make("racing-oval", &cfg).unwrap();
    env.reset(Some(0)).unwrap();
    // Straight down the +x straight: the curve's outer wall stops it.
    for t in 0..1000 {
        let st = env.step(&[1.0, 0.0]).unwrap();
        if st.done() {
            assert!(st.terminated && !st.truncated, "step {t}");
            assert!(matches!(
                st.info.termination,
                Some(TerminationCause::TooClose | TerminationCause::Contact)
            ));
            assert_eq!(st.info.reward_terms.collision, -50.0);
            assert!(
                env.step(&[0.0, 0.0]).is_err(),
                "stepping a terminated episode needs a reset"
            );
            return;
        }
    }
    panic!("never terminated");
}

#[test]
fn random_spawns_in_open_maps_face_free_space() {
    for id in ["search-outdoor-20", "search-urban-20"] {
        let mut v = make_vehicle(id, &quick_cfg()).unwrap();
        let mut poses = std::collections::HashSet::new();
        for seed in 0..60 {
            let f = v.reset(seed).unwrap();
            let scan = f.scan.unwrap();
            assert!(
                scan.min_range() >= agvrl_envs::sim_vehicle::SPAWN_VIEW_M,
                "{id} seed {seed}: {} m ahead",
                scan.min_range()
            );
            let g = f.gps.unwrap();
            poses.insert(((g.position_m[0] * 10.0) as i32, (g.position_m[1] * 10.0) as i32));
        }
        assert!(
            poses.len() > 50,
            "{id}: spawns must still spread ({} distinct)",
            poses.len()
        );
    }
}

#[test]
fn recovery_spawns_face_an_obstacle_inside_braking_reach() {
    let cfg = EnvConfig {
        spawn: SpawnMode::NearObstacle,
        ..quick_cfg()
    };
    for id in ["search-outdoor-20", "search-urban-20"] {
        let mut v = make_vehicle(id, &cfg).unwrap();
        let mut poses = std::collections::HashSet::new();
        for seed in 0..30 {
            let f = v.reset(seed).unwrap();
            let near = f.scan.unwrap().min_range();
            assert!(
                agvrl_envs::sim_vehicle::RECOVERY_SPAWN_M.contains(&near),
                "{id} seed {seed}: {near} m ahead"
            );
            let g = f.gps.unwrap();
            poses.insert(((g.position_m[0] * 10.0) as i32, (g.position_m[1] * 10.0) as i32));
            assert_eq!(v.reset(seed).unwrap().gps.unwrap().position_m, g.position_m);
        }
        assert!(poses.len() > 25, "{id}: spawns must spread ({} distinct)", poses.len());
    }
}

#[test]
fn layout_seeds_give_other_maps_of_the_same_kind() {
    let scan_at_origin = |id: &str, layout_seed: Option<u64>| {
        let cfg = EnvConfig {
            layout_seed,
            spawn: agvrl_envs::sim_vehicle::SpawnMode::Fixed,
            max_steps: 60,
            ..quick_cfg()
        };
        let mut env = make(id, &cfg).unwrap();
        check_env(env.as_mut(), 150).unwrap_or_else(|e| panic!("{id} {layout_seed:?}: {e}"));
        make_vehicle(id, &cfg).unwrap().reset(0).unwrap().scan.unwrap().ranges
    };
    for id in ["search-outdoor-20", "search-urban-50"] {
        let a = scan_at_origin(id, Some(1));
        assert_eq!(a, scan_at_origin(id, Some(1)), "{id}: a layout seed is deterministic");
        assert_ne!(a, scan_at_origin(id, Some(2)), "{id}: another seed, another layout");
        assert!(
            a.iter().any(|&r| r < 12.0),
            "{id}: the car sees something from the origin"
        );
    }
}

#[test]
fn a_new_layout_each_episode_comes_from_the_episode_seed_and_its_half() {
    // The map a reset builds, seen as the free cells of the coverage grid.
    let free = |v: &mut Box<dyn agvrl_envs::Vehicle>, seed: u64| {
        v.reset(seed).unwrap();
        v.map().unwrap().free_cells.clone()
    };
    let cfg = EnvConfig {
        layout_seed: Some(5),
        new_layout_each_episode: true,
        ..quick_cfg()
    };
    let mut v = make_vehicle("search-urban-20", &cfg).unwrap();
    let a = free(&mut v, 1);
    assert_ne!(a, free(&mut v, 2), "another episode, another map");
    assert_eq!(a, free(&mut v, 1), "the episode seed decides the map");
    let held = agvrl_envs::heldout::split(1, true);
    assert_ne!(a, free(&mut v, held), "the held-out half draws other maps");
    // A fixed layout seed maps into the half the config asks for.
    let fixed = |held_out| {
        let cfg = EnvConfig {
            layout_seed: Some(5),
            held_out,
            ..quick_cfg()
        };
        free(&mut make_vehicle("search-outdoor-20", &cfg).unwrap(), 0)
    };
    assert_ne!(fixed(false), fixed(true));
    let bad = EnvConfig {
        new_layout_each_episode: true,
        ..quick_cfg()
    };
    assert!(
        make_vehicle("search-outdoor-20", &bad).is_err(),
        "nothing to redraw without layout_seed"
    );
}

#[test]
fn held_out_episodes_differ_from_training_episodes_of_the_same_seed() {
    let first_obs = |held_out| {
        let cfg = EnvConfig {
            held_out,
            ..quick_cfg()
        };
        let mut env = make("search-outdoor-20", &cfg).unwrap();
        (0..8u64).map(|s| env.reset(Some(s)).unwrap().0).collect::<Vec<_>>()
    };
    let (train, eval) = (first_obs(false), first_obs(true));
    for (t, e) in train.iter().zip(&eval) {
        assert_ne!(t, e, "a seed gives a training episode and a different held-out one");
    }
}

#[test]
fn the_time_limit_truncates_without_terminating() {
    let mut env = make(
        "search-outdoor-20",
        &EnvConfig {
            max_steps: 5,
            ..quick_cfg()
        },
    )
    .unwrap();
    env.reset(Some(2)).unwrap();
    for t in 1..=5 {
        // Scaled mapping: a0 = -1 is zero throttle; the car stays put.
        let st = env.step(&[-1.0, 0.0]).unwrap();
        assert_eq!(st.truncated, t == 5);
        assert!(!st.terminated);
    }
    let mut p = make("pendulum", &agvrl_envs::EnvConfig::default()).unwrap();
    p.reset(Some(0)).unwrap();
    for t in 1..=200 {
        let st = p.step(&[0.0]).unwrap();
        assert_eq!((st.truncated, st.terminated), (t == 200, false));
    }
}

#[test]
fn pendulum_matches_gymnasium_closed_form() {
    let mut p = Pendulum::new();
    for (th, thd, u) in [(0.3f64, -0.5f64, 1.5f64), (3.0, 7.9, -2.0), (-2.0, 0.0, 5.0)] {
        p.set_state(th, thd);
        let st = p.step(&[u as f32]).unwrap();
        let uc = u.clamp(-2.0, 2.0);
        let nthd = (thd + (3.0 * 10.0 / 2.0 * th.sin() + 3.0 * uc) * 0.05).clamp(-8.0, 8.0);
        let nth = th + nthd * 0.05;
        let cost = angle_normalize(th).powi(2) + 0.1 * thd * thd + 0.001 * uc * uc;
        assert!((st.reward + cost).abs() < 1e-12);
        assert_eq!(p.state(), (nth, nthd));
        assert_eq!(st.obs, vec![nth.cos() as f32, nth.sin() as f32, nthd as f32]);
    }
}

#[test]
fn search_reports_coverage_and_distance() {
    let cfg = EnvConfig {
        spawn: SpawnMode::Fixed,
        ..quick_cfg()
    };
    let mut env = make("search-outdoor-20", &cfg).unwrap();
    env.reset(Some(0)).unwrap();
    let mut last = None;
    for _ in 0..150 {
        let st = env.step(&[0.2, 0.3]).unwrap();
        last = st.info.search.clone();
        if st.done() {
            break;
        }
    }
    let s = last.unwrap();
    assert!(s.distance_m > 1.0 && s.coverage > 0.01 && s.coverage < 0.5, "{s:?}");
}

#[test]
fn oval_progress_runs_clockwise_along_the_centre_line() {
    // The built-in oval's numbers (assets/scenes/oval.toml).
    let t = agvrl_envs::api::OvalTrack {
        straight_m: 14.0,
        inner_radius_m: 3.0,
        outer_radius_m: 5.0,
    };
    assert!((t.lap_length_m() - (28.0 + 8.0 * std::f32::consts::PI)).abs() < 1e-3);
    // Clockwise progress: start of the +x straight, then down it, round the bottom.
    assert!(t.centreline_s(4.0, 7.0).abs() < 1e-4);
    assert!((t.centreline_s(4.0, -7.0) - 14.0).abs() < 1e-4);
    assert!((t.centreline_s(0.0, -11.0) - (14.0 + 2.0 * std::f32::consts::PI)).abs() < 1e-3);
    assert!((t.centreline_s(-4.0, 0.0) - (21.0 + 4.0 * std::f32::consts::PI)).abs() < 1e-3);
    for k in 0..100 {
        let s = k as f32 * t.lap_length_m() / 100.0;
        let ([x, y], [dx, dy]) = t.centreline_at(s);
        assert!((t.centreline_s(x, y) - s).abs() < 1e-3, "s {s}");
        assert!(t.lateral_offset_m(x, y).abs() < 1e-4);
        // The direction points along increasing s.
        let ahead = t.centreline_s(x + 0.01 * dx, y + 0.01 * dy);
        assert!(
            (ahead - s - 0.01).abs() < 1e-3 || s > t.lap_length_m() - 0.02,
            "s {s}: ahead {ahead}"
        );
    }
}

/// The oval the racing task reads is the scene's track.
#[test]
fn the_racing_map_carries_the_scene_s_oval() {
    let car = agvrl_envs::make_sim_car("racing-oval", &EnvConfig::default()).unwrap();
    let spec = car.sim().scene().file.track.clone().unwrap();
    let Some(agvrl_envs::api::Track::Oval(t)) = car.map().unwrap().track.clone() else {
        panic!("the oval's map carries the oval");
    };
    assert_eq!(
        (t.straight_m, t.inner_radius_m, t.outer_radius_m),
        (spec.straight_m, spec.inner_radius_m, spec.outer_radius_m)
    );
    assert_eq!((t.straight_m, t.inner_radius_m, t.outer_radius_m), (14.0, 3.0, 5.0));
}

/// Pure pursuit along the oval's centre line, from the GPS: a known-good driver.
fn pursue(frame: &SensorFrame, map: &MapInfo) -> f32 {
    let t = map.track.as_ref().unwrap();
    let g = frame.gps.as_ref().unwrap();
    let (x, y, yaw) = (g.position_m[0] as f32, g.position_m[1] as f32, g.rpy_rad[2] as f32);
    let s = t.centreline_s(x, y);
    let ([tx, ty], _) = t.centreline_at(s + 1.2);
    let alpha = (ty - y).atan2(tx - x) - yaw;
    let alpha = alpha.sin().atan2(alpha.cos());
    let delta = (2.0 * 0.33 * alpha.sin() / 1.2).atan();
    (delta / 0.36).clamp(-1.0, 1.0)
}

#[test]
fn racing_counts_laps_along_the_centre_line() {
    let sim = agvrl_sim::SimConfig {
        scene: agvrl_sim::SceneSource::Builtin("oval".into()),
        ..Default::default()
    };
    let vehicle = SimVehicle::new(sim, SpawnMode::Fixed, Randomisation::default()).unwrap();
    let mut env = TaskEnv::new(vehicle, Racing::new(RacingConfig::default(), 0.36));
    let r = pursue_a_lap(&mut env, 1500);
    let lap_s = r.last_lap_s.unwrap();
    assert_eq!(r.best_lap_s, Some(lap_s));
    // 53.1 m at no more than the top speed of 1.79 m/s.
    assert!(lap_s > 53.1 / 1.8 && lap_s < 120.0, "lap {lap_s} s");
}

/// The racing env on a map-file track (the shipped bean, centre line from its CSV): the
/// centre-line driver laps it without coming within 0.8 m of a wall, and progress counts
/// one lap of the centre line's length.
#[test]
fn racing_on_a_map_file_track_counts_a_lap_of_its_centre_line() {
    let yaml = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/tracks/bean.yaml");
    let cfg = EnvConfig {
        track: Some(agvrl_envs::TrackSetting::Path(yaml)),
        spawn: SpawnMode::Fixed,
        ..EnvConfig::default()
    };
    let mut env = make_sim_env_for_test("racing-oval", &cfg);
    let lap_m = env.vehicle().map().unwrap().track.as_ref().unwrap().lap_length_m();
    assert!((lap_m - 65.9).abs() < 0.5, "the bean's centre line is 65.9 m: {lap_m}");
    let r = pursue_a_lap(&mut env, 2500);
    let lap_s = r.last_lap_s.unwrap();
    assert!(lap_s > lap_m as f64 / 1.8 && lap_s < 150.0, "lap {lap_s} s");
}

/// Drive the centre-line pursuer at throttle 0.2 from seed 0 until a lap is counted (at
/// most `steps` control periods): it never gets within 0.8 m of a wall.
fn pursue_a_lap(env: &mut TaskEnv<SimVehicle, Racing>, steps: usize) -> agvrl_envs::api::RacingInfo {
    env.reset(Some(0)).unwrap();
    let mut info = None;
    for _ in 0..steps {
        let steer = pursue(env.last_frame().unwrap(), env.vehicle().map().unwrap());
        let st = env.step(&[0.2, steer]).unwrap();
        assert!(
            !st.terminated,
            "a centre-line driver never gets within 0.8 m: {:?}",
            st.info.termination
        );
        info = st.info.racing.clone();
        if info.as_ref().unwrap().laps >= 1 {
            break;
        }
    }
    let r = info.unwrap();
    assert_eq!(r.laps, 1, "{r:?}");
    r
}

fn make_sim_env_for_test(id: &str, cfg: &EnvConfig) -> TaskEnv<SimVehicle, Racing> {
    let mut sim_cfg = cfg.clone();
    sim_cfg.embed_track().unwrap();
    let Some(agvrl_envs::TrackSetting::Loaded(t)) = sim_cfg.track else {
        panic!("embedded");
    };
    assert_eq!(id, "racing-oval");
    let sim = agvrl_sim::SimConfig {
        scene: agvrl_sim::SceneSource::Map(t),
        ..Default::default()
    };
    let vehicle = SimVehicle::new(sim, cfg.spawn, Randomisation::default()).unwrap();
    TaskEnv::new(vehicle, Racing::new(RacingConfig::default(), 0.36))
}

/// The circuit each of `episodes` resets of racing-circuit drives, as eval resets them
/// (episode k with seed k).
fn circuits(held_out: bool, episodes: u64) -> Vec<String> {
    let cfg = EnvConfig {
        held_out,
        ..EnvConfig::default()
    };
    let vehicle = make_sim_car(CIRCUIT_ENV, &cfg).unwrap();
    let task = agvrl_envs::make_task(CIRCUIT_ENV, &cfg, vehicle.steering_limit_rad()).unwrap();
    let mut env = TaskEnv::new(vehicle, task).with_held_out(held_out);
    (0..episodes)
        .map(|k| {
            env.reset(Some(k)).unwrap();
            env.vehicle().sim().scene().file.name.clone()
        })
        .collect()
}

#[test]
fn held_out_circuits_are_never_trained_on_and_hold_the_hard_cases() {
    let eval = circuits(true, 100);
    let train = circuits(false, 300);
    let distinct: std::collections::HashSet<&String> = eval.iter().collect();
    assert_eq!(distinct.len(), 100, "every evaluation episode draws its own circuit");
    assert!(
        train.iter().all(|t| !distinct.contains(t)),
        "a training circuit is held out"
    );
    // The 100 held-out circuits evaluation draws: at least 30 % with a hairpin of <= 1.5 m
    // radius, 30 % at most 2 m wide.
    let infos: Vec<agvrl_sim::CircuitInfo> = eval
        .iter()
        .map(|n| {
            let seed: u64 = n.strip_prefix("circuit-").unwrap().parse().unwrap();
            assert!(agvrl_envs::heldout::is_held_out(seed), "{n}");
            agvrl_sim::MapTrack::generated(seed, &Default::default()).unwrap().1
        })
        .collect();
    let tight = infos.iter().filter(|i| i.min_radius_m <= 1.5).count();
    let narrow = infos.iter().filter(|i| i.width_m <= 2.0).count();
    assert!(tight >= 30 && narrow >= 30, "tight {tight}, narrow {narrow}");
}

/// A layout seed pins one circuit: every episode drives it.
#[test]
fn a_layout_seed_pins_one_circuit() {
    let cfg = EnvConfig {
        layout_seed: Some(7),
        ..EnvConfig::default()
    };
    let mut env = agvrl_envs::make_sim_car(CIRCUIT_ENV, &cfg).unwrap();
    let name = |v: &SimCar| v.sim().scene().file.name.clone();
    use agvrl_envs::Vehicle as _;
    env.reset(1).unwrap();
    let first = name(&env);
    env.reset(2).unwrap();
    assert_eq!(name(&env), first);
    assert_eq!(first, "circuit-7");
    // A map-file track on racing-circuit, and circuit settings elsewhere, are refused.
    let yaml = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/tracks/bean.yaml");
    let both = EnvConfig {
        track: Some(TrackSetting::Path(yaml)),
        ..EnvConfig::default()
    };
    assert!(
        make(CIRCUIT_ENV, &both)
            .err()
            .unwrap()
            .to_string()
            .contains("generated circuits")
    );
    let misplaced = EnvConfig {
        circuit: Some(Default::default()),
        ..EnvConfig::default()
    };
    assert!(
        make("racing-oval", &misplaced)
            .err()
            .unwrap()
            .to_string()
            .contains("circuit")
    );
}
