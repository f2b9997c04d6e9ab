//! `check_env`: what Stable-Baselines3's `check_env` checks, for any `Env`: sane spaces,
//! seeding, determinism, finite observations and rewards inside the spaces, and rejection of
//! malformed actions.

use crate::api::{BoxSpace, Env};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};

fn check_space(name: &str, s: &BoxSpace, bounded: bool) -> Result<(), String> {
    if s.dim() == 0 || s.low.len() != s.high.len() {
        return Err(format!("{name} space is empty or malformed"));
    }
    for (i, (lo, hi)) in s.low.iter().zip(&s.high).enumerate() {
        if lo.is_nan() || hi.is_nan() || lo > hi {
            return Err(format!("{name} space element {i}: bounds [{lo}, {hi}]"));
        }
        if bounded && !(lo.is_finite() && hi.is_finite()) {
            return Err(format!("{name} space element {i} must be bounded, got [{lo}, {hi}]"));
        }
    }
    Ok(())
}

/// (observation, reward, terminated, truncated) per step.
type Trajectory = Vec<(Vec<f32>, f64, bool, bool)>;

fn rollout(env: &mut dyn Env, seed: u64, steps: usize) -> Result<Trajectory, String> {
    let obs_space = env.observation_space();
    let act_space = env.action_space();
    let mut rng = StdRng::seed_from_u64(seed.wrapping_mul(31).wrapping_add(7));
    let (obs, _) = env.reset(Some(seed)).map_err(|e| format!("reset: {e}"))?;
    let mut out = vec![(obs, 0.0, false, false)];
    for t in 0..steps {
        let a: Vec<f32> = act_space
            .low
            .iter()
            .zip(&act_space.high)
            .map(|(lo, hi)| rng.random_range(*lo..=*hi))
            .collect();
        let st = env.step(&a).map_err(|e| format!("step {t}: {e}"))?;
        if !st.obs.iter().all(|v| v.is_finite()) {
            return Err(format!("step {t}: observation not finite"));
        }
        if !obs_space.contains(&st.obs) {
            return Err(format!("step {t}: observation outside the observation space"));
        }
        if !st.reward.is_finite() {
            return Err(format!("step {t}: reward {}", st.reward));
        }
        let done = st.done();
        out.push((st.obs, st.reward, st.terminated, st.truncated));
        if done {
            let (obs, _) = env.reset(None).map_err(|e| format!("reset after step {t}: {e}"))?;
            out.push((obs, 0.0, false, false));
        }
    }
    Ok(out)
}

/// Check `env` over `steps` random steps. Err names the first problem.
pub fn check_env(env: &mut dyn Env, steps: usize) -> Result<(), String> {
    check_space("observation", &env.observation_space(), false)?;
    check_space("action", &env.action_space(), true)?;
    let (o1, _) = env.reset(Some(123)).map_err(|e| format!("reset: {e}"))?;
    if !env.observation_space().contains(&o1) {
        return Err("first observation outside the observation space".into());
    }
    let (o2, _) = env.reset(Some(123)).map_err(|e| format!("reset: {e}"))?;
    if o1 != o2 {
        return Err("reset with the same seed gave different observations".into());
    }
    let dim = env.action_space().dim();
    if env.step(&vec![f32::NAN; dim]).is_ok() {
        return Err("a NaN action was accepted".into());
    }
    if env.step(&vec![0.0; dim + 1]).is_ok() {
        return Err("an action of the wrong length was accepted".into());
    }
    let a = rollout(env, 5, steps)?;
    let b = rollout(env, 5, steps)?;
    if a != b {
        return Err("the same seed and actions gave different trajectories".into());
    }
    if env.dt_s().is_nan() || env.dt_s() <= 0.0 {
        return Err(format!("dt_s = {}", env.dt_s()));
    }
    Ok(())
}
