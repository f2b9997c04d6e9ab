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
//! `load_checkpoint`, [`Policy::load`] + [`Policy::act`], [`evaluate`],
//! [`learning::sac_parity`] / [`learning::ppo_parity`].
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
//! - Each network is laid out once (PPO's `Layout`, SAC's `NetParts`, over [`nets::MlpSpec`]
//!   and [`cnn::ImageSpec`]) and runs on one of two paths ([`NetPath`]): Burn's tensors and
//!   autodiff on the device (`ppo/network.rs`, `sac/update.rs`; the default on a GPU), or the
//!   host kernels on the same weights (`ppo/host.rs`, `sac/host.rs`, `host_cnn.rs`; the default
//!   on the CPU backends, the fast path). Both compute the same losses and gradients to 1e-5
//!   of their scale (the `burn_path_*` tests); the loss heads, Adam and the action sampling are
//!   the same code on either. SAC with an image runs through Burn on either path. A
//!   [`Policy`] runs through Burn unless set to the host path, where it computes the host
//!   rollout's forward pass bit for bit.
//! - Files (policy, checkpoint) are written atomically and carry a CRC-32; a truncated,
//!   corrupted or mismatching file is an error, never a silently wrong policy.
//!
//! Features (both default): `train`, the learners and everything that needs Burn's autodiff
//! (SAC, PPO, checkpoints, `learning`); `ndarray`, a second CPU backend beside flex,
//! picked at run time with [`CpuBackend`]. Without them the crate is inference only
//! ([`Policy`], [`evaluate`], on flex), which is what agvrl-drive links.
//!
//! Why the weights are not Burn `Module`s: every network is a stack of members evaluated with
//! one batched matmul per layer (the twin critics, PPO's actor and critic trunks), Adam runs as
//! one fused host loop over a flat tensor list, and checkpoints and policy files write that list
//! in order. Each learner names the parts of its list in one place (PPO's `Layout`, SAC's
//! `NetParts`), so adding a part is a field there, not a renumbering of uses.
//!
//! Limitations: gSDE for PPO only (not SAC), no discrete actions, no learning-rate
//! schedules; envs restart their episodes on resume (the `Env` trait has no state snapshot);
//! policy files use agvrl's own container (see `file.rs`), not burn-store, because the
//! weights are plain stacked tensors rather than `Module`s.

#![warn(missing_docs)]

pub mod adam;
#[cfg(feature = "train")]
mod buffer;
#[cfg(feature = "train")]
mod checkpoint;
pub mod cnn;
pub mod config;
pub mod device;
mod error;
pub mod eval;
mod file;
#[doc(hidden)]
pub mod fuzz;
#[cfg(feature = "train")]
mod gaussian;
pub mod host_cnn;
mod host_gemm;
#[cfg(feature = "train")]
mod learner;
#[cfg(feature = "train")]
pub mod learning;
pub mod nets;
pub mod normalize;
pub mod policy;
#[cfg(feature = "train")]
pub mod ppo;
#[cfg(feature = "train")]
mod progress;
pub mod rng;
#[cfg(feature = "train")]
pub mod sac;

#[cfg(feature = "train")]
pub use buffer::ReplayBuffer;
#[cfg(feature = "train")]
pub use checkpoint::CHECKPOINT_FORMAT_VERSION;
pub use cnn::ImageSpec;
pub use config::{EntCoef, PpoConfig, SacConfig};
pub use device::{CpuBackend, DeviceChoice, NetPath, default_device, device_by_name};
pub use error::{Result, RlError};
pub use eval::evaluate;
#[cfg(feature = "train")]
pub use learner::Learner;
pub use normalize::ObsNormalizer;
pub use policy::{Algorithm, EncoderData, POLICY_FORMAT_VERSION, Policy, PolicyData};
#[cfg(feature = "train")]
pub use ppo::Ppo;
#[cfg(feature = "train")]
pub use progress::{Control, Losses, Progress};
#[cfg(feature = "train")]
pub use sac::Sac;

/// Re-exported so callers can name the device without depending on Burn.
pub use burn::tensor::Device;

/// The pool a learner's gradient steps run on with `threads` threads (the caller's included):
/// its VecEnv's own when that has as many, since stepping the envs and updating the networks
/// take turns; else a pool of its own.
#[cfg(feature = "train")]
fn shared_workers<E: agvrl_envs::Env>(
    env: &agvrl_envs::VecEnv<E>,
    threads: usize,
    learner: &str,
) -> Result<std::sync::Arc<agvrl_envs::Workers>> {
    if env.workers().len() + 1 == threads {
        return Ok(env.workers().clone());
    }
    agvrl_envs::Workers::new(threads - 1)
        .map(std::sync::Arc::new)
        .map_err(|e| RlError::Internal(format!("cannot start {learner} worker threads: {e}")))
}
