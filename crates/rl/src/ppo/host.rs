//! PPO's MLP networks on the host: forward and backward of the stacked actor/critic trunk and
//! the two heads, in plain loops over row-major slices.
//!
//! A minibatch of SB3-sized networks (64 samples, 64x64 layers) is a few hundred thousand
//! multiply-adds: through the tensor backend its time goes to dispatch, graph building, buffer
//! churn and a scalar libm `expf` per activation. Here the products are ndarray's
//! `general_mat_mul` (matrixmultiply's kernels, picked for the CPU at run time) on views of the
//! host weights, and tanh is a rational approximation of a few ulp in a loop the compiler
//! vectorises, so one minibatch costs a fraction of the tensor path. With an image, the
//! NatureCNN runs on the host too ([`crate::host_cnn`]) and its features join the vector part
//! at the trunks' input. `tests::host_gradients_match_autodiff` checks both against Burn's
//! autodiff.

use super::network::Layout;
use crate::host_cnn::{EncoderPass, HostEncoder};
use crate::host_gemm::{activate, activation_grad, affine, input_grads, weight_grads};
use crate::nets::{Activation, HostParams};

/// One forward pass of `n` rows: every layer's output per member (for the backward pass), the
/// action mean and the value.
pub(crate) struct Forward {
    n: usize,
    /// With an image: the encoder's pass and the trunks' input rows `[vector | features]`.
    encoder: Option<(EncoderPass, Vec<f32>)>,
    /// `outs[l][m]`: layer `l`'s activated output for member `m` (0 actor, 1 critic), `[n x out]`.
    outs: Vec<[Vec<f32>; 2]>,
    /// Action mean, `[n x a]`.
    pub(crate) mean: Vec<f32>,
    /// Value, `[n]`.
    pub(crate) value: Vec<f32>,
}

impl Forward {
    /// What the trunks saw for observations `obs`: `obs` itself, or with an image its encoding.
    pub(crate) fn input<'a>(&'a self, obs: &'a [f32]) -> &'a [f32] {
        self.encoder.as_ref().map_or(obs, |(_, x)| x)
    }

    /// The actor's last hidden layer (gSDE's latent), `[n x latent]`; the input without hidden layers.
    pub(crate) fn latent<'a>(&'a self, obs: &'a [f32]) -> &'a [f32] {
        self.outs.last().map_or(self.input(obs), |o| &o[0])
    }
}

/// The networks of `params` (laid out as [`Layout`]) on the observations `obs [n x o]`; with
/// `image` (the encoder made from `params`), the last `C*H*W` values of a row are an image.
pub(crate) fn forward(
    params: &HostParams,
    l: &Layout,
    act: Activation,
    image: Option<&HostEncoder>,
    obs: &[f32],
    n: usize,
) -> Forward {
    let encoder = image.map(|e| e.encode_rows(obs, obs.len() / n, n));
    let x = encoder.as_ref().map_or(obs, |(_, x)| x.as_slice());
    let mut outs: Vec<[Vec<f32>; 2]> = Vec::with_capacity(l.trunk.len() / 2);
    for k in (l.trunk.start..l.trunk.end).step_by(2) {
        let [_, i, o] = params.shapes[k];
        let member = |m: usize, input: &[f32]| {
            let mut out = Vec::new();
            let (w, b) = (
                &params.data[k][m * i * o..(m + 1) * i * o],
                &params.data[k + 1][m * o..(m + 1) * o],
            );
            affine(input, w, b, (n, i, o), &mut out);
            activate(&mut out, act);
            out
        };
        let layer = match outs.last() {
            None => [member(0, x), member(1, x)],
            Some([h0, h1]) => [member(0, h0), member(1, h1)],
        };
        outs.push(layer);
    }
    let last = |m: usize| outs.last().map_or(x, |o| &o[m]);
    let [_, lat, a] = params.shapes[l.pi_w];
    let mut mean = Vec::new();
    affine(
        last(0),
        &params.data[l.pi_w],
        &params.data[l.pi_b],
        (n, lat, a),
        &mut mean,
    );
    let [_, lat_v, _] = params.shapes[l.vf_w];
    let mut value = Vec::new();
    affine(
        last(1),
        &params.data[l.vf_w],
        &params.data[l.vf_b],
        (n, lat_v, 1),
        &mut value,
    );
    Forward {
        n,
        encoder,
        outs,
        mean,
        value,
    }
}

/// Gradients of `sum(mean * d_mean) + sum(value * d_value)` with respect to every tensor of
/// `params`, in its order (zeros for `log_std`), for the pass `f` on `obs` (`image` as there).
#[allow(clippy::too_many_arguments)]
pub(crate) fn backward(
    params: &HostParams,
    l: &Layout,
    act: Activation,
    image: Option<&HostEncoder>,
    obs: &[f32],
    f: &Forward,
    d_mean: &[f32],
    d_value: &[f32],
) -> Vec<Vec<f32>> {
    let n = f.n;
    let x = f.input(obs);
    let mut grads: Vec<Vec<f32>> = params.data.iter().map(|p| vec![0.0; p.len()]).collect();
    let last = |m: usize| f.outs.last().map_or(x, |o| &o[m]);
    // Heads, then each member's trunk from the top.
    let mut dh: [Vec<f32>; 2] = [Vec::new(), Vec::new()];
    for (m, (w, b, d)) in [(l.pi_w, l.pi_b, d_mean), (l.vf_w, l.vf_b, d_value)]
        .into_iter()
        .enumerate()
    {
        let [_, i, o] = params.shapes[w];
        let (gw, rest) = split_two(&mut grads, w, b);
        weight_grads(last(m), d, (n, i, o), gw, rest);
        input_grads(d, &params.data[w], (n, i, o), &mut dh[m]);
    }
    let layers: Vec<usize> = (l.trunk.start..l.trunk.end).step_by(2).collect();
    for (depth, &k) in layers.iter().enumerate().rev() {
        let [_, i, o] = params.shapes[k];
        for (m, dhm) in dh.iter_mut().enumerate() {
            activation_grad(dhm, &f.outs[depth][m], act);
            let input = if depth == 0 { x } else { &f.outs[depth - 1][m] };
            let (gw, gb) = split_two(&mut grads, k, k + 1);
            weight_grads(
                input,
                dhm,
                (n, i, o),
                &mut gw[m * i * o..(m + 1) * i * o],
                &mut gb[m * o..(m + 1) * o],
            );
            if depth > 0 || image.is_some() {
                let dz = std::mem::take(dhm);
                input_grads(&dz, &params.data[k][m * i * o..(m + 1) * i * o], (n, i, o), dhm);
            }
        }
    }
    if let (Some(enc), Some((pass, _))) = (image, &f.encoder) {
        // `dh` now holds each member's gradient at the trunks' input; both read the features.
        let (w, fd) = (x.len() / n, enc.features_dim());
        let v = w - fd;
        let mut d_features = Vec::with_capacity(n * fd);
        for (a, c) in dh[0].chunks_exact(w).zip(dh[1].chunks_exact(w)) {
            d_features.extend(a[v..].iter().zip(&c[v..]).map(|(a, c)| a + c));
        }
        enc.backward(pass, &d_features, &mut grads[l.encoder.clone()]);
    }
    grads
}

/// Mutable borrows of two different entries `a < b` of `v`.
fn split_two(v: &mut [Vec<f32>], a: usize, b: usize) -> (&mut [f32], &mut [f32]) {
    let (lo, hi) = v.split_at_mut(b);
    (&mut lo[a], &mut hi[0])
}
