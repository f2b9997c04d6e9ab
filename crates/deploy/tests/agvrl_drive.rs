//! agvrl-drive as shipped: what it links, the shipped policies driving every search scene and a
//! held-out circuit on the simulated car, a setting `agvrl train` would refuse, a closed stdout.

use crate::shipped_policy;

/// The deploy binary's dependency tree (normal edges, default features): no viewer, no
/// TLS / OpenSSL (a static link needs none), no zenoh, and inference only (no autodiff, no
/// second CPU backend). Cheaper than a static build in CI.
#[test]
fn deploy_links_no_rerun_openssl_zenoh_or_autodiff() {
    let cargo = option_env!("CARGO").unwrap_or("cargo");
    let out = std::process::Command::new(cargo)
        .args([
            "tree",
            "-p",
            "agvrl-deploy",
            "-e",
            "normal",
            "--prefix",
            "none",
            "--offline",
        ])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("cargo tree runs");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let tree = String::from_utf8(out.stdout).unwrap();
    let names: Vec<&str> = tree.lines().filter_map(|l| l.split_whitespace().next()).collect();
    assert!(names.contains(&"ros2-client"), "the ros2 feature is on by default");
    for bad in [
        "rerun",
        "openssl",
        "openssl-sys",
        "native-tls",
        "zenoh",
        "ring",
        "plotters",
        "burn-autodiff",
        "burn-optim",
        "burn-ndarray",
    ] {
        assert!(!names.contains(&bad), "agvrl-deploy depends on {bad}");
    }
}

/// The shipped search policy, with its settings file (the safety filter on), drives every
/// search scene in `agvrl-drive` on the simulated car without a termination or a watchdog stop.
#[test]
fn the_shipped_search_policy_drives_every_search_scene_in_agvrl_drive() {
    let policy = shipped_policy("search");
    for env in [
        "search-outdoor-20",
        "search-urban-20",
        "search-outdoor-50",
        "search-urban-50",
    ] {
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_agvrl-drive"))
            .arg("--policy")
            .arg(&policy)
            .args(["--env", env, "--steps", "1000", "--seed", "3", "--quiet"])
            .output()
            .unwrap();
        let out = String::from_utf8_lossy(&o.stdout);
        assert!(o.status.success(), "{env}: {}", String::from_utf8_lossy(&o.stderr));
        assert!(
            out.contains("summary ticks=1000 events=0 terminations=0 filter_interventions="),
            "{env}: {out}"
        );
    }
}

/// agvrl-drive reads a policy's settings with the run config type `agvrl train` writes: a
/// `--set` key `agvrl train` would refuse (a typo) stops the drive with the key named, instead
/// of driving on defaults; spelt right, it drives. A file of format 1 drives with the TOML
/// beside it.
#[test]
fn agvrl_drive_refuses_a_setting_that_agvrl_train_would_refuse() {
    let drive = |policy: &std::path::Path, set: &[&str]| {
        let mut c = std::process::Command::new(env!("CARGO_BIN_EXE_agvrl-drive"));
        c.arg("--policy").arg(policy).args(["--steps", "5", "--quiet"]);
        for s in set {
            c.args(["--set", s]);
        }
        c.output().unwrap()
    };
    let policy = shipped_policy("racing-oval-ppo");
    let o = drive(&policy, &["env_config.substepz=8"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("substepz"), "{err}");
    let o = drive(&policy, &["env_config.substeps=8"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let old = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../run/tests/fixtures/racing-v1.agvrl");
    let o = drive(&old, &[]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

/// A drive whose stdout is closed early (`agvrl-drive ... | head -1`) drives on to the end and
/// exits cleanly: printing never panics the control loop.
#[test]
fn a_closed_stdout_does_not_stop_the_drive() {
    use std::io::BufRead;
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_agvrl-drive"))
        .arg("--policy")
        .arg(shipped_policy("racing-oval-ppo"))
        .args(["--steps", "600"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut first = String::new();
    std::io::BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut first)
        .unwrap();
    assert!(first.starts_with("tick="), "{first}");
    // The reader is dropped here: later lines meet a closed pipe.
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success() && !err.contains("panicked"), "{err}");
}

/// The shipped generalist drives a held-out generated circuit (a seed from the evaluation half,
/// never trained on) in agvrl-drive: a full lap with no crash and no watchdog event.
#[test]
fn the_shipped_generalist_laps_a_held_out_circuit_in_agvrl_drive() {
    let seed = (agvrl_envs::heldout::EVAL_BIT | 5).to_string();
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_agvrl-drive"))
        .arg("--policy")
        .arg(shipped_policy("racing-any-track"))
        .args(["--steps", "9000", "--seed", &seed, "--quiet"])
        .output()
        .unwrap();
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(out.contains(" events=0 terminations=0 "), "{out}");
    assert!(!out.contains(" laps=0 "), "{out}");
}
