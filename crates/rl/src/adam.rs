//! Adam on the host-side master weights ([`HostParams`]): one fused loop per tensor, and
//! PyTorch's global gradient-norm clipping.

use crate::nets::HostParams;
use serde::{Deserialize, Serialize};

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
        self.t += 1;
        let (b1, b2) = (self.beta1 as f32, self.beta2 as f32);
        let bc1 = 1.0 - self.beta1.powi(self.t as i32);
        let bc2 = 1.0 - self.beta2.powi(self.t as i32);
        let step_size = (self.lr / bc1) as f32;
        let inv_sqrt_bc2 = (1.0 / bc2.sqrt()) as f32;
        let eps = self.eps as f32;
        for (((p, g), m), v) in params.data.iter_mut().zip(grads).zip(&mut self.m).zip(&mut self.v) {
            for (((p, g), m), v) in p.iter_mut().zip(g).zip(m.iter_mut()).zip(v.iter_mut()) {
                *m = b1 * *m + (1.0 - b1) * g;
                *v = b2 * *v + (1.0 - b2) * g * g;
                *p -= step_size * *m / (v.sqrt() * inv_sqrt_bc2 + eps);
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
}
