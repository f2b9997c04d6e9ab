//! `check_env`: what Stable-Baselines3's `check_env` checks, for any `Env`: sane spaces,
//! seeding, determinism, finite observations and rewards inside the spaces, and rejection of
//! malformed actions.

use crate::api::{BoxSpace, Env, EnvError};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};

/// What [`check_env`] found wrong, the first problem only.
#[derive(Debug, thiserror::Error)]
pub enum CheckError {
    /// A space is empty, malformed, or (the action space) unbounded.
    #[error("{space} space: {reason}")]
    Space {
        /// `observation` or `action`.
        space: &'static str,
        /// What is wrong with it.
        reason: String,
    },
    /// The env returned an error where it must not (`stage`: reset, step N, ...).
    #[error("{stage}: {source}")]
    Env {
        /// Where it failed.
        stage: String,
        /// The env's error.
        source: EnvError,
    },
    /// The env broke Gymnasium's contract (determinism, spaces, finite values, rejections).
    #[error("{0}")]
    Contract(String),
}

fn check_space(space: &'static str, s: &BoxSpace, bounded: bool) -> Result<(), CheckError> {
    let bad = |reason: String| Err(CheckError::Space { space, reason });
    if s.dim() == 0 || s.low.len() != s.high.len() {
        return bad("empty or malformed".into());
    }
    for (i, (lo, hi)) in s.low.iter().zip(&s.high).enumerate() {
        if lo.is_nan() || hi.is_nan() || lo > hi {
            return bad(format!("element {i}: bounds [{lo}, {hi}]"));
        }
        if bounded && !(lo.is_finite() && hi.is_finite()) {
            return bad(format!("element {i} must be bounded, got [{lo}, {hi}]"));
        }
    }
    Ok(())
}

fn at(stage: impl Into<String>) -> impl FnOnce(EnvError) -> CheckError {
    let stage = stage.into();
    move |source| CheckError::Env { stage, source }
}

fn broken<T>(what: impl Into<String>) -> Result<T, CheckError> {
    Err(CheckError::Contract(what.into()))
}

/// (observation, reward, terminated, truncated) per step.
type Trajectory = Vec<(Vec<f32>, f64, bool, bool)>;

fn rollout(env: &mut dyn Env, seed: u64, steps: usize) -> Result<Trajectory, CheckError> {
    let obs_space = env.observation_space();
    let act_space = env.action_space();
    let mut rng = StdRng::seed_from_u64(seed.wrapping_mul(31).wrapping_add(7));
    let (obs, _) = env.reset(Some(seed)).map_err(at("reset"))?;
    let mut out = vec![(obs, 0.0, false, false)];
    for t in 0..steps {
        let a: Vec<f32> = act_space
            .low
            .iter()
            .zip(&act_space.high)
            .map(|(lo, hi)| rng.random_range(*lo..=*hi))
            .collect();
        let st = env.step(&a).map_err(at(format!("step {t}")))?;
        if !st.obs.iter().all(|v| v.is_finite()) {
            return broken(format!("step {t}: observation not finite"));
        }
        if !obs_space.contains(&st.obs) {
            return broken(format!("step {t}: observation outside the observation space"));
        }
        if !st.reward.is_finite() {
            return broken(format!("step {t}: reward {}", st.reward));
        }
        let done = st.done();
        out.push((st.obs, st.reward, st.terminated, st.truncated));
        if done {
            let (obs, _) = env.reset(None).map_err(at(format!("reset after step {t}")))?;
            out.push((obs, 0.0, false, false));
        }
    }
    Ok(out)
}

/// Check `env` over `steps` random steps. Err names the first problem.
pub fn check_env(env: &mut dyn Env, steps: usize) -> Result<(), CheckError> {
    check_space("observation", &env.observation_space(), false)?;
    check_space("action", &env.action_space(), true)?;
    let (o1, _) = env.reset(Some(123)).map_err(at("reset"))?;
    if !env.observation_space().contains(&o1) {
        return broken("first observation outside the observation space");
    }
    let (o2, _) = env.reset(Some(123)).map_err(at("reset"))?;
    if o1 != o2 {
        return broken("reset with the same seed gave different observations");
    }
    let dim = env.action_space().dim();
    if env.step(&vec![f32::NAN; dim]).is_ok() {
        return broken("a NaN action was accepted");
    }
    if env.step(&vec![0.0; dim + 1]).is_ok() {
        return broken("an action of the wrong length was accepted");
    }
    let a = rollout(env, 5, steps)?;
    let b = rollout(env, 5, steps)?;
    if a != b {
        return broken("the same seed and actions gave different trajectories");
    }
    if env.dt_s().is_nan() || env.dt_s() <= 0.0 {
        return broken(format!("dt_s = {}", env.dt_s()));
    }
    Ok(())
}
