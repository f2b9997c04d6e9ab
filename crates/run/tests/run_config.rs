//! The run TOML: round trips, --set, and errors that name their file.

use agvrl_rl::Algorithm;
use agvrl_run::RunConfig;

/// The run TOML (shared by `agvrl train` and agvrl-drive) round-trips, takes `--set` overrides
/// on dotted keys, and its errors start with the file they come from.
#[test]
fn a_run_config_round_trips_and_its_errors_name_the_file() {
    let text = "env = \"search-urban-20\"\nalgo = \"sac\"\n[env_config]\nsubsteps = 5\n";
    let c = RunConfig::from_toml(text, "x.toml").unwrap();
    assert_eq!((c.algo, c.env_config.sim.substeps), (Algorithm::Sac, 5));
    assert_eq!(RunConfig::from_toml(&c.to_toml().unwrap(), "back").unwrap(), c);
    let c = RunConfig::from_toml_with(text, "x.toml", &["env_config.lidar.n_rays=40".into()]).unwrap();
    assert_eq!(c.env_config.sim.lidar.n_rays, 40);
    let e = RunConfig::from_toml("env = \"search-mars\"", "x.toml")
        .unwrap_err()
        .to_string();
    assert!(e.starts_with("x.toml: unknown env id 'search-mars'"), "{e}");
    let e = RunConfig::from_toml("[env_config]\nheld_out = true", "y.toml")
        .unwrap_err()
        .to_string();
    assert!(e.starts_with("y.toml: env_config.held_out"), "{e}");
}

/// `env_config.track` given as a map YAML's path is loaded when the config is read: the TOML
/// it writes carries the walls and centre line, reads back to the same track without the
/// files, and makes the same env. A path to no file, or a track with procedural layouts or on
/// a search env, is refused with the key named.
#[test]
fn a_track_path_is_loaded_into_the_config_and_travels_without_the_files() {
    let dir = tempfile::Builder::new().prefix("agvrl-run-track-").tempdir().unwrap();
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/tracks");
    for f in ["bean.yaml", "bean.pgm", "bean.csv"] {
        std::fs::copy(root.join(f), dir.path().join(f)).unwrap();
    }
    let yaml = dir.path().join("bean.yaml");
    let set = agvrl_run::track_set(&yaml);
    let c = RunConfig::from_toml_with("env = \"racing-oval\"\n", "x.toml", std::slice::from_ref(&set)).unwrap();
    let Some(agvrl_envs::TrackSetting::Loaded(t)) = &c.env_config.track else {
        panic!("loaded: {:?}", c.env_config.track);
    };
    assert_eq!((t.name.as_str(), t.centreline_source.as_str()), ("bean", "csv"));
    let text = c.to_toml().unwrap();
    drop(dir);
    assert!(!yaml.exists());
    let back = RunConfig::from_toml(&text, "back").unwrap();
    assert_eq!(back, c);
    let mut env = agvrl_envs::make("racing-oval", &back.env_config).unwrap();
    env.reset(Some(3)).unwrap();
    let e = RunConfig::from_toml_with("env = \"racing-oval\"\n", "x.toml", std::slice::from_ref(&set))
        .unwrap_err()
        .to_string();
    assert!(e.contains("env_config.track") && e.contains("bean.yaml"), "{e}");
    let e = RunConfig::from_toml(
        &text.replace("procedural_layouts = 0", "procedural_layouts = 2"),
        "z.toml",
    )
    .unwrap_err()
    .to_string();
    assert!(e.starts_with("z.toml: procedural_layouts"), "{e}");
    let search = text.replace("env = \"racing-oval\"", "env = \"search-urban-20\"");
    let cfg = RunConfig::from_toml(&search, "s.toml").unwrap();
    let e = agvrl_envs::make("search-urban-20", &cfg.env_config)
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("track is a racing setting"), "{e}");
}

