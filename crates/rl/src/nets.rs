//! Networks as plain parameter lists, their initialisation and forward pass (Adam, which
//! steps them on the host, is in `adam.rs`).
//!
//! Every learnable tensor is `[n_members, rows, cols]`: a stack of `n_members` independent
//! networks evaluated with one batched matmul per layer. SAC's twin critics are one 2-member
//! stack, PPO's actor and critic trunks another, so each layer costs one GEMM call and one graph
//! node instead of two. The master copy of the weights and Adam's moments live on the host
//! ([`HostParams`], [`crate::adam::Adam`]): the optimiser step is one fused loop per tensor instead of ~8
//! tensor ops each, and the whole training state serialises without touching the device.

use crate::error::{Result, RlError};
use crate::rng::Rng;
use burn::tensor::activation::{relu, sigmoid};
use burn::tensor::{Device, Tensor, TensorData};
use serde::{Deserialize, Serialize};

/// Where a network's parts sit in its flat tensor list: the MLP's weights and biases, layer by
/// layer, then the image encoder's tensors (none without `image`). Adam, checkpoints and policy
/// files walk the list as a whole; forward passes take their part through this.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct NetParts {
    mlp_tensors: usize,
}

impl NetParts {
    /// The layout of an MLP with `hidden` hidden layers (plus its output layer).
    pub fn mlp(hidden: usize) -> Self {
        Self {
            mlp_tensors: 2 * (hidden + 1),
        }
    }

    /// The MLP's tensors.
    pub fn mlp_of<'a, T>(&self, params: &'a [T]) -> &'a [T] {
        &params[..self.mlp_tensors]
    }

    /// The encoder's tensors.
    pub fn encoder_of<'a, T>(&self, params: &'a [T]) -> &'a [T] {
        &params[self.mlp_tensors..]
    }
}

/// Hidden-layer activation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Activation {
    /// max(0, x) (SB3's SAC default).
    Relu,
    /// tanh (SB3's PPO default).
    Tanh,
}

impl Activation {
    fn apply<const D: usize>(self, x: Tensor<D>) -> Tensor<D> {
        match self {
            Activation::Relu => relu(x),
            // tanh(x) = 2 sigmoid(2x) - 1: the CPU backends evaluate tanh with libm's scalar
            // tanhf (~20 ns/element, 2/3 of PPO's update time when profiled) and sigmoid with
            // expf, several times cheaper even with the two extra scaling ops.
            Activation::Tanh => sigmoid(x * 2.0) * 2.0 - 1.0,
        }
    }
}

/// Host copy of a list of `[n_members, rows, cols]` tensors.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HostParams {
    /// Shape of each tensor.
    pub shapes: Vec<[usize; 3]>,
    /// Row-major values of each tensor.
    pub data: Vec<Vec<f32>>,
}

impl HostParams {
    /// Total number of scalars.
    pub fn len(&self) -> usize {
        self.data.iter().map(Vec::len).sum()
    }

    /// Whether there are no scalars.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Append a tensor.
    pub fn push(&mut self, shape: [usize; 3], data: Vec<f32>) {
        debug_assert_eq!(shape.iter().product::<usize>(), data.len());
        self.shapes.push(shape);
        self.data.push(data);
    }

    /// Plain (no-gradient) device tensors.
    pub fn to_device(&self, device: &Device) -> Vec<Tensor<3>> {
        self.shapes
            .iter()
            .zip(&self.data)
            .map(|(s, d)| Tensor::from_data(TensorData::new(d.clone(), *s), device))
            .collect()
    }

    /// Leaf tensors that record gradients (`device` must have autodiff on).
    #[cfg(feature = "train")]
    pub fn to_tracked(&self, device: &Device) -> Vec<Tensor<3>> {
        self.to_device(device).into_iter().map(|t| t.require_grad()).collect()
    }

    /// `self = (1 - tau) self + tau other` (Polyak averaging of target networks).
    pub fn polyak(&mut self, other: &HostParams, tau: f32) {
        for (t, o) in self.data.iter_mut().zip(&other.data) {
            for (a, b) in t.iter_mut().zip(o) {
                *a = (1.0 - tau) * *a + tau * *b;
            }
        }
    }

    /// Whether every value is finite.
    pub fn all_finite(&self) -> bool {
        self.data.iter().all(|d| d.iter().all(|v| v.is_finite()))
    }
}

/// Layer widths of a multilayer perceptron with `n_members` stacked copies.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct MlpSpec {
    /// Stacked independent copies.
    pub n_members: usize,
    /// Input width, hidden widths, output width.
    pub sizes: Vec<usize>,
    /// Activation after each hidden layer.
    pub activation: Activation,
    /// Whether the activation also follows the last layer (a trunk without a head).
    pub activate_last: bool,
}

/// How to initialise a layer.
#[derive(Clone, Copy, Debug)]
pub enum Init {
    /// PyTorch's `nn.Linear` default: weights and biases U(-1/sqrt(fan_in), 1/sqrt(fan_in)).
    TorchDefault,
    /// Orthogonal weights with this gain, zero bias (SB3's `ortho_init`).
    Orthogonal(f64),
}

impl MlpSpec {
    /// Number of layers.
    pub fn n_layers(&self) -> usize {
        self.sizes.len() - 1
    }

    /// Fresh weights; `inits[l]` initialises layer `l` (the last entry repeats).
    pub fn init(&self, inits: &[Init], rng: &mut Rng) -> HostParams {
        let mut p = HostParams {
            shapes: vec![],
            data: vec![],
        };
        for l in 0..self.n_layers() {
            let (fan_in, fan_out) = (self.sizes[l], self.sizes[l + 1]);
            let init = inits[l.min(inits.len() - 1)];
            let (w, b) = init_layer(init, self.n_members, fan_in, fan_out, rng);
            p.push([self.n_members, fan_in, fan_out], w);
            p.push([self.n_members, 1, fan_out], b);
        }
        p
    }
}

