//! The trained policy: its file format and the [`Policy`] inference type used by eval and
//! deploy. A policy file holds everything inference needs and nothing training needs: the
//! actor's weights (and its image encoder), the observation normaliser, both spaces, the
//! algorithm and a format version.
//!
//! Format versions: 1 (MLP only) still loads; 2 adds an optional `encoder` (image spec in the
//! header, its 8 arrays after the MLP's); 3 adds the settings the policy drives with (a run
//! TOML in the header), so a policy file is self-contained.

use crate::cnn::ImageSpec;
use crate::device::NetPath;
use crate::error::{Result, RlError};
use crate::file;
use crate::host_gemm::mlp_forward as mlp_forward_host;
use crate::nets::{HostParams, MlpSpec, mlp_forward, to_vec};
use crate::normalize::ObsNormalizer;
use crate::rng::Rng;
use agvrl_envs::BoxSpace;
use burn::tensor::{Device, Tensor, TensorData};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Version of the policy file layout this build writes and reads.
pub const POLICY_FORMAT_VERSION: u32 = 3;
/// Older versions this build still reads.
const POLICY_READS: [u32; 3] = [1, 2, 3];
const POLICY_MAGIC: &[u8; 8] = b"AGVRLPOL";

/// Which algorithm trained a policy.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase", try_from = "String")]
pub enum Algorithm {
    /// Soft Actor-Critic.
    Sac,
    /// Proximal Policy Optimisation.
    #[default]
    Ppo,
}

impl std::str::FromStr for Algorithm {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "sac" => Ok(Self::Sac),
            "ppo" => Ok(Self::Ppo),
            _ => Err(format!("unknown algo '{s}'; use ppo or sac")),
        }
    }
}

impl TryFrom<String> for Algorithm {
    type Error = String;
    fn try_from(s: String) -> std::result::Result<Self, String> {
        s.parse()
    }
}

impl std::fmt::Display for Algorithm {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Algorithm::Sac => "sac",
            Algorithm::Ppo => "ppo",
        })
    }
}

/// How the network's output becomes an action.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ActionHead {
    /// SAC: the net outputs `[mean, log_std]` per action element; the action is
    /// `tanh(mean + exp(log_std) * noise)` mapped linearly from `[-1, 1]` onto the action box.
    SquashedGaussian,
    /// PPO: the net outputs the mean; the action is `mean + exp(log_std) * noise` with a
    /// state-independent `log_std`, clipped to the action box.
    Gaussian {
        /// Log standard deviation per action element.
        log_std: Vec<f32>,
    },
    /// PPO with gSDE: the net outputs the mean; stochastic actions add `latent @ E` with
    /// `E ~ N(0, exp(log_std)^2)` (`latent` the last hidden layer), drawn afresh per `act` call;
    /// clipped to the action box.
    StateDependent {
        /// Log standard deviation, `latent_dim x act_dim` row-major.
        log_std: Vec<f32>,
    },
}

/// A policy's contents on the host: what a policy file stores.
#[derive(Clone, Debug, PartialEq)]
pub struct PolicyData {
    /// The algorithm that trained it.
    pub algorithm: Algorithm,
    /// Observation space of the env it was trained on.
    pub observation_space: BoxSpace,
    /// Action space of the env it was trained on.
    pub action_space: BoxSpace,
    /// Layer widths of the actor network (one member).
    pub net: MlpSpec,
    /// Actor weights, `[w0, b0, w1, b1, ...]`.
    pub params: HostParams,
    /// How outputs become actions.
    pub head: ActionHead,
    /// Observation normaliser of the vector part, if training used one.
    pub normalizer: Option<ObsNormalizer>,
    /// The learner's configuration, as resolved TOML (provenance only).
    pub config_toml: String,
    /// The actor's image encoder, when the observation ends with an image.
    pub encoder: Option<EncoderData>,
    /// The run TOML the policy drives with: its env id and env settings (agvrl-run's
    /// `RunConfig`; opaque here). `None` in files of formats 1 and 2, whose settings sit in a
    /// TOML beside them.
    pub settings_toml: Option<String>,
}

/// An image encoder's spec and weights (see [`crate::cnn`]).
#[derive(Clone, Debug, PartialEq)]
pub struct EncoderData {
    /// Image layout and feature width.
    pub spec: ImageSpec,
    /// Weights, in [`ImageSpec::param_shapes`] order.
    pub params: HostParams,
}

#[derive(Serialize, Deserialize)]
struct Header {
    algorithm: Algorithm,
    observation_space: BoxSpace,
    action_space: BoxSpace,
    net: MlpSpec,
    shapes: Vec<[usize; 3]>,
    head: ActionHead,
    normalizer: Option<ObsNormalizer>,
    config_toml: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    image: Option<ImageSpec>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    settings: Option<String>,
}

