//! PPO's networks, declared once: where each tensor sits in the flat parameter list
//! ([`Layout`], which the host kernels in `host.rs` read too) and their forward pass on Burn.

use crate::config::PpoConfig;
use burn::tensor::Tensor;

/// Where each part of PPO's networks sits in the one flat parameter list that Adam, the
/// gradient clipping and checkpoints walk as a whole:
/// `[trunk..., pi_w, pi_b, vf_w, vf_b, log_std, encoder...]`. The trunk is a 2-member stack
/// (member 0 the actor's MLP, member 1 the critic's); `log_std` is `[1, 1, a]`, or
/// `[1, latent, a]` with gSDE; the encoder tensors are there with `image`. Adding a part means
/// adding a field here, not renumbering uses.
#[derive(Clone, Debug)]
pub(crate) struct Layout {
    /// The actor and critic MLPs (weights and biases, layer by layer).
    pub(crate) trunk: std::ops::Range<usize>,
    /// The action-mean head, weight and bias.
    pub(crate) pi_w: usize,
    pub(crate) pi_b: usize,
    /// The value head, weight and bias.
    pub(crate) vf_w: usize,
    pub(crate) vf_b: usize,
    /// The exploration log std (state-independent, or gSDE's per latent unit).
    pub(crate) log_std: usize,
    /// The NatureCNN's tensors (empty without `image`).
    pub(crate) encoder: std::ops::RangeFrom<usize>,
}

impl Layout {
    /// The actor and critic MLPs' tensors.
    pub(crate) fn trunk_of<'a, T>(&self, params: &'a [T]) -> &'a [T] {
        &params[self.trunk.clone()]
    }

    /// The encoder's tensors.
    pub(crate) fn encoder_of<'a, T>(&self, params: &'a [T]) -> &'a [T] {
        &params[self.encoder.clone()]
    }

    pub(crate) fn of(cfg: &PpoConfig) -> Self {
        let h = 2 * cfg.net_arch.len();
        Self {
            trunk: 0..h,
            pi_w: h,
            pi_b: h + 1,
            vf_w: h + 2,
            vf_b: h + 3,
            log_std: h + 4,
            encoder: h + 5..,
        }
    }
}

/// `(mean [1, b, a], value [1, b, 1], actor latent [1, b, latent])` for observations
/// `x [1, b, o]`, with `params` laid out as [`Layout`]: the networks on the Burn path
/// ([`NetPath::Burn`](crate::device::NetPath::Burn)), and what the host path is checked against.
pub(crate) fn forward(params: &[Tensor<3>], x: Tensor<3>, cfg: &PpoConfig) -> (Tensor<3>, Tensor<3>, Tensor<3>) {
    let l = Layout::of(cfg);
    let x = match &cfg.image {
        Some(spec) => crate::cnn::encode(l.encoder_of(params), spec, x),
        None => x,
    };
    let h = crate::nets::mlp_forward(l.trunk_of(params), x, cfg.activation_fn, true);
    let latent = h.clone().narrow(0, 0, 1);
    let mean = latent.clone().matmul(params[l.pi_w].clone()) + params[l.pi_b].clone();
    let value = h.narrow(0, 1, 1).matmul(params[l.vf_w].clone()) + params[l.vf_b].clone();
    (mean, value, latent)
}
