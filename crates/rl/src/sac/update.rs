//! One SAC gradient step, in SB3's `SAC.train` order: entropy coefficient, critic update,
//! actor update through the just-updated critics, Polyak averaging.
//!
//! Graph work is kept to what the gradients need: the target and the entropy statistics come
//! from one plain forward of the actor on `[obs; next_obs]`, the critic loss differentiates only
//! the critics (one batched forward for both), and the actor loss runs through the updated
//! critics as constants, so their weight gradients are never formed.
//!
//! With `threads > 1` the minibatch is split into row blocks whose losses (sums over rows
//! divided by the full batch size) are differentiated on separate threads and their gradients
//! summed in block order: the same update as one thread up to float summation order, and
//! deterministic for a fixed thread count.

use super::Sac;
use crate::cnn::{ImageSpec, encode};
use crate::error::{Result, RlError};
use crate::nets::{Activation, NetParts, grads_of, mlp_forward, to_vec};
use crate::policy::{LOG_STD_MAX, LOG_STD_MIN};
use agvrl_envs::Env;
use burn::tensor::{Device, Tensor, TensorData};

/// `(tanh action [m, b, a], log_prob [m, b, 1])` of the squashed Gaussian with
/// reparameterisation noise `eps`, from actor outputs `[m, b, 2a]`.
pub(crate) fn squashed_sample(out: Tensor<3>, eps: Tensor<3>, a: usize) -> (Tensor<3>, Tensor<3>) {
    let mean = out.clone().narrow(2, 0, a);
    let log_std = out.narrow(2, a, a).clamp(LOG_STD_MIN, LOG_STD_MAX);
    let u = mean + log_std.clone().exp() * eps.clone();
    let y = u.tanh();
    // log N(u; mean, std) = -eps^2/2 - log std - ln(2 pi)/2, minus the tanh Jacobian.
    let gauss = crate::gaussian::log_prob_of_noise(eps, log_std);
    let jac = (y.clone().powi_scalar(2).neg() + (1.0 + 1e-6)).log().sum_dim(2);
    (y, gauss - jac)
}

fn min_of_twins(q: Tensor<3>) -> Tensor<3> {
    q.clone().narrow(0, 0, 1).min_pair(q.narrow(0, 1, 1))
}

/// One row block of the minibatch, host side.
struct Block {
    rows: usize,
    obs: Vec<f32>,
    next_obs: Vec<f32>,
    actions: Vec<f32>,
    rewards: Vec<f32>,
    not_done: Vec<f32>,
    eps_pi: Vec<f32>,
    eps_next: Vec<f32>,
}

/// What a block contributes to the critic step.
struct CriticOut {
    grads: Vec<Vec<f32>>,
    loss: f64,
    log_prob_sum: f64,
}

/// Device weights and constants every block reads.
struct Shared<'a> {
    device: &'a Device,
    actor: &'a [Tensor<3>],
    critic: &'a [Tensor<3>],
    target: &'a [Tensor<3>],
    o: usize,
    a: usize,
    /// Full minibatch size: every block's loss is a sum over its rows divided by it.
    batch: usize,
    gamma: f64,
    ent_coef: f64,
    /// Where the MLP and the encoder sit in each net's tensors.
    parts: NetParts,
    image: Option<ImageSpec>,
}

