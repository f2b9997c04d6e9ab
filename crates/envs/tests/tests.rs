//! agvrl-envs: the Env contract, episodes and rewards, vector envs and noise, camera frames,
//! image observations.

use agvrl_envs::api::{Control, MapInfo, SensorFrame, TerminationCause};
use agvrl_envs::pendulum::{Pendulum, angle_normalize};
use agvrl_envs::task::racing::RacingConfig;
use agvrl_envs::task::{Racing, Task};
use agvrl_envs::wrappers::TimeLimit;
use agvrl_envs::*;

fn quick_cfg() -> EnvConfig {
    EnvConfig::default()
}

mod env_contract {
    use super::*;

    #[test]
    fn check_env_passes_on_every_registered_id() {
        for id in ENV_IDS {
            for cfg in [EnvConfig::default(), EnvConfig::paper(), EnvConfig::sim2real()] {
                let name = format!("{id} {:?}", cfg.spawn);
                let mut env = make(id, &EnvConfig { max_steps: 60, ..cfg }).unwrap();
                check_env(env.as_mut(), 150).unwrap_or_else(|e| panic!("{name}: {e}"));
            }
        }
    }

    #[test]
    fn the_env_table_is_what_make_builds() {
        use agvrl_envs::registry::{scene_of, spec};
        use agvrl_envs::{ENVS, TaskKind, make_vehicle};
        assert_eq!(ENV_IDS, ENVS.iter().map(|s| s.id).collect::<Vec<_>>());
        for s in ENVS {
            assert_eq!(spec(s.id), Some(&s));
            assert_eq!(scene_of(s.id), s.scene);
            // A vehicle exactly where the table names a scene.
            assert_eq!(
                make_vehicle(s.id, &EnvConfig::default()).is_ok(),
                s.scene.is_some(),
                "{}",
                s.id
            );
            // Procedural layouts like the scene exactly where the table names a generator.
            let procedural = EnvConfig {
                layout_seed: Some(3),
                ..EnvConfig::default()
            };
            if s.procedural.is_some() {
                make_vehicle(s.id, &procedural).unwrap_or_else(|e| panic!("{}: {e}", s.id));
            }
            let (o, _) = make(s.id, &EnvConfig::default()).unwrap().reset(Some(0)).unwrap();
            match s.task {
                TaskKind::Pendulum => assert_eq!(o.len(), 3),
                TaskKind::Search | TaskKind::Racing => assert!(o.len() > 3 && s.scene.is_some(), "{}", s.id),
            }
        }
    }

    #[test]
    fn unknown_id_lists_the_valid_ids() {
        let e = make("racing-moon", &agvrl_envs::EnvConfig::default())
            .err()
            .unwrap()
            .to_string();
        assert!(
            e.contains("racing-moon") && e.contains("racing-oval") && e.contains("pendulum"),
            "{e}"
        );
    }

    #[test]
    fn nan_is_rejected_and_out_of_range_is_clamped() {
        let mut a = make("racing-oval", &agvrl_envs::EnvConfig::default()).unwrap();
        let mut b = make("racing-oval", &agvrl_envs::EnvConfig::default()).unwrap();
        a.reset(Some(3)).unwrap();
        b.reset(Some(3)).unwrap();
        assert!(a.step(&[f32::NAN, 0.0]).is_err());
        assert!(a.step(&[0.0]).is_err());
        for _ in 0..20 {
            let sa = a.step(&[5.0, -7.0]).unwrap();
            let sb = b.step(&[1.0, -1.0]).unwrap();
            assert_eq!(sa.obs, sb.obs);
        }
    }

    #[test]
    fn observation_presets_have_the_documented_shapes() {
        let mut env = make("search-outdoor-20", &EnvConfig::paper()).unwrap();
        let (obs, _) = env.reset(Some(1)).unwrap();
        assert_eq!(obs.len(), 100);
        assert!(obs.iter().any(|v| *v > 1.0), "paper preset keeps metres");
        let mut env = make("search-outdoor-20", &agvrl_envs::EnvConfig::default()).unwrap();
        let (obs, _) = env.reset(Some(1)).unwrap();
        assert_eq!(obs.len(), 104);
        assert!(obs[..100].iter().all(|v| (0.0..=1.0).contains(v)));
    }

