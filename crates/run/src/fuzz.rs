//! The bodies of the fuzz targets on the run TOML and the policy file as a policy's user reads
//! them (`fuzz/`, cargo-fuzz on nightly), here so that the inputs they kept replay on stable
//! (`fuzz_regressions_*`).

use crate::{PolicySettings, RunConfig};
use agvrl_envs::Env;
use agvrl_rl::{Policy, PolicyData};
use std::path::Path;

/// `run_toml`: text through [`RunConfig::from_toml`]; a config it accepts writes back to a TOML
/// that reads to the same config, and its evaluation env is made, reset and stepped once.
pub fn run_toml(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let Ok(cfg) = RunConfig::from_toml(text, "fuzz.toml") else {
        return;
    };
    let written = cfg.to_toml().expect("an accepted config writes");
    let again = RunConfig::from_toml(&written, "written").expect("a written config reads back");
    assert_eq!(
        again.to_toml().expect("writes"),
        written,
        "the TOML round trip changed the config"
    );
    drive_once(&cfg);
}

/// The env of `cfg` made with its evaluation settings, reset and stepped once with a zero action.
fn drive_once(cfg: &RunConfig) {
    let Ok(mut env) = agvrl_envs::make(&cfg.env, &cfg.eval_env_config()) else {
        return;
    };
    if env.reset(Some(cfg.seed)).is_ok() {
        let _ = env.step(&vec![0.0; env.action_space().dim()]);
    }
}

/// `policy_file`: a policy file without its checksum (see `agvrl_rl::fuzz`), read as
/// `--policy FILE` reads one: decoded, its embedded settings resolved, and the policy acting
/// once, deterministically and not, on a zero observation.
pub fn policy_file(data: &[u8]) {
    let path = Path::new("fuzz.agvrl");
    let Ok(policy) = PolicyData::from_bytes(path, &agvrl_rl::fuzz::with_crc(data)) else {
        return;
    };
    if let Ok(settings) = PolicySettings::of_policy(path, &policy, &[]) {
        let _ = (settings.drive_env_config(), settings.eval_env_config());
    }
    let obs = vec![0.0; policy.observation_space.dim()];
    let mut policy = Policy::new(policy, &agvrl_rl::default_device());
    for deterministic in [true, false] {
        let _ = policy.act(&obs, deterministic);
    }
}