impl Shared<'_> {
    fn t3(&self, v: &[f32], s: [usize; 3]) -> Tensor<3> {
        Tensor::<3>::from_data(TensorData::new(v.to_vec(), s), self.device)
    }

    /// The observation as a net's MLP sees it: the image part replaced by the net's encoder
    /// features.
    fn features(&self, net: &[Tensor<3>], obs: Tensor<3>) -> Tensor<3> {
        match &self.image {
            Some(spec) => encode(self.parts.encoder_of(net), spec, obs),
            None => obs,
        }
    }

    /// Actor outputs `[1, b, 2a]`.
    fn actor_out(&self, actor: &[Tensor<3>], obs: Tensor<3>) -> Tensor<3> {
        mlp_forward(
            self.parts.mlp_of(actor),
            self.features(actor, obs),
            Activation::Relu,
            false,
        )
    }

    /// Twin Q values `[2, b, 1]` from critic features and actions.
    fn q(&self, critic: &[Tensor<3>], features: Tensor<3>, action: Tensor<3>) -> Tensor<3> {
        mlp_forward(
            self.parts.mlp_of(critic),
            Tensor::cat(vec![features, action], 2),
            Activation::Relu,
            false,
        )
    }

    /// Entropy statistics, TD target and critic gradients for one block.
    fn critic_block(&self, b: &Block) -> Result<CriticOut> {
        let (n, o, a) = (b.rows, self.o, self.a);
        let obs = self.t3(&b.obs, [1, n, o]);
        let next_obs = self.t3(&b.next_obs, [1, n, o]);
        // One plain actor forward on [obs; next_obs].
        let both = Tensor::cat(vec![obs.clone(), next_obs.clone()], 1);
        let eps = Tensor::cat(vec![self.t3(&b.eps_pi, [1, n, a]), self.t3(&b.eps_next, [1, n, a])], 1);
        let (act, log_prob) = squashed_sample(self.actor_out(self.actor, both), eps, a);
        let log_prob_sum = to_vec(log_prob.clone().narrow(1, 0, n).sum())?[0] as f64;
        let (next_action, next_log_prob) = (act.narrow(1, n, n), log_prob.narrow(1, n, n));
        // Target: r + gamma (1 - terminated) (min Q_targ(s', a') - alpha log pi(a'|s')).
        let q_next = self.q(self.target, self.features(self.target, next_obs), next_action);
        let q_next = min_of_twins(q_next) - next_log_prob * self.ent_coef;
        let target_q = self.t3(&b.rewards, [1, n, 1]) + self.t3(&b.not_done, [1, n, 1]) * q_next * self.gamma;
        // 0.5 * sum over both critics of the MSE, one batched forward.
        let critic: Vec<Tensor<3>> = self
            .critic
            .iter()
            .map(|t| t.clone().autodiff().require_grad())
            .collect();
        let features = self.features(&critic, obs.autodiff());
        let q = self.q(&critic, features, self.t3(&b.actions, [1, n, a]).autodiff());
        let loss = (q - target_q.autodiff()).powi_scalar(2).sum() * (0.5 / self.batch as f64);
        let grads = grads_of(&critic, &loss.backward())?;
        Ok(CriticOut {
            grads,
            loss: to_vec(loss.inner())?[0] as f64,
            log_prob_sum,
        })
    }

    /// Actor gradients for one block: `sum(alpha log pi - min Q(s, pi(s))) / batch` through
    /// the (updated) critics held constant.
    fn actor_block(&self, b: &Block) -> Result<(Vec<Vec<f32>>, f64)> {
        let (n, o, a) = (b.rows, self.o, self.a);
        let obs = self.t3(&b.obs, [1, n, o]);
        let actor: Vec<Tensor<3>> = self.actor.iter().map(|t| t.clone().autodiff().require_grad()).collect();
        let out = self.actor_out(&actor, obs.clone().autodiff());
        let (pi_action, log_prob) = squashed_sample(out, self.t3(&b.eps_pi, [1, n, a]).autodiff(), a);
        // The critics' features are constants here: computed plain, then joined to the graph.
        let critic_features = self.features(self.critic, obs).autodiff();
        let q_pi = self.q(self.critic, critic_features, pi_action);
        let loss = (log_prob * self.ent_coef - min_of_twins(q_pi)).sum() / self.batch as f64;
        let grads = grads_of(&actor, &loss.backward())?;
        Ok((grads, to_vec(loss.inner())?[0] as f64))
    }
}

/// Run `f` on every block, block 0 on this thread and the others on scoped threads; results
/// in block order.
fn run_blocks<T: Send>(blocks: &[Block], f: impl Fn(&Block) -> Result<T> + Sync) -> Result<Vec<T>> {
    if blocks.len() == 1 {
        return Ok(vec![f(&blocks[0])?]);
    }
    std::thread::scope(|s| {
        let handles: Vec<_> = blocks[1..].iter().map(|b| s.spawn(|| f(b))).collect();
        let mut out = vec![f(&blocks[0])?];
        for h in handles {
            out.push(
                h.join()
                    .map_err(|_| RlError::Internal("SAC worker thread panicked".into()))??,
            );
        }
        Ok(out)
    })
}