    #[test]
    fn a_task_refuses_a_vehicle_without_the_sensors_it_needs() {
        struct Blind;
        impl Vehicle for Blind {
            fn reset(&mut self, _: u64) -> Result<SensorFrame, EnvError> {
                Ok(SensorFrame {
                    scan: Some(Default::default()),
                    ..SensorFrame::default()
                })
            }
            fn actuate(&mut self, _: Control) -> Result<(), EnvError> {
                Ok(())
            }
            fn sense(&mut self) -> Result<SensorFrame, EnvError> {
                self.reset(0)
            }
            fn control_period_s(&self) -> f64 {
                1.0 / 30.0
            }
            fn steering_limit_rad(&self) -> f64 {
                0.36
            }
        }
        let mut env = TaskEnv::new(Blind, Racing::new(RacingConfig::default(), 0.36));
        let e = env.reset(Some(0)).err().unwrap().to_string();
        assert!(e.contains("IMU"), "{e}");
    }
}

mod env_config_file {
    use super::*;

    /// The simulator's settings are embedded in `EnvConfig` and read at the top level of its
    /// TOML; every one of them reaches the simulator, and a misspelt key is an error.
    #[test]
    fn simulator_keys_sit_at_the_top_level_reach_the_simulator_and_typos_are_refused() {
        let text = "substeps = 6\nbrake_mps2 = 2.5\ncontrol_period_s = 0.025\nmax_steps = 7\n\
                    [lidar]\nn_rays = 50\n";
        let cfg: EnvConfig = toml::from_str(text).unwrap();
        assert_eq!((cfg.sim.substeps, cfg.sim.lidar.n_rays, cfg.max_steps), (6, 50, 7));
        let car = agvrl_envs::make_sim_car("racing-oval", &cfg).unwrap();
        assert_eq!(car.sim().config().settings, cfg.sim);
        assert_eq!(car.control_period_s(), 0.025);
        let back: EnvConfig = toml::from_str(&toml::to_string(&cfg).unwrap()).unwrap();
        assert_eq!(back, cfg);
        for bad in ["substepz = 6", "[lidar]\nn_rayz = 3", "dynamics = \"warp\""] {
            let e = toml::from_str::<EnvConfig>(bad).unwrap_err().to_string();
            let key = bad.trim_start_matches("[lidar]\n").split([' ', '=']).next().unwrap();
            assert!(e.contains(key) || e.contains("warp"), "{bad}: {e}");
        }
    }

    /// The reverse lengths widen a search env's observation by `n`, and a racing env refuses them.
    #[test]
    fn rear_lengths_widen_a_search_observation_and_a_racing_env_refuses_them() {
        let rear: EnvConfig = toml::from_str("[observation.rear]\nn = 3\n").unwrap();
        let dim = |cfg: &EnvConfig| make("search-outdoor-20", cfg).unwrap().observation_space().dim();
        assert_eq!(dim(&rear), dim(&EnvConfig::default()) + 3);
        // At a spawn the car has driven nowhere, so it may reverse nowhere.
        let (obs, _) = make("search-outdoor-20", &rear).unwrap().reset(Some(0)).unwrap();
        assert_eq!(obs[obs.len() - 3..], [0.0; 3]);
        let e = make("racing-oval", &rear).err().unwrap().to_string();
        assert!(e.contains("observation.rear is a search observation"), "{e}");
    }
}

mod episodes {
    use super::*;

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
}

/// Generated env counts, thread counts, reset splits and actions.
mod vec_env_properties {
    use super::*;
    use proptest::prelude::*;

    fn bits(v: &[f32]) -> Vec<u32> {
        v.iter().map(|x| x.to_bits()).collect()
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(24))]

        /// Any thread count, and the first reset split over several masked calls in any
        /// order, give the bits of one thread and one reset (auto-resets included).
        #[test]
        fn a_vec_env_gives_the_same_bits_for_any_thread_count_and_any_split_of_resets(
            n in 1usize..6,
            threads in 1usize..5,
            groups in prop::collection::vec(0usize..3, 5),
            max_steps in 3u64..12,
            seed in 0u64..1000,
            actions in prop::collection::vec(-1.0f32..=1.0, 2 * 5 * 24),
        ) {
            let cfg = EnvConfig { max_steps, ..quick_cfg() };
            let mk = || (0..n).map(|_| make("search-urban-20", &cfg).unwrap()).collect::<Vec<_>>();
            let mut one = VecEnv::new(mk(), 1).unwrap();
            let mut many = VecEnv::new(mk(), threads).unwrap();
            let (o1, _) = one.reset(Some(seed)).unwrap();
            let mut rows = vec![vec![]; n];
            for g in [2, 0, 1] {
                let mask: Vec<bool> = (0..n).map(|i| groups[i] == g).collect();
                if !mask.contains(&true) {
                    continue;
                }
                let seeds = (0..n as u64).map(|i| Some(seed + i)).collect();
                let (o, _) = many.reset_envs(seeds, Some(mask.clone())).unwrap();
                let dim = o.len() / n;
                for i in (0..n).filter(|&i| mask[i]) {
                    rows[i] = o[i * dim..(i + 1) * dim].to_vec();
                }
            }
            prop_assert_eq!(bits(&o1), bits(&rows.concat()));
            for t in 0..24 {
                let a = &actions[t * 10..t * 10 + 2 * n];
                let (s1, s2) = (one.step(a).unwrap(), many.step(a).unwrap());
                prop_assert_eq!(bits(&s1.obs), bits(&s2.obs), "step {}", t);
                prop_assert_eq!(
                    s1.rewards.iter().map(|r| r.to_bits()).collect::<Vec<_>>(),
                    s2.rewards.iter().map(|r| r.to_bits()).collect::<Vec<_>>()
                );
                prop_assert_eq!(&s1.terminated, &s2.terminated);
                prop_assert_eq!(&s1.truncated, &s2.truncated);
            }
        }
    }
}

