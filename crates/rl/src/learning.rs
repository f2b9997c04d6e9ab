//! Learning checks against Stable-Baselines3 on `pendulum` (Gymnasium's Pendulum-v1): each
//! trains with SB3's (or rl-zoo3's) settings and returns the mean return of 200-step
//! deterministic episodes from the 100 start states shared with SB3's side
//! ([`parity_states`]), the same states for every seed and both algorithms.

use crate::device::default_device;
use crate::error::{Result, RlError};
use crate::policy::Policy;
use crate::ppo::{Ppo, PpoConfig};
use crate::progress::{Control, Progress};
use crate::sac::{Sac, SacConfig};
use agvrl_envs::pendulum::Pendulum;
use agvrl_envs::{Env, VecEnv, make};

/// `n` pendulum envs stepped on the caller's thread (the parity runs' vector env).
pub fn pendulum_envs(n: usize) -> Result<VecEnv<Box<dyn Env>>> {
    let envs = (0..n)
        .map(|_| make("pendulum", &agvrl_envs::EnvConfig::default()))
        .collect::<std::result::Result<Vec<_>, _>>()?;
    Ok(VecEnv::new(envs, 1)?)
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

/// The 100 Pendulum start states `(theta, theta_dot)` shared with Stable-Baselines3's side
/// (`pendulum_parity.py --make-states`: numpy `default_rng(20261123)`, theta in [-pi, pi),
/// theta_dot in [-1, 1)).
pub fn parity_states() -> Vec<(f64, f64)> {
    let raw: Vec<[f64; 2]> = serde_json::from_str(include_str!("../data/pendulum_start_states.json"))
        .expect("the embedded start states are valid JSON");
    raw.into_iter().map(|[t, td]| (t, td)).collect()
}

/// Mean return of 200-step deterministic episodes of `policy` from each state (actions clipped
/// to the torque limit, as SB3's `predict`).
pub fn score_on_states(policy: &mut Policy, states: &[(f64, f64)]) -> Result<f64> {
    if states.is_empty() {
        return Err(RlError::Config("no start states".into()));
    }
    let mut total = 0.0;
    for &(theta, theta_dot) in states {
        let mut env = Pendulum::new();
        env.set_state(theta, theta_dot);
        let space = env.action_space();
        let mut obs = vec![theta.cos() as f32, theta.sin() as f32, theta_dot as f32];
        for _ in 0..200 {
            let mut a = policy.act(&obs, true)?;
            for (j, v) in a.iter_mut().enumerate() {
                *v = v.clamp(space.low[j], space.high[j]);
            }
            let st = env.step(&a)?;
            total += st.reward;
            obs = st.obs;
        }
    }
    Ok(total / states.len() as f64)
}

/// PPO with rl-zoo3's Pendulum settings (`use_sde`: gSDE, else Gaussian) for `steps`, then
/// scored on [`parity_states`]; `on_update` sees every rollout + update.
pub fn ppo_parity(use_sde: bool, seed: u64, steps: u64, on_update: &mut dyn FnMut(&Progress<'_>)) -> Result<f64> {
    let dev = default_device();
    let mut ppo = Ppo::new(zoo_pendulum_ppo_config(use_sde), pendulum_envs(4)?, &dev, seed)?;
    ppo.learn(steps, &mut |p| {
        on_update(p);
        Control::Continue
    })?;
    score_on_states(&mut ppo.policy(&dev), &parity_states())
}

/// SAC with SB3's defaults on one env for `steps`, then scored on [`parity_states`].
pub fn sac_parity(seed: u64, steps: u64) -> Result<f64> {
    let dev = default_device();
    let mut sac = Sac::new(SacConfig::default(), pendulum_envs(1)?, &dev, seed)?;
    sac.learn(steps, &mut |_| Control::Continue)?;
    score_on_states(&mut sac.policy(&dev), &parity_states())
}
