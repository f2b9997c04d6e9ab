//! One PPO update over a rollout, as SB3's `PPO.train`: `n_epochs` passes of shuffled
//! minibatches, clipped surrogate + `vf_coef` * value MSE - `ent_coef` * entropy, global
//! gradient clipping, Adam.
//!
//! The loss head is fused: the networks run forward on the autodiff device once, the loss and
//! its gradients with respect to the action mean, the value and `log_std` are computed in one
//! host pass ([`loss_head`]), and a single backward of `sum(mean * dL/dmean) + sum(value *
//! dL/dvalue)` carries them into the weights. That replaces ~25 small graph ops per minibatch
//! (each a Burn dispatch plus its backward) by 5; `tests::fused_head_matches_autodiff` checks
//! the result against the plain autodiff formulation.

use super::{Ppo, Rollout, forward, head_idx};
use crate::error::{Result, RlError};
use crate::nets::{Adam, grads_of, to_vec};
use agvrl_envs::Env;
use burn::tensor::{Tensor, TensorData};

const HALF_LN_2PI: f64 = 0.918_938_533_204_672_7;

/// Loss values and gradients of one minibatch.
pub(crate) struct Head {
    pub(crate) pg_loss: f64,
    pub(crate) vf_loss: f64,
    pub(crate) approx_kl: f64,
    pub(crate) clip_fraction: f64,
    /// dL/dmean, `n * a`.
    pub(crate) d_mean: Vec<f32>,
    /// dL/dvalue, `n`.
    pub(crate) d_value: Vec<f32>,
    /// dL/dlog_std, `a`.
    pub(crate) d_log_std: Vec<f32>,
}

/// Inputs of the loss head for `n` samples with `a` action elements.
pub(crate) struct HeadInput<'a> {
    pub(crate) mean: &'a [f32],
    pub(crate) value: &'a [f32],
    pub(crate) log_std: &'a [f32],
    pub(crate) actions: &'a [f32],
    pub(crate) old_log_prob: &'a [f32],
    /// Already normalised if configured.
    pub(crate) advantages: &'a [f32],
    pub(crate) returns: &'a [f32],
}

/// PPO's loss and its gradient w.r.t. the network outputs and `log_std`:
/// `L = -mean(min(r A, clip(r, 1-c, 1+c) A)) + vf_coef mean((R - v)^2) - ent_coef H`, with
/// `r = exp(log_prob - old_log_prob)`, `H = sum(log_std + (1 + ln 2 pi) / 2)`.
pub(crate) fn loss_head(x: &HeadInput<'_>, clip: f64, vf_coef: f64, ent_coef: f64) -> Head {
    let a = x.log_std.len();
    let n = x.value.len();
    let inv_n = 1.0 / n as f64;
    let inv_std: Vec<f64> = x.log_std.iter().map(|l| (-*l as f64).exp()).collect();
    let lp_const = -x.log_std.iter().map(|l| *l as f64).sum::<f64>() - a as f64 * HALF_LN_2PI;
    let mut h = Head {
        pg_loss: 0.0,
        vf_loss: 0.0,
        approx_kl: 0.0,
        clip_fraction: 0.0,
        d_mean: vec![0.0; n * a],
        d_value: vec![0.0; n],
        d_log_std: vec![-ent_coef as f32; a],
    };
    let mut d_log_std = vec![-ent_coef; a];
    let mut z = vec![0.0f64; a];
    for i in 0..n {
        let mut lp = lp_const;
        for j in 0..a {
            z[j] = (x.actions[i * a + j] - x.mean[i * a + j]) as f64 * inv_std[j];
            lp -= 0.5 * z[j] * z[j];
        }
        let log_ratio = lp - x.old_log_prob[i] as f64;
        let ratio = log_ratio.exp();
        let adv = x.advantages[i] as f64;
        let unclipped = ratio * adv;
        let clipped = ratio.clamp(1.0 - clip, 1.0 + clip) * adv;
        h.pg_loss -= unclipped.min(clipped) * inv_n;
        // The min's gradient flows through r A when that branch is selected (or both are equal,
        // inside the clip range); the clipped branch is constant outside the range.
        let d_lp = if unclipped <= clipped {
            -adv * ratio * inv_n
        } else {
            0.0
        };
        for j in 0..a {
            h.d_mean[i * a + j] = (d_lp * z[j] * inv_std[j]) as f32; // d lp / d mean = z / std
            d_log_std[j] += d_lp * (z[j] * z[j] - 1.0); // d lp / d log_std = z^2 - 1
        }
        let err = x.returns[i] as f64 - x.value[i] as f64;
        h.vf_loss += err * err * inv_n;
        h.d_value[i] = (-2.0 * vf_coef * err * inv_n) as f32;
        h.approx_kl += (ratio - 1.0 - log_ratio) * inv_n;
        h.clip_fraction += ((ratio - 1.0).abs() > clip) as u8 as f64 * inv_n;
    }
    h.d_log_std = d_log_std.iter().map(|g| *g as f32).collect();
    h
}

