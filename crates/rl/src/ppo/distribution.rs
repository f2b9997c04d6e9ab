//! PPO's action distribution, defined once for the rollout (sample and log-prob) and the loss
//! (log-prob, entropy and their gradients). It is a diagonal Gaussian around the actor's mean,
//! in one of two forms:
//!
//! - **Gaussian**: a state-independent std `exp(log_std)` (`a` values);
//! - **gSDE** (`use_sde`): `latent_dim x a` values of `log_std`. The variance of action `j`
//!   is `sum_k latent_k^2 exp(2 log_std_kj) + 1e-6`, and the noise is `latent . E_j`, with an
//!   exploration matrix `E ~ N(0, exp(log_std)^2)` drawn every `sde_sample_freq` steps.
//!
//! The rollout sums in f32 and the loss in f64, as the learners were validated against
//! Stable-Baselines3 (`sb3_numerics.rs`).

use crate::gaussian::{self, HALF_LN_2PI, HALF_LN_2PI_F32};
use crate::rng::Rng;

/// The distribution at one set of `log_std` (a rollout's, or a minibatch's).
pub(crate) struct ActionDist {
    a: usize,
    /// gSDE's latent width; 0 for the plain Gaussian.
    latent_dim: usize,
    /// `exp(log_std)`: the rollout's draws.
    std: Vec<f32>,
    /// `exp(2 log_std)`.
    sigma_sq: Vec<f64>,
    /// The Gaussian rollout's log-prob less its draws' `-z^2 / 2`.
    lp_const: f32,
}

impl ActionDist {
    /// The distribution over `a` action elements at `log_std`; gSDE when `latent_dim` is given.
    pub(crate) fn new(log_std: &[f32], a: usize, latent_dim: Option<usize>) -> Self {
        Self {
            a,
            latent_dim: latent_dim.unwrap_or(0),
            std: log_std.iter().map(|l| l.exp()).collect(),
            sigma_sq: log_std.iter().map(|l| (2.0 * *l as f64).exp()).collect(),
            lp_const: gaussian::log_prob_const(log_std),
        }
    }

    /// gSDE: a new exploration matrix per env, into `expl` (`n_envs * latent_dim * a`).
    pub(crate) fn draw_exploration(&self, rng: &mut Rng, expl: &mut [f32]) {
        let per_env = self.latent_dim * self.a;
        for (k, e) in expl.iter_mut().enumerate() {
            *e = self.std[k % per_env] * rng.normal() as f32;
        }
    }

    /// The variance of each action element into `out`: `exp(2 log_std)`, or with gSDE that of a
    /// sample whose actor latent is `latent` (SB3's `StateDependentNoiseDistribution` with
    /// `full_std`).
    pub(crate) fn variance(&self, latent: Option<&[f32]>, out: &mut [f64]) {
        let Some(latent) = latent else {
            out.copy_from_slice(&self.sigma_sq);
            return;
        };
        out.iter_mut().for_each(|v| *v = 1e-6);
        for (k, h) in latent.iter().enumerate() {
            let h2 = (*h as f64) * (*h as f64);
            let row = &self.sigma_sq[k * self.a..(k + 1) * self.a];
            for (o, s) in out.iter_mut().zip(row) {
                *o += h2 * s;
            }
        }
    }

    /// One rollout sample around `mean`, pushed onto `out`, and its log-prob. Gaussian: `mean +
    /// std z` with `z` drawn from `rng`. gSDE (`sde`: the sample's actor latent and its env's
    /// exploration matrix): `mean + latent . E_j`, `var` receiving the variances.
    pub(crate) fn sample(
        &self,
        mean: &[f32],
        sde: Option<(&[f32], &[f32])>,
        rng: &mut Rng,
        var: &mut [f64],
        out: &mut Vec<f32>,
    ) -> f32 {
        let a = self.a;
        match sde {
            Some((h, m)) => {
                self.variance(Some(h), var);
                let mut lp = -(a as f32) * HALF_LN_2PI_F32;
                for j in 0..a {
                    let noise: f32 = h.iter().enumerate().map(|(k, hk)| hk * m[k * a + j]).sum();
                    lp -= gaussian::neg_log_density(noise as f64, var[j]) as f32;
                    out.push(mean[j] + noise);
                }
                lp
            }
            None => {
                let mut lp = self.lp_const;
                for (m, s) in mean.iter().zip(&self.std) {
                    let z = rng.normal() as f32;
                    out.push(m + s * z);
                    lp -= 0.5 * z * z;
                }
                lp
            }
        }
    }

    /// The loss's log-prob of `actions` around `mean` with variances `var`; the differences go
    /// into `diff`, and each element's entropy times `weight` is added to `entropy`.
    pub(crate) fn log_prob(
        &self,
        actions: &[f32],
        mean: &[f32],
        var: &[f64],
        diff: &mut [f64],
        entropy: &mut f64,
        weight: f64,
    ) -> f64 {
        let mut lp = -(self.a as f64) * HALF_LN_2PI;
        for j in 0..self.a {
            diff[j] = (actions[j] - mean[j]) as f64;
            lp -= gaussian::neg_log_density(diff[j], var[j]);
            *entropy += gaussian::entropy(var[j]) * weight;
        }
        lp
    }

    /// The gradient of `d_lp * log_prob - d_ent * entropy` (`weights = (d_lp, d_ent)`) through
    /// element `j` (difference `diff`, variance `var`; `latent` the sample's with gSDE): returns
    /// d/d mean_j and adds d/d log_std into `d_log_std`.
    pub(crate) fn backward(
        &self,
        latent: Option<&[f32]>,
        j: usize,
        diff: f64,
        var: f64,
        (d_lp, d_ent): (f64, f64),
        d_log_std: &mut [f64],
    ) -> f64 {
        let a = self.a;
        let d_var = d_lp * (0.5 * diff * diff / (var * var) - 0.5 / var) - d_ent * 0.5 / var;
        match latent {
            // var_j = sum_k latent_k^2 sigma_kj^2 + eps: d var / d log_std_kj = 2 latent_k^2 sigma_kj^2
            Some(l) => {
                for k in 0..self.latent_dim {
                    let hk = l[k] as f64;
                    d_log_std[k * a + j] += d_var * 2.0 * hk * hk * self.sigma_sq[k * a + j];
                }
            }
            // var_j = sigma_j^2: d var / d log_std_j = 2 var_j
            None => d_log_std[j] += d_var * 2.0 * var,
        }
        d_lp * diff / var
    }
}
