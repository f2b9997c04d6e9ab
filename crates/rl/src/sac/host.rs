//! SAC's gradient step on the host, for configs without an image encoder: the same losses as
//! `update.rs`'s tensor path, with the backward passes written out.
//!
//! Through the tensor backend a step of SB3-sized networks spends about a tenth of its time on
//! dispatch, graph building and buffer churn, repeated for every row block when two threads
//! share a step; and the autodiff graph sits behind one process-wide lock. Here a block is
//! plain products on the host weights (`host_gemm`), so a second thread splits the work and
//! little else. `tests::host_gradients_match_autodiff` checks both losses' gradients against
//! the tensor path's.
//!
//! Networks are stacked MLPs ([`HostParams`], weights `[members, in, out]`): ReLU between
//! layers, none after the last. The actor's output is `[mean | log_std]`; the critics read
//! `[obs | action]`.

use crate::gaussian::HALF_LN_2PI_F32;
use crate::host_gemm::{activation_grad, input_grads, mlp_forward, view, view_mut, weight_grads};
use crate::nets::{Activation, HostParams};
use crate::policy::{LOG_STD_MAX, LOG_STD_MIN};
use ndarray::linalg::general_mat_mul;

/// Member `m` of the MLP made of `p`'s first `2 * layers` tensors on `x [n x in]`: every
/// layer's output, hidden ones after ReLU.
pub(crate) fn forward(p: &HostParams, layers: usize, m: usize, x: &[f32], n: usize) -> Vec<Vec<f32>> {
    mlp_forward(p, layers, m, (Activation::Relu, false), x, n)
}

/// Back from `d_out` (the loss's gradient at member `m`'s output) through the layers of
/// [`forward`]; adds the weight gradients into `grads` (laid out as `p`) where given. Returns
/// the gradient at the first layer's pre-activation, `[n x hidden]`.
fn backward(
    p: &HostParams,
    layers: usize,
    m: usize,
    x: &[f32],
    outs: &[Vec<f32>],
    d_out: Vec<f32>,
    mut grads: Option<&mut [Vec<f32>]>,
) -> Vec<f32> {
    let n = outs[0].len() / p.shapes[0][2];
    let mut d = d_out;
    for l in (0..layers).rev() {
        let [_, i, o] = p.shapes[2 * l];
        if l + 1 < layers {
            activation_grad(&mut d, &outs[l], Activation::Relu);
        }
        let input = if l == 0 { x } else { &outs[l - 1] };
        if let Some(g) = grads.as_deref_mut() {
            let (lo, hi) = g.split_at_mut(2 * l + 1);
            weight_grads(
                input,
                &d,
                (n, i, o),
                &mut lo[2 * l][m * i * o..(m + 1) * i * o],
                &mut hi[0][m * o..(m + 1) * o],
            );
        }
        if l > 0 {
            let mut dx = Vec::new();
            input_grads(&d, &p.data[2 * l][m * i * o..(m + 1) * i * o], (n, i, o), &mut dx);
            d = dx;
        }
    }
    d
}

/// The squashed Gaussian of the actor outputs `out [n x 2a]` with noise `eps [n x a]`:
/// `tanh` actions, their log-probabilities, and what the actor's backward pass needs.
pub(crate) struct Squashed {
    /// `tanh(mean + std eps)`, `[n x a]`.
    pub(crate) action: Vec<f32>,
    /// Log-probability per row.
    pub(crate) log_prob: Vec<f32>,
    std: Vec<f32>,
    /// Whether `log_std` was inside the clamp (where it has a gradient).
    free: Vec<bool>,
}

/// [`Squashed`], in `update.rs`'s `squashed_sample` operation order.
pub(crate) fn squash(out: &[f32], eps: &[f32], a: usize) -> Squashed {
    let n = eps.len() / a;
    let mut s = Squashed {
        action: Vec::with_capacity(n * a),
        log_prob: Vec::with_capacity(n),
        std: Vec::with_capacity(n * a),
        free: Vec::with_capacity(n * a),
    };
    for (row, e) in out.chunks_exact(2 * a).zip(eps.chunks_exact(a)) {
        let (mut gauss, mut jac) = (0.0f32, 0.0f32);
        for j in 0..a {
            let raw = row[a + j];
            let log_std = raw.clamp(LOG_STD_MIN, LOG_STD_MAX);
            let std = log_std.exp();
            let y = (row[j] + std * e[j]).tanh();
            gauss += e[j] * e[j] * -0.5 - log_std - HALF_LN_2PI_F32;
            jac += (-(y * y) + (1.0 + 1e-6)).ln();
            s.action.push(y);
            s.std.push(std);
            s.free.push((LOG_STD_MIN..=LOG_STD_MAX).contains(&raw));
        }
        s.log_prob.push(gauss - jac);
    }
    s
}