mod vec_and_noise {
    use super::*;

    fn actions(n: usize, t: usize) -> Vec<f32> {
        (0..n * 2)
            .map(|k| (((t * 7 + k * 13) % 17) as f32 / 8.0) - 1.0)
            .collect()
    }

    #[test]
    fn vec_env_equals_serial_stepping_for_any_thread_count() {
        const N: usize = 5;
        let cfg = EnvConfig {
            max_steps: 40,
            ..quick_cfg()
        };
        let mk = || {
            (0..N)
                .map(|_| make("search-urban-20", &cfg).unwrap())
                .collect::<Vec<_>>()
        };
        let mut v1 = VecEnv::new(mk(), 1).unwrap();
        // 2 and 3 threads over 5 envs: uneven chunks, and threads take over each other's envs.
        let mut v2 = VecEnv::new(mk(), 2).unwrap();
        let mut v3 = VecEnv::new(mk(), 3).unwrap();
        let mut serial = mk();
        let (o1, _) = v1.reset(Some(10)).unwrap();
        let (o2, _) = v2.reset(Some(10)).unwrap();
        let (o3, _) = v3.reset(Some(10)).unwrap();
        let mut os: Vec<f32> = Vec::new();
        for (i, e) in serial.iter_mut().enumerate() {
            os.extend(e.reset(Some(10 + i as u64)).unwrap().0);
        }
        assert_eq!(o1, o2);
        assert_eq!(o1, o3);
        assert_eq!(o1, os);
        let mut saw_done = false;
        for t in 0..100 {
            let a = actions(N, t);
            let s1 = v1.step(&a).unwrap();
            let s2 = v2.step(&a).unwrap();
            let s3 = v3.step(&a).unwrap();
            assert_eq!(s1.obs, s2.obs);
            assert_eq!(s1.obs, s3.obs);
            assert_eq!(s1.rewards, s2.rewards);
            assert_eq!(s1.rewards, s3.rewards);
            assert_eq!(s1.terminated, s3.terminated);
            for (i, e) in serial.iter_mut().enumerate() {
                let st = e.step(&a[i * 2..i * 2 + 2]).unwrap();
                assert_eq!(st.reward, s1.rewards[i]);
                if st.done() {
                    saw_done = true;
                    assert_eq!(
                        s1.infos[i].final_obs.as_ref(),
                        Some(&st.obs),
                        "final_obs keeps the last observation"
                    );
                    assert!(s1.infos[i].episode.is_some());
                    let (o, _) = e.reset(None).unwrap();
                    assert_eq!(&s1.obs[i * 104..(i + 1) * 104], &o[..]);
                } else {
                    assert_eq!(&s1.obs[i * 104..(i + 1) * 104], &st.obs[..]);
                }
            }
        }
        assert!(saw_done, "the test must cross an auto-reset");
    }