/// One layer's weights `[n, fan_in, fan_out]` and biases `[n, 1, fan_out]`.
pub fn init_layer(init: Init, n: usize, fan_in: usize, fan_out: usize, rng: &mut Rng) -> (Vec<f32>, Vec<f32>) {
    let mut w = Vec::with_capacity(n * fan_in * fan_out);
    let mut b = Vec::with_capacity(n * fan_out);
    for _ in 0..n {
        match init {
            Init::TorchDefault => {
                let bound = 1.0 / (fan_in as f64).sqrt();
                w.extend((0..fan_in * fan_out).map(|_| ((rng.uniform() * 2.0 - 1.0) * bound) as f32));
                b.extend((0..fan_out).map(|_| ((rng.uniform() * 2.0 - 1.0) * bound) as f32));
            }
            Init::Orthogonal(gain) => {
                w.extend(orthogonal(fan_in, fan_out, gain, rng));
                b.extend(std::iter::repeat_n(0.0, fan_out));
            }
        }
    }
    (w, b)
}

/// A `rows x cols` row-major matrix with orthonormal rows or columns (whichever are fewer),
/// times `gain`: Gram-Schmidt on a Gaussian matrix, as `torch.nn.init.orthogonal_`.
fn orthogonal(rows: usize, cols: usize, gain: f64, rng: &mut Rng) -> Vec<f32> {
    let (long, short) = (rows.max(cols), rows.min(cols));
    // `short` vectors of length `long`, made orthonormal.
    let mut q: Vec<Vec<f64>> = (0..short).map(|_| (0..long).map(|_| rng.normal()).collect()).collect();
    for i in 0..short {
        for j in 0..i {
            let d: f64 = q[i].iter().zip(&q[j]).map(|(a, b)| a * b).sum();
            let qj = q[j].clone();
            q[i].iter_mut().zip(&qj).for_each(|(a, b)| *a -= d * b);
        }
        let n = q[i].iter().map(|a| a * a).sum::<f64>().sqrt().max(1e-12);
        q[i].iter_mut().for_each(|a| *a /= n);
    }
    let mut m = vec![0.0f32; rows * cols];
    for r in 0..rows {
        for c in 0..cols {
            let v = if rows >= cols { q[c][r] } else { q[r][c] };
            m[r * cols + c] = (gain * v) as f32;
        }
    }
    m
}

/// `x [n_members or 1, batch, in] -> [n_members, batch, out]` through the layers in `params`
/// (`[w0, b0, w1, b1, ...]`).
pub fn mlp_forward(params: &[Tensor<3>], x: Tensor<3>, activation: Activation, activate_last: bool) -> Tensor<3> {
    let n_layers = params.len() / 2;
    let mut h = x;
    for l in 0..n_layers {
        h = h.matmul(params[2 * l].clone()) + params[2 * l + 1].clone();
        if l + 1 < n_layers || activate_last {
            h = activation.apply(h);
        }
    }
    h
}

/// Tensor values as a host vector.
pub fn to_vec<const D: usize>(t: Tensor<D>) -> Result<Vec<f32>> {
    t.try_into_data()
        .map_err(|e| RlError::Tensor(format!("{e:?}")))?
        .try_into_vec::<f32>()
        .map_err(|e| RlError::Tensor(format!("{e:?}")))
}

/// Gradients of `params` after a backward pass, as host vectors (zeros where none flowed).
#[cfg(feature = "train")]
pub fn grads_of(params: &[Tensor<3>], grads: &burn::tensor::Gradients) -> Result<Vec<Vec<f32>>> {
    params
        .iter()
        .map(|p| match p.grad(grads) {
            Some(g) => to_vec(g),
            None => Ok(vec![0.0; p.shape().num_elements()]),
        })
        .collect()
}

/// Largest difference over `q`'s largest magnitude: how closely two computations of a tensor
/// agree, relative to its scale.
#[cfg(test)]
pub(crate) fn scaled_diff(p: &[f32], q: &[f32]) -> f64 {
    assert_eq!(p.len(), q.len());
    let scale = q.iter().fold(0.0f64, |m, v| m.max(v.abs() as f64));
    let diff = p.iter().zip(q).fold(0.0f64, |m, (p, q)| m.max((p - q).abs() as f64));
    if scale == 0.0 { diff } else { diff / scale }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tanh_activation_matches_tanh() {
        let dev = crate::device::default_device();
        let xs: Vec<f32> = (-80..=80).map(|i| i as f32 * 0.1).collect();
        let t = Tensor::<1>::from_data(TensorData::new(xs.clone(), [xs.len()]), &dev);
        let ys = to_vec(Activation::Tanh.apply(t)).unwrap();
        assert!(xs.iter().zip(&ys).all(|(x, y)| (x.tanh() - y).abs() < 1e-6));
    }

    #[test]
    fn orthogonal_columns_are_orthonormal_times_gain() {
        let mut rng = Rng::new(0);
        let (rows, cols) = (5, 3);
        let m = orthogonal(rows, cols, 2.0, &mut rng);
        for a in 0..cols {
            for b in 0..cols {
                let d: f32 = (0..rows).map(|r| m[r * cols + a] * m[r * cols + b]).sum();
                let want = if a == b { 4.0 } else { 0.0 };
                assert!((d - want).abs() < 1e-4, "{a} {b} {d}");
            }
        }
    }
}
