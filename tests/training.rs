//! Training from the command line: fine-tuning with `init_from` (from a run, or from a config
//! trained first), SAC's gradient steps with the default eight envs, SAC learning the pendulum with
//! the defaults.

use crate::{agvrl, json_lines, key, stderr, stdout, tmp};
use std::path::{Path, PathBuf};
use std::process::Command;

/// The flags of a PPO run of 128 steps on one env, a 16-unit network, into `out`.
fn tiny_run(out: &Path) -> Vec<&str> {
    let mut args = vec!["--steps", "128", "--n-envs", "1", "--out", out.to_str().unwrap()];
    for s in ["ppo.n_steps=64", "ppo.batch_size=64", "ppo.net_arch=[16]"] {
        args.extend(["--set", s]);
    }
    args
}

#[test]
fn init_from_fine_tunes_a_run_with_added_observation_parts_and_refuses_lost_ones() {
    let d = tmp("init-from");
    let (base, tuned) = (d.path().join("base"), d.path().join("tuned"));
    let train = |out: &Path, sets: &[&str]| {
        let mut args = vec!["train", "--env", "search-outdoor-20", "--algo", "ppo"];
        args.extend(tiny_run(out));
        for s in ["eval_episodes=1", "eval_max_steps=20"].iter().chain(sets) {
            args.extend(["--set", s]);
        }
        agvrl(&args)
    };
    let o = train(&base, &["env_config.observation.arcs.n=3"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let from = format!("init_from=\"{}\"", base.display());
    let o = train(
        &tuned,
        &[
            "env_config.observation.arcs.n=3",
            "env_config.observation.rear.n=3",
            &from,
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("3 observation inputs added"), "{}", stderr(&o));
    // A run whose network read inputs this one lacks cannot start from it.
    let o = train(&d.path().join("lost"), &[&from]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("arcs is gone"), "{}", stderr(&o));
    assert!(!d.path().join("lost").exists() && !d.path().join("lost.partial").exists());
}

/// A config whose `init_from` names another config trains that one first and fine-tunes
/// from it in one command, to the bits of the two commands by hand (same CPU); run again,
/// it keeps the finished first stage, and refuses one of another config.
#[test]
fn init_from_a_config_trains_it_first_then_fine_tunes_as_two_commands_do() {
    let d = tmp("init-config");
    let first = "env = \"search-outdoor-20\"\nalgo = \"ppo\"\nsteps = 128\nn_envs = 1\n\
                 eval_episodes = 1\neval_max_steps = 20\n\
                 [ppo]\nn_steps = 64\nbatch_size = 64\nnet_arch = [16]\n";
    let tune = "init_from = \"first.toml\"\nsteps = 64\n\
                [ppo]\nlearning_rate = 1e-4\n[env_config.observation.rear]\nn = 3\n";
    let run = |cwd: &Path, args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_agvrl"))
            .current_dir(cwd)
            .args(["train", "--seed", "5", "--progress", "none"])
            .args(args)
            .output()
            .expect("run agvrl")
    };
    let (one, two) = (d.path().join("one"), d.path().join("two"));
    for dir in [&one, &two] {
        std::fs::create_dir(dir).unwrap();
        std::fs::write(dir.join("first.toml"), first).unwrap();
        std::fs::write(dir.join("tune.toml"), tune).unwrap();
    }
    let o = run(&one, &["--config", "tune.toml", "--out", "tuned"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("3 observation inputs added"), "{}", stderr(&o));
    let o = run(&two, &["--config", "first.toml", "--out", "tuned-init"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = run(
        &two,
        &[
            "--config",
            "tune.toml",
            "--out",
            "tuned",
            "--set",
            "init_from=\"tuned-init\"",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let read = |p: PathBuf| std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    let policy = |dir: &Path| read(dir.join("tuned/policy.agvrl"));
    assert!(policy(&one) == policy(&two), "one command and two give other policies");
    let cfg = String::from_utf8(read(one.join("tuned/config.toml"))).unwrap();
    assert!(cfg.contains("init_from = \"tuned-init\""), "{cfg}");
    assert!(cfg.contains("env = \"search-outdoor-20\""), "{cfg}");
    let first_cfg = String::from_utf8(read(one.join("tuned-init/config.toml"))).unwrap();
    assert!(
        first_cfg.contains("seed = 5") && first_cfg.contains("steps = 128"),
        "{first_cfg}"
    );
    // Run again: the first stage is kept, and the fine-tuning is the same.
    std::fs::remove_dir_all(one.join("tuned")).unwrap();
    let o = run(&one, &["--config", "tune.toml", "--out", "tuned"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("trained"), "{}", stderr(&o));
    assert!(policy(&one) == policy(&two));
    // A first stage of another config is not taken for this one's.
    std::fs::remove_dir_all(one.join("tuned")).unwrap();
    std::fs::write(one.join("first.toml"), first.replace("steps = 128", "steps = 256")).unwrap();
    let o = run(&one, &["--config", "tune.toml", "--out", "tuned"]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("is not a finished training of first.toml"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn sac_takes_one_gradient_step_per_env_step_with_the_default_eight_envs() {
    // With one gradient step per vector step, 8 envs would get 1/8 of SB3's updates per env
    // step, and SAC learns far less per env step.
    let d = tmp("sac-ratio");
    let o = agvrl(&[
        "train",
        "--env",
        "pendulum",
        "--algo",
        "sac",
        "--steps",
        "400",
        "--seed",
        "0",
        "--progress",
        "json",
        "--set",
        "sac.net_arch=[16]",
        "--set",
        "sac.batch_size=32",
        "--set",
        "eval_episodes=1",
        "--out",
        d.path().join("run").to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let last = json_lines(&stdout(&o))
        .into_iter()
        .rfind(|v| v["event"] == "progress")
        .expect("progress lines");
    // Learning starts after 100 env steps: 38 vector steps of 8 envs train, 8 steps each.
    assert_eq!(last["steps"], 400);
    assert_eq!(last["updates"], 304, "{last}");
}

#[test]
fn sac_with_the_cli_defaults_learns_pendulum_in_six_thousand_steps() {
    // The default 8 envs with SB3's update-to-data ratio: a small SAC swings the pendulum up
    // within 6,000 env steps (-140 to -250 over seeds 0-2 on 10 held-out episodes; the
    // random policy scores about -1,200 there). With one gradient step per vector step (1/8 of
    // the updates) seed 0 scores -1,600.
    let d = tmp("sac-learns");
    let run = d.path().join("run");
    let o = agvrl(&[
        "train",
        "--env",
        "pendulum",
        "--algo",
        "sac",
        "--steps",
        "6000",
        "--seed",
        "0",
        "--set",
        "sac.net_arch=[64,64]",
        "--out",
        run.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let score = |random: bool| -> f64 {
        let mut args = vec!["eval", "--run", run.to_str().unwrap(), "--episodes", "10"];
        if random {
            args.push("--random");
        }
        let o = agvrl(&args);
        assert!(o.status.success(), "{}", stderr(&o));
        key(&stdout(&o), "mean_return").parse().unwrap()
    };
    let (trained, random) = (score(false), score(true));
    assert!(
        trained > -500.0 && random < -900.0,
        "trained {trained}, random {random}"
    );
}

#[test]
fn net_path_burn_trains_either_learner_through_burn_and_the_cpu_default_is_the_host() {
    let d = tmp("net-path");
    for algo in ["ppo", "sac"] {
        for path in [None, Some("burn"), Some("host")] {
            let out = d.path().join(format!("{algo}-{path:?}"));
            let mut args = vec![
                "train",
                "--env",
                "pendulum",
                "--algo",
                algo,
                "--steps",
                "256",
                "--n-envs",
                "2",
                "--set",
                "eval_episodes=1",
                "--set",
                "sac.learning_starts=200",
                "--set",
                "sac.batch_size=32",
                "--set",
                "ppo.n_steps=64",
                "--out",
                out.to_str().unwrap(),
            ];
            if let Some(p) = path {
                args.extend(["--net-path", p]);
            }
            let o = agvrl(&args);
            assert!(o.status.success(), "{algo} {path:?}: {}", stderr(&o));
            let want = format!("networks: {} path on flex", path.unwrap_or("host"));
            assert!(stderr(&o).contains(&want), "{algo} {path:?}: {}", stderr(&o));
            assert!(out.join("policy.agvrl").is_file());
        }
    }
}

/// `agvrl train --track` without `--config` trains the per-track recipe (gSDE, `attempts`): runs
/// that fail their validation episodes (here 30 steps: none can lap) are trained again at the
/// next seed, the first of equals is kept in the run directory and the others stay in its
/// `attempts/`, every one listed in `attempts.csv`.
#[test]
fn attempts_train_the_next_seed_and_keep_the_run_that_lapped_most() {
    let d = tmp("attempts");
    let out = d.path().join("run");
    let mut args = vec!["train", "--track", "assets/tracks/bean.yaml", "--seed", "5"];
    args.extend(tiny_run(&out));
    for s in ["attempts=2", "eval_episodes=1", "eval_max_steps=30"] {
        args.extend(["--set", s]);
    }
    let o = agvrl(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = stdout(&o);
    assert_eq!(key(&text, "attempts"), "2 kept_seed=5 validation_lapped=0/1", "{text}");
    let cfg = std::fs::read_to_string(out.join("config.toml")).unwrap();
    for line in ["seed = 5", "attempts = 2", "use_sde = true"] {
        assert!(cfg.lines().any(|l| l == line), "{line} missing in the kept config");
    }
    for f in [
        "policy.agvrl",
        "checkpoint.ckpt",
        "eval.json",
        "attempts/seed-6/policy.agvrl",
    ] {
        assert!(out.join(f).is_file(), "missing {f}");
    }
    assert!(!out.join("attempts/seed-5").exists());
    let other = std::fs::read_to_string(out.join("attempts/seed-6/config.toml")).unwrap();
    assert!(other.lines().any(|l| l == "seed = 6"));
    let csv = std::fs::read_to_string(out.join("attempts.csv")).unwrap();
    let rows: Vec<Vec<&str>> = csv.lines().skip(1).map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 2, "{csv}");
    assert_eq!((rows[0][1], rows[0][3], rows[0][6]), ("5", "0", "true"), "{csv}");
    assert_eq!((rows[1][1], rows[1][3], rows[1][6]), ("6", "0", "false"), "{csv}");
}
