//! The bodies of the fuzz targets on policy files and checkpoints (`fuzz/`, cargo-fuzz on
//! nightly), here so that the inputs they kept replay on stable (`fuzz_regressions_*`).
//!
//! Both formats end in a CRC-32, which random bytes never match: an input is the file without
//! its last four bytes, and the body appends the checksum, so mutations reach the decoder behind
//! it.

use crate::file::crc32;

/// `body` with its CRC-32 appended: a file the checksum accepts.
pub fn with_crc(body: &[u8]) -> Vec<u8> {
    let mut bytes = body.to_vec();
    bytes.extend_from_slice(&crc32(body).to_le_bytes());
    bytes
}

/// `checkpoint`: byte 0 picks PPO (even) or SAC (odd); the rest is a checkpoint for the
/// `pendulum` env without its checksum, loaded as `train --resume` loads one, and a resumed
/// learner's policy written back out.
#[cfg(feature = "train")]
pub fn checkpoint(data: &[u8]) {
    use crate::{Ppo, Sac, default_device};
    let Some((&which, body)) = data.split_first() else {
        return;
    };
    let path = std::env::temp_dir().join(format!("agvrl-fuzz-{}.ckpt", std::process::id()));
    if std::fs::write(&path, with_crc(body)).is_err() {
        return;
    }
    let env = || {
        let cfg = agvrl_envs::EnvConfig::default();
        agvrl_envs::VecEnv::new(vec![agvrl_envs::make("pendulum", &cfg).expect("pendulum")], 1).expect("one env")
    };
    let device = default_device();
    let policy = if which % 2 == 0 {
        Ppo::load_checkpoint(&path, env(), &device).map(|l| l.policy_data())
    } else {
        Sac::load_checkpoint(&path, env(), &device).map(|l| l.policy_data())
    };
    let _ = std::fs::remove_file(&path);
    if let Ok(p) = policy {
        p.to_bytes().expect("a loaded learner's policy encodes");
    }
}