impl PolicyData {
    /// Encode as policy-file bytes.
    pub fn to_bytes(&self) -> Result<Vec<u8>> {
        let header = Header {
            algorithm: self.algorithm,
            observation_space: self.observation_space.clone(),
            action_space: self.action_space.clone(),
            net: self.net.clone(),
            shapes: self.params.shapes.clone(),
            head: self.head.clone(),
            normalizer: self.normalizer.clone(),
            config_toml: self.config_toml.clone(),
            image: self.encoder.as_ref().map(|e| e.spec),
            settings: self.settings_toml.clone(),
        };
        let mut arrays: Vec<&[f32]> = self.params.data.iter().map(Vec::as_slice).collect();
        if let Some(e) = &self.encoder {
            arrays.extend(e.params.data.iter().map(Vec::as_slice));
        }
        file::encode(POLICY_MAGIC, POLICY_FORMAT_VERSION, &header, &arrays)
    }

    /// Write the policy file atomically.
    pub fn save(&self, path: &Path) -> Result<()> {
        file::write_atomic(path, &self.to_bytes()?)
    }

    /// Read a policy file; rejects other formats, versions, truncation and corruption.
    pub fn load(path: &Path) -> Result<Self> {
        let (h, arrays): (Header, _) = file::read(path, POLICY_MAGIC, &POLICY_READS, "policy")?;
        Self::from_parts(path, h, arrays)
    }

    /// Decode policy-file bytes as [`PolicyData::load`] does; `path` names them in errors.
    pub fn from_bytes(path: &Path, bytes: &[u8]) -> Result<Self> {
        let (h, arrays): (Header, _) = file::decode(path, bytes, POLICY_MAGIC, &POLICY_READS, "policy")?;
        Self::from_parts(path, h, arrays)
    }

    fn from_parts(path: &Path, h: Header, mut arrays: Vec<Vec<f32>>) -> Result<Self> {
        let bad = |reason: String| RlError::BadFile {
            path: path.to_path_buf(),
            reason,
        };
        let (o, a) = (h.observation_space.dim(), h.action_space.dim());
        // The MLP sees the vector part and the image features instead of the raw image.
        let (encoder, mlp_in, vec_dim) = match h.image {
            None => (None, o, o),
            Some(spec) => {
                let shapes = spec.param_shapes().map_err(|e| bad(format!("image encoder: {e}")))?;
                let vec_dim = spec.vector_dim(o).map_err(|e| bad(format!("image encoder: {e}")))?;
                if arrays.len() < shapes.len() {
                    return Err(bad("image encoder weights are missing".into()));
                }
                let data = arrays.split_off(arrays.len() - shapes.len());
                if data
                    .iter()
                    .zip(&shapes)
                    .any(|(d, s)| d.len() != s.iter().product::<usize>())
                {
                    return Err(bad("an image encoder weight array has the wrong length".into()));
                }
                let params = HostParams { shapes, data };
                (Some(EncoderData { spec, params }), vec_dim + spec.features_dim, vec_dim)
            }
        };
        let expect_shapes: Vec<[usize; 3]> = h
            .net
            .sizes
            .windows(2)
            .flat_map(|w| [[1, w[0], w[1]], [1, 1, w[1]]])
            .collect();
        if h.net.n_members != 1 || h.shapes != expect_shapes || arrays.len() != h.shapes.len() {
            return Err(bad("weights do not match the network description".into()));
        }
        if arrays
            .iter()
            .zip(&h.shapes)
            .any(|(a, s)| a.len() != s.iter().product::<usize>())
        {
            return Err(bad("a weight array has the wrong length".into()));
        }
        let out = match h.head {
            ActionHead::SquashedGaussian => 2 * a,
            ActionHead::Gaussian { ref log_std } if log_std.len() == a => a,
            ActionHead::Gaussian { .. } => {
                return Err(bad("log_std length differs from the action space".into()));
            }
            ActionHead::StateDependent { ref log_std }
                if h.net.sizes.len() > 2 && log_std.len() == h.net.sizes[h.net.sizes.len() - 2] * a =>
            {
                a
            }
            ActionHead::StateDependent { .. } => {
                return Err(bad("gSDE log_std shape differs from latent x action".into()));
            }
        };
        if h.net.sizes.first() != Some(&mlp_in) || h.net.sizes.last() != Some(&out) {
            return Err(bad("network widths do not match the spaces".into()));
        }
        if h.normalizer.as_ref().is_some_and(|n| n.dim() != vec_dim) {
            return Err(bad("normaliser width differs from the observation space".into()));
        }
        Ok(Self {
            algorithm: h.algorithm,
            observation_space: h.observation_space,
            action_space: h.action_space,
            net: h.net,
            params: HostParams {
                shapes: h.shapes,
                data: arrays,
            },
            head: h.head,
            normalizer: h.normalizer,
            config_toml: h.config_toml,
            encoder,
            settings_toml: h.settings,
        })
    }

