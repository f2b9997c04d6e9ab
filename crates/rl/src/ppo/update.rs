//! One PPO update over a rollout, as SB3's `PPO.train`: `n_epochs` passes of shuffled
//! minibatches, clipped surrogate + `vf_coef` * value MSE - `ent_coef` * entropy, global
//! gradient clipping, Adam.
//!
//! The loss head is fused: the networks run forward on the host once ([`super::host`]), the
//! loss and its gradients with respect to the action mean, the value and `log_std` are computed
//! in one pass ([`loss_head`]), and a single backward of `sum(mean * dL/dmean) + sum(value *
//! dL/dvalue)` carries them into the weights. `tests::fused_head_matches_autodiff` checks the
//! head against the plain autodiff formulation, `tests::host_gradients_match_autodiff` the
//! networks.

use super::distribution::ActionDist;
use super::network::Layout;
use super::{Ppo, Rollout, host};
use crate::adam::Adam;
use crate::device::NetPath;
use crate::error::{Result, RlError};
use crate::nets::{grads_of, to_vec};
use agvrl_envs::Env;
use agvrl_envs::Workers;
use burn::tensor::{Tensor, TensorData};

/// What [`Ppo::gradient_probe`] returns (weights in agvrl's layout: `[members, in, out]`).
#[cfg(any(test, feature = "parity"))]
#[doc(hidden)]
#[derive(serde::Serialize)]
pub struct GradientProbe {
    pub shapes: Vec<[usize; 3]>,
    /// The weights the rollout was collected with.
    pub params_before: Vec<Vec<f32>>,
    /// The weights after the update on it, where `grads` were taken.
    pub params: Vec<Vec<f32>>,
    pub obs: Vec<f32>,
    pub actions: Vec<f32>,
    pub old_log_prob: Vec<f32>,
    pub advantages: Vec<f32>,
    pub returns: Vec<f32>,
    pub pg_loss: f64,
    pub vf_loss: f64,
    pub approx_kl: f64,
    pub clip_fraction: f64,
    pub grads: Vec<Vec<f32>>,
    /// The whole rollout (`obs`, ... above are its first minibatch), advantages unnormalised.
    pub rollout_obs: Vec<f32>,
    pub rollout_actions: Vec<f32>,
    pub rollout_log_prob: Vec<f32>,
    pub rollout_advantages: Vec<f32>,
    pub rollout_returns: Vec<f32>,
    /// GAE's inputs: rewards (truncations bootstrapped), values, episode starts, last values,
    /// last done flags.
    pub gae_inputs: [Vec<f32>; 5],
    /// What this learner's update on that rollout reported.
    pub update_approx_kl: f64,
    pub update_clip_fraction: f64,
    pub update_std: f64,
}

/// Loss values and gradients of one minibatch.
pub(crate) struct Head {
    pub(crate) pg_loss: f64,
    pub(crate) vf_loss: f64,
    pub(crate) approx_kl: f64,
    pub(crate) clip_fraction: f64,
    /// Mean entropy of the action distribution, nats.
    pub(crate) entropy: f64,
    /// dL/dmean, `n * a`.
    pub(crate) d_mean: Vec<f32>,
    /// dL/dvalue, `n`.
    pub(crate) d_value: Vec<f32>,
    /// dL/dlog_std, the shape of `log_std`.
    pub(crate) d_log_std: Vec<f32>,
    /// The correction term `sum_i c_i |mean_i - target_i|^2 / n` (before its coefficient).
    pub(crate) correction: f64,
}

/// The actions an env sent instead of the policy's, for the correction term of
/// [`loss_head`].
#[derive(Clone, Copy)]
pub(crate) struct Correction<'a> {
    /// `n * a` actions (any value where `mask` is 0).
    pub(crate) actions: &'a [f32],
    /// `n` weights: 1 where the env corrected the step, else 0.
    pub(crate) mask: &'a [f32],
    /// The term's coefficient.
    pub(crate) coef: f64,
}

/// Inputs of the loss head for `n` samples with `a` action elements.
pub(crate) struct HeadInput<'a> {
    pub(crate) mean: &'a [f32],
    pub(crate) value: &'a [f32],
    /// `a` values, or `latent_dim * a` with gSDE.
    pub(crate) log_std: &'a [f32],
    /// gSDE only: the actor's last hidden layer, `n * latent_dim` (held constant, as SB3's
    /// `learn_features = False`).
    pub(crate) latent: Option<&'a [f32]>,
    pub(crate) actions: &'a [f32],
    pub(crate) old_log_prob: &'a [f32],
    /// Already normalised if configured.
    pub(crate) advantages: &'a [f32],
    pub(crate) returns: &'a [f32],
    /// The correction term's inputs (`correction_coef > 0`).
    pub(crate) correction: Option<Correction<'a>>,
}