    /// Single envs stepped in a loop the way Gymnasium's `NEXT_STEP` mode describes: an env
    /// whose episode ended resets on its next step instead of stepping.
    #[test]
    fn next_step_autoreset_equals_single_envs_reset_on_the_following_step() {
        const N: usize = 3;
        let cfg = EnvConfig {
            max_steps: 25,
            ..quick_cfg()
        };
        let mk = || {
            (0..N)
                .map(|_| make("search-urban-20", &cfg).unwrap())
                .collect::<Vec<_>>()
        };
        let mut v = VecEnv::with_autoreset(mk(), 2, Autoreset::NextStep).unwrap();
        let mut serial = mk();
        let (o, _) = v.reset(Some(5)).unwrap();
        let mut os = Vec::new();
        for (i, e) in serial.iter_mut().enumerate() {
            os.extend(e.reset(Some(5 + i as u64)).unwrap().0);
        }
        assert_eq!(o, os);
        let mut ended = [false; N];
        let (mut ends, mut resets) = (0, 0);
        for t in 0..80 {
            let a = actions(N, t);
            let s = v.step(&a).unwrap();
            for (i, e) in serial.iter_mut().enumerate() {
                let row = &s.obs[i * 104..(i + 1) * 104];
                if ended[i] {
                    resets += 1;
                    let (o, _) = e.reset(None).unwrap();
                    assert_eq!(row, &o[..]);
                    assert_eq!((s.rewards[i], s.terminated[i], s.truncated[i]), (0.0, false, false));
                    assert!(s.infos[i].episode.is_none());
                    ended[i] = false;
                } else {
                    let st = e.step(&a[i * 2..i * 2 + 2]).unwrap();
                    assert_eq!(row, &st.obs[..], "no reset within the ending step");
                    assert_eq!(
                        (s.rewards[i], s.terminated[i], s.truncated[i]),
                        (st.reward, st.terminated, st.truncated)
                    );
                    assert!(s.infos[i].final_obs.is_none());
                    ended[i] = st.done();
                    ends += usize::from(st.done());
                    assert_eq!(s.infos[i].episode.is_some(), st.done());
                }
            }
        }
        assert!(ends >= N && resets >= N, "ends {ends}, resets {resets}");
    }

    #[test]
    fn disabled_autoreset_refuses_an_ended_env_until_a_masked_reset() {
        let cfg = EnvConfig {
            max_steps: 5,
            ..quick_cfg()
        };
        let mk = || (0..2).map(|_| make("racing-oval", &cfg).unwrap()).collect::<Vec<_>>();
        let mut v = VecEnv::with_autoreset(mk(), 1, Autoreset::Disabled).unwrap();
        let mut solo = mk();
        let (o0, _) = v.reset(Some(1)).unwrap();
        let mut last = Vec::new();
        for t in 0..5 {
            let s = v.step(&actions(2, t)).unwrap();
            last = s.obs.clone();
            assert_eq!(s.truncated, [t == 4, t == 4]);
        }
        let e = v.step(&actions(2, 5)).unwrap_err();
        assert!(matches!(e.innermost(), EnvError::NeedsReset), "{e}");
        assert!(e.to_string().starts_with("env 0:"), "{e}");
        // Only env 1 resets, with its own seed; env 0 keeps its last observation.
        let (o, infos) = v.reset_envs(vec![None, Some(77)], Some(vec![false, true])).unwrap();
        assert_eq!(infos.len(), 2);
        assert_eq!(&o[..o.len() / 2], &last[..last.len() / 2]);
        assert_eq!(&o[o.len() / 2..], &solo[1].reset(Some(77)).unwrap().0[..]);
        assert_ne!(&o[o.len() / 2..], &o0[o0.len() / 2..]);
        assert!(v.step(&actions(2, 6)).is_err(), "env 0 still needs its reset");
        assert!(v.reset_envs(vec![None], None).is_err(), "one seed per env");
    }

    #[test]
    fn a_nan_action_in_any_row_steps_no_env() {
        let mk = || {
            (0..2)
                .map(|_| make("racing-oval", &quick_cfg()).unwrap())
                .collect::<Vec<_>>()
        };
        let mut v = VecEnv::new(mk(), 2).unwrap();
        let mut w = VecEnv::new(mk(), 2).unwrap();
        v.reset(Some(2)).unwrap();
        w.reset(Some(2)).unwrap();
        let e = v.step(&[0.5, 0.0, f32::NAN, 0.0]).unwrap_err();
        assert_eq!(e.to_string(), "env 1: action element 0 is not finite (NaN)");
        // Env 0 did not move: both vectors still agree after the same valid step.
        assert_eq!(v.step(&actions(2, 0)).unwrap().obs, w.step(&actions(2, 0)).unwrap().obs);
    }

    #[test]
    fn vec_env_of_tiny_envs_on_two_threads_equals_one_thread() {
        // Pendulum rounds are too short to hand over: the caller's thread steps them alone,
        // after a first round on both threads; results must not change either way.
        let mk = || {
            (0..8)
                .map(|_| make("pendulum", &EnvConfig::default()).unwrap())
                .collect::<Vec<_>>()
        };
        let mut v1 = VecEnv::new(mk(), 1).unwrap();
        let mut v2 = VecEnv::new(mk(), 2).unwrap();
        assert_eq!(v1.reset(Some(3)).unwrap().0, v2.reset(Some(3)).unwrap().0);
        let mut ended = 0;
        for t in 0..450 {
            // One torque per env.
            let a: Vec<f32> = actions(4, t).iter().map(|x| x * 2.0).collect();
            let (s1, s2) = (v1.step(&a).unwrap(), v2.step(&a).unwrap());
            assert_eq!(s1.obs, s2.obs);
            assert_eq!(s1.rewards, s2.rewards);
            assert_eq!(s1.truncated, s2.truncated);
            ended += s1.truncated.iter().filter(|&&x| x).count();
            for (i1, i2) in s1.infos.iter().zip(&s2.infos) {
                assert_eq!(i1.final_obs, i2.final_obs);
            }
        }
        assert_eq!(ended, 16, "two 200-step time limits per env");
    }

