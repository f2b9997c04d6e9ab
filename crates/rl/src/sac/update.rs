//! One SAC gradient step, in SB3's `SAC.train` order: entropy coefficient, critic update,
//! actor update through the just-updated critics, Polyak averaging.
//!
//! Configs without an image encoder compute the losses' gradients on the host (`host.rs`);
//! the tensor path below is what images use, and the reference the host path is tested
//! against. In the tensor path, graph work is kept to what the gradients need: the target and the entropy statistics come
//! from one plain forward of the actor on `[obs; next_obs]`, the critic loss differentiates only
//! the critics (one batched forward for both), and the actor loss runs through the updated
//! critics as constants, so their weight gradients are never formed.
//!
//! With `threads > 1` the minibatch is split into row blocks whose losses (sums over rows
//! divided by the full batch size) are differentiated on separate threads (the learner's
//! [`Workers`]) and their gradients summed in block order: the same update as one thread up
//! to float summation order, and deterministic for a fixed thread count.

use super::Sac;
use super::host::{ActorPass, CriticPart, Nets, Rows};
use crate::cnn::{ImageSpec, encode};
use crate::error::{Result, RlError};
use crate::nets::{Activation, NetParts, grads_of, mlp_forward, to_vec};
use crate::policy::{LOG_STD_MAX, LOG_STD_MIN};
use agvrl_envs::Env;
use agvrl_envs::Workers;
use burn::tensor::{Device, Tensor, TensorData};
use std::sync::Arc;

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

impl Block {
    fn rows(&self) -> Rows<'_> {
        Rows {
            obs: &self.obs,
            next_obs: &self.next_obs,
            actions: &self.actions,
            rewards: &self.rewards,
            not_done: &self.not_done,
            eps_pi: &self.eps_pi,
            eps_next: &self.eps_next,
        }
    }
}

