//! Policy files and checkpoints: round trip, rejection of corrupt, truncated and mismatching
//! files, size bound.

use crate::reach::vec_env;
use agvrl_envs::{Env, make};
use agvrl_rl::{Control, Policy, PolicyData, Ppo, PpoConfig, RlError, Sac, SacConfig, default_device};
use std::path::PathBuf;

fn tmp(name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("agvrl-rl-tests");
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(format!("{name}-{}", std::process::id()))
}

fn small_sac(seed: u64) -> Sac<crate::reach::Reach> {
    let cfg = SacConfig {
        net_arch: vec![32, 32],
        batch_size: 32,
        learning_starts: 50,
        normalize_obs: true,
        ..SacConfig::default()
    };
    let mut sac = Sac::new(cfg, vec_env(2), &default_device(), seed).unwrap();
    sac.learn(200, &mut |_| Control::Continue).unwrap();
    sac
}

#[test]
fn policy_round_trip_gives_the_same_actions() {
    let sac = small_sac(0);
    let path = tmp("sac.policy");
    sac.save_policy(&path).unwrap();
    let loaded = PolicyData::load(&path).unwrap();
    assert_eq!(loaded, sac.policy_data());
    let mut a = Policy::load(&path).unwrap();
    let mut b = sac.policy(&default_device());
    let obs = [0.3, -0.2, -0.5, 0.9];
    let (xa, xb) = (a.act(&obs, true).unwrap(), b.act(&obs, true).unwrap());
    assert_eq!(xa, xb);
    assert_eq!(xa.len(), 2);
    assert!(xa.iter().all(|v| (-2.0..=2.0).contains(v)));
}

/// The ndarray backend (built with `--features ndarray`) reads the same file and agrees to float
/// tolerance.
#[cfg(feature = "ndarray")]
#[test]
fn a_policy_file_acts_alike_on_the_ndarray_backend() {
    let sac = small_sac(0);
    let path = tmp("sac-ndarray.policy");
    sac.save_policy(&path).unwrap();
    let obs = [0.3, -0.2, -0.5, 0.9];
    let xa = Policy::load(&path).unwrap().act(&obs, true).unwrap();
    let mut c = Policy::load_on(&path, &agvrl_rl::CpuBackend::NdArray.device()).unwrap();
    let xc = c.act(&obs, true).unwrap();
    assert!(xa.iter().zip(&xc).all(|(p, q)| (p - q).abs() < 1e-4), "{xa:?} {xc:?}");
}

#[test]
fn corrupted_truncated_and_foreign_files_are_rejected() {
    let sac = small_sac(1);
    let path = tmp("corrupt.policy");
    sac.save_policy(&path).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let is_bad_file = |b: &[u8]| {
        std::fs::write(&path, b).unwrap();
        matches!(Policy::load(&path), Err(RlError::BadFile { .. }))
    };
    let mut flipped = bytes.clone();
    let mid = bytes.len() / 2;
    flipped[mid] ^= 0x10;
    assert!(is_bad_file(&flipped));
    assert!(is_bad_file(&bytes[..bytes.len() - 1]));
    assert!(is_bad_file(&bytes[..bytes.len() / 3]));
    assert!(is_bad_file(b"not a policy"));
    // A checkpoint is not a policy file.
    let ck = tmp("as-policy.ckpt");
    sac.save_checkpoint(&ck).unwrap();
    let e = Policy::load(&ck).err().unwrap().to_string();
    assert!(e.contains("not an agvrl policy file"), "{e}");
}

#[test]
fn policy_for_another_env_is_rejected() {
    let sac = small_sac(2);
    let policy = sac.policy(&default_device());
    let pendulum = make("pendulum", &agvrl_envs::EnvConfig::default()).unwrap();
    let e = policy
        .check_spaces(&pendulum.observation_space(), &pendulum.action_space())
        .unwrap_err();
    assert!(
        matches!(
            e,
            RlError::Mismatch {
                what: "observation space",
                ..
            }
        ),
        "{e}"
    );
    let mut env = make("pendulum", &agvrl_envs::EnvConfig::default()).unwrap();
    assert!(agvrl_rl::evaluate(&mut sac.policy(&default_device()), &mut env, 1, 0).is_err());
    let mut p = sac.policy(&default_device());
    assert!(matches!(p.act(&[1.0, 2.0, 3.0], true), Err(RlError::Shape { .. })));
}