    #[test]
    fn noise_is_seeded_and_changes_observations() {
        let run = |cfg: &EnvConfig| {
            let mut env = make("search-outdoor-20", cfg).unwrap();
            let mut out = vec![env.reset(Some(4)).unwrap().0];
            for t in 0..30 {
                out.push(env.step(&actions(1, t)).unwrap().obs);
            }
            out
        };
        let clean = run(&EnvConfig::default());
        let noisy = run(&EnvConfig::sim2real());
        assert_eq!(noisy, run(&EnvConfig::sim2real()), "same seed, same noise");
        assert_ne!(clean, noisy);
    }

    #[test]
    fn latency_delays_commands_by_k_periods() {
        let base = EnvConfig {
            spawn: SpawnMode::Fixed,
            ..quick_cfg()
        };
        let late = EnvConfig {
            noise: wrappers::NoiseConfig {
                latency_steps: 3,
                ..Default::default()
            },
            ..base.clone()
        };
        let mut a = make("search-outdoor-20", &base).unwrap();
        let mut b = make("search-outdoor-20", &late).unwrap();
        a.reset(Some(0)).unwrap();
        b.reset(Some(0)).unwrap();
        // Without latency: three idle periods, then the commands. With 3 periods of latency:
        // the commands from the start. Both cars must drive the same trajectory.
        let cmd = |k: usize| [1.0f32, if k < 20 { 0.5 } else { -0.5 }];
        let mut moved = false;
        for t in 0..40 {
            let sa = a.step(&if t < 3 { [-1.0, 0.0] } else { cmd(t - 3) }).unwrap();
            let sb = b.step(&cmd(t)).unwrap();
            assert_eq!(sa.obs, sb.obs, "step {t}");
            moved |= sb.obs[100] > 0.1;
        }
        assert!(moved);
    }

    #[test]
    fn randomisation_draws_parameters_per_episode_from_the_seed() {
        let sim = || agvrl_sim::SimConfig {
            scene: agvrl_sim::SceneSource::Builtin("oval".into()),
            ..Default::default()
        };
        let mut v = SimVehicle::new(sim(), SpawnMode::Random, Randomisation::sim2real()).unwrap();
        v.reset(1).unwrap();
        let p1 = v.sim().params();
        v.reset(2).unwrap();
        let p2 = v.sim().params();
        v.reset(1).unwrap();
        assert_eq!(v.sim().params(), p1);
        assert_ne!(p1, p2);
        let nominal = v.sim().nominal_params();
        assert!((p1.drive.c_t / nominal.drive.c_t - 1.0).abs() <= 0.1);
        assert!(p1.steering_offset_rad.abs() <= 0.02);
    }

    #[test]
    fn time_limit_passes_termination_through() {
        let cfg = EnvConfig {
            spawn: SpawnMode::Fixed,
            ..quick_cfg()
        };
        let inner = {
            let sim = agvrl_sim::SimConfig {
                scene: agvrl_sim::SceneSource::Builtin("oval".into()),
                ..Default::default()
            };
            TaskEnv::new(
                SimVehicle::new(sim, cfg.spawn, cfg.randomisation).unwrap(),
                Racing::new(RacingConfig::default(), 0.36),
            )
        };
        let mut env = TimeLimit::new(inner, 100_000);
        env.reset(Some(0)).unwrap();
        let _ = env.inner().task().observation_space();
        loop {
            let st = env.step(&[1.0, 0.0]).unwrap();
            if st.done() {
                assert!(st.terminated && !st.truncated);
                break;
            }
        }
    }
}

mod camera_frames {
    use super::*;

    #[test]
    fn a_configured_camera_fills_the_sensor_frame() {
        let camera = Some(agvrl_sim::sensors::CameraConfig {
            width: 32,
            height: 24,
            ..Default::default()
        });
        let cfg = EnvConfig {
            sim: agvrl_sim::SimSettings {
                camera,
                ..Default::default()
            },
            spawn: SpawnMode::Fixed,
            ..EnvConfig::default()
        };
        let mut v = make_vehicle("racing-oval", &cfg).unwrap();
        let f = v.reset(0).unwrap();
        let img = f.image.expect("camera frame");
        assert_eq!(
            (img.width, img.height, img.rgb.len(), img.depth_m.len()),
            (32, 24, 32 * 24 * 3, 32 * 24)
        );
        let mut plain = make_vehicle("racing-oval", &EnvConfig::default()).unwrap();
        assert!(plain.reset(0).unwrap().image.is_none());
    }