impl<E: Env> Ppo<E> {
    pub(crate) fn update(&mut self, r: &Rollout) -> Result<()> {
        let (o, a) = (self.obs_dim, self.act_dim);
        let total = r.log_probs.len();
        let bs = self.cfg.batch_size.min(total);
        let dev = self.device.clone();
        let ad = dev.clone().autodiff();
        let log_std_idx = head_idx(&self.cfg) + 4;
        let mut idx: Vec<usize> = (0..total).collect();
        let (mut pg_sum, mut vf_sum, mut kl_sum, mut clip_sum, mut n_mb) = (0.0, 0.0, 0.0, 0.0, 0usize);
        'epochs: for _ in 0..self.cfg.n_epochs {
            self.rng.shuffle(&mut idx);
            // SB3 yields whole minibatches and a smaller last one.
            for mb in idx.chunks(bs) {
                let n = mb.len();
                let mut obs = Vec::with_capacity(n * o);
                let mut act = Vec::with_capacity(n * a);
                let mut old_lp = Vec::with_capacity(n);
                let mut adv = Vec::with_capacity(n);
                let mut ret = Vec::with_capacity(n);
                for &k in mb {
                    obs.extend_from_slice(&r.obs[k * o..(k + 1) * o]);
                    act.extend_from_slice(&r.actions[k * a..(k + 1) * a]);
                    old_lp.push(r.log_probs[k]);
                    adv.push(r.advantages[k]);
                    ret.push(r.returns[k]);
                }
                if self.cfg.normalize_advantage && n > 1 {
                    let mean = adv.iter().map(|v| *v as f64).sum::<f64>() / n as f64;
                    // torch.std is unbiased.
                    let var = adv.iter().map(|v| (*v as f64 - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
                    let sd = var.sqrt() + 1e-8;
                    adv.iter_mut().for_each(|v| *v = ((*v as f64 - mean) / sd) as f32);
                }
                let t3 = |v: Vec<f32>, s: [usize; 3]| Tensor::<3>::from_data(TensorData::new(v, s), &ad);
                // log_std's gradient comes from the host head; only the networks are tracked.
                let mut params: Vec<Tensor<3>> = self.params.to_tracked(&ad);
                params[log_std_idx] = params[log_std_idx].clone().detach();
                let (mean, value) = forward(&params, t3(obs, [1, n, o]), &self.cfg);
                let (mean_h, value_h) = (to_vec(mean.clone().inner())?, to_vec(value.clone().inner())?);
                let head = loss_head(
                    &HeadInput {
                        mean: &mean_h,
                        value: &value_h,
                        log_std: &self.params.data[log_std_idx],
                        actions: &act,
                        old_log_prob: &old_lp,
                        advantages: &adv,
                        returns: &ret,
                    },
                    self.cfg.clip_range,
                    self.cfg.vf_coef,
                    self.cfg.ent_coef,
                );
                if !head.pg_loss.is_finite() || !head.vf_loss.is_finite() {
                    return Err(RlError::NonFinite("PPO loss"));
                }
                pg_sum += head.pg_loss;
                vf_sum += head.vf_loss;
                kl_sum += head.approx_kl;
                clip_sum += head.clip_fraction;
                n_mb += 1;
                if self.cfg.target_kl.is_some_and(|t| head.approx_kl > 1.5 * t) {
                    break 'epochs;
                }
                let surrogate = (mean * t3(head.d_mean, [1, n, a])).sum() + (value * t3(head.d_value, [1, n, 1])).sum();
                let mut grads = grads_of(&params, &surrogate.backward())?;
                grads[log_std_idx] = head.d_log_std;
                Adam::clip_grad_norm(&mut grads, self.cfg.max_grad_norm);
                self.opt.step(&mut self.params, &grads);
                self.n_updates += 1;
            }
        }
        let m = n_mb.max(1) as f64;
        self.losses.policy = pg_sum / m;
        self.losses.value = vf_sum / m;
        self.losses.approx_kl = kl_sum / m;
        self.losses.clip_fraction = clip_sum / m;
        self.losses.entropy = self.params.data[log_std_idx]
            .iter()
            .map(|l| *l as f64 + 0.5 + HALF_LN_2PI)
            .sum();
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    /// The loss written with autodiff tensor ops (the unfused formulation).
    fn autodiff_loss(x: &HeadInput<'_>, clip: f64, vf_coef: f64, ent_coef: f64) -> (f64, Vec<f32>, Vec<f32>, Vec<f32>) {
        let dev = crate::device::default_device().autodiff();
        let (n, a) = (x.value.len(), x.log_std.len());
        let t = |v: &[f32], s: [usize; 3]| Tensor::<3>::from_data(TensorData::new(v.to_vec(), s), &dev);
        let mean = t(x.mean, [1, n, a]).require_grad();
        let value = t(x.value, [1, n, 1]).require_grad();
        let log_std = t(x.log_std, [1, 1, a]).require_grad();
        let z = (t(x.actions, [1, n, a]) - mean.clone()) * log_std.clone().neg().exp();
        let lp = (z.powi_scalar(2) * -0.5 - log_std.clone() - HALF_LN_2PI).sum_dim(2);
        let ratio = (lp - t(x.old_log_prob, [1, n, 1])).exp();
        let adv = t(x.advantages, [1, n, 1]);
        let pg = (ratio.clone() * adv.clone())
            .min_pair(ratio.clamp(1.0 - clip, 1.0 + clip) * adv)
            .mean()
            .neg();
        let vf = (t(x.returns, [1, n, 1]) - value.clone()).powi_scalar(2).mean();
        let ent = (log_std.clone() + (0.5 + HALF_LN_2PI)).sum();
        let loss = pg + vf * vf_coef - ent * ent_coef;
        let g = loss.backward();
        let v = |x: &Tensor<3>| to_vec(x.grad(&g).unwrap()).unwrap();
        (
            to_vec(loss.inner()).unwrap()[0] as f64,
            v(&mean),
            v(&value),
            v(&log_std),
        )
    }

    #[test]
    fn fused_head_matches_autodiff() {
        let mut rng = Rng::new(9);
        let (n, a) = (64, 2);
        let mean = rng.normals(n * a);
        let actions: Vec<f32> = mean.iter().map(|m| m + 0.7 * rng.normal() as f32).collect();
        let log_std = vec![-0.3, 0.2];
        // Old log-probs near the current ones, so some ratios fall outside the clip range.
        let old: Vec<f32> = (0..n).map(|_| -2.0 + 0.4 * rng.normal() as f32).collect();
        let x = HeadInput {
            mean: &mean,
            value: &rng.normals(n),
            log_std: &log_std,
            actions: &actions,
            old_log_prob: &old,
            advantages: &rng.normals(n),
            returns: &rng.normals(n),
        };
        let h = loss_head(&x, 0.2, 0.5, 0.01);
        let (loss, d_mean, d_value, d_log_std) = autodiff_loss(&x, 0.2, 0.5, 0.01);
        let ent = log_std.iter().map(|l| *l as f64 + 0.5 + HALF_LN_2PI).sum::<f64>();
        assert!(
            (h.pg_loss + 0.5 * h.vf_loss - 0.01 * ent - loss).abs() < 1e-4,
            "{} vs {loss}",
            h.pg_loss
        );
        assert!(h.clip_fraction > 0.0 && h.clip_fraction < 1.0);
        let close = |p: &[f32], q: &[f32]| p.iter().zip(q).all(|(p, q)| (p - q).abs() < 1e-5 + 1e-3 * q.abs());
        assert!(close(&h.d_mean, &d_mean), "{:?}\n{:?}", &h.d_mean[..6], &d_mean[..6]);
        assert!(close(&h.d_value, &d_value));
        assert!(close(&h.d_log_std, &d_log_std), "{:?} {:?}", h.d_log_std, d_log_std);
    }
}