/// PPO's loss and its gradient w.r.t. the network outputs and `log_std`:
/// `L = -mean(min(r A, clip(r, 1-c, 1+c) A)) + vf_coef mean((R - v)^2) - ent_coef mean(H)`,
/// `r = exp(log_prob - old_log_prob)`, for a diagonal Gaussian with variance `var_ij`:
/// `exp(2 log_std_j)`, or with gSDE `sum_k latent_ik^2 exp(2 log_std_kj) + 1e-6`; with a
/// [`Correction`], `+ coef sum_i c_i |mean_i - target_i|^2 / n`.
pub(crate) fn loss_head(x: &HeadInput<'_>, clip: f64, vf_coef: f64, ent_coef: f64) -> Head {
    let n = x.value.len();
    let a = x.mean.len() / n.max(1);
    let latent_dim = x.latent.map_or(0, |l| l.len() / n.max(1));
    let inv_n = 1.0 / n as f64;
    let dist = ActionDist::new(x.log_std, a, x.latent.map(|_| latent_dim));
    let mut h = Head {
        pg_loss: 0.0,
        vf_loss: 0.0,
        approx_kl: 0.0,
        clip_fraction: 0.0,
        entropy: 0.0,
        d_mean: vec![0.0; n * a],
        d_value: vec![0.0; n],
        d_log_std: vec![],
        correction: 0.0,
    };
    let mut d_log_std = vec![0.0f64; x.log_std.len()];
    let (mut var, mut diff) = (vec![0.0f64; a], vec![0.0f64; a]);
    for i in 0..n {
        let latent = x.latent.map(|l| &l[i * latent_dim..(i + 1) * latent_dim]);
        dist.variance(latent, &mut var);
        let (actions, mean) = (&x.actions[i * a..(i + 1) * a], &x.mean[i * a..(i + 1) * a]);
        let lp = dist.log_prob(actions, mean, &var, &mut diff, &mut h.entropy, inv_n);
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
        // The entropy bonus enters the loss as -ent_coef mean(H).
        for j in 0..a {
            let d_mean = dist.backward(latent, j, diff[j], var[j], (d_lp, ent_coef * inv_n), &mut d_log_std);
            h.d_mean[i * a + j] = d_mean as f32;
        }
        if let Some(c) = &x.correction
            && c.mask[i] != 0.0
        {
            let w = c.mask[i] as f64 * inv_n;
            for j in 0..a {
                let e = x.mean[i * a + j] as f64 - c.actions[i * a + j] as f64;
                h.correction += w * e * e;
                h.d_mean[i * a + j] += (2.0 * c.coef * w * e) as f32;
            }
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

/// A minibatch's advantages to zero mean and unit (unbiased, as torch.std) deviation; a
/// single sample is left as it is (SB3 skips it too).
fn normalize_advantages(adv: &mut [f32]) {
    let n = adv.len();
    if n < 2 {
        return;
    }
    let mean = adv.iter().map(|v| *v as f64).sum::<f64>() / n as f64;
    let var = adv.iter().map(|v| (*v as f64 - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
    let sd = var.sqrt() + 1e-8;
    adv.iter_mut().for_each(|v| *v = ((*v as f64 - mean) / sd) as f32);
}

/// `1 - Var(returns - values) / Var(returns)` with `returns - values = advantages`; NaN when
/// the returns do not vary (SB3's `explained_variance`).
fn explained_variance(returns: &[f32], advantages: &[f32]) -> f64 {
    let var = |x: &[f32]| {
        let m = x.iter().map(|v| *v as f64).sum::<f64>() / x.len() as f64;
        x.iter().map(|v| (*v as f64 - m).powi(2)).sum::<f64>() / x.len() as f64
    };
    let vr = var(returns);
    if vr == 0.0 {
        return f64::NAN;
    }
    1.0 - var(advantages) / vr
}

/// `job` on every item, item 0 on the calling thread and the others on `workers` (at most one
/// item more than helpers); results in item order.
fn on_threads<T: Sync, R: Send>(workers: &Workers, items: &[T], job: impl Fn(&T) -> R + Sync) -> Result<Vec<R>> {
    let job = &job;
    let jobs = items
        .iter()
        .map(|t| Box::new(move || job(t)) as Box<dyn FnOnce() -> R + Send + '_>)
        .collect();
    workers
        .run(jobs)
        .into_iter()
        .map(|r| r.ok_or_else(|| RlError::Internal("a PPO minibatch thread panicked".into())))
        .collect()
}

impl<E: Env> Ppo<E> {
    /// Loss and gradients (before clipping) of one minibatch; `adv` already normalised. The
    /// networks run on the host ([`super::host`]), an image minibatch split over the threads.
    fn minibatch(
        &self,
        obs: Vec<f32>,
        act: Vec<f32>,
        old_lp: &[f32],
        adv: &[f32],
        ret: &[f32],
        correction: Option<Correction<'_>>,
    ) -> Result<(Head, Vec<Vec<f32>>)> {
        let (o, a, n) = (self.row_dim(), self.act_dim, old_lp.len());
        let l = Layout::of(&self.cfg);
        let head_of = |mean: &[f32], value: &[f32], latent: Option<&[f32]>| {
            let x = HeadInput {
                mean,
                value,
                log_std: &self.params.data[l.log_std],
                latent,
                actions: &act,
                old_log_prob: old_lp,
                advantages: adv,
                returns: ret,
                correction,
            };
            loss_head(&x, self.cfg.clip_range, self.cfg.vf_coef, self.cfg.ent_coef)
        };
        if self.net_path == NetPath::Burn {
            let (head, mut grads) = self.minibatch_burn(&obs, head_of)?;
            self.mask_critic_inputs(&mut grads);
            return Ok((head, grads));
        }
        let (encoder, act_fn) = (self.encoder(), self.cfg.activation_fn);
        let image = encoder.as_ref();
        // An image minibatch is split over the threads (MLP-only ones are too small to gain).
        let workers = self.workers.as_deref().filter(|_| image.is_some());
        let k = workers.map_or(1, |w| (w.len() + 1).clamp(1, n));
        let (head, mut grads) = match workers.filter(|_| k > 1) {
            None => {
                let f = host::forward(&self.params, &l, act_fn, image, &obs, n);
                let head = head_of(&f.mean, &f.value, self.cfg.use_sde.then(|| f.latent(&obs)));
                let grads = host::backward(&self.params, &l, act_fn, image, &obs, &f, &head.d_mean, &head.d_value);
                (head, grads)
            }
            Some(workers) => {
                let rows: Vec<std::ops::Range<usize>> = (0..k).map(|i| i * n / k..(i + 1) * n / k).collect();
                let (params, l, obs) = (&self.params, &l, &obs);
                let passes = on_threads(workers, &rows, |r| {
                    host::forward(params, l, act_fn, image, &obs[r.start * o..r.end * o], r.len())
                })?;
                let (mut mean, mut value, mut latent) = (Vec::with_capacity(n * a), Vec::with_capacity(n), Vec::new());
                for (f, r) in passes.iter().zip(&rows) {
                    mean.extend_from_slice(&f.mean);
                    value.extend_from_slice(&f.value);
                    if self.cfg.use_sde {
                        latent.extend_from_slice(f.latent(&obs[r.start * o..r.end * o]));
                    }
                }
                let head = head_of(&mean, &value, self.cfg.use_sde.then_some(&latent[..]));
                let (d_mean, d_value) = (&head.d_mean, &head.d_value);
                let jobs: Vec<_> = rows.iter().cloned().zip(&passes).collect();
                let parts = on_threads(workers, &jobs, |(r, f)| {
                    host::backward(
                        params,
                        l,
                        act_fn,
                        image,
                        &obs[r.start * o..r.end * o],
                        f,
                        &d_mean[r.start * a..r.end * a],
                        &d_value[r.clone()],
                    )
                })?;
                // Summed in row order, so a thread count gives the same bits every run.
                let mut parts = parts.into_iter();
                let mut grads = parts.next().expect("one part per thread");
                for p in parts {
                    for (g, q) in grads.iter_mut().zip(p) {
                        g.iter_mut().zip(q).for_each(|(g, q)| *g += q);
                    }
                }
                (head, grads)
            }
        };
        grads[l.log_std] = head.d_log_std.clone();
        self.mask_critic_inputs(&mut grads);
        Ok((head, grads))
    }

    /// [`Self::minibatch`] on the Burn path: the networks forward on the device with autodiff,
    /// the fused head on the host, then one backward of `sum(mean * dL/dmean) + sum(value *
    /// dL/dvalue)`, as the host path does.
    fn minibatch_burn(
        &self,
        obs: &[f32],
        head_of: impl Fn(&[f32], &[f32], Option<&[f32]>) -> Head,
    ) -> Result<(Head, Vec<Vec<f32>>)> {
        let (o, a) = (self.row_dim(), self.act_dim);
        let n = obs.len() / o;
        let ad = self.device.clone().autodiff();
        let t3 = |v: &[f32], s: [usize; 3]| Tensor::<3>::from_data(TensorData::new(v.to_vec(), s), &ad);
        let params = self.params.to_tracked(&ad);
        let (mean, value, latent) = super::network::forward(&params, t3(obs, [1, n, o]), &self.cfg);
        let (mean_v, value_v) = (to_vec(mean.clone().inner())?, to_vec(value.clone().inner())?);
        let latent = if self.cfg.use_sde {
            Some(to_vec(latent.inner())?)
        } else {
            None
        };
        let head = head_of(&mean_v, &value_v, latent.as_deref());
        let surrogate = (mean * t3(&head.d_mean, [1, n, a])).sum() + (value * t3(&head.d_value, [1, n, 1])).sum();
        let mut grads = grads_of(&params, &surrogate.backward())?;
        grads[Layout::of(&self.cfg).log_std] = head.d_log_std.clone();
        Ok((head, grads))
    }

    /// Collect one rollout, update on it, then return the rollout's first `batch_size` samples
    /// (advantages normalised as the update does) with their loss and gradients before clipping
    /// at the updated weights (ratios away from 1, some clipped), and the weights before and
    /// after: for checking the loss and the update against another implementation.
    #[cfg(any(test, feature = "parity"))]
    pub fn gradient_probe(&mut self) -> Result<GradientProbe> {
        let r = self.collect_rollout()?;
        let params_before = self.params.data.clone();
        self.update(&r)?;
        let (o, a) = (self.row_dim(), self.act_dim);
        let n = self.cfg.batch_size.min(r.log_probs.len());
        let mut adv = r.advantages[..n].to_vec();
        if self.cfg.normalize_advantage {
            normalize_advantages(&mut adv);
        }
        let (head, grads) = self.minibatch(
            r.obs[..n * o].to_vec(),
            r.actions[..n * a].to_vec(),
            &r.log_probs[..n],
            &adv,
            &r.returns[..n],
            None,
        )?;
        Ok(GradientProbe {
            shapes: self.params.shapes.clone(),
            params_before,
            params: self.params.data.clone(),
            rollout_obs: r.obs.clone(),
            rollout_actions: r.actions.clone(),
            rollout_log_prob: r.log_probs.clone(),
            rollout_advantages: r.advantages.clone(),
            rollout_returns: r.returns.clone(),
            gae_inputs: r.gae_inputs.clone(),
            update_approx_kl: self.losses.approx_kl,
            update_clip_fraction: self.losses.clip_fraction,
            update_std: self.losses.std,
            obs: r.obs[..n * o].to_vec(),
            actions: r.actions[..n * a].to_vec(),
            old_log_prob: r.log_probs[..n].to_vec(),
            advantages: adv,
            returns: r.returns[..n].to_vec(),
            pg_loss: head.pg_loss,
            vf_loss: head.vf_loss,
            approx_kl: head.approx_kl,
            clip_fraction: head.clip_fraction,
            grads,
        })
    }

    /// Loss and gradients (before clipping) of one minibatch at `params` (agvrl's layout; `adv`
    /// already normalised): `(pg_loss, vf_loss, clip_fraction, grads)`. For checking against
    /// another implementation's numbers (tests against Stable-Baselines3's).
    #[cfg(any(test, feature = "parity"))]
    pub fn gradients_at(
        &mut self,
        params: Vec<Vec<f32>>,
        minibatch: [&[f32]; 5],
    ) -> Result<(f64, f64, f64, Vec<Vec<f32>>)> {
        if params.len() != self.params.data.len()
            || params.iter().zip(&self.params.data).any(|(p, q)| p.len() != q.len())
        {
            return Err(RlError::Config(
                "gradients_at: the weights do not fit this learner".into(),
            ));
        }
        self.params.data = params;
        let [obs, act, old_lp, adv, ret] = minibatch;
        let (h, g) = self.minibatch(obs.to_vec(), act.to_vec(), old_lp, adv, ret, None)?;
        Ok((h.pg_loss, h.vf_loss, h.clip_fraction, g))
    }

    pub(crate) fn update(&mut self, r: &Rollout) -> Result<()> {
        let (o, a) = (self.row_dim(), self.act_dim);
        let total = r.log_probs.len();
        let bs = self.cfg.batch_size.min(total);
        let log_std_idx = Layout::of(&self.cfg).log_std;
        let mut idx: Vec<usize> = (0..total).collect();
        let (mut pg_sum, mut vf_sum, mut clip_sum, mut ent_sum, mut n_mb) = (0.0, 0.0, 0.0, 0.0, 0usize);
        let (mut gn_sum, mut n_steps) = (0.0, 0usize);
        let correct = self.cfg.correction_coef > 0.0 && r.corrected.len() == total;
        let mut corr_sum = 0.0;
        // SB3 logs the KL of the last epoch only (its list restarts every epoch).
        let (mut kl_epoch, mut n_epoch) = (0.0, 0usize);
        'epochs: for _ in 0..self.cfg.n_epochs {
            (kl_epoch, n_epoch) = (0.0, 0);
            if self.shuffle {
                self.rng.shuffle(&mut idx);
            }
            // SB3 yields whole minibatches and a smaller last one.
            for mb in idx.chunks(bs) {
                let n = mb.len();
                let mut obs = Vec::with_capacity(n * o);
                let mut act = Vec::with_capacity(n * a);
                let mut old_lp = Vec::with_capacity(n);
                let mut adv = Vec::with_capacity(n);
                let mut ret = Vec::with_capacity(n);
                let (mut c_act, mut c_mask) = (Vec::new(), Vec::new());
                for &k in mb {
                    if correct {
                        c_act.extend_from_slice(&r.corrected_actions[k * a..(k + 1) * a]);
                        c_mask.push(r.corrected[k]);
                    }
                    obs.extend_from_slice(&r.obs[k * o..(k + 1) * o]);
                    act.extend_from_slice(&r.actions[k * a..(k + 1) * a]);
                    old_lp.push(r.log_probs[k]);
                    adv.push(r.advantages[k]);
                    ret.push(r.returns[k]);
                }
                if self.cfg.normalize_advantage {
                    normalize_advantages(&mut adv);
                }
                let correction = correct.then_some(Correction {
                    actions: &c_act,
                    mask: &c_mask,
                    coef: self.cfg.correction_coef,
                });
                let (head, mut grads) = self.minibatch(obs, act, &old_lp, &adv, &ret, correction)?;
                if !head.pg_loss.is_finite() || !head.vf_loss.is_finite() {
                    return Err(RlError::NonFinite("PPO loss"));
                }
                pg_sum += head.pg_loss;
                vf_sum += head.vf_loss;
                kl_epoch += head.approx_kl;
                n_epoch += 1;
                clip_sum += head.clip_fraction;
                ent_sum += head.entropy;
                corr_sum += head.correction;
                n_mb += 1;
                if self.cfg.target_kl.is_some_and(|t| head.approx_kl > 1.5 * t) {
                    break 'epochs;
                }
                gn_sum += Adam::clip_grad_norm(&mut grads, self.cfg.max_grad_norm);
                n_steps += 1;
                self.opt.step(&mut self.params, &grads);
                self.n_updates += 1;
            }
        }
        let m = n_mb.max(1) as f64;
        self.losses.policy = pg_sum / m;
        self.losses.value = vf_sum / m;
        self.losses.approx_kl = kl_epoch / n_epoch.max(1) as f64;
        self.losses.clip_fraction = clip_sum / m;
        self.losses.entropy = ent_sum / m;
        self.losses.grad_norm = gn_sum / n_steps.max(1) as f64;
        self.losses.correction = if correct { corr_sum / m } else { f64::NAN };
        self.losses.corrected_fraction = r.corrected.iter().map(|c| *c as f64).sum::<f64>() / total.max(1) as f64;
        let log_std = &self.params.data[log_std_idx];
        self.losses.std = log_std.iter().map(|l| (*l as f64).exp()).sum::<f64>() / log_std.len() as f64;
        // values = returns - advantages (before normalisation).
        self.losses.explained_variance = explained_variance(&r.returns, &r.advantages);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::super::network::forward;
    use super::*;
    use crate::gaussian;
    use crate::nets::{grads_of, scaled_diff, to_vec};
    use crate::rng::Rng;
    use agvrl_envs::VecEnv;
    use burn::tensor::{Tensor, TensorData};

    /// The loss written with autodiff tensor ops (the unfused formulation, SB3's).
    fn autodiff_loss(x: &HeadInput<'_>, clip: f64, vf_coef: f64, ent_coef: f64) -> (f64, Vec<f32>, Vec<f32>, Vec<f32>) {
        let dev = crate::device::default_device().autodiff();
        let n = x.value.len();
        let a = x.mean.len() / n;
        let t = |v: &[f32], s: [usize; 3]| Tensor::<3>::from_data(TensorData::new(v.to_vec(), s), &dev);
        let mean = t(x.mean, [1, n, a]).require_grad();
        let value = t(x.value, [1, n, 1]).require_grad();
        let (log_std, var) = match x.latent {
            None => {
                let log_std = t(x.log_std, [1, 1, a]).require_grad();
                (log_std.clone(), (log_std * 2.0).exp())
            }
            Some(l) => {
                let k = l.len() / n;
                let log_std = t(x.log_std, [1, k, a]).require_grad();
                let h = t(l, [1, n, k]);
                (log_std.clone(), (h.clone() * h).matmul((log_std * 2.0).exp()) + 1e-6)
            }
        };
        let diff = t(x.actions, [1, n, a]) - mean.clone();
        let lp = gaussian::log_prob(diff, var.clone());
        let ratio = (lp - t(x.old_log_prob, [1, n, 1])).exp();
        let adv = t(x.advantages, [1, n, 1]);
        let pg = (ratio.clone() * adv.clone())
            .min_pair(ratio.clamp(1.0 - clip, 1.0 + clip) * adv)
            .mean()
            .neg();
        let vf = (t(x.returns, [1, n, 1]) - value.clone()).powi_scalar(2).mean();
        let ent = gaussian::entropy_of(var).mean();
        let mut loss = pg + vf * vf_coef - ent * ent_coef;
        if let Some(c) = &x.correction {
            let err = mean.clone() - t(c.actions, [1, n, a]);
            let per_sample = (err.clone() * err).sum_dim(2);
            loss = loss + (per_sample * t(c.mask, [1, n, 1])).sum() * (c.coef / n as f64);
        }
        let g = loss.backward();
        let v = |x: &Tensor<3>| to_vec(x.grad(&g).unwrap()).unwrap();
        (
            to_vec(loss.inner()).unwrap()[0] as f64,
            v(&mean),
            v(&value),
            v(&log_std),
        )
    }

    fn check(latent_dim: Option<usize>, correction_coef: f64) {
        let mut rng = Rng::new(9);
        let (n, a) = (64, 2);
        let mean = rng.normals(n * a);
        let actions: Vec<f32> = mean.iter().map(|m| m + 0.7 * rng.normal() as f32).collect();
        let latent = latent_dim.map(|k| rng.normals(n * k).iter().map(|v| v.tanh()).collect::<Vec<f32>>());
        let log_std: Vec<f32> = (0..latent_dim.unwrap_or(1) * a)
            .map(|_| -0.5 + 0.3 * rng.normal() as f32)
            .collect();
        // Old log-probs near the current ones, so some ratios fall outside the clip range.
        let old: Vec<f32> = (0..n).map(|_| -2.0 + 0.4 * rng.normal() as f32).collect();
        // About a third of the samples corrected, to actions in the box.
        let corrected: Vec<f32> = rng.normals(n * a).iter().map(|v| v.tanh()).collect();
        let mask: Vec<f32> = (0..n).map(|_| (rng.normal() > 0.43) as u8 as f32).collect();
        let x = HeadInput {
            mean: &mean,
            value: &rng.normals(n),
            log_std: &log_std,
            latent: latent.as_deref(),
            actions: &actions,
            old_log_prob: &old,
            advantages: &rng.normals(n),
            returns: &rng.normals(n),
            correction: (correction_coef > 0.0).then_some(Correction {
                actions: &corrected,
                mask: &mask,
                coef: correction_coef,
            }),
        };
        let h = loss_head(&x, 0.2, 0.5, 0.01);
        let (loss, d_mean, d_value, d_log_std) = autodiff_loss(&x, 0.2, 0.5, 0.01);
        let fused = h.pg_loss + 0.5 * h.vf_loss - 0.01 * h.entropy + correction_coef * h.correction;
        assert_eq!(h.correction > 0.0, correction_coef > 0.0);
        assert!((fused - loss).abs() < 1e-4, "{fused} vs {loss}");
        assert!(h.clip_fraction > 0.0 && h.clip_fraction < 1.0);
        // Equal lengths first: a zip would pass a missing gradient.
        let close = |p: &[f32], q: &[f32], name: &str| {
            assert!(
                !q.is_empty() && p.len() == q.len(),
                "{name}: {} values vs {}",
                p.len(),
                q.len()
            );
            for (k, (p, q)) in p.iter().zip(q).enumerate() {
                assert!((p - q).abs() < 1e-5 + 1e-3 * q.abs(), "{name}[{k}]: {p} vs {q}");
            }
        };
        close(&h.d_mean, &d_mean, "d_mean");
        close(&h.d_value, &d_value, "d_value");
        close(&h.d_log_std, &d_log_std, "d_log_std");
    }

    /// An env of `o`-value observations in [0, 1] and 2 actions, in one endless episode whose
    /// observation follows the first action and whose reward pays it near 0.3.
    struct Shape(usize);

    impl Env for Shape {
        fn observation_space(&self) -> agvrl_envs::BoxSpace {
            agvrl_envs::BoxSpace::uniform(self.0, 0.0, 1.0)
        }
        fn action_space(&self) -> agvrl_envs::BoxSpace {
            agvrl_envs::BoxSpace::uniform(2, -1.0, 1.0)
        }
        fn reset(&mut self, _: Option<u64>) -> std::result::Result<(Vec<f32>, agvrl_envs::Info), agvrl_envs::EnvError> {
            Ok((vec![0.0; self.0], Default::default()))
        }
        fn step(&mut self, action: &[f32]) -> std::result::Result<agvrl_envs::Step, agvrl_envs::EnvError> {
            Ok(agvrl_envs::Step {
                obs: (0..self.0)
                    .map(|k| (k as f32 * 0.618 + action[0]).rem_euclid(1.0))
                    .collect(),
                reward: -((action[0] - 0.3) as f64).powi(2),
                terminated: false,
                truncated: false,
                info: Default::default(),
            })
        }
        fn dt_s(&self) -> f64 {
            0.1
        }
    }

    /// A small NatureCNN over a `c`-channel 38x44 image after `v` vector values.
    fn small_image(c: usize, v: usize) -> Option<(crate::cnn::ImageSpec, usize)> {
        let spec = crate::cnn::ImageSpec {
            features_dim: 24,
            ..crate::cnn::ImageSpec::new(c, 38, 44)
        };
        Some((spec, v))
    }

    /// Envs for a learner of that observation: pendulum without an image, else [`Shape`].
    fn envs_for(image: Option<(crate::cnn::ImageSpec, usize)>) -> VecEnv<Box<dyn Env>> {
        match image {
            None => crate::learning::pendulum_envs(2).unwrap(),
            Some((spec, v)) => VecEnv::new(vec![Box::new(Shape(v + spec.len())) as Box<dyn Env>], 1).unwrap(),
        }
    }

    /// `n` observation rows of `o` values: images in [0, 1] as the envs give them, a vector
    /// part of any sign.
    fn observations(image: Option<(crate::cnn::ImageSpec, usize)>, o: usize, n: usize, rng: &mut Rng) -> Vec<f32> {
        (0..n * o)
            .map(|k| match image {
                Some((_, v)) if k % o >= v => rng.uniform() as f32,
                _ => 2.0 * rng.normal() as f32,
            })
            .collect()
    }

    /// A warm start gives the added inputs zero weights in both trunks (actor and critic) and
    /// keeps every other weight, so the actor acts as the checkpoint's on the inputs they share.
    #[test]
    fn a_warm_start_keeps_the_weights_and_zeroes_the_added_inputs() {
        use super::super::{Ppo, PpoConfig};
        let cfg = PpoConfig {
            net_arch: vec![8, 8],
            n_steps: 8,
            batch_size: 8,
            ..PpoConfig::default()
        };
        let dev = crate::default_device();
        let learner = |n, cfg: &PpoConfig, seed| {
            Ppo::new(cfg.clone(), VecEnv::new(vec![Shape(n)], 1).unwrap(), &dev, seed).unwrap()
        };
        let from = learner(3, &cfg, 1);
        let path = std::env::temp_dir().join(format!("agvrl-warm-start-{}.ckpt", std::process::id()));
        from.save_checkpoint(&path).unwrap();
        let mut to = learner(5, &cfg, 2);
        to.warm_start(&path, &[0, 3]).unwrap();
        let [members, rows, cols] = to.params.shapes[0];
        assert_eq!([members, rows], [2, 5]);
        let row = |p: &[f32], n: usize, m: usize, i: usize| p[(m * n + i) * cols..][..cols].to_vec();
        for m in 0..members {
            for (i, was) in [None, Some(0), Some(1), None, Some(2)].into_iter().enumerate() {
                let expected = was.map_or(vec![0.0; cols], |k| row(&from.params.data[0], 3, m, k));
                assert_eq!(row(&to.params.data[0], 5, m, i), expected, "member {m}, input {i}");
            }
        }
        assert_eq!(to.params.data[1..], from.params.data[1..]);
        let (mut a, mut b) = (from.policy(&dev), to.policy(&dev));
        let acts = (
            a.act(&[0.3, 0.7, 0.9], true).unwrap(),
            b.act(&[0.5, 0.3, 0.7, 1.0, 0.9], true).unwrap(),
        );
        assert!(
            acts.0.iter().zip(&acts.1).all(|(p, q)| (p - q).abs() < 1e-6),
            "{acts:?}"
        );
        // Another network, or inputs that do not account for the difference, are refused.
        let narrow = PpoConfig {
            net_arch: vec![4],
            ..cfg.clone()
        };
        assert!(learner(5, &narrow, 3).warm_start(&path, &[0, 3]).is_err());
        assert!(learner(5, &cfg, 3).warm_start(&path, &[0]).is_err());
        std::fs::remove_file(&path).unwrap();
    }

    /// A warm start may switch gSDE on (or off): every weight is the checkpoint's, so the mean
    /// action is too, and the log std is the new learner's own, at `log_std_init`, in its shape.
    #[test]
    fn a_warm_start_switching_gsde_keeps_the_weights_and_starts_exploration_afresh() {
        use super::super::{Ppo, PpoConfig};
        let plain = PpoConfig {
            net_arch: vec![8, 8],
            n_steps: 8,
            batch_size: 8,
            log_std_init: 0.5,
            ..PpoConfig::default()
        };
        let sde = PpoConfig {
            use_sde: true,
            log_std_init: -1.5,
            ..plain.clone()
        };
        let dev = crate::default_device();
        let learner =
            |cfg: &PpoConfig, seed| Ppo::new(cfg.clone(), VecEnv::new(vec![Shape(3)], 1).unwrap(), &dev, seed).unwrap();
        let path = std::env::temp_dir().join(format!("agvrl-warm-start-sde-{}.ckpt", std::process::id()));
        for (from_cfg, to_cfg) in [(&plain, &sde), (&sde, &plain)] {
            let from = learner(from_cfg, 1);
            from.save_checkpoint(&path).unwrap();
            let mut to = learner(to_cfg, 2);
            let fresh = to.params.clone();
            to.warm_start(&path, &[]).unwrap();
            let log_std = Layout::of(to_cfg).log_std;
            assert_eq!(to.params.shapes, fresh.shapes);
            for (k, data) in to.params.data.iter().enumerate() {
                let expected = if k == log_std {
                    &fresh.data[k]
                } else {
                    &from.params.data[k]
                };
                assert_eq!(data, expected, "parameter {k}, use_sde {}", to_cfg.use_sde);
            }
            let obs = [0.3, -0.7, 0.9];
            let (a, b) = (
                from.policy(&dev).act(&obs, true).unwrap(),
                to.policy(&dev).act(&obs, true).unwrap(),
            );
            assert!(a.iter().zip(&b).all(|(p, q)| (p - q).abs() < 1e-6), "{a:?} {b:?}");
        }
        std::fs::remove_file(&path).unwrap();
    }

    /// The host networks' outputs and gradients against the same networks through Burn's
    /// autodiff (tanh there is `2 sigmoid(2x) - 1` on libm's `expf`), for both activations,
    /// with and without gSDE's latent, and with the NatureCNN (1 and 3 channels, a vector part
    /// or none, split over 1 and 3 threads).
    #[test]
    fn host_gradients_match_autodiff() {
        use crate::nets::Activation;
        let image = small_image;
        for (arch, act, sde, image, threads) in [
            (vec![64, 64], Activation::Tanh, false, None, 1),
            (vec![32, 16], Activation::Relu, true, None, 1),
            (vec![8], Activation::Tanh, true, None, 1),
            (vec![16, 8], Activation::Tanh, false, image(1, 5), 1),
            (vec![16], Activation::Relu, true, image(3, 0), 3),
            (vec![12], Activation::Tanh, false, image(1, 2), 2),
        ] {
            let cfg = super::super::PpoConfig {
                net_arch: arch.clone(),
                activation_fn: act,
                use_sde: sde,
                image: image.map(|(s, _)| s),
                ..Default::default()
            };
            let device = crate::device::default_device();
            let mut ppo = Ppo::new(cfg.clone(), envs_for(image), &device, 3).unwrap();
            ppo.set_threads(threads).unwrap();
            let (o, a, n) = (ppo.obs_dim, ppo.act_dim, 40);
            let mut rng = Rng::new(5);
            let x = observations(image, o, n, &mut rng);
            let (d_mean, d_value) = (rng.normals(n * a), rng.normals(n));
            let l = Layout::of(&cfg);
            let enc = ppo.encoder();
            let f = host::forward(&ppo.params, &l, act, enc.as_ref(), &x, n);
            let host_grads = host::backward(&ppo.params, &l, act, enc.as_ref(), &x, &f, &d_mean, &d_value);

            let ad = device.clone().autodiff();
            let t3 = |v: Vec<f32>, s: [usize; 3]| Tensor::<3>::from_data(TensorData::new(v, s), &ad);
            let params = ppo.params.to_tracked(&ad);
            let (mean, value, latent) = forward(&params, t3(x.clone(), [1, n, o]), &cfg);
            let what = format!("{arch:?} {act:?} image {image:?}");
            let close = |p: &[f32], q: &[f32], name: &str| {
                assert_eq!(p.len(), q.len(), "{what} {name}");
                let scale = q.iter().fold(0.0f32, |m, v| m.max(v.abs()));
                for (k, (p, q)) in p.iter().zip(q).enumerate() {
                    assert!(
                        (p - q).abs() < 2e-5 + 2e-4 * q.abs() + 1e-5 * scale,
                        "{what} {name}[{k}]: {p} vs {q}"
                    );
                }
            };
            close(&f.mean, &to_vec(mean.clone().inner()).unwrap(), "mean");
            close(&f.value, &to_vec(value.clone().inner()).unwrap(), "value");
            if sde {
                close(f.latent(&x), &to_vec(latent.inner()).unwrap(), "latent");
            }
            let surrogate =
                (mean * t3(d_mean.clone(), [1, n, a])).sum() + (value * t3(d_value.clone(), [1, n, 1])).sum();
            let auto = grads_of(&params, &surrogate.backward()).unwrap();
            assert_eq!(host_grads.len(), auto.len(), "{what}");
            for k in (0..auto.len()).filter(|k| *k != l.log_std) {
                close(&host_grads[k], &auto[k], &format!("grad {k}"));
            }
            assert!(host_grads[l.log_std].iter().all(|g| *g == 0.0));
            if image.is_some() {
                // The encoder's gradients are there, and the split minibatch sums to the same.
                assert!(host_grads[l.encoder.start].iter().any(|g| *g != 0.0), "{what}");
                let (adv, old_lp) = (rng.normals(n), vec![-1.0; n]);
                let (ret, acts) = (rng.normals(n), rng.normals(n * a));
                let mb =
                    |p: &Ppo<Box<dyn Env>>| p.minibatch(x.clone(), acts.clone(), &old_lp, &adv, &ret, None).unwrap();
                let (h1, g1) = mb(&ppo);
                ppo.set_threads(1).unwrap();
                let (h2, g2) = mb(&ppo);
                // Products of other shapes round differently: equal to f32 rounding.
                let near = |p: f64, q: f64| (p - q).abs() < 1e-5 * (1.0 + q.abs());
                assert!(near(h1.pg_loss, h2.pg_loss) && near(h1.vf_loss, h2.vf_loss), "{what}");
                assert_eq!(g1.len(), g2.len(), "{what}");
                for (k, (p, q)) in g1.iter().zip(&g2).enumerate() {
                    close(p, q, &format!("split grad {k}"));
                }
            }
        }
    }

    /// The Burn path (the networks through autodiff on a CPU backend: what a GPU runs) against
    /// the host kernels on one minibatch, MLP with either activation, gSDE, and the NatureCNN:
    /// the losses and every gradient agree to 1e-5 of their scale; a rollout and an update on
    /// each path from the same seed end at weights within 1e-4 of theirs.
    #[test]
    fn burn_path_gives_the_host_paths_loss_and_gradients() {
        use crate::nets::Activation;
        let image = small_image;
        for (arch, act, sde, image) in [
            (vec![64, 64], Activation::Tanh, false, None),
            (vec![32, 16], Activation::Relu, true, None),
            (vec![16, 8], Activation::Tanh, false, image(1, 5)),
        ] {
            let cfg = super::super::PpoConfig {
                net_arch: arch.clone(),
                activation_fn: act,
                use_sde: sde,
                image: image.map(|(s, _)| s),
                n_steps: 32,
                batch_size: 16,
                n_epochs: 2,
                ..Default::default()
            };
            let device = crate::device::default_device();
            let mut host = Ppo::new(cfg.clone(), envs_for(image), &device, 3).unwrap();
            let mut burn = Ppo::new(cfg.clone(), envs_for(image), &device, 3).unwrap();
            assert_eq!(host.net_path(), NetPath::Host);
            burn.set_net_path(NetPath::Burn);
            let (o, a, n) = (host.obs_dim, host.act_dim, 40);
            let mut rng = Rng::new(5);
            let x = observations(image, o, n, &mut rng);
            let (acts, adv, ret) = (rng.normals(n * a), rng.normals(n), rng.normals(n));
            let old_lp = vec![-1.0; n];
            let mb = |p: &Ppo<Box<dyn Env>>| p.minibatch(x.clone(), acts.clone(), &old_lp, &adv, &ret, None).unwrap();
            let ((hh, hg), (bh, bg)) = (mb(&host), mb(&burn));
            let what = format!("{arch:?} {act:?} sde {sde} image {}", image.is_some());
            let rel = |p: f64, q: f64| (p - q).abs() / q.abs().max(1e-12);
            eprintln!(
                "{what}: pg {:.2e} vf {:.2e}",
                rel(bh.pg_loss, hh.pg_loss),
                rel(bh.vf_loss, hh.vf_loss)
            );
            assert!(
                rel(bh.pg_loss, hh.pg_loss) < 1e-5,
                "{what} pg {} vs {}",
                bh.pg_loss,
                hh.pg_loss
            );
            assert!(
                rel(bh.vf_loss, hh.vf_loss) < 1e-5,
                "{what} vf {} vs {}",
                bh.vf_loss,
                hh.vf_loss
            );
            assert_eq!(hg.len(), bg.len());
            let worst = hg.iter().zip(&bg).map(|(h, b)| scaled_diff(b, h)).fold(0.0, f64::max);
            eprintln!("{what}: gradients {worst:.2e}");
            for (k, (h, b)) in hg.iter().zip(&bg).enumerate() {
                assert!(h.iter().any(|g| *g != 0.0), "{what} grad {k} is all zero");
                assert!(scaled_diff(b, h) < 1e-5, "{what} grad {k}: {:.2e}", scaled_diff(b, h));
            }
            let before = host.params.data.clone();
            host.learn(64, &mut |_| crate::Control::Continue).unwrap();
            burn.learn(64, &mut |_| crate::Control::Continue).unwrap();
            assert!(host.n_updates > 0 && burn.n_updates == host.n_updates, "{what}");
            for (k, (p, q)) in before.iter().zip(&burn.params.data).enumerate() {
                assert!(p != q, "{what}: tensor {k} did not move");
            }
            let worst = host
                .params
                .data
                .iter()
                .zip(&burn.params.data)
                .map(|(h, b)| scaled_diff(b, h))
                .fold(0.0, f64::max);
            eprintln!("{what}: weights after an update {worst:.2e}");
            // Adam's first steps scale every gradient to about the learning rate, so weights
            // agree less closely than the gradients they were stepped by.
            for (k, (h, b)) in host.params.data.iter().zip(&burn.params.data).enumerate() {
                assert!(
                    scaled_diff(b, h) < 1e-4,
                    "{what} weights {k}: {:.2e}",
                    scaled_diff(b, h)
                );
            }
        }
    }

    #[test]
    fn fused_head_matches_autodiff() {
        check(None, 0.0);
    }

    #[test]
    fn fused_gsde_head_matches_autodiff() {
        check(Some(8), 0.0);
    }

    /// The correction term (the policy imitates the actions a safety filter sent) and its
    /// gradient against autodiff, beside the PPO loss and with gSDE.
    #[test]
    fn correction_term_and_its_gradient_match_autodiff() {
        check(None, 2.0);
        check(Some(8), 0.5);
    }
}
