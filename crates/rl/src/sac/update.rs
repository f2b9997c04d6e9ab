//! One SAC gradient step, top to bottom as in SB3's `SAC.train`.
//!
//! Graph work is kept to what the gradients need: the target is computed on plain tensors,
//! the critic loss differentiates only the critics, and the actor loss runs through the
//! just-updated critics as constants (their weight gradients are never formed). The actor's
//! forward pass on the batch is done once and feeds both the entropy-coefficient and the
//! actor loss.

use super::Sac;
use crate::error::{Result, RlError};
use crate::nets::{grads_of, mlp_forward, to_vec, Activation};
use crate::policy::{LOG_STD_MAX, LOG_STD_MIN};
use agvrl_envs::Env;
use burn::tensor::{Tensor, TensorData};

const HALF_LN_2PI: f32 = 0.918_938_5;

/// `(tanh action [m, b, a], log_prob [m, b, 1])` of the squashed Gaussian with
/// reparameterisation noise `eps`, from actor outputs `[m, b, 2a]`.
pub(crate) fn squashed_sample(out: Tensor<3>, eps: Tensor<3>, a: usize) -> (Tensor<3>, Tensor<3>) {
    let mean = out.clone().narrow(2, 0, a);
    let log_std = out.narrow(2, a, a).clamp(LOG_STD_MIN, LOG_STD_MAX);
    let u = mean + log_std.clone().exp() * eps.clone();
    let y = u.tanh();
    // log N(u; mean, std) = -eps^2/2 - log std - ln(2 pi)/2, minus the tanh Jacobian.
    let gauss = (eps.powi_scalar(2) * -0.5 - log_std - HALF_LN_2PI).sum_dim(2);
    let jac = (y.clone().powi_scalar(2).neg() + (1.0 + 1e-6)).log().sum_dim(2);
    (y, gauss - jac)
}

fn min_of_twins(q: Tensor<3>) -> Tensor<3> {
    q.clone().narrow(0, 0, 1).min_pair(q.narrow(0, 1, 1))
}

impl<E: Env> Sac<E> {
    pub(crate) fn update(&mut self) -> Result<()> {
        let (b, o, a) = (self.cfg.batch_size, self.obs_dim, self.act_dim);
        let dev = self.device.clone();
        let batch = self.buffer.sample(b, &mut self.rng, self.normalizer.as_ref());
        let t3 = |v: Vec<f32>, s: [usize; 3]| Tensor::<3>::from_data(TensorData::new(v, s), &dev);
        let obs = t3(batch.obs, [1, b, o]);
        let next_obs = t3(batch.next_obs, [1, b, o]);
        let actions = t3(batch.actions, [1, b, a]);
        let rewards = t3(batch.rewards, [1, b, 1]);
        let not_done = t3(batch.dones.iter().map(|d| 1.0 - d).collect(), [1, b, 1]);
        let eps_pi = t3(self.rng.normals(b * a), [1, b, a]);
        let eps_next = t3(self.rng.normals(b * a), [1, b, a]);

        // Actor forward with gradients; reused below by the entropy and actor losses.
        let actor_tr: Vec<Tensor<3>> = self.actor_dev.iter().map(|t| t.clone().autodiff().require_grad()).collect();
        let out = mlp_forward(&actor_tr, obs.clone().autodiff(), Activation::Relu, false);
        let (pi_action, log_prob) = squashed_sample(out, eps_pi.autodiff(), a);
        let log_prob_host = to_vec(log_prob.clone().inner())?;
        let mean_log_prob = log_prob_host.iter().map(|v| *v as f64).sum::<f64>() / b as f64;

        // Entropy coefficient: alpha for this step is taken before its own update (as SB3).
        let ent_coef = (self.log_ent_coef.data[0][0] as f64).exp();
        if let Some(opt) = &mut self.ent_opt {
            // d/d(log alpha) of -log alpha * (log_prob + target_entropy).mean()
            let g = -(mean_log_prob + self.target_entropy) as f32;
            opt.step(&mut self.log_ent_coef, &[vec![g]]);
        }

        // Target: r + gamma (1 - terminated) (min Q_targ(s', a') - alpha log pi(a'|s')).
        let next_out = mlp_forward(&self.actor_dev, next_obs.clone(), Activation::Relu, false);
        let (next_action, next_log_prob) = squashed_sample(next_out, eps_next, a);
        let q_next = mlp_forward(&self.target_dev, Tensor::cat(vec![next_obs, next_action], 2), Activation::Relu, false);
        let q_next = min_of_twins(q_next) - next_log_prob * ent_coef;
        let target_q = rewards + not_done * q_next * self.cfg.gamma;

        // Critic loss: 0.5 * sum over both critics of MSE, one batched forward.
        let critic_tr: Vec<Tensor<3>> = self.critic_dev.iter().map(|t| t.clone().autodiff().require_grad()).collect();
        let q = mlp_forward(&critic_tr, Tensor::cat(vec![obs.clone(), actions], 2).autodiff(), Activation::Relu, false);
        let critic_loss = (q - target_q.autodiff()).powi_scalar(2).sum() * (0.5 / b as f64);
        let critic_grads = grads_of(&critic_tr, &critic_loss.backward())?;
        let critic_loss = to_vec(critic_loss.inner())?[0] as f64;
        self.critic_opt.step(&mut self.critic, &critic_grads);
        self.critic_dev = self.critic.to_device(&dev);

        // Actor loss through the updated critics, held constant.
        let q_pi = mlp_forward(&self.critic_dev, Tensor::cat(vec![obs.autodiff(), pi_action], 2), Activation::Relu, false);
        let actor_loss = (log_prob * ent_coef - min_of_twins(q_pi)).mean();
        let actor_grads = grads_of(&actor_tr, &actor_loss.backward())?;
        let actor_loss = to_vec(actor_loss.inner())?[0] as f64;
        self.actor_opt.step(&mut self.actor, &actor_grads);
        self.actor_dev = self.actor.to_device(&dev);

        self.n_updates += 1;
        if self.n_updates % self.cfg.target_update_interval == 0 {
            self.critic_target.polyak(&self.critic, self.cfg.tau as f32);
            self.target_dev = self.critic_target.to_device(&dev);
        }
        if !critic_loss.is_finite() || !actor_loss.is_finite() {
            return Err(RlError::NonFinite("SAC loss"));
        }
        self.losses.policy = actor_loss;
        self.losses.value = critic_loss;
        self.losses.entropy = -mean_log_prob;
        self.losses.ent_coef = ent_coef;
        Ok(())
    }
}
