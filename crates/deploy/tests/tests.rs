//! agvrl-deploy integration tests, one binary with a module per topic: the drive loop's watchdog
//! and policy checks, ROS 2 over DDS on loopback, agvrl-drive as shipped, bags and replays, damaged
//! inputs, classical racers. The helpers here (shipped policies, scratch directories, agvrl-drive's
//! command line) serve several topics.

mod agvrl_drive;
mod bags;
mod damaged_inputs;
mod racers;
mod replay;
#[cfg(feature = "ros2")]
mod ros2_loopback;
mod watchdog;

/// A shipped policy of assets/policies.
fn shipped_policy(name: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../../assets/policies/{name}.agvrl"))
}

/// A scratch directory, removed when the test ends, passed or failed.
fn scratch(name: &str) -> tempfile::TempDir {
    tempfile::Builder::new()
        .prefix(&format!("agvrl-{name}-"))
        .tempdir()
        .unwrap()
}

/// Run agvrl-drive with `args`; (success, stdout, stderr).
fn drive_cli(args: &[&std::ffi::OsStr]) -> (bool, String, String) {
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_agvrl-drive"))
        .args(args)
        .output()
        .unwrap();
    (
        o.status.success(),
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

/// `agvrl-drive --policy POLICY --replay BAG --fast --check --tolerance 0`: the same bits on the
/// CPU that recorded.
fn replay_check(policy: &std::path::Path, bag: &std::path::Path) -> (bool, String, String) {
    drive_cli(&[
        "--policy".as_ref(),
        policy.as_os_str(),
        "--replay".as_ref(),
        bag.as_os_str(),
        "--fast".as_ref(),
        "--check".as_ref(),
        "--quiet".as_ref(),
        "--tolerance".as_ref(),
        "0".as_ref(),
    ])
}

/// The `key=value` of a summary line.
fn kv(out: &str, key: &str) -> f64 {
    out.split_whitespace()
        .find_map(|w| w.strip_prefix(&format!("{key}=")))
        .unwrap_or_else(|| panic!("no {key} in {out}"))
        .parse()
        .unwrap()
}
