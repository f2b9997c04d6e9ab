//! The Env contract: check_env on every registered id, the env table, unknown ids, NaN and
//! out-of-range actions, observation presets, the sensors a task needs; the config file's simulator
//! keys and reverse lengths.

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

/// The past scans of a racing env are its own earlier ranges, pooled: the env hands every frame
/// to the task's history before the policy observes it.
#[test]
fn past_scans_repeat_the_ranges_seen_every_steps_before() {
    let cfg: EnvConfig = toml::from_str("[observation.past_scans]\nn = 2\nevery = 3\npool = 4\n").unwrap();
    let mut env = make("racing-oval", &cfg).unwrap();
    let n_rays = 100;
    assert_eq!(env.observation_space().dim(), n_rays + 4 + 2 * 25);
    let pooled = |obs: &[f32]| -> Vec<f32> {
        obs[..n_rays]
            .chunks(4)
            .map(|c| c.iter().cloned().fold(f32::MAX, f32::min))
            .collect()
    };
    let (first, _) = env.reset(Some(0)).unwrap();
    let mut seen = vec![first];
    for t in 1..=10usize {
        let obs = env.step(&[0.6, 0.3]).unwrap().obs;
        let back = |k: usize| pooled(&seen[t.saturating_sub(k)]);
        assert_eq!(obs[n_rays + 4..], [back(3), back(6)].concat(), "step {t}");
        seen.push(obs);
    }
    assert_ne!(pooled(&seen[0]), pooled(&seen[10]), "the car should have moved");
}
