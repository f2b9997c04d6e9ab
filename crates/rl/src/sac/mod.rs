//! Soft Actor-Critic (Haarnoja et al. 2018) as Stable-Baselines3 runs it: tanh-squashed
//! Gaussian actor, twin critics with Polyak-averaged targets, learned entropy coefficient.
//!
//! With `image`, the actor and the critics each have a NatureCNN ([`crate::cnn`]) whose
//! features replace the image part of the observation at their input (SB3's SAC default: no
//! sharing; the twin critics share theirs, and the target critics copy it). Its tensors follow
//! the MLP's in `actor`, `critic` and `critic_target`. The replay buffer stores raw f32
//! observations, images included: size `buffer_size` for the memory (2 x 4 bytes x
//! observation width per transition).
//!
//! Data flow per vector step: actor (or uniform noise before `learning_starts`) -> env ->
//! replay buffer (`next_obs` is `final_obs` where an episode ended; only termination stops
//! bootstrapping) -> `update.rs` every `train_freq` steps.

mod host;
mod update;

pub use crate::config::{EntCoef, SacConfig};

use crate::adam::Adam;
use crate::buffer::ReplayBuffer;
use crate::checkpoint::{self, AdamMeta, ArrayWriter, Common};
use crate::cnn::encode;
use crate::device::NetPath;
use crate::error::{Result, RlError};
use crate::nets::{Activation, HostParams, Init, MlpSpec, NetParts, mlp_forward, to_vec};
use crate::normalize::ObsNormalizer;
use crate::policy::{ActionHead, Algorithm, EncoderData, Policy, PolicyData, unsquash};
use crate::progress::{Control, Episodes, Losses, Progress};
use crate::rng::Rng;
use agvrl_envs::Workers;
use agvrl_envs::{BoxSpace, Env, VecEnv};
use burn::tensor::{Device, Tensor, TensorData};
use serde::{Deserialize, Serialize};
use std::path::Path;
use std::sync::Arc;

/// A SAC learner bound to a vector env.
pub struct Sac<E: Env> {
    cfg: SacConfig,
    /// `cfg` as TOML, for policy files (serialised once, where a failure can be reported).
    cfg_toml: String,
    env: VecEnv<E>,
    device: Device,
    /// Where the networks run (the host kernels, or Burn on `device`).
    net_path: NetPath,
    obs_dim: usize,
    act_dim: usize,
    actor_spec: MlpSpec,
    /// Master weights (shared with a gradient step's helper threads while it runs).
    actor: Arc<HostParams>,
    critic: Arc<HostParams>,
    critic_target: Arc<HostParams>,
    actor_opt: Adam,
    critic_opt: Adam,
    /// `[log(alpha)]` and its optimiser when alpha is learned.
    log_ent_coef: HostParams,
    ent_opt: Option<Adam>,
    target_entropy: f64,
    buffer: ReplayBuffer,
    normalizer: Option<ObsNormalizer>,
    rng: Rng,
    seed: u64,
    num_timesteps: u64,
    n_updates: u64,
    episodes: Episodes,
    losses: Losses,
    /// Current observations (raw), `None` until the envs are reset.
    last_obs: Option<Vec<f32>>,
    /// Threads one gradient step may use (row blocks of the minibatch).
    threads: usize,
    /// Helper threads for `threads > 1`.
    workers: Option<std::sync::Arc<Workers>>,
    /// Device copies of the actor, critics and target critics, refreshed after each change;
    /// empty on the host path (no image encoder), which reads the master weights.
    actor_dev: Vec<Tensor<3>>,
    critic_dev: Vec<Tensor<3>>,
    target_dev: Vec<Tensor<3>>,
}

#[derive(Serialize, Deserialize)]
struct Header {
    algorithm: Algorithm,
    config: SacConfig,
    #[serde(flatten)]
    common: Common,
    actor_opt: AdamMeta,
    critic_opt: AdamMeta,
    ent_opt: Option<AdamMeta>,
    buffer_len: usize,
    buffer_pos: usize,
}

impl checkpoint::Header for Header {
    fn common(&self) -> &Common {
        &self.common
    }
}