#[test]
fn a_large_sac_policy_file_stays_under_10_mb() {
    // obs 100, act 2, [256, 256]: the size `agvrl bench` times.
    struct Wide;
    impl Env for Wide {
        fn observation_space(&self) -> agvrl_envs::BoxSpace {
            agvrl_envs::BoxSpace::uniform(100, -1.0, 1.0)
        }
        fn action_space(&self) -> agvrl_envs::BoxSpace {
            agvrl_envs::BoxSpace::uniform(2, -1.0, 1.0)
        }
        fn reset(&mut self, _: Option<u64>) -> Result<(Vec<f32>, agvrl_envs::Info), agvrl_envs::EnvError> {
            Ok((vec![0.0; 100], agvrl_envs::Info::default()))
        }
        fn step(&mut self, _: &[f32]) -> Result<agvrl_envs::Step, agvrl_envs::EnvError> {
            unreachable!("only the spaces are used")
        }
        fn dt_s(&self) -> f64 {
            0.05
        }
    }
    let env = agvrl_envs::VecEnv::new(vec![Wide], 1).unwrap();
    let sac = Sac::new(SacConfig::default(), env, &default_device(), 0).unwrap();
    let bytes = sac.policy_data().to_bytes().unwrap();
    assert!(bytes.len() < 10 * 1024 * 1024, "{}", bytes.len());
    assert!(bytes.len() > 4 * (100 * 256 + 256 * 256), "weights are in the file");
}

/// A checkpoint loads only into its own algorithm on its own env, and not once truncated.
/// (That a resumed learner trains on as if never stopped: resume.rs.)
#[test]
fn checkpoints_of_another_algorithm_another_env_or_truncated_are_refused() {
    let sac = small_sac(3);
    let a = tmp("sac-a.ckpt");
    sac.save_checkpoint(&a).unwrap();
    assert!(Sac::load_checkpoint(&a, vec_env(2), &default_device()).is_ok());
    assert!(matches!(
        Ppo::load_checkpoint(&a, vec_env(2), &default_device()),
        Err(RlError::Mismatch { .. })
    ));
    let pend = agvrl_envs::VecEnv::new(vec![make("pendulum", &agvrl_envs::EnvConfig::default()).unwrap()], 1).unwrap();
    assert!(matches!(
        Sac::load_checkpoint(&a, pend, &default_device()),
        Err(RlError::Mismatch { .. })
    ));
    let cfg = PpoConfig {
        n_steps: 64,
        net_arch: vec![16],
        normalize_obs: true,
        ..PpoConfig::default()
    };
    let mut ppo = Ppo::new(cfg, vec_env(2), &default_device(), 4).unwrap();
    ppo.learn(128, &mut |_| Control::Continue).unwrap();
    let b = tmp("ppo-b.ckpt");
    ppo.save_checkpoint(&b).unwrap();
    assert!(Ppo::load_checkpoint(&b, vec_env(2), &default_device()).is_ok());
    let mut bytes = std::fs::read(&b).unwrap();
    bytes.truncate(bytes.len() - 7);
    std::fs::write(&b, &bytes).unwrap();
    assert!(matches!(
        Ppo::load_checkpoint(&b, vec_env(2), &default_device()),
        Err(RlError::BadFile { .. })
    ));
}

#[test]
fn gsde_policy_round_trip_and_stochastic_actions() {
    let cfg = PpoConfig {
        n_steps: 64,
        use_sde: true,
        sde_sample_freq: 4,
        ..PpoConfig::default()
    };
    let mut ppo = Ppo::new(cfg, vec_env(2), &default_device(), 6).unwrap();
    ppo.learn(256, &mut |_| Control::Continue).unwrap();
    let path = tmp("gsde.policy");
    ppo.save_policy(&path).unwrap();
    let mut a = Policy::load(&path).unwrap();
    let mut b = ppo.policy(&default_device());
    let obs = [0.5, -0.25];
    assert_eq!(a.act(&obs, true).unwrap(), b.act(&obs, true).unwrap());
    a.seed(1);
    let samples: Vec<f32> = (0..50).map(|_| a.act(&obs, false).unwrap()[0]).collect();
    assert!(samples.iter().all(|v| (-2.0..=2.0).contains(v)));
    let spread = samples.iter().cloned().fold(f32::MIN, f32::max) - samples.iter().cloned().fold(f32::MAX, f32::min);
    assert!(spread > 1e-3, "stochastic gSDE actions vary: {spread}");
}

/// Generated network shapes, heads and spaces.
mod properties {
    use super::*;
    use proptest::prelude::*;

    /// An env of given widths; only its spaces are used.
    struct Shaped {
        obs: usize,
        act: usize,
    }

    impl Env for Shaped {
        fn observation_space(&self) -> agvrl_envs::BoxSpace {
            agvrl_envs::BoxSpace::uniform(self.obs, -2.0, 3.0)
        }
        fn action_space(&self) -> agvrl_envs::BoxSpace {
            agvrl_envs::BoxSpace::uniform(self.act, -1.0, 0.5)
        }
        fn reset(&mut self, _: Option<u64>) -> Result<(Vec<f32>, agvrl_envs::Info), agvrl_envs::EnvError> {
            Ok((vec![0.0; self.obs], agvrl_envs::Info::default()))
        }
        fn step(&mut self, _: &[f32]) -> Result<agvrl_envs::Step, agvrl_envs::EnvError> {
            unreachable!("only the spaces are used")
        }
        fn dt_s(&self) -> f64 {
            0.05
        }
    }

