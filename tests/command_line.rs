//! The command line: an error is one line naming the file and the reason once, bad inputs, a closed
//! stdout, `probe`, `envs`, `bench --quick`, what `--help` says and bad choices listing the valid
//! ones.

use crate::{agvrl, stderr, stdout, tmp};
use std::process::Command;

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
fn help_says_the_defaults_a_user_must_know_and_bad_choices_list_the_valid_ones() {
    let h = stdout(&agvrl(&["train", "--help"]));
    for line in [
        "one gradient step per env step",
        "8 in",
        "configs/default.toml",
        "configs/racing-track.toml",
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
    // burn-ndarray (deprecated upstream) is not in the README's build; one line says how to add it,
    // before a run directory is made.
    let d = tmp("ndarray");
    let run = d.path().join("run");
    let o = agvrl(&[
        "train",
        "--device",
        "ndarray",
        "--steps",
        "64",
        "--out",
        run.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert_eq!(
        stderr(&o).trim(),
        "error: config: device 'ndarray' needs a build with the 'ndarray' feature: cargo build --release --features ndarray"
    );
    assert!(!run.exists());
}