/// Device weights (handles) and constants every block reads.
#[derive(Clone)]
struct Shared {
    device: Device,
    actor: Vec<Tensor<3>>,
    critic: Vec<Tensor<3>>,
    target: Vec<Tensor<3>>,
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

impl Shared {
    fn t3(&self, v: &[f32], s: [usize; 3]) -> Tensor<3> {
        Tensor::<3>::from_data(TensorData::new(v.to_vec(), s), &self.device)
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
    fn critic_block(&self, b: &Block) -> Result<CriticPart> {
        let (n, o, a) = (b.rows, self.o, self.a);
        let obs = self.t3(&b.obs, [1, n, o]);
        let next_obs = self.t3(&b.next_obs, [1, n, o]);
        // One plain actor forward on [obs; next_obs].
        let both = Tensor::cat(vec![obs.clone(), next_obs.clone()], 1);
        let eps = Tensor::cat(vec![self.t3(&b.eps_pi, [1, n, a]), self.t3(&b.eps_next, [1, n, a])], 1);
        let (act, log_prob) = squashed_sample(self.actor_out(&self.actor, both), eps, a);
        let log_prob_sum = to_vec(log_prob.clone().narrow(1, 0, n).sum())?[0] as f64;
        let (next_action, next_log_prob) = (act.narrow(1, n, n), log_prob.narrow(1, n, n));
        // Target: r + gamma (1 - terminated) (min Q_targ(s', a') - alpha log pi(a'|s')).
        let q_next = self.q(&self.target, self.features(&self.target, next_obs), next_action);
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
        Ok(CriticPart {
            grads,
            loss: to_vec(loss.inner())?[0] as f64,
            log_prob_sum,
            actor_pass: None,
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
        let critic_features = self.features(&self.critic, obs).autodiff();
        let q_pi = self.q(&self.critic, critic_features, pi_action);
        let loss = (log_prob * self.ent_coef - min_of_twins(q_pi)).sum() / self.batch as f64;
        let grads = grads_of(&actor, &loss.backward())?;
        Ok((grads, to_vec(loss.inner())?[0] as f64))
    }
}

/// Run `f` on every block with its input, block 0 on this thread and the others on
/// `workers`; results in block order.
fn run_blocks<S: Send + Sync + 'static, X: Send + 'static, T: Send + 'static>(
    workers: Option<&Workers>,
    shared: &Arc<S>,
    blocks: &Arc<Vec<Block>>,
    inputs: Vec<X>,
    f: fn(&S, &Block, X) -> Result<T>,
) -> Result<Vec<T>> {
    let Some(workers) = workers.filter(|_| blocks.len() > 1) else {
        return blocks.iter().zip(inputs).map(|(b, x)| f(shared, b, x)).collect();
    };
    let jobs = inputs
        .into_iter()
        .enumerate()
        .map(|(i, x)| {
            let (shared, blocks) = (shared.clone(), blocks.clone());
            Box::new(move || f(&shared, &blocks[i], x)) as Box<dyn FnOnce() -> Result<T> + Send>
        })
        .collect();
    workers
        .run(jobs)
        .into_iter()
        .map(|r| r.unwrap_or_else(|| Err(RlError::Internal("SAC worker thread panicked".into()))))
        .collect()
}

impl<E: Env> Sac<E> {
    /// The tensor path's weights and constants for one step.
    fn shared(&self, ent_coef: f64) -> Shared {
        Shared {
            device: self.device.clone(),
            actor: self.actor_dev.clone(),
            critic: self.critic_dev.clone(),
            target: self.target_dev.clone(),
            o: self.obs_dim,
            a: self.act_dim,
            batch: self.cfg.batch_size,
            gamma: self.cfg.gamma,
            ent_coef,
            parts: self.parts(),
            image: self.cfg.image,
        }
    }

    /// The host path's weights (shared handles) and constants for one step.
    fn nets(&self, ent_coef: f64) -> Nets {
        Nets {
            actor: self.actor.clone(),
            critic: self.critic.clone(),
            target: self.critic_target.clone(),
            layers: self.mlp_layers(),
            o: self.obs_dim,
            a: self.act_dim,
            batch: self.cfg.batch_size,
            gamma: self.cfg.gamma,
            ent_coef,
        }
    }

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
        let blocks = Arc::new(blocks);
        // alpha for this step is taken before its own update (as SB3).
        let ent_coef = (self.log_ent_coef.data[0][0] as f64).exp();
        let on_host = self.on_host();
        // Each phase's shared handles are dropped before the weights they point at are
        // stepped, so the steps below write in place.
        let none = || vec![(); blocks.len()];
        let mut critic_out = if on_host {
            let nets = Arc::new(self.nets(ent_coef));
            run_blocks(self.workers.as_deref(), &nets, &blocks, none(), |n, b, ()| {
                Ok(n.critic_part(&b.rows()))
            })?
        } else {
            let shared = Arc::new(self.shared(ent_coef));
            run_blocks(self.workers.as_deref(), &shared, &blocks, none(), |s, b, ()| {
                s.critic_block(b)
            })?
        };
        let mean_log_prob = critic_out.iter().map(|c| c.log_prob_sum).sum::<f64>() / b as f64;
        let critic_loss: f64 = critic_out.iter().map(|c| c.loss).sum();
        if let Some(opt) = &mut self.ent_opt {
            // d/d(log alpha) of -log alpha * (log_prob + target_entropy).mean()
            let g = -(mean_log_prob + self.target_entropy) as f32;
            opt.step(&mut self.log_ent_coef, &[vec![g]]);
        }
        let parts: Vec<&[Vec<f32>]> = critic_out.iter().map(|c| c.grads.as_slice()).collect();
        self.critic_opt.step_sum(Arc::make_mut(&mut self.critic), &parts);
        if !on_host {
            self.critic_dev = self.critic.to_device(&self.device);
        }

        let actor_out = if on_host {
            let nets = Arc::new(self.nets(ent_coef));
            let passes: Vec<ActorPass> = critic_out.iter_mut().filter_map(|c| c.actor_pass.take()).collect();
            run_blocks(self.workers.as_deref(), &nets, &blocks, passes, |n, b, pass| {
                Ok(n.actor_part(&b.rows(), pass))
            })?
        } else {
            let shared = Arc::new(self.shared(ent_coef));
            run_blocks(self.workers.as_deref(), &shared, &blocks, none(), |s, b, ()| {
                s.actor_block(b)
            })?
        };
        let actor_loss: f64 = actor_out.iter().map(|x| x.1).sum();
        let parts: Vec<&[Vec<f32>]> = actor_out.iter().map(|x| x.0.as_slice()).collect();
        self.actor_opt.step_sum(Arc::make_mut(&mut self.actor), &parts);
        if !on_host {
            self.actor_dev = self.actor.to_device(&self.device);
        }

        self.n_updates += 1;
        if self.n_updates.is_multiple_of(self.cfg.target_update_interval) {
            Arc::make_mut(&mut self.critic_target).polyak(&self.critic, self.cfg.tau as f32);
            if !on_host {
                self.target_dev = self.critic_target.to_device(&self.device);
            }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nets::{HostParams, Init, MlpSpec, scaled_diff};
    use crate::rng::Rng;

    fn mlp(sizes: Vec<usize>, members: usize, rng: &mut Rng) -> HostParams {
        let spec = MlpSpec {
            n_members: members,
            sizes,
            activation: Activation::Relu,
            activate_last: false,
        };
        spec.init(&[Init::TorchDefault], rng)
    }

    fn close(p: &[f32], q: &[f32], what: &str) {
        assert_eq!(p.len(), q.len(), "{what}");
        for (k, (p, q)) in p.iter().zip(q).enumerate() {
            assert!((p - q).abs() < 2e-5 + 2e-4 * q.abs(), "{what}[{k}]: {p} vs {q}");
        }
    }

    /// A learner on the Burn path (autodiff on a CPU backend: what a GPU runs) against one on
    /// the host kernels, from the same seed: the first gradient step's losses agree to 1e-5,
    /// and after 30 steps the weights to 1e-4 of their scale.
    #[test]
    fn burn_path_learner_steps_as_the_host_path() {
        use crate::device::NetPath;
        let cfg = crate::SacConfig {
            learning_starts: 64,
            batch_size: 32,
            net_arch: vec![32, 32],
            ..Default::default()
        };
        let device = crate::device::default_device();
        let make = || crate::Sac::new(cfg.clone(), crate::learning::pendulum_envs(1).unwrap(), &device, 4).unwrap();
        let (mut host, mut burn) = (make(), make());
        assert_eq!(host.net_path(), NetPath::Host);
        burn.set_net_path(NetPath::Burn);
        assert_eq!(burn.net_path(), NetPath::Burn);
        let go = |s: &mut crate::Sac<_>, steps| s.learn(steps, &mut |_| crate::Control::Continue).unwrap();
        go(&mut host, 65);
        go(&mut burn, 65);
        assert_eq!((host.n_updates, burn.n_updates), (1, 1));
        let rel = |p: f64, q: f64| (p - q).abs() / q.abs().max(1e-12);
        let (h, b) = (&host.losses, &burn.losses);
        eprintln!(
            "first step: critic {:.2e} actor {:.2e}",
            rel(b.value, h.value),
            rel(b.policy, h.policy)
        );
        assert!(rel(b.value, h.value) < 1e-5, "critic loss {} vs {}", b.value, h.value);
        assert!(
            rel(b.policy, h.policy) < 1e-5,
            "actor loss {} vs {}",
            b.policy,
            h.policy
        );
        let before = host.actor.data.clone();
        go(&mut host, 30);
        go(&mut burn, 30);
        for (what, h, b) in [
            ("actor", &host.actor, &burn.actor),
            ("critic", &host.critic, &burn.critic),
        ] {
            let worst = h
                .data
                .iter()
                .zip(&b.data)
                .map(|(h, b)| scaled_diff(b, h))
                .fold(0.0, f64::max);
            eprintln!("{what} weights after 31 steps: {worst:.2e}");
            assert!(worst < 1e-4, "{what} weights {worst:.2e}");
        }
        assert!(before.iter().zip(&burn.actor.data).all(|(p, q)| p != q));
    }

    #[test]
    fn host_gradients_match_autodiff() {
        for (hidden, o, a, rows) in [(vec![16, 12], 5, 2, 9), (vec![8], 3, 1, 6), (vec![], 4, 3, 5)] {
            let mut rng = Rng::new(11);
            let sizes = |i: usize, out: usize| [vec![i], hidden.clone(), vec![out]].concat();
            let mut actor = mlp(sizes(o, 2 * a), 1, &mut rng);
            // Push one output's log_std past the clamp: its gradient must vanish on both paths.
            let last = actor.data.len() - 1;
            actor.data[last][a] = 40.0;
            let critic = mlp(sizes(o + a, 1), 2, &mut rng);
            let target = mlp(sizes(o + a, 1), 2, &mut rng);
            let block = Block {
                rows,
                obs: rng.normals(rows * o),
                next_obs: rng.normals(rows * o),
                actions: (0..rows * a).map(|_| rng.uniform() as f32 * 2.0 - 1.0).collect(),
                rewards: rng.normals(rows),
                not_done: (0..rows).map(|r| (r % 3 != 0) as u8 as f32).collect(),
                eps_pi: rng.normals(rows * a),
                eps_next: rng.normals(rows * a),
            };
            let device = crate::device::default_device();
            let (batch, gamma, ent_coef) = (2 * rows, 0.97, 0.3);
            let shared = Shared {
                device: device.clone(),
                actor: actor.to_device(&device),
                critic: critic.to_device(&device),
                target: target.to_device(&device),
                o,
                a,
                batch,
                gamma,
                ent_coef,
                parts: NetParts::mlp(hidden.len()),
                image: None,
            };
            let nets = Nets {
                actor: Arc::new(actor),
                critic: Arc::new(critic),
                target: Arc::new(target),
                layers: hidden.len() + 1,
                o,
                a,
                batch,
                gamma,
                ent_coef,
            };
            let what = format!("{hidden:?}");
            let (t, h) = (shared.critic_block(&block).unwrap(), nets.critic_part(&block.rows()));
            assert!(
                (t.loss - h.loss).abs() < 1e-4 * t.loss.abs().max(1e-3),
                "{what} critic loss"
            );
            assert!((t.log_prob_sum - h.log_prob_sum).abs() < 1e-3, "{what} log prob");
            for (k, (tg, hg)) in t.grads.iter().zip(&h.grads).enumerate() {
                close(hg, tg, &format!("{what} critic grad {k}"));
                assert!(
                    scaled_diff(hg, tg) < 1e-5,
                    "{what} critic grad {k}: {:.2e}",
                    scaled_diff(hg, tg)
                );
            }
            let pass = h.actor_pass.expect("the host path keeps the actor pass");
            let ((tg, tl), (hg, hl)) = (
                shared.actor_block(&block).unwrap(),
                nets.actor_part(&block.rows(), pass),
            );
            assert!(
                (tl - hl).abs() < 1e-4 * tl.abs().max(1e-3),
                "{what} actor loss {tl} vs {hl}"
            );
            for (k, (tg, hg)) in tg.iter().zip(&hg).enumerate() {
                close(hg, tg, &format!("{what} actor grad {k}"));
                assert!(
                    scaled_diff(hg, tg) < 1e-5,
                    "{what} actor grad {k}: {:.2e}",
                    scaled_diff(hg, tg)
                );
            }
            // The clamped log_std's bias got no gradient, the free ones did.
            assert_eq!(hg[last][a], 0.0, "{what}");
            assert!(hg[last][..a].iter().all(|g| *g != 0.0), "{what}");
        }
    }
}