    /// configs/racing-camera.toml's env settings.
    fn camera_only() -> EnvConfig {
        let run: toml::Table = toml::from_str(include_str!("../../../configs/racing-camera.toml")).unwrap();
        run["env_config"].clone().try_into().unwrap()
    }

    /// Without the LiDAR the observation is speed, yaw rate, steering, throttle and the depth
    /// image; under sim2real the depth gets noise growing with distance, holes and the minimum
    /// range, and a pixel without a reading reads 0.
    #[test]
    fn a_camera_only_observation_and_its_depth_noise() {
        let cfg = EnvConfig {
            spawn: SpawnMode::Fixed,
            ..camera_only()
        };
        let mut env = make("racing-oval", &cfg).unwrap();
        let (obs, _) = env.reset(Some(0)).unwrap();
        assert_eq!(obs.len(), 4 + 64 * 48);
        assert_eq!(env.observation_space().dim(), obs.len());
        let image = &obs[4..];
        assert!(image.iter().all(|v| (0.0..=1.0).contains(v)));
        let clean_frame = make_vehicle("racing-oval", &cfg).unwrap().reset(0).unwrap();
        let depth = clean_frame.image.unwrap().depth_m;
        assert!(depth.iter().all(|z| z.is_finite()));
        let noisy_cfg = EnvConfig {
            noise: EnvConfig::sim2real().noise,
            ..cfg.clone()
        };
        let frame = make_vehicle("racing-oval", &noisy_cfg).unwrap().reset(0).unwrap();
        let noisy = frame.image.unwrap().depth_m;
        let holes = noisy.iter().filter(|z| z.is_nan()).count();
        // The ground just in front of the car lies within the camera's 0.3 m minimum range.
        let pairs = || depth.iter().zip(&noisy);
        assert!(pairs().filter(|(z, _)| **z < 0.299).all(|(_, n)| n.is_nan()));
        // 2 % holes elsewhere.
        let beyond = pairs().filter(|(z, _)| **z > 0.4).count();
        let far_holes = pairs().filter(|(z, n)| **z > 0.4 && n.is_nan()).count();
        let expected = 0.02 * beyond as f64;
        assert!(
            (far_holes as f64 - expected).abs() < 4.0 * expected.sqrt() + 2.0,
            "{far_holes} holes among {beyond} pixels"
        );
        let err = |near: bool| {
            let d: Vec<f64> = depth
                .iter()
                .zip(&noisy)
                .filter(|(z, n)| !n.is_nan() && (**z < 2.0) == near && **z < 8.0)
                .map(|(z, n)| ((n - z) / (z * z)) as f64)
                .collect();
            (d.iter().map(|v| v * v).sum::<f64>() / d.len() as f64).sqrt()
        };
        // The error over z^2 has the same spread near and far: 0.0033 / m.
        for near in [true, false] {
            assert!((err(near) - 0.0033).abs() < 0.001, "near {near}: {}", err(near));
        }
        let mut noisy_env = make("racing-oval", &noisy_cfg).unwrap();
        let (obs, _) = noisy_env.reset(Some(0)).unwrap();
        let zeros = obs[4..].iter().filter(|v| **v == 0.0).count();
        let too_near = depth.iter().filter(|z| **z < 0.299).count();
        assert!(
            too_near > 0 && zeros > too_near && holes > too_near,
            "{zeros} {too_near} {holes}"
        );
        let rgb = EnvConfig {
            observation: agvrl_envs::task::ObsConfig {
                image: agvrl_envs::task::ImageObs {
                    channels: agvrl_envs::task::ImageChannels::Rgb,
                    ..cfg.observation.image
                },
                ..cfg.observation
            },
            ..cfg
        };
        let e = make("racing-oval", &rgb).err().unwrap().to_string();
        assert!(e.contains("depth_only"), "{e}");
        // Search subjects are found by segmentation, which a depth camera leaves out.
        let mut search = camera_only();
        search.sim.subjects = 3;
        let e = make("search-outdoor-20", &search).err().unwrap().to_string();
        assert!(e.contains("segmentation") && e.contains("depth_only"), "{e}");
        search.sim.subjects = 0;
        assert!(make("search-outdoor-20", &search).is_ok());
    }
}