/// Per-env training keys reach only the envs they name, and never evaluation: the recovery
/// spawns, the advising filter and the sim2real noise; an index past `n_envs` is refused by key.
#[test]
fn per_env_training_keys_reach_their_envs_and_never_evaluation() {
    use agvrl_envs::SpawnMode;
    let text = "env = \"search-urban-20\"\nn_envs = 4\nadvisory_filter_envs = [1]\nrecovery_spawn_envs = [0, 2]\n\
                sim2real_envs = [3]\n\
                [env_config]\nbrake_mps2 = 3.0\n[env_config.safety_filter]\nenabled = true\n";
    let c = RunConfig::from_toml(text, "x.toml").unwrap();
    let spawns: Vec<SpawnMode> = (0..4).map(|i| c.train_env_config(i).spawn).collect();
    assert_eq!(
        spawns,
        [
            SpawnMode::NearObstacle,
            SpawnMode::Random,
            SpawnMode::NearObstacle,
            SpawnMode::Random
        ]
    );
    let advising: Vec<bool> = (0..4).map(|i| c.train_env_config(i).safety_filter.advisory).collect();
    assert_eq!(advising, [false, true, false, false]);
    let s2r = agvrl_envs::EnvConfig::sim2real();
    let noisy: Vec<bool> = (0..4)
        .map(|i| {
            let e = c.train_env_config(i);
            assert_eq!(e.noise == s2r.noise, e.randomisation == s2r.randomisation);
            e.noise == s2r.noise
        })
        .collect();
    assert_eq!(noisy, [false, false, false, true]);
    assert_ne!(c.eval_env_config().noise, s2r.noise);
    assert_eq!(c.eval_env_config().spawn, SpawnMode::Random);
    assert!(!c.eval_env_config().safety_filter.advisory);
    assert_eq!(RunConfig::from_toml(&c.to_toml().unwrap(), "back").unwrap(), c);
    // Left out of the written config when unused, so earlier policy files keep their bytes.
    let plain = RunConfig::from_toml("env = \"search-urban-20\"\n", "p.toml").unwrap();
    assert!(!plain.to_toml().unwrap().contains("recovery_spawn_envs"));
    assert!(!plain.to_toml().unwrap().contains("sim2real_envs"));
    let e = RunConfig::from_toml(&text.replace("sim2real_envs = [3]", "sim2real_envs = [9]"), "s.toml")
        .unwrap_err()
        .to_string();
    assert!(e.starts_with("s.toml: sim2real_envs: env 9 does not exist"), "{e}");
    let e = RunConfig::from_toml(&text.replace("[0, 2]", "[4]"), "y.toml")
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("y.toml: recovery_spawn_envs: env 4 does not exist"),
        "{e}"
    );
}

