//! Adam on the host-side master weights ([`HostParams`]): one fused loop per tensor, and
//! PyTorch's global gradient-norm clipping.

use crate::nets::HostParams;
use serde::{Deserialize, Serialize};

/// Moments below this are zero. A weight whose gradient stays 0 (a dead ReLU) has a first
/// moment that decays by `beta1` a step down through the subnormal range, and products of
/// small moments and gradients land there too; every such operation takes a slow microcode
/// path. In SAC on pendulum a fifth of the critic's moments were subnormal after 1,000 updates
/// and single steps took 10x longer. A moment under 1e-30 moves its weight by less than 1e-20
/// (the update is `lr m / (sqrt(v) + eps)`), so flushing it changes no weight in practice.
const TINY_MOMENT: f32 = 1e-30;
/// Gradients below this are zero: their square times `1 - beta2` would be subnormal, and
/// they move their weight by less than `1e-9 lr`.
const TINY_GRAD: f32 = 1e-17;

#[inline(always)]
fn flush(x: f32, tiny: f32) -> f32 {
    if x.abs() < tiny { 0.0 } else { x }
}

/// Adam as in PyTorch (`torch.optim.Adam`, no weight decay, no amsgrad).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Adam {
    /// Learning rate.
    pub lr: f64,
    /// First-moment decay.
    pub beta1: f64,
    /// Second-moment decay.
    pub beta2: f64,
    /// Denominator epsilon.
    pub eps: f64,
    /// Steps taken.
    pub t: u64,
    m: Vec<Vec<f32>>,
    v: Vec<Vec<f32>>,
}

impl Adam {
    /// Zeroed moments for `params`.
    pub fn new(params: &HostParams, lr: f64, eps: f64) -> Self {
        let zeros: Vec<Vec<f32>> = params.data.iter().map(|d| vec![0.0; d.len()]).collect();
        Self {
            lr,
            beta1: 0.9,
            beta2: 0.999,
            eps,
            t: 0,
            m: zeros.clone(),
            v: zeros,
        }
    }

    /// Rebuild from saved parts (checkpoints).
    #[cfg(feature = "train")]
    pub(crate) fn from_parts(
        lr: f64,
        beta1: f64,
        beta2: f64,
        eps: f64,
        t: u64,
        m: Vec<Vec<f32>>,
        v: Vec<Vec<f32>>,
    ) -> Self {
        Self {
            lr,
            beta1,
            beta2,
            eps,
            t,
            m,
            v,
        }
    }

    /// First and second moments (checkpoints).
    #[cfg(feature = "train")]
    pub(crate) fn moments(&self) -> (&[Vec<f32>], &[Vec<f32>]) {
        (&self.m, &self.v)
    }

    /// Scale `grads` so their global L2 norm is at most `max_norm` (PyTorch's
    /// `clip_grad_norm_`); returns the norm before clipping.
    pub fn clip_grad_norm(grads: &mut [Vec<f32>], max_norm: f64) -> f64 {
        let norm = grads
            .iter()
            .flatten()
            .map(|g| (*g as f64) * (*g as f64))
            .sum::<f64>()
            .sqrt();
        let coef = max_norm / (norm + 1e-6);
        if coef < 1.0 {
            grads.iter_mut().flatten().for_each(|g| *g *= coef as f32);
        }
        norm
    }

    /// One update of `params` with `grads` (same layout).
    pub fn step(&mut self, params: &mut HostParams, grads: &[Vec<f32>]) {
        self.step_sum(params, &[grads]);
    }