mod subjects {
    use super::*;
    use agvrl_envs::task::Search;
    use agvrl_envs::task::search::SearchConfig;
    use agvrl_sim::PlanarPose;

    #[test]
    fn subjects_stand_by_trees_and_are_found_when_the_camera_sees_them() {
        let sim = agvrl_sim::SimConfig {
            scene: agvrl_sim::SceneSource::Builtin("outdoor-20".into()),
            settings: agvrl_sim::SimSettings {
                subjects: 3,
                subject_seed: 7,
                camera: Some(agvrl_sim::sensors::CameraConfig {
                    width: 80,
                    height: 60,
                    ..Default::default()
                }),
                ..Default::default()
            },
        };
        let vehicle = SimVehicle::new(sim.clone(), SpawnMode::Fixed, Randomisation::default()).unwrap();
        let subjects = vehicle.map().unwrap().subjects.clone();
        assert_eq!(subjects.len(), 3);
        let scene = vehicle.sim().scene();
        let target = &scene.objects[subjects[0] as usize];
        let p = target.shapes[0].pose.translation;
        // Every subject stands near a tree (outdoor scenes have no buildings).
        for id in &subjects {
            let s = scene.objects[*id as usize].shapes[0].pose.translation;
            let near_tree = scene
                .file
                .objects
                .iter()
                .any(|o| o.model == "tree" && ((o.x_m - s.x).powi(2) + (o.y_m - s.y).powi(2)).sqrt() < 1.7);
            assert!(near_tree, "subject at ({}, {})", s.x, s.y);
        }
        let mut env = TaskEnv::new(vehicle, Search::new(SearchConfig::default(), 0.36));
        env.reset(Some(0)).unwrap();
        // Stand 3 m from the first subject, looking at it.
        let yaw = 0.3f32;
        let pose = PlanarPose {
            x_m: p.x - 3.0 * yaw.cos(),
            y_m: p.y - 3.0 * yaw.sin(),
            yaw_rad: yaw,
        };
        env.vehicle_mut().sim_mut().reset(pose).unwrap();
        let st = env.step(&[-1.0, 0.0]).unwrap();
        let info = st.info.search.unwrap();
        assert_eq!(info.subjects_total, 3);
        assert!(info.subjects_found >= 1, "{info:?}");
        assert_eq!(info.find_times_s.len(), info.subjects_found);
        // The same view with a 2 m detection range: 3 m away is too far.
        let v2 = SimVehicle::new(sim, SpawnMode::Fixed, Randomisation::default()).unwrap();
        let near_only = SearchConfig {
            found_range_m: 2.0,
            ..SearchConfig::default()
        };
        let mut env = TaskEnv::new(v2, Search::new(near_only, 0.36));
        env.reset(Some(0)).unwrap();
        env.vehicle_mut().sim_mut().reset(pose).unwrap();
        let st = env.step(&[-1.0, 0.0]).unwrap();
        assert_eq!(st.info.search.unwrap().subjects_found, 0);
    }
}

mod image_observations {
    use super::*;
    use agvrl_envs::task::{ImageChannels, ImageObs, ObsConfig};

    fn cfg(channels: ImageChannels, camera: bool) -> EnvConfig {
        EnvConfig {
            sim: agvrl_sim::SimSettings {
                camera: camera.then(|| agvrl_sim::sensors::CameraConfig {
                    width: 64,
                    height: 48,
                    ..Default::default()
                }),
                ..Default::default()
            },
            observation: ObsConfig {
                image: ImageObs {
                    channels,
                    width: 16,
                    height: 12,
                    depth_max_m: 12.0,
                },
                ..ObsConfig::default()
            },
            max_steps: 40,
            ..EnvConfig::default()
        }
    }

    #[test]
    fn camera_channels_are_stacked_after_the_lidar_vector() {
        for (ch, n) in [
            (ImageChannels::Depth, 1),
            (ImageChannels::Rgb, 3),
            (ImageChannels::DepthRgb, 4),
        ] {
            let mut env = make("racing-oval", &cfg(ch, true)).unwrap();
            assert_eq!(env.observation_space().dim(), 104 + n * 16 * 12);
            check_env(env.as_mut(), 60).unwrap();
            let (obs, _) = env.reset(Some(1)).unwrap();
            let img = &obs[104..];
            assert!(img.iter().all(|v| (0.0..=1.0).contains(v)));
            assert!(
                img.iter().any(|v| *v > 0.0) && img.iter().any(|v| *v < 1.0),
                "{ch:?}: the image carries information"
            );
        }
        // Depth in the bottom row (the track just ahead) is nearer than in the middle row.
        let mut env = make("racing-oval", &cfg(ImageChannels::Depth, true)).unwrap();
        let (obs, _) = env.reset(Some(1)).unwrap();
        let img = &obs[104..];
        assert!(
            img[11 * 16 + 8] < img[6 * 16 + 8],
            "bottom {} middle {}",
            img[11 * 16 + 8],
            img[6 * 16 + 8]
        );
    }

