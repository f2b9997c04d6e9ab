//! Run directories: `train` writes a complete one (plots and recording included) that `eval` reads,
//! and Ctrl-C leaves one that `train --resume` continues.

use crate::{agvrl, key, png_summary, rrd_check, stderr, stdout, tiny_config, tmp};
use std::path::PathBuf;
use std::process::Command;

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