fn finite_box(space: &BoxSpace) -> Result<()> {
    if space.low.iter().chain(&space.high).all(|v| v.is_finite())
        && space.low.iter().zip(&space.high).all(|(l, h)| l < h)
    {
        Ok(())
    } else {
        Err(RlError::Config("SAC needs a finite action box with low < high".into()))
    }
}

impl<E: Env> Sac<E> {
    /// A fresh learner. `device` is a plain device (autodiff is switched on where needed);
    /// `seed` seeds the weights, the noise and the envs' first reset.
    pub fn new(cfg: SacConfig, env: VecEnv<E>, device: &Device, seed: u64) -> Result<Self> {
        cfg.validate()?;
        let obs_dim = env.observation_space().dim();
        let act_dim = env.action_space().dim();
        finite_box(env.action_space())?;
        if env.critic_obs_dim() > 0 {
            return Err(RlError::Config(
                "SAC's critics do not read critic observations (race.critic_sees_opponents); train with PPO".into(),
            ));
        }
        let (vec_dim, mlp_in) = match &cfg.image {
            Some(spec) => {
                let v = spec.vector_dim(obs_dim)?;
                (v, v + spec.features_dim)
            }
            None => (obs_dim, obs_dim),
        };
        let mut rng = Rng::new(seed);
        let hidden = |input: usize, out: usize, members: usize| {
            let mut sizes = vec![input];
            sizes.extend(&cfg.net_arch);
            sizes.push(out);
            MlpSpec {
                n_members: members,
                sizes,
                activation: Activation::Relu,
                activate_last: false,
            }
        };
        let actor_spec = hidden(mlp_in, 2 * act_dim, 1);
        let critic_spec = hidden(mlp_in + act_dim, 1, 2);
        let mut actor = actor_spec.init(&[Init::TorchDefault], &mut rng);
        let mut critic = critic_spec.init(&[Init::TorchDefault], &mut rng);
        if let Some(spec) = &cfg.image {
            // Drawn after the MLPs, so MLP-only runs draw exactly what they always did.
            for net in [&mut actor, &mut critic] {
                let enc = spec.init(Init::TorchDefault, &mut rng)?;
                for (s, d) in enc.shapes.into_iter().zip(enc.data) {
                    net.push(s, d);
                }
            }
        }
        let (actor, critic) = (Arc::new(actor), Arc::new(critic));
        let critic_target = critic.clone();
        let ent_init = cfg.ent_coef.auto_init()?;
        let log_ent_coef = HostParams {
            shapes: vec![[1, 1, 1]],
            data: vec![vec![match (&cfg.ent_coef, ent_init) {
                (_, Some(init)) => init.ln() as f32,
                (EntCoef::Fixed(v), None) => v.ln() as f32,
                _ => 0.0,
            }]],
        };
        let ent_opt = ent_init.map(|_| Adam::new(&log_ent_coef, cfg.learning_rate, 1e-8));
        let net_path = NetPath::for_device(device);
        let device = device.clone().without_autodiff();
        let mut s = Self {
            actor_opt: Adam::new(&actor, cfg.learning_rate, 1e-8),
            critic_opt: Adam::new(&critic, cfg.learning_rate, 1e-8),
            target_entropy: cfg.target_entropy.unwrap_or(-(act_dim as f64)),
            buffer: ReplayBuffer::new(cfg.buffer_size, obs_dim, act_dim),
            normalizer: cfg.normalize_obs.then(|| ObsNormalizer::new(vec_dim)),
            threads: 1,
            workers: None,
            cfg_toml: cfg.to_toml()?,
            actor_dev: vec![],
            critic_dev: vec![],
            target_dev: vec![],
            cfg,
            env,
            device,
            net_path,
            obs_dim,
            act_dim,
            actor_spec,
            actor,
            critic,
            critic_target,
            log_ent_coef,
            ent_opt,
            rng,
            seed,
            num_timesteps: 0,
            n_updates: 0,
            episodes: Episodes::default(),
            losses: Losses::default(),
            last_obs: None,
        };
        s.upload_all();
        Ok(s)
    }

    /// The parts of the actor's (and each critic stack's) tensor list.
    fn parts(&self) -> NetParts {
        NetParts::mlp(self.cfg.net_arch.len())
    }

    /// Whether gradient steps and actions run on the host ([`host`]) rather than through Burn
    /// on the device: configs without an image encoder on [`NetPath::Host`].
    fn on_host(&self) -> bool {
        self.cfg.image.is_none() && self.net_path == NetPath::Host
    }