    /// One update of `params` with the sum of `parts` (each laid out as `params`), added in
    /// order as it is read: no pass of its own over the gradients.
    pub fn step_sum(&mut self, params: &mut HostParams, parts: &[&[Vec<f32>]]) {
        self.t += 1;
        let (b1, b2) = (self.beta1 as f32, self.beta2 as f32);
        let bc1 = 1.0 - self.beta1.powi(self.t as i32);
        let bc2 = 1.0 - self.beta2.powi(self.t as i32);
        let step_size = (self.lr / bc1) as f32;
        let inv_sqrt_bc2 = (1.0 / bc2.sqrt()) as f32;
        let eps = self.eps as f32;
        let adam = |p: &mut f32, g: f32, m: &mut f32, v: &mut f32| {
            let g = flush(g, TINY_GRAD);
            *m = flush(b1 * *m + (1.0 - b1) * g, TINY_MOMENT);
            *v = flush(b2 * *v + (1.0 - b2) * g * g, TINY_MOMENT);
            *p -= step_size * *m / (v.sqrt() * inv_sqrt_bc2 + eps);
        };
        for (k, ((p, m), v)) in params.data.iter_mut().zip(&mut self.m).zip(&mut self.v).enumerate() {
            let pmv = p.iter_mut().zip(m.iter_mut()).zip(v.iter_mut());
            match parts {
                [g] => pmv.zip(&g[k]).for_each(|(((p, m), v), g)| adam(p, *g, m, v)),
                [a, b] => pmv
                    .zip(a[k].iter().zip(&b[k]))
                    .for_each(|(((p, m), v), (a, b))| adam(p, a + b, m, v)),
                _ => pmv.enumerate().for_each(|(i, ((p, m), v))| {
                    let g = parts[1..].iter().fold(parts[0][k][i], |acc, g| acc + g[k][i]);
                    adam(p, g, m, v)
                }),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn adam_first_step_moves_by_lr_against_the_gradient() {
        let mut p = HostParams {
            shapes: vec![[1, 1, 2]],
            data: vec![vec![1.0, -1.0]],
        };
        let mut adam = Adam::new(&p, 0.1, 1e-8);
        adam.step(&mut p, &[vec![3.0, -0.5]]);
        assert!((p.data[0][0] - 0.9).abs() < 1e-5);
        assert!((p.data[0][1] + 0.9).abs() < 1e-5);
    }

    #[test]
    fn moments_of_a_weight_without_gradient_decay_to_zero_not_to_subnormals_and_keep_its_value() {
        let mut p = HostParams {
            shapes: vec![[1, 1, 1]],
            data: vec![vec![0.5]],
        };
        let mut adam = Adam::new(&p, 1e-3, 1e-8);
        adam.step(&mut p, &[vec![1e-3]]);
        for _ in 0..2000 {
            adam.step(&mut p, &[vec![0.0]]);
            let m = adam.m[0][0];
            assert!(
                m == 0.0 || m.abs() >= TINY_MOMENT,
                "first moment {m:e} at step {}",
                adam.t
            );
        }
        assert_eq!(adam.m[0][0], 0.0);
        assert!(adam.v[0][0].is_normal());
        // The exact update from the same moments, with nothing flushed, moves the weight no
        // further than the last bit.
        let mut exact = (0.5f64, 0.0f64, 0.0f64);
        for t in 1..=2001 {
            let g = if t == 1 { 1e-3 } else { 0.0 };
            exact.1 = 0.9 * exact.1 + 0.1 * g;
            exact.2 = 0.999 * exact.2 + 0.001 * g * g;
            let (bc1, bc2) = (1.0 - 0.9f64.powi(t), 1.0 - 0.999f64.powi(t));
            exact.0 -= 1e-3 / bc1 * exact.1 / (exact.2.sqrt() / bc2.sqrt() + 1e-8);
        }
        assert!(
            (p.data[0][0] as f64 - exact.0).abs() < 1e-6,
            "{} vs {}",
            p.data[0][0],
            exact.0
        );
    }

    #[test]
    fn a_step_on_gradient_parts_equals_a_step_on_their_sum() {
        let start = HostParams {
            shapes: vec![[1, 1, 3], [1, 1, 1]],
            data: vec![vec![0.5, -0.25, 2.0], vec![1.0]],
        };
        let parts: Vec<Vec<Vec<f32>>> = (0..3)
            .map(|i| vec![vec![0.1 * i as f32, -0.3, 0.7 - i as f32], vec![0.01 * i as f32 - 0.02]])
            .collect();
        for n in 1..=3 {
            let sum: Vec<Vec<f32>> = (0..2)
                .map(|k| {
                    (0..parts[0][k].len())
                        .map(|i| parts[1..n].iter().fold(parts[0][k][i], |acc, g| acc + g[k][i]))
                        .collect()
                })
                .collect();
            let (mut by_sum, mut by_parts) = (start.clone(), start.clone());
            let (mut a, mut b) = (Adam::new(&start, 0.01, 1e-8), Adam::new(&start, 0.01, 1e-8));
            for _ in 0..3 {
                a.step(&mut by_sum, &sum);
                let refs: Vec<&[Vec<f32>]> = parts[..n].iter().map(|p| p.as_slice()).collect();
                b.step_sum(&mut by_parts, &refs);
            }
            assert_eq!(by_sum.data, by_parts.data, "{n} parts");
            assert_ne!(by_sum.data, start.data);
        }
    }
}
