//! One PPO update over a rollout, top to bottom as in SB3's `PPO.train`.

use super::{forward, head_idx, Ppo, Rollout};
use crate::error::{Result, RlError};
use crate::nets::{grads_of, to_vec, Adam};
use agvrl_envs::Env;
use burn::tensor::{Tensor, TensorData};

const HALF_LN_2PI: f64 = 0.918_938_533_204_672_7;

impl<E: Env> Ppo<E> {
    pub(crate) fn update(&mut self, r: &Rollout) -> Result<()> {
        let (o, a) = (self.obs_dim, self.act_dim);
        let total = r.log_probs.len();
        let bs = self.cfg.batch_size.min(total);
        let dev = self.device.clone();
        let clip = self.cfg.clip_range;
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
                let t3 = |v: Vec<f32>, s: [usize; 3]| Tensor::<3>::from_data(TensorData::new(v, s), &dev);
                let params: Vec<Tensor<3>> = self.params.to_tracked(&dev.clone().autodiff());
                let (mean, value) = forward(&params, t3(obs, [1, n, o]).autodiff(), &self.cfg);
                let log_std = params[params.len() - 1].clone();
                // log N(act; mean, exp(log_std)) summed over action elements.
                let z = (t3(act, [1, n, a]).autodiff() - mean) * log_std.clone().neg().exp();
                let lp = (z.powi_scalar(2) * -0.5 - log_std.clone() - HALF_LN_2PI).sum_dim(2);
                let old = t3(old_lp.clone(), [1, n, 1]).autodiff();
                let ratio = (lp.clone() - old).exp();
                let adv_t = t3(adv, [1, n, 1]).autodiff();
                let surr1 = ratio.clone() * adv_t.clone();
                let surr2 = ratio.clamp(1.0 - clip, 1.0 + clip) * adv_t;
                let pg_loss = surr1.min_pair(surr2).mean().neg();
                let values_pred = value;
                let vf_loss = (t3(ret, [1, n, 1]).autodiff() - values_pred).powi_scalar(2).mean();
                let mut loss = pg_loss.clone() + vf_loss.clone() * self.cfg.vf_coef;
                if self.cfg.ent_coef != 0.0 {
                    // Entropy of a diagonal Gaussian: sum(log_std + (1 + ln 2 pi) / 2).
                    let entropy = (log_std + (0.5 + HALF_LN_2PI)).sum();
                    loss = loss - entropy * self.cfg.ent_coef;
                }
                let mut grads = grads_of(&params, &loss.backward())?;
                let new_lp = to_vec(lp.inner())?;
                let pg = to_vec(pg_loss.inner())?[0] as f64;
                let vf = to_vec(vf_loss.inner())?[0] as f64;
                if !pg.is_finite() || !vf.is_finite() {
                    return Err(RlError::NonFinite("PPO loss"));
                }
                let (mut kl, mut clipped) = (0.0, 0usize);
                for (new, old) in new_lp.iter().zip(&old_lp) {
                    let log_ratio = (new - old) as f64;
                    kl += log_ratio.exp() - 1.0 - log_ratio;
                    clipped += ((log_ratio.exp() - 1.0).abs() > clip) as usize;
                }
                let kl = kl / n as f64;
                pg_sum += pg;
                vf_sum += vf;
                kl_sum += kl;
                clip_sum += clipped as f64 / n as f64;
                n_mb += 1;
                if self.cfg.target_kl.is_some_and(|t| kl > 1.5 * t) {
                    break 'epochs;
                }
                Adam::clip_grad_norm(&mut grads, self.cfg.max_grad_norm);
                self.opt.step(&mut self.params, &grads);
                self.n_updates += 1;
            }
        }
        let m = n_mb.max(1) as f64;
        let log_std = &self.params.data[head_idx(&self.cfg) + 4];
        self.losses.policy = pg_sum / m;
        self.losses.value = vf_sum / m;
        self.losses.approx_kl = kl_sum / m;
        self.losses.clip_fraction = clip_sum / m;
        self.losses.entropy = log_std.iter().map(|l| *l as f64 + 0.5 + HALF_LN_2PI).sum();
        Ok(())
    }
}
