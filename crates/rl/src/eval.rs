//! Deterministic evaluation: one episode loop, used by the learners' `evaluate` and by the
//! CLI's evaluation and viewers (which look at every step).

use crate::error::Result;
use crate::policy::Policy;
use agvrl_envs::{Env, EnvError, Step};

/// Drive one episode of `env` from `reset(seed)`. `act` picks each action from the observation;
/// `seen` is called after the reset (step 0, no `Step`) and after every step `k >= 1`. Returns
/// the return and the last step. The env must end its episodes (a `TimeLimit` does).
pub fn run_episode<E, Err>(
    env: &mut E,
    seed: u64,
    mut act: impl FnMut(&[f32]) -> std::result::Result<Vec<f32>, Err>,
    mut seen: impl FnMut(&E, u64, Option<&Step>) -> std::result::Result<(), Err>,
) -> std::result::Result<(f64, Step), Err>
where
    E: Env + ?Sized,
    Err: From<EnvError>,
{
    let (mut obs, _) = env.reset(Some(seed))?;
    seen(env, 0, None)?;
    let (mut ret, mut k) = (0.0, 0);
    loop {
        let action = act(&obs)?;
        let st = env.step(&action)?;
        k += 1;
        ret += st.reward;
        seen(env, k, Some(&st))?;
        if st.done() {
            return Ok((ret, st));
        }
        obs = st.obs;
    }
}

/// Mean return of `n_episodes` episodes with deterministic actions; episode `k` resets with
/// seed `seed + k`.
pub fn evaluate<E: Env + ?Sized>(policy: &mut Policy, env: &mut E, n_episodes: usize, seed: u64) -> Result<f64> {
    policy.check_spaces(&env.observation_space(), &env.action_space())?;
    let mut total = 0.0;
    for k in 0..n_episodes {
        let (ret, _) = run_episode(env, seed + k as u64, |o| policy.act(o, true), |_, _, _| Ok(()))?;
        total += ret;
    }
    Ok(total / n_episodes.max(1) as f64)
}