/// `train_safety_filter` is the filter of every training env (advising where
/// `advisory_filter_envs` says) and never of evaluation, which drives behind
/// `env_config.safety_filter`; it survives the written config, and bad values are refused by key.
#[test]
fn train_safety_filter_shields_training_envs_and_never_evaluation() {
    let text = "env = \"search-urban-20\"\nn_envs = 2\nadvisory_filter_envs = [1]\n\
                [env_config]\nbrake_mps2 = 3.0\n\
                [env_config.safety_filter]\nenabled = true\nclearance_m = 0.7\nlookahead_m = 0.0\n\
                [train_safety_filter]\nenabled = true\nclearance_m = 0.85\n";
    let c = RunConfig::from_toml(text, "x.toml").unwrap();
    let train: Vec<_> = (0..2).map(|i| c.train_env_config(i).safety_filter).collect();
    assert_eq!((train[0].clearance_m, train[0].lookahead_m), (0.85, 0.25));
    assert!(!train[0].advisory && train[1].advisory);
    assert_eq!(train[1].clearance_m, 0.85);
    let eval = c.eval_env_config().safety_filter;
    assert_eq!((eval.clearance_m, eval.lookahead_m, eval.advisory), (0.7, 0.0, false));
    assert_eq!(c.drive_env_config().safety_filter.clearance_m, 0.7);
    assert_eq!(RunConfig::from_toml(&c.to_toml().unwrap(), "back").unwrap(), c);
    // Without it the training envs drive behind env_config's filter, and the key is not written.
    let plain = RunConfig::from_toml(
        &text.replace("[train_safety_filter]\nenabled = true\nclearance_m = 0.85\n", ""),
        "p.toml",
    )
    .unwrap();
    assert_eq!(plain.train_env_config(0).safety_filter.clearance_m, 0.7);
    assert!(!plain.to_toml().unwrap().contains("train_safety_filter"));
    let e = RunConfig::from_toml(&text.replace("clearance_m = 0.85", "clearance_m = -1.0"), "y.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("train_safety_filter") && e.contains("clearance_m"), "{e}");
    // The advising envs need a filter in training, wherever it is set.
    let off = text.replace(
        "[train_safety_filter]\nenabled = true",
        "[train_safety_filter]\nenabled = false",
    );
    let e = RunConfig::from_toml(&off, "z.toml").unwrap_err().to_string();
    assert!(e.contains("advisory_filter_envs"), "{e}");
}

/// `init_from` naming a run config: this config's keys go over that file's (tables key by
/// key), `--set` over both; the file is the first stage, and one that has a first stage of
/// its own, or is missing, is refused by name.
#[test]
fn a_config_starting_from_another_takes_its_keys_under_its_own() {
    let dir = tempfile::Builder::new().prefix("agvrl-run-stages-").tempdir().unwrap();
    let first = dir.path().join("first.toml");
    std::fs::write(
        &first,
        "env = \"search-urban-20\"\nsteps = 500\nn_envs = 4\n[ppo]\nn_steps = 64\nlearning_rate = 3e-4\n",
    )
    .unwrap();
    let tune = format!(
        "init_from = \"{}\"\nsteps = 100\n[ppo]\nlearning_rate = 1e-4\n",
        first.display()
    );
    let c = RunConfig::from_toml(&tune, "tune.toml").unwrap();
    assert_eq!((c.env.as_str(), c.steps, c.n_envs), ("search-urban-20", 100, 4));
    assert_eq!((c.ppo.n_steps, c.ppo.learning_rate), (64, 1e-4));
    assert_eq!(c.init_config(), Some(first.as_path()));
    let c = RunConfig::from_toml_with(&tune, "tune.toml", &["n_envs=2".into()]).unwrap();
    assert_eq!((c.n_envs, c.ppo.n_steps), (2, 64));
    // A run directory is not a first stage, and brings no keys.
    let c = RunConfig::from_toml("init_from = \"runs/x\"\n", "d.toml").unwrap();
    assert_eq!((c.init_config(), c.env.as_str()), (None, "racing-oval"));
    let second = dir.path().join("second.toml");
    std::fs::write(&second, &tune).unwrap();
    let e = RunConfig::from_toml(&format!("init_from = \"{}\"\n", second.display()), "third.toml")
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("third.toml: init_from = ") && e.contains("at most two stages"),
        "{e}"
    );
    let e = RunConfig::from_toml("init_from = \"nowhere.toml\"\n", "x.toml")
        .unwrap_err()
        .to_string();
    assert!(e.starts_with("x.toml: init_from = nowhere.toml: "), "{e}");
}

/// A race's `opponents` round-trip and are checked when the config is read: a racer that does
/// not parse, or opponents on an env that drives alone, are refused by key.
#[test]
fn opponents_are_a_races_and_each_must_parse() {
    let text = "env = \"racing-duel\"\nopponents = [\"self\", \"pure-pursuit@0.75\", \"follow-the-gap\"]\n";
    let c = RunConfig::from_toml(text, "o.toml").unwrap();
    assert_eq!(c.opponents.len(), 3);
    assert_eq!(RunConfig::from_toml(&c.to_toml().unwrap(), "back").unwrap(), c);
    for (bad, says) in [
        ("[\"pure-pursuit@1.5\"]", "speed scale must be in (0, 1]"),
        ("[\"stanley\"]", "the kind is pure-pursuit or follow-the-gap"),
        ("[\"follow-the-gap@x\"]", "the scale after @ is not a number"),
    ] {
        let e = RunConfig::from_toml(&format!("env = \"racing-duel\"\nopponents = {bad}\n"), "o.toml")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("o.toml: opponents: ") && e.contains(says), "{e}");
    }
    let e = RunConfig::from_toml("env = \"racing-oval\"\nopponents = [\"self\"]\n", "o.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("opponents are a race's"), "{e}");
    // Without opponents the TOML has no such key: self-play run files stay as they were.
    let c = RunConfig::from_toml("env = \"racing-duel\"\n", "d.toml").unwrap();
    assert!(!c.to_toml().unwrap().contains("opponents"));
}