    /// Run the networks on `path` from the next step on: the host kernels (the CPU fast path,
    /// the default on CPU devices; configs with an image run through Burn either way) or Burn's
    /// tensors on the learner's device (the default on any other). Both compute the same
    /// functions; they differ in f32 rounding.
    pub fn set_net_path(&mut self, path: NetPath) {
        self.net_path = path;
        self.upload_all();
    }

    /// Where the networks run.
    pub fn net_path(&self) -> NetPath {
        if self.on_host() { NetPath::Host } else { NetPath::Burn }
    }

    /// Layers of each MLP (hidden + output).
    fn mlp_layers(&self) -> usize {
        self.cfg.net_arch.len() + 1
    }

    fn upload_all(&mut self) {
        if self.on_host() {
            return;
        }
        self.actor_dev = self.actor.to_device(&self.device);
        self.critic_dev = self.critic.to_device(&self.device);
        self.target_dev = self.critic_target.to_device(&self.device);
    }

    /// Start fresh episodes at the next step, as a learner resumed from a checkpoint does (see
    /// [`crate::Ppo::restart_episodes`]).
    pub fn restart_episodes(&mut self) {
        self.last_obs = None;
    }

    /// Let each gradient step split its minibatch over `threads` threads (default 1). The
    /// result is deterministic for a given thread count but differs from other counts in the
    /// last float bits.
    pub fn set_threads(&mut self, threads: usize) -> Result<()> {
        self.threads = threads.max(1);
        self.workers = None;
        if self.threads > 1 {
            self.workers = Some(crate::shared_workers(&self.env, self.threads, "SAC")?);
        }
        Ok(())
    }

    /// The configuration.
    pub fn config(&self) -> &SacConfig {
        &self.cfg
    }

    /// Env steps taken so far (summed over envs).
    pub fn num_timesteps(&self) -> u64 {
        self.num_timesteps
    }

    /// The vector env.
    pub fn env(&self) -> &VecEnv<E> {
        &self.env
    }

    /// The current entropy coefficient alpha.
    pub fn ent_coef(&self) -> f64 {
        (self.log_ent_coef.data[0][0] as f64).exp()
    }

