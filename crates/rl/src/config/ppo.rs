//! PPO hyperparameters.

use crate::error::{Result, RlError};
use serde::{Deserialize, Serialize};

/// Proximal Policy Optimisation hyperparameters. `Default` is Stable-Baselines3's
/// (`ppo/ppo.py` `PPO.__init__`, `common/policies.py` `ActorCriticPolicy`); a TOML table
/// overrides any subset, with rl-zoo3's key names.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PpoConfig {
    /// Adam learning rate (3e-4; Adam eps 1e-5 as SB3).
    pub learning_rate: f64,
    /// Steps per env per rollout (2048).
    pub n_steps: usize,
    /// Minibatch size (64).
    pub batch_size: usize,
    /// Passes over each rollout (10).
    pub n_epochs: usize,
    /// Discount factor (0.99).
    pub gamma: f64,
    /// GAE lambda (0.95).
    pub gae_lambda: f64,
    /// Policy ratio clip (0.2).
    pub clip_range: f64,
    /// Value clip around the old value (None: no clipping).
    pub clip_range_vf: Option<f64>,
    /// Normalise advantages per minibatch (true).
    pub normalize_advantage: bool,
    /// Entropy bonus coefficient (0.0).
    pub ent_coef: f64,
    /// Value loss coefficient (0.5).
    pub vf_coef: f64,
    /// Global gradient-norm clip (0.5).
    pub max_grad_norm: f64,
    /// Stop an update's epochs early when the approximate KL exceeds 1.5 times this (None).
    pub target_kl: Option<f64>,
    /// Hidden widths of the separate actor and critic networks ([64, 64]).
    pub net_arch: Vec<usize>,
    /// Hidden activation ("tanh").
    pub activation_fn: crate::nets::Activation,
    /// Orthogonal initialisation (gains sqrt 2 hidden, 0.01 action, 1 value) (true).
    pub ortho_init: bool,
    /// Initial log standard deviation of the action distribution (0.0).
    pub log_std_init: f64,
    /// Generalised State-Dependent Exploration (Raffin et al. 2022, SB3's `use_sde` with
    /// `full_std`, features not learned): exploration noise `latent @ E` with a matrix `E`
    /// resampled every `sde_sample_freq` steps and at each rollout start (false).
    pub use_sde: bool,
    /// Steps between gSDE noise-matrix resamples; -1 or 0: once per rollout (-1).
    pub sde_sample_freq: i64,
    /// Running observation normalisation (off).
    pub normalize_obs: bool,
    /// The last `C*H*W` observation values are an image, encoded by one NatureCNN shared by
    /// actor and critic (SB3's `CnnPolicy` default) and left out of `normalize_obs` (None).
    pub image: Option<crate::cnn::ImageSpec>,
    /// Weight of a supervised term beside the PPO loss: on the steps where the env replaced the
    /// policy's action (`Info::corrected_action`, a safety filter's correction), the squared
    /// distance from the action mean to the action sent, `coef * sum_i |mean_i - target_i|^2 /
    /// n` over a minibatch of `n`. The policy learns to propose what the filter let through
    /// (0: off, SB3's loss; not an SB3 setting).
    #[serde(skip_serializing_if = "is_zero")]
    pub correction_coef: f64,
    /// Anneal the learning rate linearly from `learning_rate` at step 0 to this at the run's
    /// last step (rl-zoo3's `lin_` schedules when 0; None: constant, SB3's default). The run's
    /// length comes from [`crate::Ppo::set_schedule_steps`]; `agvrl train` passes its `steps`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub learning_rate_final: Option<f64>,
    /// The env's corrections as a constraint (Reward Constrained Policy Optimisation, Tessler
    /// et al. 2019): each env's reward is charged its multiplier `lambda_e` on every step it
    /// corrected the policy's action (`Info::corrected_action`), and after every rollout
    /// `lambda_e` moves by `correction_lambda_lr * (env e's corrected fraction - this)`,
    /// floored at 0, so the charge grows only where the policy is corrected more often than
    /// this fraction of its steps, and only as far as needed (None: off; not an SB3 setting).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub correction_limit: Option<f64>,
    /// The multipliers' step per rollout per unit of excess corrected fraction (1.0).
    #[serde(skip_serializing_if = "is_one")]
    pub correction_lambda_lr: f64,
}

fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

fn is_one(v: &f64) -> bool {
    *v == 1.0
}

impl Default for PpoConfig {
    fn default() -> Self {
        Self {
            learning_rate: 3e-4,
            n_steps: 2048,
            batch_size: 64,
            n_epochs: 10,
            gamma: 0.99,
            gae_lambda: 0.95,
            clip_range: 0.2,
            clip_range_vf: None,
            normalize_advantage: true,
            ent_coef: 0.0,
            vf_coef: 0.5,
            max_grad_norm: 0.5,
            target_kl: None,
            net_arch: vec![64, 64],
            activation_fn: crate::nets::Activation::Tanh,
            ortho_init: true,
            log_std_init: 0.0,
            use_sde: false,
            sde_sample_freq: -1,
            normalize_obs: false,
            image: None,
            correction_coef: 0.0,
            learning_rate_final: None,
            correction_limit: None,
            correction_lambda_lr: 1.0,
        }
    }
}

impl PpoConfig {
    /// Defaults overridden by the keys of a TOML table.
    pub fn from_toml(s: &str) -> Result<Self> {
        let c: Self = toml::from_str(s).map_err(|e| RlError::Config(format!("PPO config: {e}")))?;
        c.validate()?;
        Ok(c)
    }

    /// The configuration as TOML.
    pub fn to_toml(&self) -> Result<String> {
        toml::to_string(self).map_err(|e| RlError::Config(format!("PPO config to TOML: {e}")))
    }

    /// Reject values the learner cannot run with.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: &str| Err(RlError::Config(format!("PPO: {m}")));
        if self.learning_rate.is_nan()
            || self.learning_rate <= 0.0
            || self.n_steps == 0
            || self.batch_size == 0
            || self.n_epochs == 0
        {
            return bad("learning_rate, n_steps, batch_size and n_epochs must be > 0");
        }
        if self.learning_rate_final.is_some_and(|f| f.is_nan() || f < 0.0) {
            return bad("learning_rate_final must be >= 0");
        }
        if !(0.0..=1.0).contains(&self.gamma) || !(0.0..=1.0).contains(&self.gae_lambda) {
            return bad("gamma and gae_lambda must lie in [0, 1]");
        }
        if self.clip_range.is_nan()
            || self.clip_range <= 0.0
            || self.max_grad_norm.is_nan()
            || self.max_grad_norm <= 0.0
        {
            return bad("clip_range and max_grad_norm must be > 0");
        }
        if self.net_arch.is_empty() || self.net_arch.contains(&0) {
            return bad("net_arch needs at least one non-zero width");
        }
        if !(self.correction_coef.is_finite() && self.correction_coef >= 0.0) {
            return bad("correction_coef must be finite and >= 0");
        }
        if self.correction_limit.is_some_and(|l| !(0.0..=1.0).contains(&l)) {
            return bad("correction_limit must lie in [0, 1] (a fraction of the steps)");
        }
        if !(self.correction_lambda_lr.is_finite() && self.correction_lambda_lr > 0.0) {
            return bad("correction_lambda_lr must be finite and > 0");
        }
        if let Some(image) = &self.image {
            image.conv_shapes()?;
        }
        Ok(())
    }
}
