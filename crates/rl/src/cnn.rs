//! A NatureCNN-like image encoder (Mnih et al. 2015, SB3's `NatureCNN`) on host-held weights.
//!
//! ```text
//! obs row [vector (v values) | image (C*H*W values, [C, H, W], in [0, 1])]
//!                 |                    |
//!                 |   conv 8x8 s4 32 -> ReLU -> conv 4x4 s2 64 -> ReLU -> conv 3x3 s1 64 -> ReLU
//!                 |   -> flatten -> linear features_dim -> ReLU
//!                 v                    v
//!          [vector (normalised if configured) | features]  -> the MLP heads
//! ```
//!
//! Weights are four conv/linear pairs in a [`HostParams`] list, every tensor stored 3-D like
//! the MLP's: conv weights `[1, out_c, in_c * k * k]` (reshaped to `[out_c, in_c, k, k]` on
//! the device), conv biases `[1, 1, out_c]`, the linear layer `[1, n_flatten, features_dim]`
//! and `[1, 1, features_dim]`. Gradients flow through the reshapes into those leaves, so the
//! learners' Adam and checkpoints handle them as any other tensor.

use crate::error::{Result, RlError};
use crate::nets::{HostParams, Init, init_layer};
use crate::rng::Rng;
use burn::tensor::Tensor;
use burn::tensor::activation::relu;
use burn::tensor::module::conv2d;
use burn::tensor::ops::ConvOptions;
use serde::{Deserialize, Serialize};

/// NatureCNN's conv layers: (output channels, kernel, stride), no padding.
pub const CONV_LAYERS: [(usize, usize, usize); 3] = [(32, 8, 4), (64, 4, 2), (64, 3, 1)];

fn default_features_dim() -> usize {
    256
}

/// "The last `channels * height * width` observation values are an image", channel-major
/// `[C, H, W]` with values in [0, 1] (they are not normalised), and the encoder's width.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImageSpec {
    /// Channels C (1 depth, 3 RGB, 4 depth + RGB).
    pub channels: usize,
    /// Height H, pixels.
    pub height: usize,
    /// Width W, pixels.
    pub width: usize,
    /// Width of the encoder's output (SB3's `features_dim`, 256).
    #[serde(default = "default_features_dim")]
    pub features_dim: usize,
}

impl ImageSpec {
    /// `channels` x `height` x `width` with SB3's 256 features.
    pub fn new(channels: usize, height: usize, width: usize) -> Self {
        Self {
            channels,
            height,
            width,
            features_dim: default_features_dim(),
        }
    }

    /// Values the image takes in an observation row.
    pub fn len(&self) -> usize {
        self.channels * self.height * self.width
    }

    /// Whether the image has no values.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// `(channels, height, width)` after each conv layer; an error when the image is too small
    /// for the kernels (NatureCNN needs at least 36 x 36 pixels) or a size is zero.
    pub fn conv_shapes(&self) -> Result<[(usize, usize, usize); 3]> {
        if self.channels == 0 || self.features_dim == 0 {
            return Err(RlError::Config("image: channels and features_dim must be > 0".into()));
        }
        let (mut h, mut w) = (self.height, self.width);
        let mut out = [(0, 0, 0); 3];
        for (i, (c, k, s)) in CONV_LAYERS.into_iter().enumerate() {
            if h < k || w < k {
                return Err(RlError::Config(format!(
                    "image {}x{} (height x width) is too small for NatureCNN: conv layer {} ({k}x{k}, \
                     stride {s}) sees {h}x{w}; use at least 36x36",
                    self.height,
                    self.width,
                    i + 1
                )));
            }
            (h, w) = ((h - k) / s + 1, (w - k) / s + 1);
            out[i] = (c, h, w);
        }
        Ok(out)
    }

    /// Values entering the linear layer.
    pub fn n_flatten(&self) -> Result<usize> {
        let (c, h, w) = self.conv_shapes()?[2];
        Ok(c * h * w)
    }

    /// Check the spec against an observation width; returns the vector part's width.
    pub fn vector_dim(&self, obs_dim: usize) -> Result<usize> {
        self.conv_shapes()?;
        obs_dim.checked_sub(self.len()).ok_or_else(|| {
            RlError::Config(format!(
                "image {}x{}x{} needs {} observation values, the observation has {obs_dim}",
                self.channels,
                self.height,
                self.width,
                self.len()
            ))
        })
    }