/// Rows of `[x | y]`, `x [n x xw]`, `y [n x yw]`.
fn join(x: &[f32], xw: usize, y: &[f32], yw: usize) -> Vec<f32> {
    let mut out = Vec::with_capacity(x.len() + y.len());
    for (xr, yr) in x.chunks_exact(xw).zip(y.chunks_exact(yw)) {
        out.extend_from_slice(xr);
        out.extend_from_slice(yr);
    }
    out
}

/// The networks and constants of one gradient step.
#[derive(Clone)]
pub(crate) struct Nets {
    pub(crate) actor: std::sync::Arc<HostParams>,
    pub(crate) critic: std::sync::Arc<HostParams>,
    pub(crate) target: std::sync::Arc<HostParams>,
    /// Layers per MLP (hidden + 1).
    pub(crate) layers: usize,
    pub(crate) o: usize,
    pub(crate) a: usize,
    /// Full minibatch size: every block's loss is a sum over its rows divided by it.
    pub(crate) batch: usize,
    pub(crate) gamma: f64,
    pub(crate) ent_coef: f64,
}

/// One row block of the minibatch.
pub(crate) struct Rows<'a> {
    pub(crate) obs: &'a [f32],
    pub(crate) next_obs: &'a [f32],
    pub(crate) actions: &'a [f32],
    pub(crate) rewards: &'a [f32],
    pub(crate) not_done: &'a [f32],
    pub(crate) eps_pi: &'a [f32],
    pub(crate) eps_next: &'a [f32],
}

/// The actor's pass on a block's observations: every layer's output and the squashed sample
/// with the block's `eps_pi`. The critic step computes it and the actor step reuses it (the
/// actor does not change in between).
pub(crate) struct ActorPass {
    outs: Vec<Vec<f32>>,
    squashed: Squashed,
}

/// What a block contributes to the critic step.
pub(crate) struct CriticPart {
    pub(crate) grads: Vec<Vec<f32>>,
    pub(crate) loss: f64,
    pub(crate) log_prob_sum: f64,
    /// For the actor step (the host path's only).
    pub(crate) actor_pass: Option<ActorPass>,
}

impl Nets {
    /// `[q1, q2]` of `critic` on `x [n x (o + a)]`, with every layer's output.
    fn twins(&self, critic: &HostParams, x: &[f32], n: usize) -> [Vec<Vec<f32>>; 2] {
        [0, 1].map(|m| forward(critic, self.layers, m, x, n))
    }