    /// Map network outputs (`n` rows) to actions in the action box. `deterministic` uses the
    /// mean; otherwise noise comes from `rng` (gSDE also needs the last hidden layer, `latent`).
    pub(crate) fn actions_from_outputs(
        &self,
        out: &[f32],
        latent: &[f32],
        deterministic: bool,
        rng: &mut Rng,
    ) -> Vec<f32> {
        let a_dim = self.action_space.dim();
        let (low, high) = (&self.action_space.low, &self.action_space.high);
        match &self.head {
            ActionHead::SquashedGaussian => {
                let mut acts = Vec::with_capacity(out.len() / 2);
                for row in out.chunks_exact(2 * a_dim) {
                    for i in 0..a_dim {
                        let mut u = row[i];
                        if !deterministic {
                            u += row[a_dim + i].clamp(LOG_STD_MIN, LOG_STD_MAX).exp() * rng.normal() as f32;
                        }
                        acts.push(unsquash(u.tanh(), low[i], high[i]));
                    }
                }
                acts
            }
            ActionHead::Gaussian { log_std } => {
                let mut acts = Vec::with_capacity(out.len());
                for row in out.chunks_exact(a_dim) {
                    for i in 0..a_dim {
                        let mut u = row[i];
                        if !deterministic {
                            u += log_std[i].exp() * rng.normal() as f32;
                        }
                        acts.push(u.clamp(low[i], high[i]));
                    }
                }
                acts
            }
            ActionHead::StateDependent { log_std } => {
                let n = out.len() / a_dim;
                let l = log_std.len() / a_dim;
                let e: Vec<f32> = if deterministic {
                    vec![]
                } else {
                    log_std.iter().map(|s| s.exp() * rng.normal() as f32).collect()
                };
                let mut acts = Vec::with_capacity(out.len());
                for r in 0..n {
                    for j in 0..a_dim {
                        let mut u = out[r * a_dim + j];
                        if !deterministic {
                            u += (0..l).map(|k| latent[r * l + k] * e[k * a_dim + j]).sum::<f32>();
                        }
                        acts.push(u.clamp(low[j], high[j]));
                    }
                }
                acts
            }
        }
    }
}

/// SB3's clamp on SAC's predicted log standard deviation.
pub(crate) const LOG_STD_MIN: f32 = -20.0;
/// SB3's clamp on SAC's predicted log standard deviation.
pub(crate) const LOG_STD_MAX: f32 = 2.0;

/// `[-1, 1] -> [low, high]` (SB3's `unscale_action`).
pub(crate) fn unsquash(y: f32, low: f32, high: f32) -> f32 {
    low + 0.5 * (y + 1.0) * (high - low)
}

/// Check that `a` and `b` are the same space; `what` names it in the error.
pub(crate) fn check_space(what: &'static str, file: &BoxSpace, env: &BoxSpace) -> Result<()> {
    if file == env {
        return Ok(());
    }
    let show = |s: &BoxSpace| format!("dim {} low {:?} high {:?}", s.dim(), s.low, s.high);
    Err(RlError::Mismatch {
        what,
        file: show(file),
        env: show(env),
    })
}

/// A trained policy on an inference (non-autodiff) device.
///
/// ```no_run
/// # fn main() -> agvrl_rl::Result<()> {
/// let mut policy = agvrl_rl::Policy::load(std::path::Path::new("runs/x/policy.agvrl"))?;
/// let action = policy.act(&[1.0, 0.0, 0.0], true)?;
/// # Ok(()) }
/// ```
pub struct Policy {
    data: PolicyData,
    /// Where the networks run: the host kernels (the learners' host rollouts compute the same),
    /// or Burn on `device` (as their Burn rollouts).
    net_path: NetPath,
    /// The MLP's weights on the device (the Burn path only).
    weights: Vec<Tensor<3>>,
    /// The image encoder on the host, when there is one, on either path: batch-1 inference is
    /// dominated by per-op overhead on the tensor path.
    encoder: Option<crate::host_cnn::HostEncoder>,
    device: Device,
    rng: Rng,
    scratch: Vec<f32>,
}

