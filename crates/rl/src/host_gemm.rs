//! Dense layers on the host, `[rows x cols]` row-major slices: the products and activations of
//! the learners' host paths (PPO's networks, SAC's networks), through ndarray's
//! `general_mat_mul` (matrixmultiply's kernels, picked for the CPU at run time).

use crate::nets::{Activation, HostParams};
use ndarray::linalg::general_mat_mul;
use ndarray::{ArrayView2, ArrayViewMut2};

pub(crate) fn view(v: &[f32], rows: usize, cols: usize) -> ArrayView2<'_, f32> {
    ArrayView2::from_shape((rows, cols), v).expect("a slice of rows x cols")
}

pub(crate) fn view_mut(v: &mut [f32], rows: usize, cols: usize) -> ArrayViewMut2<'_, f32> {
    ArrayViewMut2::from_shape((rows, cols), v).expect("a slice of rows x cols")
}

/// `out[n x o] = x[n x i] w[i x o] + b[o]`.
pub(crate) fn affine(x: &[f32], w: &[f32], b: &[f32], (n, i, o): (usize, usize, usize), out: &mut Vec<f32>) {
    out.clear();
    for _ in 0..n {
        out.extend_from_slice(b);
    }
    general_mat_mul(1.0, &view(x, n, i), &view(w, i, o), 1.0, &mut view_mut(out, n, o));
}

/// The first `layers` layers of member `m` of the stacked MLP `p` (`[w0, b0, w1, b1, ...]`) on
/// `n` rows of `x`: every layer's output, each activated with `act` except the last unless
/// `activate_last`. The learners' host rollouts and `Policy::act` on the host path run this.
pub(crate) fn mlp_forward(
    p: &HostParams,
    layers: usize,
    m: usize,
    (act, activate_last): (Activation, bool),
    x: &[f32],
    n: usize,
) -> Vec<Vec<f32>> {
    let mut outs: Vec<Vec<f32>> = Vec::with_capacity(layers);
    for l in 0..layers {
        let [_, i, o] = p.shapes[2 * l];
        let (w, b) = (
            &p.data[2 * l][m * i * o..(m + 1) * i * o],
            &p.data[2 * l + 1][m * o..(m + 1) * o],
        );
        let mut out = Vec::new();
        affine(outs.last().map_or(x, |h| h.as_slice()), w, b, (n, i, o), &mut out);
        if l + 1 < layers || activate_last {
            activate(&mut out, act);
        }
        outs.push(out);
    }
    outs
}

/// `dw[i x o] += x[n x i]^T dz[n x o]`, `db[o] += sum over rows of dz`.
#[cfg(feature = "train")]
pub(crate) fn weight_grads(x: &[f32], dz: &[f32], (n, i, o): (usize, usize, usize), dw: &mut [f32], db: &mut [f32]) {
    for r in 0..n {
        db.iter_mut().zip(&dz[r * o..(r + 1) * o]).for_each(|(b, d)| *b += d);
    }
    general_mat_mul(1.0, &view(x, n, i).t(), &view(dz, n, o), 1.0, &mut view_mut(dw, i, o));
}

/// `dx[n x i] = dz[n x o] w[i x o]^T`.
#[cfg(feature = "train")]
pub(crate) fn input_grads(dz: &[f32], w: &[f32], (n, i, o): (usize, usize, usize), dx: &mut Vec<f32>) {
    dx.clear();
    dx.resize(n * i, 0.0);
    general_mat_mul(1.0, &view(dz, n, o), &view(w, i, o).t(), 0.0, &mut view_mut(dx, n, i));
}

/// tanh within 5e-7 of the exact value (Eigen's and MLAS's rational form, clamped where f32
/// tanh is +-1), in plain arithmetic so a loop over it vectorises.
#[inline]
pub(crate) fn fast_tanh(x: f32) -> f32 {
    let x = x.clamp(-7.905_311, 7.905_311);
    let x2 = x * x;
    let mut p = -2.760_768_5e-16f32;
    p = p * x2 + 2.000_188e-13;
    p = p * x2 - 8.604_672e-11;
    p = p * x2 + 5.122_297e-8;
    p = p * x2 + 1.485_722_4e-5;
    p = p * x2 + 6.372_619_3e-4;
    p = p * x2 + 4.893_524_6e-3;
    let mut q = 1.198_258_4e-6f32;
    q = q * x2 + 1.185_347_1e-4;
    q = q * x2 + 2.268_434_6e-3;
    q = q * x2 + 4.893_525e-3;
    x * p / q
}

/// The activation in place.
pub(crate) fn activate(v: &mut [f32], act: Activation) {
    match act {
        Activation::Tanh => v.iter_mut().for_each(|x| *x = fast_tanh(*x)),
        Activation::Relu => v.iter_mut().for_each(|x| *x = x.max(0.0)),
    }
}

/// `dz = dh * act'(y)` in place on `dh`, from the activation's output `y`.
#[cfg(feature = "train")]
pub(crate) fn activation_grad(dh: &mut [f32], y: &[f32], act: Activation) {
    match act {
        Activation::Tanh => dh.iter_mut().zip(y).for_each(|(d, y)| *d *= 1.0 - y * y),
        // A select, not a branch: the loop vectorises.
        Activation::Relu => dh
            .iter_mut()
            .zip(y)
            .for_each(|(d, y)| *d = if *y > 0.0 { *d } else { 0.0 }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fast_tanh_is_within_5e_7_of_tanh_everywhere() {
        let mut worst = 0.0f64;
        for k in -200_000..=200_000 {
            let x = k as f32 * 1e-4;
            worst = worst.max((fast_tanh(x) as f64 - (x as f64).tanh()).abs());
        }
        for x in [-1e30f32, -20.0, 20.0, 1e30] {
            worst = worst.max((fast_tanh(x) as f64 - (x as f64).tanh()).abs());
        }
        assert!(worst < 5e-7, "{worst}");
        assert_eq!(fast_tanh(0.0), 0.0);
    }
}