    /// Tensor shapes of the encoder's weights, in order.
    pub fn param_shapes(&self) -> Result<Vec<[usize; 3]>> {
        let mut shapes = vec![];
        let mut in_c = self.channels;
        for (c, k, _) in CONV_LAYERS {
            shapes.push([1, c, in_c * k * k]);
            shapes.push([1, 1, c]);
            in_c = c;
        }
        shapes.push([1, self.n_flatten()?, self.features_dim]);
        shapes.push([1, 1, self.features_dim]);
        Ok(shapes)
    }

    /// Fresh weights: `init` for every layer (PyTorch's default draws U(+-1/sqrt(fan_in)) for
    /// conv and linear alike; SB3's PPO uses orthogonal with gain sqrt 2).
    pub fn init(&self, init: Init, rng: &mut Rng) -> Result<HostParams> {
        let mut p = HostParams {
            shapes: vec![],
            data: vec![],
        };
        for (l, pair) in self.param_shapes()?.chunks_exact(2).enumerate() {
            let [_, a, b] = pair[0];
            let (w, bias) = if l < CONV_LAYERS.len() {
                // Conv weights are `[out_c, fan_in]`: drawn as a `[fan_in, out_c]` layer and
                // transposed, so the bounds use the right fan-in.
                let (w, bias) = init_layer(init, 1, b, a, rng);
                (transpose(&w, b, a), bias)
            } else {
                init_layer(init, 1, a, b, rng)
            };
            p.push(pair[0], w);
            p.push(pair[1], bias);
        }
        Ok(p)
    }

    /// Multiply-adds per image, for FLOP counts.
    pub fn macs(&self) -> Result<usize> {
        let shapes = self.conv_shapes()?;
        let mut in_c = self.channels;
        let mut macs = 0;
        for ((c, h, w), (_, k, _)) in shapes.iter().zip(CONV_LAYERS) {
            macs += c * h * w * in_c * k * k;
            in_c = *c;
        }
        Ok(macs + self.n_flatten()? * self.features_dim)
    }
}

fn transpose(m: &[f32], rows: usize, cols: usize) -> Vec<f32> {
    let mut t = vec![0.0; m.len()];
    for r in 0..rows {
        for c in 0..cols {
            t[c * rows + r] = m[r * cols + c];
        }
    }
    t
}

/// `x [1, n, v + C*H*W] -> [1, n, v + features_dim]`: the vector part passes through, the image
/// goes through the encoder whose 8 weights are `params` (see [`ImageSpec::param_shapes`]).
pub fn encode(params: &[Tensor<3>], spec: &ImageSpec, x: Tensor<3>) -> Tensor<3> {
    let [_, n, o] = x.dims();
    let v = o - spec.len();
    let image = x.clone().narrow(2, v, spec.len());
    let mut h: Tensor<4> = image.reshape([n, spec.channels, spec.height, spec.width]);
    for (l, (c, k, s)) in CONV_LAYERS.into_iter().enumerate() {
        let [_, in_c, _, _] = h.dims();
        let w: Tensor<4> = params[2 * l].clone().reshape([c, in_c, k, k]);
        let b: Tensor<1> = params[2 * l + 1].clone().reshape([c]);
        h = relu(conv2d(h, w, Some(b), ConvOptions::new([s, s], [0, 0], [1, 1], 1)));
    }
    let [_, c, hh, ww] = h.dims();
    let flat: Tensor<3> = h.reshape([1, n, c * hh * ww]);
    let features = relu(flat.matmul(params[6].clone()) + params[7].clone());
    if v == 0 {
        features
    } else {
        Tensor::cat(vec![x.narrow(2, 0, v), features], 2)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nature_cnn_shapes_of_a_64x48_image() {
        let spec = ImageSpec::new(1, 48, 64);
        assert_eq!(spec.conv_shapes().unwrap(), [(32, 11, 15), (64, 4, 6), (64, 2, 4)]);
        assert_eq!(spec.n_flatten().unwrap(), 512);
        let small = ImageSpec::new(1, 35, 64);
        let e = small.conv_shapes().unwrap_err().to_string();
        assert!(e.contains("too small"), "{e}");
        assert!(ImageSpec::new(1, 36, 36).conv_shapes().is_ok());
        assert!(ImageSpec::new(1, 48, 64).vector_dim(100).is_err());
    }

    #[test]
    fn init_draws_the_torch_default_bounds() {
        let spec = ImageSpec::new(3, 36, 36);
        let p = spec.init(Init::TorchDefault, &mut Rng::new(0)).unwrap();
        assert_eq!(p.shapes, spec.param_shapes().unwrap());
        // conv1: fan_in 3 * 8 * 8 = 192.
        let bound = 1.0 / 192f32.sqrt();
        let max = p.data[0].iter().fold(0.0f32, |m, v| m.max(v.abs()));
        assert!(max <= bound && max > 0.9 * bound, "{max} {bound}");
    }
}