    fn shaped(obs: usize, act: usize) -> agvrl_envs::VecEnv<Shaped> {
        agvrl_envs::VecEnv::new(vec![Shaped { obs, act }], 1).unwrap()
    }

    /// 0: SAC (squashed Gaussian); 1: PPO (Gaussian); 2: PPO with gSDE.
    fn learner(
        kind: u8,
        obs: usize,
        act: usize,
        net_arch: Vec<usize>,
        normalize_obs: bool,
        seed: u64,
    ) -> (Option<Ppo<Shaped>>, Option<Sac<Shaped>>) {
        if kind == 0 {
            let cfg = SacConfig {
                net_arch,
                normalize_obs,
                buffer_size: 16,
                ..SacConfig::default()
            };
            (
                None,
                Some(Sac::new(cfg, shaped(obs, act), &default_device(), seed).unwrap()),
            )
        } else {
            let cfg = PpoConfig {
                net_arch,
                normalize_obs,
                use_sde: kind == 2,
                n_steps: 8,
                batch_size: 8,
                ..PpoConfig::default()
            };
            (
                Some(Ppo::new(cfg, shaped(obs, act), &default_device(), seed).unwrap()),
                None,
            )
        }
    }

    /// `bytes` with byte `at` (of its length) XORed with `flip` (non-zero).
    fn flipped(bytes: &[u8], at: prop::sample::Index, flip: u8) -> Vec<u8> {
        let mut b = bytes.to_vec();
        let i = at.index(b.len());
        b[i] ^= flip;
        b
    }

    prop_compose! {
        /// A learner kind (see [`learner`]), observation and action widths, hidden layers, a
        /// normaliser or not, and a seed.
        fn shape()(
            kind in 0u8..3,
            obs in 1usize..12,
            act in 1usize..4,
            net_arch in prop::collection::vec(1usize..24, 1..4),
            normalize_obs: bool,
            seed: u64,
        ) -> (u8, usize, usize, Vec<usize>, bool, u64) {
            (kind, obs, act, net_arch, normalize_obs, seed)
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(48))]

        /// A policy file reads back to the same policy; a file with any byte changed is
        /// refused.
        #[test]
        fn policy_files_round_trip_and_a_flipped_byte_is_refused(
            (kind, obs, act, net_arch, normalize_obs, seed) in shape(),
            at: prop::sample::Index,
            flip in 1u8..=255,
        ) {
            let data = match learner(kind, obs, act, net_arch, normalize_obs, seed) {
                (Some(p), _) => p.policy_data(),
                (_, Some(s)) => s.policy_data(),
                _ => unreachable!(),
            };
            let bytes = data.to_bytes().unwrap();
            let path = std::path::Path::new("generated.agvrl");
            prop_assert_eq!(&PolicyData::from_bytes(path, &bytes).unwrap(), &data);
            let bad = PolicyData::from_bytes(path, &flipped(&bytes, at, flip));
            prop_assert!(matches!(bad, Err(RlError::BadFile { .. })), "{:?}", bad.map(|_| ()));
        }

        /// A checkpoint resumes to a learner that writes the same bytes; a checkpoint with
        /// any byte changed is refused.
        #[test]
        fn checkpoints_round_trip_and_a_flipped_byte_is_refused(
            (kind, obs, act, net_arch, normalize_obs, seed) in shape(),
            at: prop::sample::Index,
            flip in 1u8..=255,
        ) {
            let (a, b) = (tmp("prop-a.ckpt"), tmp("prop-b.ckpt"));
            let device = default_device();
            let resumed = match learner(kind, obs, act, net_arch, normalize_obs, seed) {
                (Some(p), _) => {
                    p.save_checkpoint(&a).unwrap();
                    Ppo::load_checkpoint(&a, shaped(obs, act), &device).unwrap().save_checkpoint(&b)
                }
                (_, Some(s)) => {
                    s.save_checkpoint(&a).unwrap();
                    Sac::load_checkpoint(&a, shaped(obs, act), &device).unwrap().save_checkpoint(&b)
                }
                _ => unreachable!(),
            };
            resumed.unwrap();
            let bytes = std::fs::read(&a).unwrap();
            prop_assert!(bytes == std::fs::read(&b).unwrap(), "the resumed learner writes other bytes");
            std::fs::write(&a, flipped(&bytes, at, flip)).unwrap();
            let refused = if kind == 0 {
                Sac::load_checkpoint(&a, shaped(obs, act), &device).map(|_| ())
            } else {
                Ppo::load_checkpoint(&a, shaped(obs, act), &device).map(|_| ())
            };
            prop_assert!(matches!(refused, Err(RlError::BadFile { .. })), "{refused:?}");
        }
    }
}
