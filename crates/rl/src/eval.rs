//! Deterministic evaluation of a [`Policy`] on a single env.

use crate::error::Result;
use crate::policy::Policy;
use agvrl_envs::Env;

/// Mean return of `n_episodes` episodes with deterministic actions; episode `k` resets with
/// seed `seed + k`. The env must end its episodes (a `TimeLimit` does).
pub fn evaluate<E: Env + ?Sized>(policy: &mut Policy, env: &mut E, n_episodes: usize, seed: u64) -> Result<f64> {
    policy.check_spaces(&env.observation_space(), &env.action_space())?;
    let mut total = 0.0;
    for k in 0..n_episodes {
        let (mut obs, _) = env.reset(Some(seed + k as u64))?;
        loop {
            let action = policy.act(&obs, true)?;
            let st = env.step(&action)?;
            total += st.reward;
            if st.done() {
                break;
            }
            obs = st.obs;
        }
    }
    Ok(total / n_episodes.max(1) as f64)
}
