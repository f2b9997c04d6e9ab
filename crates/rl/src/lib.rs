//! agvrl-rl: SAC and PPO in Burn with Stable-Baselines3's defaults, generic over any
//! [`agvrl_envs::Env`].
//!
//! ```text
//! VecEnv<E> --obs--> actor (Burn, plain device) --action--> VecEnv<E>
//!     |                                                         |
//!     +-- SAC: ReplayBuffer --sample--> sac/update.rs ----------+  (every train_freq steps)
//!     +-- PPO: Rollout + GAE ---------> ppo/update.rs ----------+  (every n_steps)
//! learner --policy_data()--> PolicyData --save--> policy file --load--> Policy::act (eval, deploy)
//! learner --save_checkpoint--> checkpoint --load_checkpoint--> learner (resume)
//! ```
//!
//! Entry points: [`Sac::new`] / [`Ppo::new`] (config, `VecEnv`, device, seed), `learn(steps,
//! callback)` with [`Progress`] and [`Control`], `save_policy`, `save_checkpoint` /
//! `load_checkpoint`, [`Policy::load`] + [`Policy::act`], [`evaluate`], [`bench::run`],
//! [`learning::pendulum_sac`] / [`learning::pendulum_ppo`].
//!
//! Invariants:
//! - The learners know nothing of vehicles: observations and actions are flat `f32` rows; the
//!   action space's box is honoured (SAC maps `[-1, 1]` onto it, PPO clips to it).
//! - With `image` in the config, the last `C*H*W` values of a row are an image in [0, 1]
//!   encoded by a NatureCNN ([`cnn`]) and never normalised; without it nothing differs from
//!   an MLP-only build, bit for bit.
//! - Termination stops bootstrapping, truncation bootstraps from `Info::final_obs`.
//! - All randomness comes from one seeded [`rng::Rng`] per learner: the same seed on one thread
//!   gives the same run, bit for bit (also for a fixed `Sac::set_threads` count).
//! - The Burn `Device` is chosen by the caller ([`device`]); weights are held on the host and
//!   mirrored to the device, so a policy file loads on any backend without autodiff.
//! - Files (policy, checkpoint) are written atomically and carry a CRC-32; a truncated,
//!   corrupted or mismatching file is an error, never a silently wrong policy.
//!
//! Features: none; both CPU backends (flex, the default, and ndarray) are always built and
//! picked at run time with [`CpuBackend`].
//!
//! Limitations: gSDE for PPO only (not SAC), no discrete actions, no learning-rate
//! schedules; envs restart their episodes on resume (the `Env` trait has no state snapshot);
//! policy files use agvrl's own container (see `file.rs`), not burn-store, because the
//! weights are plain stacked tensors rather than `Module`s.

#![warn(missing_docs)]

pub mod bench;
mod buffer;
mod checkpoint;
pub mod cnn;
pub mod device;
mod error;
pub mod eval;
mod file;
pub mod learning;
pub mod nets;
pub mod normalize;
pub mod policy;
pub mod ppo;
mod progress;
pub mod rng;
pub mod sac;

pub use buffer::ReplayBuffer;
pub use checkpoint::CHECKPOINT_FORMAT_VERSION;
pub use cnn::ImageSpec;
pub use device::{CpuBackend, default_device, device_by_name};
pub use error::{Result, RlError};
pub use eval::evaluate;
pub use normalize::ObsNormalizer;
pub use policy::{Algorithm, EncoderData, POLICY_FORMAT_VERSION, Policy, PolicyData};
pub use ppo::{Ppo, PpoConfig};
pub use progress::{Control, Losses, Progress};
pub use sac::{Sac, SacConfig};

/// Re-exported so callers can name the device without depending on Burn.
pub use burn::tensor::Device;
