//! Dense layers on the host, `[rows x cols]` row-major slices: the products of the learners'
//! host paths (PPO's networks, SAC's networks), through ndarray's `general_mat_mul`
//! (matrixmultiply's kernels, picked for the CPU at run time).

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

/// `dw[i x o] += x[n x i]^T dz[n x o]`, `db[o] += sum over rows of dz`.
pub(crate) fn weight_grads(x: &[f32], dz: &[f32], (n, i, o): (usize, usize, usize), dw: &mut [f32], db: &mut [f32]) {
    for r in 0..n {
        db.iter_mut().zip(&dz[r * o..(r + 1) * o]).for_each(|(b, d)| *b += d);
    }
    general_mat_mul(1.0, &view(x, n, i).t(), &view(dz, n, o), 1.0, &mut view_mut(dw, i, o));
}

/// `dx[n x i] = dz[n x o] w[i x o]^T`.
pub(crate) fn input_grads(dz: &[f32], w: &[f32], (n, i, o): (usize, usize, usize), dx: &mut Vec<f32>) {
    dx.clear();
    dx.resize(n * i, 0.0);
    general_mat_mul(1.0, &view(dz, n, o), &view(w, i, o).t(), 0.0, &mut view_mut(dx, n, i));
}