impl Policy {
    /// A policy from host data on `device` (autodiff is stripped), its networks through Burn
    /// there: every figure in the docs was measured on that path. [`Self::set_net_path`] with
    /// [`NetPath::Host`] runs the host kernels instead, as the learners' host rollouts do.
    pub fn new(data: PolicyData, device: &Device) -> Self {
        let device = device.clone().without_autodiff();
        let encoder = (data.encoder.as_ref()).map(|e| crate::host_cnn::HostEncoder::new(&e.spec, &e.params.data));
        let mut policy = Self {
            data,
            net_path: NetPath::Host,
            weights: vec![],
            encoder,
            device,
            rng: Rng::new(0),
            scratch: Vec::new(),
        };
        policy.set_net_path(NetPath::Burn);
        policy
    }

    /// Run the networks on `path`: the host kernels, or Burn on the policy's device. The two
    /// differ in f32 rounding only (the largest action difference of each shipped policy over
    /// 1,000 recorded steps is pinned below 1e-6).
    pub fn set_net_path(&mut self, path: NetPath) {
        self.net_path = path;
        self.weights = match path {
            NetPath::Host => vec![],
            NetPath::Burn => self.data.params.to_device(&self.device),
        };
    }

    /// Where the networks run.
    pub fn net_path(&self) -> NetPath {
        self.net_path
    }

    /// Load a policy file onto the default CPU device.
    pub fn load(path: &Path) -> Result<Self> {
        Self::load_on(path, &crate::device::default_device())
    }

    /// Load a policy file onto `device`.
    pub fn load_on(path: &Path, device: &Device) -> Result<Self> {
        Ok(Self::new(PolicyData::load(path)?, device))
    }

    /// Write this policy's file.
    pub fn save(&self, path: &Path) -> Result<()> {
        self.data.save(path)
    }

    /// The host-side contents.
    pub fn data(&self) -> &PolicyData {
        &self.data
    }

    /// The algorithm that trained it.
    pub fn algorithm(&self) -> Algorithm {
        self.data.algorithm
    }

    /// Observation space it expects.
    pub fn observation_space(&self) -> &BoxSpace {
        &self.data.observation_space
    }

    /// Action space it produces.
    pub fn action_space(&self) -> &BoxSpace {
        &self.data.action_space
    }

    /// Error unless the env's spaces equal the policy's.
    pub fn check_spaces(&self, observation_space: &BoxSpace, action_space: &BoxSpace) -> Result<()> {
        check_space("observation space", &self.data.observation_space, observation_space)?;
        check_space("action space", &self.data.action_space, action_space)
    }

    /// Reseed the exploration noise used by `act(.., false)`.
    pub fn seed(&mut self, seed: u64) {
        self.rng = Rng::new(seed);
    }

    /// Actions for `n` observations given flat (`n * obs_dim` values, raw, un-normalised);
    /// returns `n * act_dim` values inside the action box. `deterministic` takes the mean
    /// action (eval, deploy); otherwise it samples as in training.
    pub fn act(&mut self, obs: &[f32], deterministic: bool) -> Result<Vec<f32>> {
        let o = self.data.observation_space.dim();
        if obs.is_empty() || !obs.len().is_multiple_of(o) {
            return Err(RlError::Shape {
                what: "observation",
                got: obs.len(),
                dim: o,
            });
        }
        let n = obs.len() / o;
        self.scratch.clear();
        self.scratch.extend_from_slice(obs);
        if let Some(norm) = &self.data.normalizer {
            norm.normalize_rows(&mut self.scratch, o);
        }
        let net = &self.data.net;
        let encoded = self.encoder.as_ref().map(|e| e.encode_rows(&self.scratch, o, n).1);
        let x = encoded.as_deref().unwrap_or(&self.scratch);
        if self.net_path == NetPath::Host {
            let layers = net.n_layers();
            let mut outs = mlp_forward_host(&self.data.params, layers, 0, (net.activation, net.activate_last), x, n);
            let out = outs.pop().unwrap_or_default();
            let latent = match self.data.head {
                ActionHead::StateDependent { .. } if !deterministic => outs.pop().unwrap_or_else(|| x.to_vec()),
                _ => vec![],
            };
            return Ok(self
                .data
                .actions_from_outputs(&out, &latent, deterministic, &mut self.rng));
        }
        let x = Tensor::<3>::from_data(TensorData::new(x.to_vec(), [1, n, x.len() / n]), &self.device);
        let (out, latent) = match self.data.head {
            ActionHead::StateDependent { .. } if !deterministic => {
                let k = self.weights.len() - 2;
                let h = mlp_forward(&self.weights[..k], x, net.activation, true);
                let out = mlp_forward(&self.weights[k..], h.clone(), net.activation, false);
                (to_vec(out)?, to_vec(h)?)
            }
            _ => (
                to_vec(mlp_forward(&self.weights, x, net.activation, net.activate_last))?,
                vec![],
            ),
        };
        Ok(self
            .data
            .actions_from_outputs(&out, &latent, deterministic, &mut self.rng))
    }
}