    /// Entropy statistics, TD target and the critics' gradients of
    /// `0.5 sum over critics of sum((q - target)^2) / batch`.
    pub(crate) fn critic_part(&self, b: &Rows<'_>) -> CriticPart {
        let (o, a) = (self.o, self.a);
        let n = b.rewards.len();
        // One actor pass on [obs; next_obs]; the obs rows are kept for the actor step.
        let both = [b.obs, b.next_obs].concat();
        let outs = forward(&self.actor, self.layers, 0, &both, 2 * n);
        let out = outs.last().map_or(&[][..], |v| v.as_slice());
        let pi = squash(&out[..n * 2 * a], b.eps_pi, a);
        let next = squash(&out[n * 2 * a..], b.eps_next, a);
        let log_prob_sum = pi.log_prob.iter().sum::<f32>() as f64;
        let (next_action, next_log_prob) = (&next.action, &next.log_prob);
        let x_next = join(b.next_obs, o, next_action, a);
        let [q1, q2] = self
            .twins(&self.target, &x_next, n)
            .map(|mut outs| outs.pop().unwrap_or_default());
        let (ent_coef, gamma) = (self.ent_coef as f32, self.gamma as f32);
        let target: Vec<f32> = (0..n)
            .map(|r| {
                let q_next = q1[r].min(q2[r]) - next_log_prob[r] * ent_coef;
                b.rewards[r] + b.not_done[r] * q_next * gamma
            })
            .collect();
        let x = join(b.obs, o, b.actions, a);
        let mut grads: Vec<Vec<f32>> = self.critic.data.iter().map(|t| vec![0.0; t.len()]).collect();
        let mut loss = 0.0f64;
        let scale = 1.0 / self.batch as f32;
        for (m, outs) in self.twins(&self.critic, &x, n).into_iter().enumerate() {
            let q = outs.last().map_or(&[][..], |v| v.as_slice());
            let d: Vec<f32> = q.iter().zip(&target).map(|(q, t)| (q - t) * scale).collect();
            loss += q
                .iter()
                .zip(&target)
                .map(|(q, t)| ((q - t) as f64).powi(2))
                .sum::<f64>();
            backward(&self.critic, self.layers, m, &x, &outs, d, Some(&mut grads));
        }
        let actor_pass = ActorPass {
            outs: outs.iter().map(|o| o[..o.len() / 2].to_vec()).collect(),
            squashed: pi,
        };
        CriticPart {
            grads,
            loss: loss * 0.5 / self.batch as f64,
            log_prob_sum,
            actor_pass: Some(actor_pass),
        }
    }

    /// The actor's gradients of `sum(alpha log pi - min Q(s, pi(s))) / batch`, the critics held
    /// constant, and that loss; `pass` is this block's from [`Nets::critic_part`].
    pub(crate) fn actor_part(&self, b: &Rows<'_>, pass: ActorPass) -> (Vec<Vec<f32>>, f64) {
        let (o, a) = (self.o, self.a);
        let n = b.rewards.len();
        let ActorPass {
            outs: actor_outs,
            squashed: s,
        } = pass;
        let x = join(b.obs, o, &s.action, a);
        let twins = self.twins(&self.critic, &x, n);
        let (q1, q2) = (&twins[0][self.layers - 1], &twins[1][self.layers - 1]);
        let (scale, ent_coef) = (1.0 / self.batch as f32, self.ent_coef as f32);
        let loss = (0..n)
            .map(|r| (s.log_prob[r] * ent_coef - q1[r].min(q2[r])) as f64)
            .sum::<f64>()
            / self.batch as f64;
        // d loss / d action, through the critic that gave the minimum.
        let mut d_action = vec![0.0f32; n * a];
        let [_, _, h] = self.critic.shapes[0];
        for (m, outs) in twins.iter().enumerate() {
            let chosen = |r: usize| if m == 0 { q1[r] <= q2[r] } else { q1[r] > q2[r] };
            let d_q: Vec<f32> = (0..n).map(|r| if chosen(r) { -scale } else { 0.0 }).collect();
            let dz = backward(&self.critic, self.layers, m, &x, outs, d_q, None);
            // Only the action rows of the first layer's weights: [a x h] from row o on.
            let w = &self.critic.data[0][m * (o + a) * h..(m + 1) * (o + a) * h];
            general_mat_mul(
                1.0,
                &view(&dz, n, h),
                &view(&w[o * h..], a, h).t(),
                1.0,
                &mut view_mut(&mut d_action, n, a),
            );
        }
        // Through tanh, the Jacobian term and the reparameterised draw to [mean | log_std].
        let d_log_prob = ent_coef * scale;
        let mut d_out = vec![0.0f32; n * 2 * a];
        for r in 0..n {
            for j in 0..a {
                let k = r * a + j;
                let y = s.action[k];
                let d_y = d_action[k] + d_log_prob * 2.0 * y / (-(y * y) + (1.0 + 1e-6));
                let d_u = d_y * (1.0 - y * y);
                d_out[r * 2 * a + j] = d_u;
                d_out[r * 2 * a + a + j] = if s.free[k] {
                    d_u * s.std[k] * b.eps_pi[k] - d_log_prob
                } else {
                    0.0
                };
            }
        }
        let mut grads: Vec<Vec<f32>> = self.actor.data.iter().map(|t| vec![0.0; t.len()]).collect();
        backward(&self.actor, self.layers, 0, b.obs, &actor_outs, d_out, Some(&mut grads));
        (grads, loss)
    }
}
