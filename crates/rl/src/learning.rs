//! Learning checks against published Stable-Baselines3 results on `pendulum` (Gymnasium's
//! Pendulum-v1). Each returns the mean return of 10 deterministic eval episodes.

use crate::device::default_device;
use crate::error::Result;
use crate::ppo::{Ppo, PpoConfig};
use crate::progress::Control;
use crate::sac::{Sac, SacConfig};
use agvrl_envs::{Env, VecEnv, make};

/// Episodes per evaluation (the protocol).
pub const EVAL_EPISODES: usize = 10;

fn pendulum_envs(n: usize) -> Result<VecEnv<Box<dyn Env>>> {
    let envs = (0..n)
        .map(|_| make("pendulum", &agvrl_envs::EnvConfig::default()))
        .collect::<std::result::Result<Vec<_>, _>>()?;
    Ok(VecEnv::new(envs, 1)?)
}

/// SAC with SB3's defaults on one pendulum env for `steps` steps; eval return after.
/// SB3 reaches -120, -118, -115 (seeds 0, 1, 2) at 20,000 steps.
pub fn pendulum_sac(seed: u64, steps: u64) -> Result<f64> {
    let device = default_device();
    let mut sac = Sac::new(SacConfig::default(), pendulum_envs(1)?, &device, seed)?;
    sac.learn(steps, &mut |_| Control::Continue)?;
    let mut env = make("pendulum", &agvrl_envs::EnvConfig::default())?;
    sac.evaluate(&mut env, EVAL_EPISODES, 1_000_000 + seed)
}

/// rl-zoo3's PPO hyperparameters for Pendulum-v1 (n_envs 4, n_steps 1024, batch 64,
/// gae_lambda 0.95, gamma 0.9, n_epochs 10, ent_coef 0, lr 1e-3, clip 0.2, use_sde,
/// sde_sample_freq 4); `use_sde = false` gives plain Gaussian exploration instead.
pub fn zoo_pendulum_ppo_config(use_sde: bool) -> PpoConfig {
    PpoConfig {
        n_steps: 1024,
        gamma: 0.9,
        learning_rate: 1e-3,
        use_sde,
        sde_sample_freq: 4,
        ..PpoConfig::default()
    }
}

/// PPO on `pendulum` with rl-zoo3's settings ([`zoo_pendulum_ppo_config`], with gSDE); eval
/// return after `steps` steps. SB3: -132 (seed 0), -151 (seed 1) at 100,000 steps.
pub fn pendulum_ppo(seed: u64, steps: u64) -> Result<f64> {
    pendulum_ppo_with(zoo_pendulum_ppo_config(true), seed, steps)
}

/// As [`pendulum_ppo`] with plain Gaussian exploration (no gSDE).
pub fn pendulum_ppo_gaussian(seed: u64, steps: u64) -> Result<f64> {
    pendulum_ppo_with(zoo_pendulum_ppo_config(false), seed, steps)
}

fn pendulum_ppo_with(cfg: PpoConfig, seed: u64, steps: u64) -> Result<f64> {
    let mut ppo = Ppo::new(cfg, pendulum_envs(4)?, &default_device(), seed)?;
    ppo.learn(steps, &mut |_| Control::Continue)?;
    let mut env = make("pendulum", &agvrl_envs::EnvConfig::default())?;
    ppo.evaluate(&mut env, EVAL_EPISODES, 1_000_000 + seed)
}