    /// Run `steps` more env steps (rounded up to whole vector steps), training as configured;
    /// `callback` sees progress after every vector step and can stop early. Calling `learn`
    /// again continues the same episodes.
    pub fn learn(&mut self, steps: u64, callback: &mut dyn FnMut(&Progress<'_>) -> Control) -> Result<()> {
        let target = self.num_timesteps + steps;
        let n_envs = self.env.n_envs();
        let gradient_steps = self.cfg.gradient_steps_per_round(n_envs);
        while self.num_timesteps < target {
            let obs = match self.last_obs.take() {
                Some(o) => o,
                None => {
                    // First reset uses the run seed; after a resume, a seed derived from the step count.
                    let seed = self.seed.wrapping_add(self.num_timesteps.wrapping_mul(0x9E37_79B9));
                    let (o, _) = self.env.reset(Some(seed))?;
                    // After a resume the normaliser has already counted the observations these
                    // replace (as PPO's).
                    if let Some(n) = self.normalizer.as_mut().filter(|_| self.num_timesteps == 0) {
                        n.update_rows(&o, self.obs_dim);
                    }
                    o
                }
            };
            let scaled = if self.num_timesteps < self.cfg.learning_starts {
                (0..n_envs * self.act_dim)
                    .map(|_| (self.rng.uniform() * 2.0 - 1.0) as f32)
                    .collect()
            } else {
                self.sample_scaled_actions(&obs)?
            };
            let space = self.env.action_space().clone();
            let env_actions: Vec<f32> = scaled
                .iter()
                .enumerate()
                .map(|(k, y)| {
                    let i = k % self.act_dim;
                    unsquash(*y, space.low[i], space.high[i])
                })
                .collect();
            let st = self.env.step(&env_actions)?;
            let o = self.obs_dim;
            for e in 0..n_envs {
                let next = st.infos[e].final_obs.as_deref().unwrap_or(&st.obs[e * o..(e + 1) * o]);
                self.buffer.push(
                    &obs[e * o..(e + 1) * o],
                    &scaled[e * self.act_dim..(e + 1) * self.act_dim],
                    st.rewards[e] as f32,
                    next,
                    st.terminated[e],
                );
            }
            if let Some(n) = &mut self.normalizer {
                n.update_rows(&st.obs, o);
            }
            self.episodes.record(&st.infos);
            self.num_timesteps += n_envs as u64;
            self.last_obs = Some(st.obs);
            // Counted over the run, not this call, so training in chunks (or resumed) keeps
            // the cadence of one straight call.
            let vec_steps = self.num_timesteps / n_envs as u64;
            if self.num_timesteps > self.cfg.learning_starts && vec_steps.is_multiple_of(self.cfg.train_freq) {
                for _ in 0..gradient_steps {
                    self.update()?;
                }
            }
            let progress = Progress {
                algorithm: Algorithm::Sac,
                steps: self.num_timesteps,
                target_steps: target,
                updates: self.n_updates,
                episodes: self.episodes.count,
                recent_returns: self.episodes.recent.make_contiguous(),
                losses: self.losses,
            };
            if callback(&progress) == Control::Stop {
                break;
            }
        }
        Ok(())
    }

    /// Stochastic actions in [-1, 1] for raw observations.
    fn sample_scaled_actions(&mut self, obs: &[f32]) -> Result<Vec<f32>> {
        let n = obs.len() / self.obs_dim;
        let mut x = obs.to_vec();
        if let Some(norm) = &self.normalizer {
            norm.normalize_rows(&mut x, self.obs_dim);
        }
        let out = if self.on_host() {
            host::forward(&self.actor, self.mlp_layers(), 0, &x, n)
                .pop()
                .unwrap_or_default()
        } else {
            let mut x = Tensor::<3>::from_data(TensorData::new(x, [1, n, self.obs_dim]), &self.device);
            let parts = self.parts();
            if let Some(spec) = &self.cfg.image {
                x = encode(parts.encoder_of(&self.actor_dev), spec, x);
            }
            to_vec(mlp_forward(parts.mlp_of(&self.actor_dev), x, Activation::Relu, false))?
        };
        let a = self.act_dim;
        let mut acts = Vec::with_capacity(n * a);
        for row in out.chunks_exact(2 * a) {
            for i in 0..a {
                let std = row[a + i]
                    .clamp(crate::policy::LOG_STD_MIN, crate::policy::LOG_STD_MAX)
                    .exp();
                acts.push((row[i] + std * self.rng.normal() as f32).tanh());
            }
        }
        Ok(acts)
    }

    /// The current policy (actor and normaliser) as host data.
    pub fn policy_data(&self) -> PolicyData {
        let mut net = self.actor_spec.clone();
        net.n_members = 1;
        let parts = self.parts();
        let mlp = || HostParams {
            shapes: parts.mlp_of(&self.actor.shapes).to_vec(),
            data: parts.mlp_of(&self.actor.data).to_vec(),
        };
        let encoder = || HostParams {
            shapes: parts.encoder_of(&self.actor.shapes).to_vec(),
            data: parts.encoder_of(&self.actor.data).to_vec(),
        };
        PolicyData {
            algorithm: Algorithm::Sac,
            observation_space: self.env.observation_space().clone(),
            action_space: self.env.action_space().clone(),
            net,
            params: mlp(),
            head: ActionHead::SquashedGaussian,
            normalizer: self.normalizer.clone(),
            config_toml: self.cfg_toml.clone(),
            encoder: self.cfg.image.map(|spec| EncoderData {
                spec,
                params: encoder(),
            }),
            settings_toml: None,
        }
    }

    /// The current policy for inference on `device`.
    pub fn policy(&self, device: &Device) -> Policy {
        Policy::new(self.policy_data(), device)
    }

    /// Write the policy file.
    pub fn save_policy(&self, path: &Path) -> Result<()> {
        self.policy_data().save(path)
    }

    /// Write a checkpoint of the whole training state (including the replay buffer).
    pub fn save_checkpoint(&self, path: &Path) -> Result<()> {
        let mut w = ArrayWriter::default();
        w.params(&self.actor);
        w.params(&self.critic);
        w.params(&self.critic_target);
        w.params(&self.log_ent_coef);
        let actor_opt = w.adam(&self.actor_opt);
        let critic_opt = w.adam(&self.critic_opt);
        let ent_opt = self.ent_opt.as_ref().map(|o| w.adam(o));
        let b = &self.buffer;
        for a in [&b.obs, &b.next_obs, &b.actions, &b.rewards, &b.dones] {
            w.array(a);
        }
        let header = Header {
            algorithm: Algorithm::Sac,
            config: self.cfg.clone(),
            common: Common::new(
                (self.env.observation_space(), self.env.action_space()),
                self.seed,
                (self.num_timesteps, self.n_updates),
                &self.episodes,
                &self.rng,
                &self.normalizer,
            ),
            actor_opt,
            critic_opt,
            ent_opt,
            buffer_len: b.len(),
            buffer_pos: b.pos,
        };
        checkpoint::write(path, &header, &w)
    }

    /// Resume from a checkpoint with `env` (whose spaces must match); training continues with
    /// the saved weights, optimisers, buffer, RNG and counters; episodes restart.
    pub fn load_checkpoint(path: &Path, env: VecEnv<E>, device: &Device) -> Result<Self> {
        let spaces = (env.observation_space(), env.action_space());
        let (h, mut r) = checkpoint::read::<Header>(path, Algorithm::Sac, spaces)?;
        let mut s = Self::new(h.config.clone(), env, device, h.common.seed)?;
        s.actor = Arc::new(r.params(&s.actor.shapes)?);
        s.critic = Arc::new(r.params(&s.critic.shapes)?);
        s.critic_target = Arc::new(r.params(&s.critic.shapes)?);
        s.log_ent_coef = r.params(&s.log_ent_coef.shapes)?;
        s.actor_opt = r.adam(&h.actor_opt, &s.actor.shapes)?;
        s.critic_opt = r.adam(&h.critic_opt, &s.critic.shapes)?;
        s.ent_opt = match (&h.ent_opt, s.ent_opt.is_some()) {
            (Some(m), true) => Some(r.adam(m, &s.log_ent_coef.shapes)?),
            (None, false) => None,
            _ => {
                return Err(RlError::BadFile {
                    path: path.to_path_buf(),
                    reason: "entropy optimiser does not match the config".into(),
                });
            }
        };
        let (n, o, a) = (h.buffer_len, s.obs_dim, s.act_dim);
        if n > s.cfg.buffer_size || h.buffer_pos >= s.cfg.buffer_size.max(1) {
            return Err(RlError::BadFile {
                path: path.to_path_buf(),
                reason: "replay buffer larger than its capacity".into(),
            });
        }
        s.buffer.obs = r.array(Some(n * o))?;
        s.buffer.next_obs = r.array(Some(n * o))?;
        s.buffer.actions = r.array(Some(n * a))?;
        s.buffer.rewards = r.array(Some(n))?;
        s.buffer.dones = r.array(Some(n))?;
        s.buffer.pos = h.buffer_pos;
        r.finish()?;
        s.episodes = h.common.episodes();
        s.rng = h.common.rng;
        s.num_timesteps = h.common.num_timesteps;
        s.n_updates = h.common.n_updates;
        s.normalizer = h.common.normalizer;
        s.upload_all();
        Ok(s)
    }

    /// Mean return of `n_episodes` deterministic episodes on `env` (seeded `seed`, `seed + 1`, ...).
    pub fn evaluate<F: Env>(&self, env: &mut F, n_episodes: usize, seed: u64) -> Result<f64> {
        crate::eval::evaluate(&mut self.policy(&self.device), env, n_episodes, seed)
    }
}

#[cfg(test)]
mod tests {
    /// SAC on as many threads as its VecEnv runs its gradient blocks on the env's pool.
    #[test]
    fn the_learner_shares_its_vec_envs_worker_pool() {
        use super::{Sac, SacConfig};
        let make = || agvrl_envs::registry::make("pendulum", &agvrl_envs::EnvConfig::default()).unwrap();
        let env = agvrl_envs::VecEnv::new(vec![make(), make()], 2).unwrap();
        let mut sac = Sac::new(SacConfig::default(), env, &crate::device::default_device(), 0).unwrap();
        sac.set_threads(2).unwrap();
        let pool = sac.workers.clone().expect("a pool on 2 threads");
        assert!(std::sync::Arc::ptr_eq(&pool, sac.env.workers()));
    }
}