    #[test]
    fn image_observations_without_a_camera_are_refused() {
        let mut env = make("racing-oval", &cfg(ImageChannels::Depth, false)).unwrap();
        let e = env.reset(Some(0)).err().unwrap().to_string();
        assert!(e.contains("camera"), "{e}");
    }
}

mod safety_filter {
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
}

mod explored_observation {
    use super::*;
    use agvrl_envs::task::{ExploredObs, ObsConfig};

    fn cfg() -> EnvConfig {
        EnvConfig {
            observation: ObsConfig {
                explored: ExploredObs {
                    sectors: 8,
                    ..ExploredObs::default()
                },
                ..ObsConfig::default()
            },
            max_steps: 200,
            ..EnvConfig::default()
        }
    }

    #[test]
    fn driving_ahead_leaves_new_ground_ahead_and_explored_ground_behind() {
        let mut env = make("search-outdoor-20", &cfg()).unwrap();
        assert_eq!(env.observation_space().dim(), 104 + 16);
        check_env(env.as_mut(), 60).unwrap();
        let (obs, _) = env.reset(Some(3)).unwrap();
        let ex = &obs[104..];
        assert!(ex.iter().all(|v| (0.0..=1.0).contains(v)), "{ex:?}");
        assert!(
            ex[8..].iter().all(|v| *v == 1.0),
            "nothing beyond 4 m explored yet: {ex:?}"
        );
        let mut last = obs;
        let mut moved = 0.0;
        for _ in 0..60 {
            let s = env.step(&[1.0, 0.0]).unwrap();
            assert!(!s.terminated, "the spawn has room to drive straight");
            moved = s.info.search.as_ref().unwrap().distance_m;
            last = s.obs;
        }
        assert!(moved > 1.0, "moved {moved} m");
        let ex = &last[104..];
        // Sector 0 is straight ahead, sector 4 behind (ring 2-4 m).
        assert!(ex[4] + 0.3 < ex[0], "behind {} ahead {}: {ex:?}", ex[4], ex[0]);
    }

    #[test]
    fn racing_refuses_it_and_bad_rings_are_an_error() {
        let err = make("racing-oval", &cfg()).err().expect("a search observation");
        assert!(err.to_string().contains("observation.explored"), "{err}");
        let mut bad = cfg();
        bad.observation.explored.radii_m = [2.0, 2.0, 8.0];
        let err = make("search-urban-20", &bad).err().expect("empty ring");
        assert!(err.to_string().contains("radii_m"), "{err}");
    }
}

mod racing_against_others {
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
        let p = env.sim().pose2_of(i);
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
                        crashed_at = Some((k, env.sim().base_pose_of(0)));
                    }
                }
                Some((_, pose)) => {
                    assert!(st.agents[0].is_none(), "a crashed car drops out");
                    assert_eq!(env.sim().base_pose_of(0), pose, "and stays put");
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
            let p = env.sim().pose2_of(i);
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
                let p = env.sim().pose2_of(i);
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
                CarInput::Control(by_action.sim().control_of(0)),
                CarInput::Action(&actions[1]),
            ];
            let c = by_control.step_inputs(&inputs).unwrap();
            assert_eq!(a, c, "step {k}");
            if k == 0 {
                assert!(by_action.sim().control_of(0).throttle > 0.0);
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
}

/// The racing rules: one setting for the end limit, the track's defaults, the progress reward,
/// the stall and time limits.
mod racing_rules {
    use super::*;
    use agvrl_envs::sim_vehicle::{Randomisation, SimVehicle, SpawnMode};
    use agvrl_envs::task::{RacingReward, RacingRules, RacingRulesSetting};
    use agvrl_envs::{Vehicle, registry};

    /// How far the car reaches to its left of the base, metres: its body and its wheels (balls
    /// of the wheel's radius on the ground).
    fn left_reach_m(model: &agvrl_sim::vehicle::VehicleModel) -> f32 {
        let body = model
            .body_shapes
            .iter()
            .map(|s| s.shape.compute_aabb(&s.pose).maxs.y)
            .fold(f32::NEG_INFINITY, f32::max);
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
}

/// racing-circuit: a new generated circuit every episode, training and evaluation circuits
/// drawn from disjoint halves of the seed space.
mod generated_circuits {
    use super::*;
    use agvrl_envs::registry::CIRCUIT_ENV;

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
}