/// `--track` over settings of generated circuits (the generalist's, the passing policy's) races
/// on that map: the circuits give way, and `racing-circuit` becomes `racing-oval`; a race keeps
/// its env. Without the track the settings are as written.
#[test]
fn a_track_set_over_generated_circuits_races_on_the_map() {
    let bean = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/tracks/bean.yaml");
    let set = [agvrl_run::track_set(&bean)];
    for (env, eval_env) in [("racing-circuit", "racing-oval"), ("racing-duel", "racing-oval")] {
        let text = format!("env = \"{env}\"\n[env_config]\nlayout_seed = 4\ncircuit = {{ width_m = [2.5, 3.0] }}\n");
        let c = RunConfig::from_toml_with(&text, "x.toml", &set).unwrap();
        assert_eq!(c.env, if env == "racing-circuit" { "racing-oval" } else { env });
        assert_eq!(c.eval_env_id(), eval_env);
        assert!(c.env_config.circuit.is_none() && c.env_config.layout_seed.is_none());
        assert!(c.env_config.track.is_some());
        let plain = RunConfig::from_toml(&text, "x.toml").unwrap();
        assert_eq!((plain.env.as_str(), plain.env_config.layout_seed), (env, Some(4)));
        assert!(plain.env_config.circuit.is_some());
    }
}

/// `attempts` retries seeds for a single car on a map track or generated circuits only,
/// validated on at least one episode; the key is absent from a config that trains once, so
/// those files stay as they were.
#[test]
fn attempts_retry_seeds_only_for_one_car_on_a_map_track_or_circuits() {
    let bean = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/tracks/bean.yaml");
    let on_bean = [agvrl_run::track_set(&bean)];
    let c = RunConfig::from_toml_with("attempts = 4\n", "a.toml", &on_bean).unwrap();
    assert_eq!(c.attempts, 4);
    assert!(c.to_toml().unwrap().contains("attempts = 4"));
    let circuits = RunConfig::from_toml("env = \"racing-circuit\"\nattempts = 2\n", "a.toml").unwrap();
    assert_eq!(circuits.attempts, 2);
    assert_eq!(circuits.attempts_lapped_share, 1.0);
    assert!(!circuits.to_toml().unwrap().contains("attempts_lapped_share"));
    let once = RunConfig::from_toml("env = \"racing-oval\"\n", "a.toml").unwrap();
    assert_eq!(once.attempts, 1);
    assert!(!once.to_toml().unwrap().contains("attempts"));
    for (text, sets, says) in [
        ("attempts = 0\n", &on_bean[..], "attempts must be at least 1"),
        (
            "attempts_lapped_share = 0.0\n",
            &on_bean[..],
            "attempts_lapped_share must be in (0, 1]",
        ),
        ("attempts = 3\n", &[][..], "needs a single car on a map track"),
        (
            "env = \"search-outdoor-20\"\nattempts = 3\n",
            &[][..],
            "or on generated circuits",
        ),
        ("attempts = 3\neval_episodes = 0\n", &on_bean[..], "eval_episodes >= 1"),
        (
            "env = \"racing-duel\"\nattempts = 3\n",
            &on_bean[..],
            "needs a single car",
        ),
    ] {
        let e = RunConfig::from_toml_with(text, "a.toml", sets).unwrap_err().to_string();
        assert!(e.contains(says), "{text}: {e}");
    }
    let dir = tempfile::Builder::new()
        .prefix("agvrl-run-attempts-")
        .tempdir()
        .unwrap();
    let first = dir.path().join("first.toml");
    std::fs::write(&first, "env = \"racing-oval\"\n").unwrap();
    let text = format!("attempts = 3\ninit_from = \"{}\"\n", first.display());
    let e = RunConfig::from_toml_with(&text, "a.toml", &on_bean)
        .unwrap_err()
        .to_string();
    assert!(e.contains("a two-stage training"), "{e}");
}
