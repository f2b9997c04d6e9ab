//! What a learner tells its caller during `learn`, and how the caller answers.

use crate::policy::Algorithm;
use std::collections::VecDeque;

/// Latest training statistics (NaN where an algorithm has no such figure yet).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Losses {
    /// Actor loss (SAC) or clipped surrogate loss (PPO).
    pub policy: f64,
    /// Critic loss (SAC, both critics summed) or value loss (PPO).
    pub value: f64,
    /// Policy entropy estimate, nats: `-mean(log_prob)` (SAC) or the Gaussian's entropy (PPO).
    pub entropy: f64,
    /// SAC's entropy coefficient (alpha).
    pub ent_coef: f64,
    /// PPO's approximate KL divergence between the rollout's policy and the one being updated,
    /// `mean((r - 1) - ln r)` before each minibatch step, over the last epoch (SB3's
    /// `train/approx_kl`, whose list restarts every epoch; `clip_fraction` and the losses are
    /// over all epochs, as SB3's).
    pub approx_kl: f64,
    /// PPO's fraction of samples whose ratio was clipped.
    pub clip_fraction: f64,
    /// PPO: `1 - Var(returns - values) / Var(returns)` over the rollout (SB3's
    /// `explained_variance`).
    pub explained_variance: f64,
    /// PPO: mean of `exp(log_std)` (SB3's `train/std`; with gSDE, over the latent x action matrix).
    pub std: f64,
    /// PPO: mean global gradient norm before clipping, over the update's minibatches.
    pub grad_norm: f64,
    /// PPO with `correction_coef`: the correction term (before its coefficient), mean over
    /// the update's minibatches.
    pub correction: f64,
    /// PPO: fraction of the rollout's steps whose action the env corrected
    /// (`Info::corrected_action`).
    pub corrected_fraction: f64,
    /// PPO with `correction_limit`: the mean of the envs' multipliers after the rollout.
    pub correction_lambda: f64,
}

impl Default for Losses {
    fn default() -> Self {
        Self {
            policy: f64::NAN,
            value: f64::NAN,
            entropy: f64::NAN,
            ent_coef: f64::NAN,
            approx_kl: f64::NAN,
            clip_fraction: f64::NAN,
            explained_variance: f64::NAN,
            std: f64::NAN,
            grad_norm: f64::NAN,
            correction: f64::NAN,
            corrected_fraction: f64::NAN,
            correction_lambda: f64::NAN,
        }
    }
}

/// Handed to the `learn` callback (SAC: after every vector step; PPO: after every rollout and
/// update).
#[derive(Clone, Debug)]
pub struct Progress<'a> {
    /// Which learner.
    pub algorithm: Algorithm,
    /// Env steps taken so far, summed over envs (across `learn` calls and resumes).
    pub steps: u64,
    /// `steps` at which the current `learn` call returns.
    pub target_steps: u64,
    /// Gradient steps taken so far.
    pub updates: u64,
    /// Episodes finished so far.
    pub episodes: u64,
    /// Returns of the last (up to 100) finished episodes, oldest first.
    pub recent_returns: &'a [f64],
    /// Latest losses.
    pub losses: Losses,
}

impl Progress<'_> {
    /// Mean of `recent_returns` (None before the first episode ends).
    pub fn mean_return(&self) -> Option<f64> {
        (!self.recent_returns.is_empty())
            .then(|| self.recent_returns.iter().sum::<f64>() / self.recent_returns.len() as f64)
    }
}

/// The callback's answer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Control {
    /// Keep training.
    Continue,
    /// Return from `learn` now (the learner stays consistent and can be saved or resumed).
    Stop,
}

/// Episode bookkeeping shared by the learners.
#[derive(Clone, Debug, Default)]
pub(crate) struct Episodes {
    pub(crate) count: u64,
    pub(crate) recent: VecDeque<f64>,
}

impl Episodes {
    pub(crate) fn record(&mut self, infos: &[agvrl_envs::Info]) {
        for ep in infos.iter().filter_map(|i| i.episode) {
            self.count += 1;
            if self.recent.len() == 100 {
                self.recent.pop_front();
            }
            self.recent.push_back(ep.ret);
        }
    }
}
