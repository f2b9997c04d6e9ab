//! What a sweep driver relies on: JSON progress, SIGTERM and a dead parent stop a training with
//! a complete run directory, `--set`, and run directories that never collide.

use crate::{agvrl, json_lines, stderr, stdout, tiny_config, tmp};
use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::Command;
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
