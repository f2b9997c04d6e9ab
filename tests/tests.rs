//! End-to-end tests of the `agvrl` binary.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn agvrl(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_agvrl"))
        .args(args)
        .output()
        .expect("run agvrl")
}

/// A test's scratch directory, removed when the test ends, whether it passed or not.
fn tmp(name: &str) -> tempfile::TempDir {
    tempfile::Builder::new()
        .prefix(&format!("agvrl-e2e-{name}-"))
        .tempdir()
        .unwrap()
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Every line of `text` as JSON (the `--progress json` output).
fn json_lines(text: &str) -> Vec<serde_json::Value> {
    text.lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("not JSON: {l:?}: {e}")))
        .collect()
}

/// Width, height and number of distinct colours of a PNG.
fn png_summary(p: &Path) -> (u32, u32, usize) {
    let dec = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(p).unwrap()));
    let mut r = dec.read_info().unwrap();
    let mut buf = vec![0; r.output_buffer_size().unwrap()];
    let info = r.next_frame(&mut buf).unwrap();
    let px = info.color_type.samples();
    let colours: std::collections::HashSet<&[u8]> = buf[..info.buffer_size()].chunks(px).collect();
    (info.width, info.height, colours.len())
}

/// A recording is non-empty and, where the official `rerun` CLI of the same version is
/// installed (always in CI: .ci/run installs it), verifies and holds `entities`.
fn rrd_check(p: &Path, entities: &[&str]) {
    let len = std::fs::metadata(p).map(|m| m.len()).unwrap_or(0);
    assert!(len > 1000, "{}: {len} bytes", p.display());
    let cli = Command::new("rerun").arg("--version").output();
    let Ok(v) = cli else {
        assert!(
            std::env::var("CI").is_err(),
            "CI must install the rerun CLI (pip install rerun-sdk==0.36.3)"
        );
        eprintln!("rerun CLI not found: skipping the viewer-side check of {}", p.display());
        return;
    };
    assert!(
        String::from_utf8_lossy(&v.stdout).contains("0.36.3"),
        "rerun CLI version: {}",
        stdout(&v)
    );
    let o = Command::new("rerun")
        .args(["rrd", "verify"])
        .arg(p)
        .env("RERUN_TELEMETRY_ENABLED", "false")
        .output()
        .unwrap();
    assert!(o.status.success(), "rerun rrd verify: {}{}", stdout(&o), stderr(&o));
    let o = Command::new("rerun")
        .args(["rrd", "print"])
        .arg(p)
        .env("RERUN_TELEMETRY_ENABLED", "false")
        .output()
        .unwrap();
    assert!(o.status.success(), "rerun rrd print: {}", stderr(&o));
    let text = stdout(&o) + &stderr(&o);
    for e in entities {
        assert!(
            text.contains(e),
            "{e} not in the recording:\n{}",
            &text[..text.len().min(3000)]
        );
    }
    // The recording carries the layout it opens with (src/viz.rs `layout`).
    for b in ["ViewBlueprint", "ContainerBlueprint"] {
        assert!(text.contains(b), "no {b} in the recording");
    }
}

fn tiny_config(dir: &Path) -> PathBuf {
    let p = dir.join("tiny.toml");
    std::fs::write(
        &p,
        "env = \"racing-oval\"\nalgo = \"ppo\"\nsteps = 512\nseed = 1\nn_envs = 2\nthreads = 1\neval_episodes = 1\n\
         [env_config]\nmax_steps = 100\n[ppo]\nn_steps = 128\nbatch_size = 64\nn_epochs = 2\n",
    )
    .unwrap();
    p
}

mod cli {
    use super::*;