fn sum_grads(mut parts: impl Iterator<Item = Vec<Vec<f32>>>) -> Vec<Vec<f32>> {
    let mut acc = parts.next().unwrap_or_default();
    for g in parts {
        for (x, y) in acc.iter_mut().zip(g) {
            x.iter_mut().zip(y).for_each(|(p, q)| *p += q);
        }
    }
    acc
}

impl<E: Env> Sac<E> {
    pub(crate) fn update(&mut self) -> Result<()> {
        let (b, o, a) = (self.cfg.batch_size, self.obs_dim, self.act_dim);
        let batch = self.buffer.sample(b, &mut self.rng, self.normalizer.as_ref());
        let eps_pi = self.rng.normals(b * a);
        let eps_next = self.rng.normals(b * a);
        let k = self.threads.clamp(1, b);
        let blocks: Vec<Block> = (0..k)
            .map(|i| {
                let (r0, r1) = (i * b / k, (i + 1) * b / k);
                Block {
                    rows: r1 - r0,
                    obs: batch.obs[r0 * o..r1 * o].to_vec(),
                    next_obs: batch.next_obs[r0 * o..r1 * o].to_vec(),
                    actions: batch.actions[r0 * a..r1 * a].to_vec(),
                    rewards: batch.rewards[r0..r1].to_vec(),
                    not_done: batch.dones[r0..r1].iter().map(|d| 1.0 - d).collect(),
                    eps_pi: eps_pi[r0 * a..r1 * a].to_vec(),
                    eps_next: eps_next[r0 * a..r1 * a].to_vec(),
                }
            })
            .collect();
        // alpha for this step is taken before its own update (as SB3).
        let ent_coef = (self.log_ent_coef.data[0][0] as f64).exp();
        let device = self.device.clone();
        // Tensor clones are handles; the learner's copies are replaced as the step proceeds.
        let (actor_dev, critic_dev, target_dev) =
            (self.actor_dev.clone(), self.critic_dev.clone(), self.target_dev.clone());
        let shared = Shared {
            device: &device,
            actor: &actor_dev,
            critic: &critic_dev,
            target: &target_dev,
            o,
            a,
            batch: b,
            gamma: self.cfg.gamma,
            ent_coef,
            parts: self.parts(),
            image: self.cfg.image,
        };
        let critic_out = run_blocks(&blocks, |blk| shared.critic_block(blk))?;
        let mean_log_prob = critic_out.iter().map(|c| c.log_prob_sum).sum::<f64>() / b as f64;
        let critic_loss: f64 = critic_out.iter().map(|c| c.loss).sum();
        let critic_grads = sum_grads(critic_out.into_iter().map(|c| c.grads));
        if let Some(opt) = &mut self.ent_opt {
            // d/d(log alpha) of -log alpha * (log_prob + target_entropy).mean()
            let g = -(mean_log_prob + self.target_entropy) as f32;
            opt.step(&mut self.log_ent_coef, &[vec![g]]);
        }
        self.critic_opt.step(&mut self.critic, &critic_grads);
        self.critic_dev = self.critic.to_device(&device);
        let updated_critic = self.critic_dev.clone();

        let shared = Shared {
            critic: &updated_critic,
            ..shared
        };
        let actor_out = run_blocks(&blocks, |blk| shared.actor_block(blk))?;
        let actor_loss: f64 = actor_out.iter().map(|x| x.1).sum();
        let actor_grads = sum_grads(actor_out.into_iter().map(|x| x.0));
        self.actor_opt.step(&mut self.actor, &actor_grads);
        self.actor_dev = self.actor.to_device(&device);

        self.n_updates += 1;
        if self.n_updates.is_multiple_of(self.cfg.target_update_interval) {
            self.critic_target.polyak(&self.critic, self.cfg.tau as f32);
            self.target_dev = self.critic_target.to_device(&device);
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