    #[test]
    fn train_writes_a_complete_run_directory_and_eval_reads_it() {
        let d = tmp("train");
        let run = d.path().join("run");
        let cfg = tiny_config(d.path());
        let o = agvrl(&[
            "train",
            "--config",
            cfg.to_str().unwrap(),
            "--out",
            run.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        for f in [
            "config.toml",
            "metrics.csv",
            "policy.agvrl",
            "checkpoint.ckpt",
            "eval.txt",
            "eval.json",
            "learning_curve.png",
            "trajectory.png",
            "eval.rrd",
        ] {
            let p = run.join(f);
            assert!(p.metadata().map(|m| m.len() > 0).unwrap_or(false), "missing {f}");
        }
        assert!(!PathBuf::from(format!("{}.partial", run.display())).exists());
        for (f, w) in [("learning_curve.png", 900), ("trajectory.png", 0)] {
            let (width, _, colours) = png_summary(&run.join(f));
            assert!(w == 0 || width == w, "{f}: width {width}");
            // Axes, text, a curve or a map: a blank or one-colour image is a broken plot.
            assert!(colours >= 4, "{f}: {colours} colours");
        }
        rrd_check(
            &run.join("eval.rrd"),
            &["world/vehicle", "world/lidar/rays", "plots/reward"],
        );
        let csv = std::fs::read_to_string(run.join("metrics.csv")).unwrap();
        assert!(csv.lines().count() >= 3, "{csv}");
        let o = agvrl(&["eval", "--run", run.to_str().unwrap(), "--episodes", "2"]);
        assert!(o.status.success(), "{}", stderr(&o));
        let out = stdout(&o);
        for key in ["mean_return=", "episodes=2", "collisions=", "laps=", "best_lap_s="] {
            assert!(out.contains(key), "{key} missing in:\n{out}");
        }
        // The policy file of a run directory is evaluated with that run's settings, not the
        // defaults: the same episodes give the same lines as --run.
        let pf = run.join("policy.agvrl");
        let o = agvrl(&[
            "eval",
            "--policy",
            pf.to_str().unwrap(),
            "--episodes",
            "2",
            "--seed",
            "2000001",
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let by_file = stdout(&o);
        // A policy file carries its run's settings.
        assert_eq!(key(&by_file, "settings"), format!("{} (embedded)", pf.display()));
        for k in ["env", "mean_return", "ended"] {
            assert_eq!(key(&by_file, k), key(&out, k), "{k}: --policy\n{by_file}\n--run\n{out}");
        }
        // A truncated policy file is refused with a one-line error.
        let pf = run.join("policy.agvrl");
        let bytes = std::fs::read(&pf).unwrap();
        std::fs::write(&pf, &bytes[..bytes.len() / 2]).unwrap();
        let o = agvrl(&["eval", "--run", run.to_str().unwrap()]);
        assert!(!o.status.success());
        let err = stderr(&o);
        assert_eq!(err.trim().lines().count(), 1, "{err}");
        assert!(err.contains("policy.agvrl"), "{err}");
    }

    #[test]
    fn an_error_is_one_line_naming_the_file_and_the_reason_once() {
        let d = tmp("errors");
        let missing = d.path().join("missing.agvrl");
        let m = missing.to_str().unwrap();
        let no_run = d.path().join("no-run");
        let cases: [(Vec<&str>, &str); 3] = [
            (vec!["eval", "--policy", m, "--env", "racing-oval"], m),
            (vec!["eval", "--run", no_run.to_str().unwrap()], "config.toml"),
            (
                vec!["view", "--policy", m, "--env", "racing-oval", "--rerun", "x.rrd"],
                m,
            ),
        ];
        for (args, file) in cases {
            let o = agvrl(&args);
            assert!(!o.status.success(), "{args:?}");
            let err = stderr(&o);
            assert_eq!(err.trim().lines().count(), 1, "{args:?}: {err}");
            assert_eq!(err.matches(file).count(), 1, "{args:?}: {err}");
            assert_eq!(err.matches("os error 2").count(), 1, "{args:?}: {err}");
        }
    }

    #[test]
    fn init_from_fine_tunes_a_run_with_added_observation_parts_and_refuses_lost_ones() {
        let d = tmp("init-from");
        let (base, tuned) = (d.path().join("base"), d.path().join("tuned"));
        let train = |out: &Path, sets: &[&str]| {
            let mut args = vec![
                "train",
                "--env",
                "search-outdoor-20",
                "--algo",
                "ppo",
                "--steps",
                "128",
                "--n-envs",
                "1",
                "--out",
                out.to_str().unwrap(),
            ];
            for s in [
                "ppo.n_steps=64",
                "ppo.batch_size=64",
                "ppo.net_arch=[16]",
                "eval_episodes=1",
                "eval_max_steps=20",
            ]
            .iter()
            .chain(sets)
            {
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
    fn ctrl_c_leaves_a_complete_run_that_resume_continues() {
        let d = tmp("ctrlc");
        let run = d.path().join("run");
        let cfg = tiny_config(d.path());
        /// Kills the training process if the test fails half-way.
        struct Guard(Option<std::process::Child>);
        impl Drop for Guard {
            fn drop(&mut self) {
                if let Some(c) = self.0.as_mut() {
                    let _ = c.kill();
                    let _ = c.wait();
                }
            }
        }
        let child = Command::new(env!("CARGO_BIN_EXE_agvrl"))
            .args([
                "train",
                "--config",
                cfg.to_str().unwrap(),
                "--steps",
                "100000000",
                "--out",
                run.to_str().unwrap(),
            ])
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let mut guard = Guard(Some(child));
        let pid = guard.0.as_ref().map(|c| c.id()).unwrap_or(0);
        // Wait until training has checkpointed once, then interrupt.
        let ckpt = PathBuf::from(format!("{}.partial", run.display())).join("checkpoint.ckpt");
        let t0 = std::time::Instant::now();
        while !ckpt.exists() && t0.elapsed().as_secs() < 120 {
            std::thread::yield_now();
        }
        assert!(ckpt.exists(), "no checkpoint appeared");
        let ok = Command::new("kill").args(["-INT", &pid.to_string()]).status().unwrap();
        assert!(ok.success());
        let o = guard.0.take().unwrap().wait_with_output().unwrap();
        assert!(o.status.success(), "{}", stderr(&o));
        let eval = std::fs::read_to_string(run.join("eval.txt")).unwrap();
        assert!(eval.contains("interrupted=true"), "{eval}");
        let step_of = |text: &str| -> u64 {
            text.lines()
                .find_map(|l| l.strip_prefix("steps="))
                .unwrap()
                .parse()
                .unwrap()
        };
        let before = step_of(&eval);
        let rows_before = std::fs::read_to_string(run.join("metrics.csv"))
            .unwrap()
            .lines()
            .count();
        let o = agvrl(&["train", "--resume", run.to_str().unwrap(), "--steps", "256"]);
        assert!(o.status.success(), "{}", stderr(&o));
        let after = step_of(&std::fs::read_to_string(run.join("eval.txt")).unwrap());
        assert!(after >= before + 256, "{before} -> {after}");
        let rows_after = std::fs::read_to_string(run.join("metrics.csv"))
            .unwrap()
            .lines()
            .count();
        assert!(rows_after > rows_before);
    }

    #[test]
    fn bad_inputs_fail_with_a_one_line_error() {
        let d = tmp("bad");
        let train_with = |config: &str, out: &str| {
            let bad = d.path().join("bad.toml");
            std::fs::write(&bad, config).unwrap();
            agvrl(&[
                "train",
                "--config",
                bad.to_str().unwrap(),
                "--out",
                d.path().join(out).to_str().unwrap(),
            ])
        };
        let o = train_with("env = \"racing-oval\"\nlearning_rat = 0.1\n", "r");
        assert!(!o.status.success());
        assert!(stderr(&o).contains("learning_rat"), "{}", stderr(&o));
        assert_eq!(stderr(&o).trim().lines().count(), 1, "{}", stderr(&o));
        let o = agvrl(&[
            "train",
            "--env",
            "racing-moon",
            "--out",
            d.path().join("r2").to_str().unwrap(),
        ]);
        assert!(!o.status.success());
        let e = stderr(&o);
        assert!(e.contains("racing-moon") && e.contains("racing-oval"), "{e}");
        let o = agvrl(&["probe", "--env", "racing-oval", "--pose", "1,2"]);
        assert!(!o.status.success() && stderr(&o).contains("x,y,yaw"));
        let o = train_with("env = \"racing-oval\"\nn_envs = 2\nprocedural_layouts = 3\n", "r3");
        assert!(!o.status.success());
        assert!(
            stderr(&o).contains("procedural_layouts (3) cannot exceed n_envs (2)"),
            "{}",
            stderr(&o)
        );
        assert_eq!(stderr(&o).trim().lines().count(), 1, "{}", stderr(&o));
    }

    #[test]
    fn a_closed_stdout_ends_the_listing_quietly_without_a_panic() {
        let (reader, writer) = std::io::pipe().unwrap();
        drop(reader);
        let o = Command::new(env!("CARGO_BIN_EXE_agvrl"))
            .arg("envs")
            .stdout(writer)
            .output()
            .unwrap();
        assert!(!stderr(&o).contains("panicked"), "{}", stderr(&o));
        #[cfg(unix)]
        {
            use std::os::unix::process::ExitStatusExt;
            assert_eq!(o.status.signal(), Some(libc::SIGPIPE), "{:?}", o.status);
        }
    }

    #[test]
    fn probe_prints_json_whose_ranges_match_the_scene() {
        let o = agvrl(&["probe", "--env", "racing-oval", "--pose", "4,0,-1.5707964"]);
        assert!(o.status.success(), "{}", stderr(&o));
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("valid JSON");
        let ranges = v["scan"]["ranges"].as_array().unwrap();
        assert_eq!(ranges.len(), 100);
        // On the straight, 1 m from both walls: the +-45 degree rays read sqrt(2) m.
        for r in [&ranges[0], &ranges[99]] {
            let r = r.as_f64().unwrap();
            assert!((r - std::f64::consts::SQRT_2).abs() < 0.01, "{r}");
        }
        // GPS reads the pose the car was put at.
        let gps = &v["gps"]["position_m"];
        let (x, y) = (gps[0].as_f64().unwrap(), gps[1].as_f64().unwrap());
        assert!((x - 4.0).abs() < 1e-6 && y.abs() < 1e-6, "{gps}");
    }

    #[test]
    fn envs_lists_every_id() {
        let o = agvrl(&["envs"]);
        assert!(o.status.success());
        let out = stdout(&o);
        for id in [
            "search-outdoor-20",
            "search-outdoor-50",
            "search-urban-20",
            "search-urban-50",
            "racing-oval",
            "pendulum",
            "racing-duel",
        ] {
            assert!(out.contains(id), "{out}");
        }
    }

    #[test]
    fn bench_quick_prints_key_value_lines() {
        let o = agvrl(&["bench", "--quick", "--only", "sim"]);
        assert!(o.status.success(), "{}", stderr(&o));
        let out = stdout(&o);
        assert!(
            out.lines()
                .any(|l| l.starts_with("scene=oval mode=raycast") && l.contains("sim_steps_per_s=")),
            "{out}"
        );
        // The circuit figures tools/f110-bench.sh reads, at every car count.
        for c in [1, 2, 8] {
            assert!(
                out.lines().any(|l| l.starts_with("circuit=")
                    && l.contains(&format!("circuit_cars{c}_sim_s_per_wall_s="))
                    && l.contains(&format!("circuit_cars{c}_scans_per_s="))),
                "{out}"
            );
        }
    }

    #[test]
    fn eval_and_view_write_recordings_and_search_eval_reports_coverage() {
        let d = tmp("rerun");
        let cfg = d.path().join("search.toml");
        std::fs::write(
            &cfg,
            "env = \"search-outdoor-20\"\nalgo = \"ppo\"\nsteps = 256\nseed = 2\nn_envs = 2\nthreads = 1\n\
             procedural_layouts = 1\neval_episodes = 1\n[env_config]\nmax_steps = 60\n[ppo]\nn_steps = 128\nbatch_size = 64\nn_epochs = 1\n",
        )
        .unwrap();
        let run = d.path().join("run");
        let o = agvrl(&[
            "train",
            "--config",
            cfg.to_str().unwrap(),
            "--out",
            run.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let rrd = d.path().join("eval.rrd");
        let png = d.path().join("paths.png");
        let o = agvrl(&[
            "eval",
            "--run",
            run.to_str().unwrap(),
            "--episodes",
            "2",
            "--rerun",
            rrd.to_str().unwrap(),
            "--plot",
            png.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let out = stdout(&o);
        for key in ["mean_return=", "episodes=2", "collisions=", "coverage="] {
            assert!(out.contains(key), "{key} missing in:\n{out}");
        }
        let cov: f64 = out
            .lines()
            .find_map(|l| l.strip_prefix("coverage="))
            .unwrap()
            .parse()
            .unwrap();
        assert!(cov > 0.0 && cov <= 1.0, "{cov}");
        let dist: f64 = out
            .lines()
            .find_map(|l| l.strip_prefix("distance_m_per_episode="))
            .expect("distance_m_per_episode= missing")
            .parse()
            .unwrap();
        // 60 steps of 1/30 s, and the car's top speed is under 2 m/s.
        assert!(dist > 0.0 && dist < 2.0 * 60.0 / 30.0, "{dist}");
        rrd_check(
            &rrd,
            &["world/scene", "world/trajectory", "world/lidar/scan", "plots/speed_mps"],
        );
        assert!(png_summary(&png).2 >= 4);
        // The same episodes on another scene with random actions: the random baseline.
        let o = agvrl(&[
            "eval",
            "--run",
            run.to_str().unwrap(),
            "--episodes",
            "1",
            "--env",
            "search-urban-50",
            "--random",
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let out = stdout(&o);
        for key in ["env=search-urban-50", "policy=random", "coverage="] {
            assert!(out.contains(key), "{key} missing in:\n{out}");
        }
        let o = agvrl(&["eval", "--run", run.to_str().unwrap(), "--env", "pendulum"]);
        assert!(!o.status.success(), "a search policy on the pendulum must be refused");
        assert!(stderr(&o).contains("does not fit"), "{}", stderr(&o));
        // `view` without a policy drives random actions into a file.
        let view = d.path().join("view.rrd");
        let o = agvrl(&[
            "view",
            "--env",
            "racing-oval",
            "--steps",
            "40",
            "--camera",
            "--rerun",
            view.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        assert!(stdout(&o).contains("policy=random"), "{}", stdout(&o));
        rrd_check(
            &view,
            &[
                "world/vehicle",
                "plots/throttle",
                "camera/rgb",
                "camera/depth",
                "camera/segmentation",
            ],
        );
        // A policy for another env is refused in one line.
        let o = agvrl(&[
            "view",
            "--env",
            "pendulum",
            "--policy",
            run.join("policy.agvrl").to_str().unwrap(),
        ]);
        assert!(!o.status.success());
        assert_eq!(stderr(&o).trim().lines().count(), 1, "{}", stderr(&o));
    }

    #[test]
    fn help_says_the_defaults_a_user_must_know_and_bad_choices_list_the_valid_ones() {
        let h = stdout(&agvrl(&["train", "--help"]));
        for line in [
            "one gradient step per env step",
            "8 in",
            "configs/default.toml",
            "- cuda:    CUDA GPU",
        ] {
            assert!(h.contains(line), "train --help lacks '{line}':\n{h}");
        }
        let o = agvrl(&["bench", "--only", "physics"]);
        assert!(!o.status.success());
        assert!(
            stderr(&o).contains("[possible values: sim, circuit, envs, rl, deploy, learning]"),
            "{}",
            stderr(&o)
        );
        let o = agvrl(&["train", "--device", "tpu"]);
        assert!(!o.status.success());
        assert!(stderr(&o).contains("flex, ndarray, cuda, wgpu"), "{}", stderr(&o));
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

    fn key<'a>(out: &'a str, k: &str) -> &'a str {
        out.lines()
            .find_map(|l| l.strip_prefix(k).and_then(|r| r.strip_prefix('=')))
            .unwrap_or_else(|| panic!("{k}= missing in:\n{out}"))
    }

    /// The policy carries its own safety: without the filter it drives 3 held-out outdoor-20
    /// episodes to the time limit, and with it the filter steers or brakes at most 20 of its
    /// 1,000 controls per episode (the search targets' bound).
    #[test]
    fn shipped_search_policy_drives_held_out_outdoor_episodes_without_a_termination() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let policy = root.join("assets/policies/search.agvrl");
        let eval_on = |env: &str, episodes: &str, filter: &[&str]| {
            let mut args = vec![
                "eval",
                "--policy",
                policy.to_str().unwrap(),
                "--env",
                env,
                "--episodes",
                episodes,
                "--seed",
                "7",
            ];
            args.extend_from_slice(filter);
            let o = agvrl(&args);
            assert!(o.status.success(), "{}", stderr(&o));
            stdout(&o)
        };
        let eval = |filter: &[&str]| eval_on("search-outdoor-20", "3", filter);
        let bare = eval(&["--safety-filter", "off"]);
        assert_eq!(key(&bare, "safety_filter"), "off");
        assert_eq!(key(&bare, "ended"), "time_limit,time_limit,time_limit", "{bare}");
        // Its embedded settings turn the safety filter on.
        let out = eval(&[]);
        assert_eq!(key(&out, "episodes"), "3");
        assert_eq!(key(&out, "safety_filter"), "on");
        assert_eq!(key(&out, "ended"), "time_limit,time_limit,time_limit", "{out}");
        assert_eq!(key(&out, "collisions"), "0");
        let corrections: f64 = key(&out, "filter_corrections_per_episode").parse().unwrap();
        assert!(corrections <= 20.0, "{out}");
        let cov: f64 = key(&out, "coverage").parse().unwrap();
        assert!(cov > 0.2, "coverage {cov}");
        let bare_cov: f64 = key(&bare, "coverage").parse().unwrap();
        assert!(bare_cov >= 0.95 * cov, "bare coverage {bare_cov}, filtered {cov}");
        // Among buildings, the wider shield it was trained behind steps in more often than the
        // backstop it drives behind.
        let urban = |filter: &str| {
            let out = eval_on("search-urban-20", "1", &["--safety-filter", filter]);
            assert_eq!(key(&out, "safety_filter"), filter);
            key(&out, "filter_corrections_per_episode").parse::<f64>().unwrap()
        };
        let (backstop, shield) = (urban("on"), urban("train"));
        assert!(shield > backstop, "shield {shield}, backstop {backstop}");
        // The same policy fits every search scene's spaces.
        for env in ["search-urban-20", "search-outdoor-50", "search-urban-50"] {
            let o = agvrl(&[
                "eval",
                "--policy",
                policy.to_str().unwrap(),
                "--env",
                env,
                "--episodes",
                "1",
                "--layouts",
                "procedural",
            ]);
            assert!(o.status.success(), "{env}: {}", stderr(&o));
        }
    }

    /// The shipped camera-only racing policy (a 64x48 depth image, no LiDAR in its observation)
    /// laps the oval in a held-out 100 s episode, with clean sensors and under sim2real's
    /// depth noise, holes and dynamics.
    #[test]
    fn the_shipped_camera_policy_laps_the_oval_from_depth_alone() {
        let policy = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/policies/racing-oval-camera.agvrl");
        for preset in [&[][..], &["--preset", "sim2real"]] {
            let mut args = vec![
                "eval",
                "--policy",
                policy.to_str().unwrap(),
                "--episodes",
                "1",
                "--seed",
                "7",
            ];
            args.extend(preset);
            let o = agvrl(&args);
            assert!(o.status.success(), "{}", stderr(&o));
            let out = stdout(&o);
            assert_eq!(key(&out, "collisions"), "0", "{preset:?}: {out}");
            assert!(key(&out, "laps").parse::<u32>().unwrap() >= 2, "{preset:?}: {out}");
        }
        let settings = agvrl(&["policy", policy.to_str().unwrap()]);
        let settings = stdout(&settings);
        assert!(
            settings.contains("ranges = \"off\"") && settings.contains("depth_only = true"),
            "{settings}"
        );
    }

    /// `agvrl eval --record`: one bag per episode with the topics of `agvrl-drive --record` in
    /// simulated time; the drive loop replaying a bag gives the evaluated actions and commands
    /// to within 1e-5 (same CPU) and every filter verdict, with the safety filter in the loop.
    #[test]
    fn eval_bags_replay_through_the_drive_loop_to_the_evaluated_actions() {
        use agvrl_deploy::bag;
        use agvrl_deploy::hardware::msg;
        const WIDER: &str = "env_config.safety_filter.clearance_m=1.1";
        let policy = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/policies/search.agvrl");
        let d = tmp("evalbag");
        let bags = d.path().join("bags");
        let o = agvrl(&[
            "eval",
            "--policy",
            policy.to_str().unwrap(),
            "--env",
            "search-urban-20",
            "--layouts",
            "procedural",
            "--episodes",
            "2",
            "--max-steps",
            "300",
            // Episodes where a wider filter corrects the policy (13 times), so the replay
            // checks its verdicts too.
            "--seed",
            "11",
            "--set",
            WIDER,
            "--record",
            bags.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let out = stdout(&o);
        assert_eq!(key(&out, "bag_episodes"), "2", "{out}");
        let mut settings = agvrl_run::PolicySettings::resolve(None, Some(&policy), &[WIDER.into()]).unwrap();
        let env_cfg = settings.eval_env_config();
        let (mut messages, mut filtered, mut first_odom) = (0, 0, Vec::new());
        for k in 0..2 {
            let dir = bags.join(format!("episode-{k:03}"));
            let (msgs, damage) = bag::read_messages(&dir).unwrap();
            assert_eq!(damage, None);
            messages += msgs.len();
            let count = |t: &str| msgs.iter().filter(|m| m.topic == t).count();
            // The reset's frame and one per step; a command and a tick per step.
            assert_eq!([count("/scan"), count("/odom"), count("/tf")], [301; 3], "episode {k}");
            assert_eq!([count("/drive"), count("/agvrl/tick")], [300, 300], "episode {k}");
            let odom: msg::Odometry = bag::decode(&msgs.iter().find(|m| m.topic == "/odom").unwrap().data).unwrap();
            first_odom.push(odom.pose.pose.position.x);
            let mut r = agvrl_deploy::replay::Replayer::open(
                &dir,
                None,
                "search-urban-20",
                &env_cfg,
                settings.load_policy().unwrap(),
                30.0,
                0,
            )
            .unwrap();
            let mut ticks = 0;
            while let Some((rec, t)) = r.step().unwrap() {
                let (_, action) = t.inference.as_ref().unwrap();
                // The bag's stamps are whole nanoseconds and the simulator's are not, and the
                // policy's reverse lengths and wait read time continuously: an action may move
                // by an f32 rounding, never more.
                let worst = action
                    .iter()
                    .zip(&rec.action)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0, f32::max);
                assert!(
                    worst <= 1e-5,
                    "episode {k} tick {}: {action:?} {:?}",
                    rec.tick,
                    rec.action
                );
                assert!(
                    (t.control.throttle - rec.throttle).abs() <= 1e-5
                        && (t.control.steering_rad - rec.steering_rad).abs() <= 1e-5,
                    "episode {k} tick {}",
                    rec.tick
                );
                assert_eq!(format!("{:?}", t.intervention).to_lowercase(), rec.intervention);
                filtered += usize::from(rec.intervention != "none");
                ticks += 1;
            }
            assert_eq!(ticks, 300);
            assert_eq!(r.diff.events, 0);
        }
        assert_eq!(key(&out, "bag_messages"), messages.to_string());
        assert_ne!(first_odom[0], first_odom[1], "each episode its own start");
        assert!(filtered > 0, "no filtered control to replay");
        let again = agvrl(&[
            "eval",
            "--policy",
            policy.to_str().unwrap(),
            "--record",
            bags.to_str().unwrap(),
        ]);
        assert!(
            !again.status.success() && stderr(&again).contains("not empty"),
            "{}",
            stderr(&again)
        );
    }

    #[test]
    fn the_map_aware_planner_covers_more_than_random_actions_on_the_same_car_and_episodes() {
        let policy = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/policies/search.agvrl");
        let eval = |env: &str, driver: &str| {
            agvrl(&[
                "eval",
                "--policy",
                policy.to_str().unwrap(),
                "--env",
                env,
                "--episodes",
                "3",
                "--seed",
                "3",
                // The filter the planners were tuned behind (the policy's training shield).
                "--safety-filter",
                "train",
                driver,
            ])
        };
        let p = eval("search-urban-20", "--planner");
        assert!(p.status.success(), "{}", stderr(&p));
        let p = stdout(&p);
        assert_eq!(key(&p, "policy"), "planner");
        assert_eq!(key(&p, "collisions"), "0", "{p}");
        let r = eval("search-urban-20", "--random");
        assert!(r.status.success(), "{}", stderr(&r));
        let r = stdout(&r);
        let cov = |out: &str| key(out, "coverage").parse::<f64>().unwrap();
        // Over 100 held-out episodes the planner covers 0.70, random actions on this car (which
        // reverse half the time) 0.07, and the forward-only random car 0.22.
        assert!(
            cov(&p) > 0.5 && cov(&p) > 2.0 * cov(&r),
            "planner {} random {}",
            cov(&p),
            cov(&r)
        );
        let oval = eval("racing-oval", "--planner");
        assert!(!oval.status.success());
        assert!(stderr(&oval).contains("needs a search env"), "{}", stderr(&oval));
    }

    #[test]
    fn the_frontier_explorer_covers_ground_and_eval_writes_coverage_over_time() {
        let policy = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/policies/search.agvrl");
        let d = tmp("frontier");
        let eval = |driver: &[&str], csv: &Path| {
            let mut args = vec![
                "eval",
                "--policy",
                policy.to_str().unwrap(),
                "--env",
                "search-urban-20",
                "--episodes",
                "3",
                "--seed",
                "3",
                "--coverage-csv",
                csv.to_str().unwrap(),
                "--safety-filter",
                "train",
            ];
            args.extend_from_slice(driver);
            let o = agvrl(&args);
            assert!(o.status.success(), "{driver:?}: {}", stderr(&o));
            stdout(&o)
        };
        let (fcsv, rcsv) = (d.path().join("frontier.csv"), d.path().join("random.csv"));
        let f = eval(&["--planner", "frontier"], &fcsv);
        let r = eval(&["--random"], &rcsv);
        assert_eq!(key(&f, "policy"), "frontier");
        let cov = |out: &str| key(out, "coverage").parse::<f64>().unwrap();
        // Over 100 held-out episodes the explorer covers 0.63 with no map, random actions on
        // this car (which reverse half the time) 0.07.
        assert!(
            cov(&f) > 0.4 && cov(&f) > 3.0 * cov(&r),
            "frontier {} random {}",
            cov(&f),
            cov(&r)
        );
        // The CSV holds every control of every episode; the mean of each episode's last row is
        // the coverage line, and the time to 25 % is where the rows cross it.
        let text = std::fs::read_to_string(&fcsv).unwrap();
        let rows: Vec<Vec<f64>> = text
            .lines()
            .skip(1)
            .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
            .collect();
        assert_eq!(text.lines().next(), Some("episode,step,time_s,coverage"));
        let last: Vec<f64> = (0..3)
            .map(|e| rows.iter().rfind(|r| r[0] == e as f64).unwrap()[3])
            .collect();
        assert!((last.iter().sum::<f64>() / 3.0 - cov(&f)).abs() < 1e-3, "{last:?}");
        let first_25: Vec<f64> = (0..3)
            .filter_map(|e| rows.iter().find(|r| r[0] == e as f64 && r[3] >= 0.25).map(|r| r[2]))
            .collect();
        assert_eq!(key(&f, "coverage_25_reached"), format!("{}/3", first_25.len()));
        let t25: f64 = key(&f, "time_to_coverage_25_s").parse().unwrap();
        assert!((t25 - first_25.iter().sum::<f64>() / first_25.len() as f64).abs() < 0.06);
        let png = d.path().join("coverage.png");
        let o = agvrl(&[
            "coverage-plot",
            "--out",
            png.to_str().unwrap(),
            &format!("frontier={}", fcsv.display()),
            rcsv.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        assert!(std::fs::read(&png).unwrap().starts_with(b"\x89PNG"));
        let bad = agvrl(&["coverage-plot", "--out", png.to_str().unwrap(), "/nonexistent.csv"]);
        assert!(!bad.status.success());
        assert!(stderr(&bad).contains("/nonexistent.csv"), "{}", stderr(&bad));
    }

    #[test]
    fn eval_of_a_policy_file_draws_its_episodes_from_the_seed_and_the_layout_option() {
        let d = tmp("evalpolicy");
        let cfg = d.path().join("search.toml");
        std::fs::write(
            &cfg,
            "env = \"search-urban-20\"\nalgo = \"ppo\"\nsteps = 128\nseed = 3\nn_envs = 1\nthreads = 1\n\
             eval_episodes = 1\n[env_config]\nmax_steps = 30\n[ppo]\nn_steps = 128\nbatch_size = 64\nn_epochs = 1\n",
        )
        .unwrap();
        let run = d.path().join("run");
        let o = agvrl(&[
            "train",
            "--config",
            cfg.to_str().unwrap(),
            "--out",
            run.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        // A policy file on its own: it carries its run's settings.
        let policy = d.path().join("p.agvrl");
        std::fs::copy(run.join("policy.agvrl"), &policy).unwrap();
        let ev = |extra: &[&str]| {
            let mut args = vec!["eval", "--policy", policy.to_str().unwrap(), "--episodes", "3"];
            args.extend_from_slice(extra);
            let o = agvrl(&args);
            assert!(o.status.success(), "{extra:?}: {}", stderr(&o));
            stdout(&o)
        };
        let a = ev(&["--seed", "11"]);
        assert_eq!(key(&a, "env"), "search-urban-20", "the env comes from the file");
        assert_eq!(key(&a, "seed"), "11");
        assert_eq!(a, ev(&["--seed", "11"]), "same seed, same episodes");
        assert_ne!(key(&a, "mean_return"), key(&ev(&["--seed", "12"]), "mean_return"));
        let p = ev(&["--seed", "11", "--layouts", "procedural"]);
        assert_eq!(key(&p, "layouts"), "procedural");
        assert_ne!(
            key(&a, "coverage"),
            key(&p, "coverage"),
            "procedural maps differ from the built-in one"
        );
        let n = ev(&["--seed", "11", "--preset", "sim2real"]);
        assert_eq!(key(&n, "preset"), "sim2real");
        assert_ne!(key(&a, "mean_return"), key(&n, "mean_return"));
        let r = ev(&["--seed", "11", "--random"]);
        assert_eq!(key(&r, "policy"), "random");
        // Sampled actions: seeded per episode, so repeatable, and not the mean's episodes.
        let s = ev(&["--seed", "11", "--sampled"]);
        assert_eq!(key(&s, "actions"), "sampled");
        assert_eq!(s, ev(&["--seed", "11", "--sampled"]), "same seed, same samples");
        assert_ne!(key(&a, "mean_return"), key(&s, "mean_return"));
        let o = agvrl(&["eval", "--policy", policy.to_str().unwrap(), "--sampled", "--random"]);
        assert!(!o.status.success(), "--sampled drives the policy, --random does not");
        // A file of format 1 without the TOML beside it carries no settings: the env must be
        // named.
        let old = d.path().join("old.agvrl");
        std::fs::copy(
            Path::new(env!("CARGO_MANIFEST_DIR")).join("crates/run/tests/fixtures/racing-v1.agvrl"),
            &old,
        )
        .unwrap();
        let o = agvrl(&["eval", "--policy", old.to_str().unwrap()]);
        assert!(!o.status.success());
        assert!(stderr(&o).contains("--env"), "{}", stderr(&o));
        let o = agvrl(&[
            "eval",
            "--policy",
            old.to_str().unwrap(),
            "--env",
            "racing-oval",
            "--episodes",
            "1",
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        assert_eq!(key(&stdout(&o), "settings"), "default");
    }
}

/// What a sweep driver relies on: JSON progress, SIGTERM and a dead parent stop a training with
/// a complete run directory, `--set`, and run directories that never collide.
mod trials {
    use super::*;
    use std::io::{BufRead, BufReader};
    use std::process::Stdio;

    #[test]
    fn progress_json_prints_one_object_per_update_and_the_run_at_the_end() {
        let d = tmp("json");
        let cfg = tiny_config(d.path());
        let run = d.path().join("run");
        let o = agvrl(&[
            "train",
            "--config",
            cfg.to_str().unwrap(),
            "--progress",
            "json",
            "--out",
            run.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let lines = json_lines(&stdout(&o));
        let (last, updates) = lines.split_last().unwrap();
        assert!(updates.len() >= 2, "{lines:?}");
        let mut prev = 0;
        for u in updates {
            assert_eq!(u["event"], "progress");
            let steps = u["steps"].as_u64().unwrap();
            assert!(steps > prev && u["wall_s"].as_f64().unwrap() >= 0.0);
            prev = steps;
        }
        assert_eq!(last["event"], "done");
        assert_eq!(last["run_dir"], run.to_str().unwrap());
        assert_eq!(last["interrupted"], false);
        assert_eq!(last["metrics"]["steps"].as_f64(), Some(512.0));
        assert_eq!(last["metrics"]["episodes"].as_f64(), Some(1.0));
        assert!(!stderr(&o).contains("ETA"), "no progress bar beside the JSON");
    }

    #[test]
    fn sigterm_stops_a_training_with_a_complete_run_directory() {
        let d = tmp("sigterm");
        let cfg = tiny_config(d.path());
        let run = d.path().join("run");
        let mut child = Command::new(env!("CARGO_BIN_EXE_agvrl"))
            .args([
                "train",
                "--config",
                cfg.to_str().unwrap(),
                "--steps",
                "100000000",
                "--progress",
                "json",
            ])
            .args(["--out", run.to_str().unwrap()])
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let mut out = BufReader::new(child.stdout.take().unwrap());
        let mut first = String::new();
        out.read_line(&mut first).unwrap();
        assert!(first.contains("\"progress\""), "{first}");
        assert!(
            Command::new("kill")
                .args(["-TERM", &child.id().to_string()])
                .status()
                .unwrap()
                .success()
        );
        let mut rest = String::new();
        std::io::Read::read_to_string(&mut out, &mut rest).unwrap();
        assert!(child.wait().unwrap().success());
        let done = json_lines(&rest).pop().unwrap();
        assert_eq!(done["event"], "done");
        assert_eq!(done["interrupted"], true);
        let eval = std::fs::read_to_string(run.join("eval.txt")).unwrap();
        assert!(eval.contains("interrupted=true"), "{eval}");
        // The done line carries eval.json's object, typed.
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(run.join("eval.json")).unwrap()).unwrap();
        assert_eq!(done["metrics"], json);
        assert!(done["metrics"]["steps"].is_u64() && done["metrics"]["ended"].is_array());
        assert!(run.join("policy.agvrl").is_file());
    }

    #[test]
    fn a_training_whose_parent_dies_stops_with_a_complete_run_directory() {
        let d = tmp("orphan");
        let cfg = tiny_config(d.path());
        let run = d.path().join("run");
        // sh starts the training in the background and is killed; the training is reparented.
        let script = format!(
            "'{}' train --config '{}' --steps 100000000 --progress json --out '{}' > '{}' 2>&1 & echo $!; sleep 60",
            env!("CARGO_BIN_EXE_agvrl"),
            cfg.display(),
            run.display(),
            d.path().join("log").display()
        );
        let mut sh = Command::new("sh")
            .args(["-c", &script])
            .stdout(Stdio::piped())
            .spawn()
            .unwrap();
        let mut line = String::new();
        BufReader::new(sh.stdout.take().unwrap()).read_line(&mut line).unwrap();
        let pid = line.trim().to_string();
        let partial = PathBuf::from(format!("{}.partial", run.display())).join("config.toml");
        let t0 = std::time::Instant::now();
        while !partial.exists() && t0.elapsed().as_secs() < 60 {
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
        std::thread::sleep(std::time::Duration::from_millis(500));
        sh.kill().unwrap();
        sh.wait().unwrap();
        let alive = |pid: &str| std::path::Path::new(&format!("/proc/{pid}")).exists();
        let t0 = std::time::Instant::now();
        while alive(&pid) && t0.elapsed().as_secs() < 120 {
            std::thread::sleep(std::time::Duration::from_millis(50));
        }
        assert!(!alive(&pid), "the orphaned training still runs");
        let eval = std::fs::read_to_string(run.join("eval.txt")).unwrap();
        assert!(eval.contains("interrupted=true"), "{eval}");
    }

    #[test]
    fn set_overrides_dotted_keys_of_the_run_config() {
        let d = tmp("set");
        let cfg = tiny_config(d.path());
        let run = d.path().join("run");
        let o = agvrl(&[
            "train",
            "--config",
            cfg.to_str().unwrap(),
            "--set",
            "ppo.learning_rate=0.001",
            "--set",
            "env_config.max_steps=60",
            "--set",
            "env_config.spawn=fixed",
            "--set",
            "steps=256",
            "--out",
            run.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let written = std::fs::read_to_string(run.join("config.toml")).unwrap();
        for line in [
            "learning_rate = 0.001",
            "max_steps = 60",
            "spawn = \"fixed\"",
            "steps = 256",
        ] {
            assert!(written.lines().any(|l| l.trim() == line), "{line} in\n{written}");
        }
        let o = agvrl(&[
            "train",
            "--config",
            cfg.to_str().unwrap(),
            "--set",
            "ppo.lerning_rate=1",
        ]);
        assert!(stderr(&o).contains("unknown field `lerning_rate`"), "{}", stderr(&o));
        let o = agvrl(&["train", "--set", "steps"]);
        assert!(stderr(&o).contains("--set steps: expected KEY=VALUE"), "{}", stderr(&o));
    }

    #[test]
    fn trainings_started_together_get_run_directories_of_their_own() {
        let d = tmp("together");
        let cfg = tiny_config(d.path());
        let children: Vec<_> = (0..3)
            .map(|_| {
                Command::new(env!("CARGO_BIN_EXE_agvrl"))
                    .current_dir(d.path())
                    .args(["train", "--config", cfg.to_str().unwrap(), "--progress", "none"])
                    .stdout(Stdio::piped())
                    .stderr(Stdio::piped())
                    .spawn()
                    .unwrap()
            })
            .collect();
        let mut dirs: Vec<String> = children
            .into_iter()
            .map(|c| {
                let o = c.wait_with_output().unwrap();
                assert!(o.status.success(), "{}", stderr(&o));
                stdout(&o)
                    .lines()
                    .find_map(|l| l.strip_prefix("run_dir="))
                    .unwrap()
                    .to_string()
            })
            .collect();
        dirs.sort();
        dirs.dedup();
        assert_eq!(dirs.len(), 3, "{dirs:?}");
        for dir in &dirs {
            let dir = d.path().join(dir);
            for f in ["config.toml", "policy.agvrl", "metrics.csv", "eval.txt"] {
                assert!(dir.join(f).is_file(), "{}/{f}", dir.display());
            }
        }
        let partial = std::fs::read_dir(d.path().join("runs"))
            .unwrap()
            .filter(|e| e.as_ref().unwrap().file_name().to_string_lossy().ends_with(".partial"))
            .count();
        assert_eq!(partial, 0);
    }
}

mod racing_against_others {
    use super::*;

    fn key<'a>(line: &'a str, k: &str) -> &'a str {
        line.split_whitespace()
            .find_map(|kv| kv.strip_prefix(&format!("{k}=")))
            .unwrap_or_else(|| panic!("no {k}= in {line}"))
    }

    /// configs/duel.toml trains by self-play (a tiny run, twice: the same policy file, bit for
    /// bit); the policy drives alone in `eval`, and `agvrl race` races it against the shipped
    /// single-car policy: a line per car, the first race's paths drawn, and a recording with
    /// every car its own entity.
    #[test]
    fn self_play_trains_a_duel_policy_that_races_the_single_car_one() {
        let d = tmp("duel");
        let train = |out: &Path| {
            let o = agvrl(&[
                "train",
                "--config",
                "configs/duel.toml",
                "--set",
                "steps=1024",
                "--set",
                "n_envs=2",
                "--set",
                "ppo.n_steps=128",
                "--set",
                "ppo.batch_size=64",
                "--set",
                "ppo.n_epochs=1",
                "--set",
                "eval_episodes=1",
                "--set",
                "eval_max_steps=60",
                "--set",
                "env_config.max_steps=100",
                "--out",
                out.to_str().unwrap(),
            ]);
            assert!(o.status.success(), "{}", stderr(&o));
            std::fs::read(out.join("policy.agvrl")).unwrap()
        };
        let (a, b) = (train(&d.path().join("a")), train(&d.path().join("b")));
        assert!(a == b, "the same self-play run twice gives the same policy file");
        let policy = d.path().join("a/policy.agvrl");
        let eval = agvrl(&[
            "eval",
            "--policy",
            policy.to_str().unwrap(),
            "--episodes",
            "1",
            "--max-steps",
            "50",
        ]);
        assert!(eval.status.success(), "{}", stderr(&eval));
        assert!(stdout(&eval).contains("env=racing-oval") && stdout(&eval).contains("track=bean"));
        let (png, rrd) = (d.path().join("race.png"), d.path().join("race.rrd"));
        let o = agvrl(&[
            "race",
            "--policy",
            policy.to_str().unwrap(),
            "--policy",
            "assets/policies/racing-oval-ppo.agvrl",
            "--races",
            "2",
            "--max-steps",
            "120",
            "--plot",
            png.to_str().unwrap(),
            "--rerun",
            rrd.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let out = stdout(&o);
        let cars: Vec<&str> = out.lines().filter(|l| l.starts_with("car=")).collect();
        assert_eq!(cars.len(), 2, "{out}");
        assert!(out.contains("track=bean cars=2 races=2"), "{out}");
        let wins: f64 = cars.iter().map(|l| key(l, "win_rate").parse::<f64>().unwrap()).sum();
        assert!((wins - 1.0).abs() < 1e-9, "one winner a race: {out}");
        for l in &cars {
            for k in [
                "mean_place",
                "laps_per_race",
                "encounters",
                "passes",
                "pass_success",
                "at_fault_incidents",
                "at_fault_share",
                "wins_from_behind",
                "contacts_per_race",
                "time_lost_s_per_race",
                "crashes",
            ] {
                key(l, k);
            }
        }
        let (w, h, colours) = png_summary(&png);
        assert!(w > 400 && h > 300 && colours > 5, "{w}x{h}, {colours} colours");
        rrd_check(
            &rrd,
            &["world/car_0", "world/car_1", "world/paths/car_1", "world/lidar/car_0"],
        );
        // On generated circuits, a new one each race, from a start 2 m behind pure pursuit at
        // 0.75 of its speed: every race begins with an encounter for car 0.
        let circuits = |extra: &[&str]| {
            let args = [
                &[
                    "race",
                    "--policy",
                    "assets/policies/racing-any-track.agvrl",
                    "--racer",
                    "pure-pursuit@0.75",
                    "--circuits",
                    "--start-behind",
                    "--races",
                    "2",
                    "--max-steps",
                    "150",
                ][..],
                extra,
            ]
            .concat();
            let o = agvrl(&args);
            assert!(o.status.success(), "{}", stderr(&o));
            stdout(&o)
        };
        let json = d.path().join("race.json");
        let out = circuits(&["--json", json.to_str().unwrap()]);
        assert!(out.contains("track=circuits cars=2 races=2"), "{out}");
        // --json holds the printed figures, and every race falls in one width band.
        let report = agvrl_run::RaceReport::load(&json).unwrap();
        assert_eq!(
            report.text(),
            out.lines()
                .filter(|l| !l.starts_with("json="))
                .map(|l| format!("{l}\n"))
                .collect::<String>()
        );
        for (i, all) in report.figures.iter().enumerate() {
            let bands: Vec<&agvrl_run::CarFigures> = report.by_width.iter().map(|b| &b.figures[i]).collect();
            assert_eq!(bands.iter().map(|f| f.races).sum::<usize>(), 2, "{out}");
            assert_eq!(bands.iter().map(|f| f.encounters).sum::<u64>(), all.encounters, "{out}");
            assert_eq!(
                bands.iter().map(|f| f.at_fault_incidents).sum::<u64>(),
                all.at_fault_incidents,
                "{out}"
            );
            let km: f64 = bands.iter().map(|f| f.covered_km).sum();
            assert!((km - all.covered_km).abs() < 1e-9 && all.covered_km > 0.0, "{out}");
        }
        let car = |i: usize| out.lines().find(|l| l.starts_with(&format!("car={i} "))).unwrap();
        assert_eq!(key(car(0), "starts_behind"), "2", "{out}");
        assert_eq!(key(car(1), "starts_behind"), "0", "{out}");
        assert_eq!(key(car(1), "policy"), "pure-pursuit@0.75", "{out}");
        assert!(key(car(0), "encounters").parse::<u32>().unwrap() >= 2, "{out}");
        assert!(out.contains(" split=held_out"), "{out}");
        // --train-split races the training half of the seed space.
        let train = circuits(&["--train-split"]);
        assert!(train.contains(" split=train"), "{train}");
        let o = agvrl(&["race", "--policy", "a.agvrl", "--policy", "b.agvrl", "--cars", "3"]);
        assert!(!o.status.success());
        assert_eq!(
            stderr(&o).trim(),
            "error: 2 policies for 3 cars: give one policy per car, or one for all"
        );
    }
}
