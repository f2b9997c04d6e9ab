//! Proximal Policy Optimisation (Schulman et al. 2017) as Stable-Baselines3 runs it: separate
//! tanh MLPs for actor and critic (evaluated as one 2-member stack), state-independent log
//! std (or gSDE with `use_sde`), GAE, clipped surrogate, advantage normalisation, global
//! gradient clipping.
//!
//! With `image`, one NatureCNN ([`crate::cnn`]) shared by actor and critic turns the image
//! part of the observation into features that join the vector part at the trunks' input (SB3's
//! `CnnPolicy` / `MultiInputPolicy`); its weights follow the head tensors in the parameter list.
//!
//! Data flow per iteration: `n_steps` vector steps with the current policy on plain tensors
//! (a truncated episode adds `gamma * V(final_obs)` to its last reward, as SB3) -> GAE ->
//! `update.rs`: `n_epochs` passes of shuffled minibatches.

mod distribution;
mod host;
mod network;
#[cfg(test)]
mod sb3_numerics;
mod update;

pub use crate::config::PpoConfig;
#[doc(hidden)]
#[cfg(any(test, feature = "parity"))]
pub use update::GradientProbe;

use crate::adam::Adam;
use crate::checkpoint::{self, AdamMeta, ArrayWriter, Common};
use crate::device::NetPath;
use crate::error::{Result, RlError};
use crate::nets::{HostParams, Init, MlpSpec, init_layer, to_vec};
use crate::normalize::ObsNormalizer;
use crate::policy::{ActionHead, Algorithm, EncoderData, Policy, PolicyData};
use crate::progress::{Control, Episodes, Losses, Progress};
use crate::rng::Rng;
use agvrl_envs::{BoxSpace, Env, VecEnv};
use burn::tensor::Device;
use burn::tensor::{Tensor, TensorData};
use distribution::ActionDist;
use network::Layout;
use network::forward;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// A PPO learner bound to a vector env.
pub struct Ppo<E: Env> {
    cfg: PpoConfig,
    /// `cfg` as TOML, for policy files (serialised once, where a failure can be reported).
    cfg_toml: String,
    env: VecEnv<E>,
    device: Device,
    /// Where the networks run (the host kernels, or Burn on `device`).
    net_path: NetPath,
    obs_dim: usize,
    /// Values of `Info::critic_obs` per env (0: none): the critic's inputs beside the
    /// observation, which the actor never reads.
    critic_dim: usize,
    act_dim: usize,
    params: HostParams,
    opt: Adam,
    normalizer: Option<ObsNormalizer>,
    rng: Rng,
    seed: u64,
    num_timesteps: u64,
    n_updates: u64,
    episodes: Episodes,
    losses: Losses,
    /// Current raw observations, whether each env just started an episode, and the envs'
    /// critic observations.
    last: Option<(Vec<f32>, Vec<bool>, Vec<f32>)>,
    /// Minibatches in shuffled order (off only to replay an update in another implementation).
    shuffle: bool,
    /// Threads an image minibatch is split over (see [`Ppo::set_threads`]).
    threads: usize,
    /// Their helpers, beside the calling thread (more than one thread only).
    workers: Option<std::sync::Arc<agvrl_envs::Workers>>,
    /// The run's length for `learning_rate_final` (see [`Ppo::set_schedule_steps`]).
    schedule_steps: Option<u64>,
    /// With `correction_limit`, each env's multiplier: the charge per corrected step.
    lambdas: Vec<f64>,
}

#[derive(Serialize, Deserialize)]
struct Header {
    algorithm: Algorithm,
    config: PpoConfig,
    #[serde(flatten)]
    common: Common,
    opt: AdamMeta,
    /// The envs' correction multipliers (`correction_limit`; absent in older checkpoints).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    correction_lambdas: Vec<f64>,
    /// Critic observation values per row (absent: 0).
    #[serde(default, skip_serializing_if = "is_zero")]
    critic_obs_dim: usize,
}

fn is_zero(n: &usize) -> bool {
    *n == 0
}

/// Charge each env's reward its multiplier on a step where the env corrected the policy
/// (`corrected[e]` is 1), as RCPO's penalised reward `r - lambda c`.
fn charge_corrections(rewards: &mut [f32], corrected: &[f32], lambdas: &[f64]) {
    for ((r, c), l) in rewards.iter_mut().zip(corrected).zip(lambdas) {
        *r -= (*c as f64 * *l) as f32;
    }
}

/// RCPO's multiplier step after a rollout of `n_steps` per env: `lambda_e += lr *
/// (corrected_e / n_steps - limit)`, floored at 0.
fn step_multipliers(lambdas: &mut [f64], corrected: &[usize], n_steps: usize, limit: f64, lr: f64) {
    for (l, c) in lambdas.iter_mut().zip(corrected) {
        *l = (*l + lr * (*c as f64 / n_steps.max(1) as f64 - limit)).max(0.0);
    }
}

impl checkpoint::Header for Header {
    fn common(&self) -> &Common {
        &self.common
    }
}

/// One rollout, flat with index `step * n_envs + env`.
pub(crate) struct Rollout {
    pub(crate) obs: Vec<f32>,
    pub(crate) actions: Vec<f32>,
    pub(crate) log_probs: Vec<f32>,
    pub(crate) advantages: Vec<f32>,
    pub(crate) returns: Vec<f32>,
    /// Per step, the action the env sent instead of the policy's (`Info::corrected_action`;
    /// zeros where it sent the policy's), `a` values each, and 1 where it corrected, else 0.
    pub(crate) corrected_actions: Vec<f32>,
    pub(crate) corrected: Vec<f32>,
    /// GAE's inputs (rewards with truncation bootstraps, values, episode starts; the values and
    /// done flags after the last step), kept for checking GAE against another implementation.
    pub(crate) gae_inputs: [Vec<f32>; 5],
}

impl Rollout {
    /// Advantages and returns by GAE (SB3's `RolloutBuffer.compute_returns_and_advantage`) from
    /// `[rewards, values, episode_starts, last_values, dones]`: per step (index `step * n_envs +
    /// env`) the rewards (truncation bootstraps included), the values and whether the step began
    /// an episode; per env the values and done flags after the last step. Kept in `gae_inputs`.
    pub(crate) fn compute_gae(&mut self, inputs: [Vec<f32>; 5], g: f32, lam: f32) {
        let [rewards, values, episode_starts, last_values, dones] = &inputs;
        let n_envs = last_values.len();
        let n_steps = rewards.len() / n_envs.max(1);
        let mut last_gae = vec![0.0f32; n_envs];
        for t in (0..n_steps).rev() {
            for e in 0..n_envs {
                let k = t * n_envs + e;
                let (next_non_terminal, next_value) = if t + 1 == n_steps {
                    (1.0 - dones[e], last_values[e])
                } else {
                    (1.0 - episode_starts[k + n_envs], values[k + n_envs])
                };
                let delta = rewards[k] + g * next_value * next_non_terminal - values[k];
                last_gae[e] = delta + g * lam * next_non_terminal * last_gae[e];
                self.advantages[k] = last_gae[e];
                self.returns[k] = last_gae[e] + values[k];
            }
        }
        self.gae_inputs = inputs;
    }
}

impl<E: Env> Ppo<E> {
    /// A fresh learner on plain `device`; `seed` seeds weights, noise, shuffling and the envs.
    pub fn new(cfg: PpoConfig, env: VecEnv<E>, device: &Device, seed: u64) -> Result<Self> {
        cfg.validate()?;
        let obs_dim = env.observation_space().dim();
        let act_dim = env.action_space().dim();
        let (vec_dim, mlp_in) = match &cfg.image {
            Some(spec) => {
                let v = spec.vector_dim(obs_dim)?;
                (v, v + spec.features_dim)
            }
            None => (obs_dim, obs_dim),
        };
        let n_envs = env.n_envs();
        let critic_dim = env.critic_obs_dim();
        if critic_dim > 0 && (cfg.image.is_some() || cfg.net_arch.is_empty()) {
            return Err(RlError::Config(
                "critic observations (race.critic_sees_opponents) need an MLP with hidden layers and no image".into(),
            ));
        }
        let mut rng = Rng::new(seed);
        // The critic's own inputs follow the observation's; the actor's weights from them stay 0.
        let mut sizes = vec![mlp_in + critic_dim];
        sizes.extend(&cfg.net_arch);
        let trunk = MlpSpec {
            n_members: 2,
            sizes,
            activation: cfg.activation_fn,
            activate_last: true,
        };
        let (hidden, pi_init, vf_init) = if cfg.ortho_init {
            (
                Init::Orthogonal(2f64.sqrt()),
                Init::Orthogonal(0.01),
                Init::Orthogonal(1.0),
            )
        } else {
            (Init::TorchDefault, Init::TorchDefault, Init::TorchDefault)
        };
        let mut params = trunk.init(&[hidden], &mut rng);
        params.data[0][mlp_in * trunk.sizes[1]..(mlp_in + critic_dim) * trunk.sizes[1]].fill(0.0);
        let last = *cfg.net_arch.last().unwrap_or(&obs_dim);
        let (w, b) = init_layer(pi_init, 1, last, act_dim, &mut rng);
        params.push([1, last, act_dim], w);
        params.push([1, 1, act_dim], b);
        let (w, b) = init_layer(vf_init, 1, last, 1, &mut rng);
        params.push([1, last, 1], w);
        params.push([1, 1, 1], b);
        let rows = if cfg.use_sde { last } else { 1 };
        params.push([1, rows, act_dim], vec![cfg.log_std_init as f32; rows * act_dim]);
        debug_assert_eq!(params.shapes.len(), Layout::of(&cfg).log_std + 1);
        if let Some(spec) = &cfg.image {
            // Drawn last, so MLP-only runs draw exactly what they always did.
            let enc = spec.init(hidden, &mut rng)?;
            for (s, d) in enc.shapes.into_iter().zip(enc.data) {
                params.push(s, d);
            }
        }
        Ok(Self {
            cfg_toml: cfg.to_toml()?,
            opt: Adam::new(&params, cfg.learning_rate, 1e-5),
            normalizer: cfg.normalize_obs.then(|| ObsNormalizer::new(vec_dim)),
            device: device.clone().without_autodiff(),
            net_path: NetPath::for_device(device),
            cfg,
            env,
            obs_dim,
            critic_dim,
            act_dim,
            params,
            rng,
            seed,
            num_timesteps: 0,
            n_updates: 0,
            episodes: Episodes::default(),
            losses: Losses::default(),
            last: None,
            shuffle: true,
            threads: 1,
            workers: None,
            schedule_steps: None,
            lambdas: vec![0.0; n_envs],
        })
    }

    /// Start fresh episodes at the next step (envs reset with a seed from the run seed and the
    /// step count), as a learner resumed from a checkpoint does: the envs' mid-episode state is
    /// not in a checkpoint, so a run that restarts its episodes where it checkpoints resumes
    /// bit for bit as if it had never stopped.
    pub fn restart_episodes(&mut self) {
        self.last = None;
    }

    /// Visit minibatches in rollout order instead of shuffled (to replay an update step for
    /// step in another implementation; see `tools/parity/`).
    #[cfg(any(test, feature = "parity"))]
    pub fn set_minibatch_shuffle(&mut self, on: bool) {
        self.shuffle = on;
    }

    /// Run the networks on `path` from the next step on: the host kernels (the CPU fast path,
    /// the default on CPU devices) or Burn's tensors on the learner's device (the default on
    /// any other). Both compute the same functions; they differ in f32 rounding.
    pub fn set_net_path(&mut self, path: NetPath) {
        self.net_path = path;
    }

    /// Where the networks run.
    pub fn net_path(&self) -> NetPath {
        self.net_path
    }

    /// The image encoder at the current weights, laid out for the host products.
    pub(crate) fn encoder(&self) -> Option<crate::host_cnn::HostEncoder> {
        let l = Layout::of(&self.cfg);
        (self.cfg.image.as_ref()).map(|spec| crate::host_cnn::HostEncoder::new(spec, l.encoder_of(&self.params.data)))
    }

    /// Split each minibatch of an image config over `threads` threads (default 1). A run is
    /// the same bit for bit for a given count; configs without an image ignore it (their
    /// minibatches are too small to gain).
    pub fn set_threads(&mut self, threads: usize) -> Result<()> {
        self.threads = threads.max(1);
        self.workers = None;
        if self.threads > 1 {
            self.workers = Some(crate::shared_workers(&self.env, self.threads, "PPO")?);
        }
        Ok(())
    }

    /// The run's length in env steps, over which `learning_rate_final` anneals the learning
    /// rate (needed when it is set; a resumed run passes its length again).
    pub fn set_schedule_steps(&mut self, steps: u64) {
        self.schedule_steps = Some(steps);
    }

    /// With `learning_rate_final`, the learning rate of the update after `num_timesteps` steps:
    /// linear from `learning_rate` at step 0 to `learning_rate_final` at the run's last step
    /// and after.
    fn scheduled_learning_rate(&self) -> Result<Option<f64>> {
        let Some(last) = self.cfg.learning_rate_final else {
            return Ok(None);
        };
        let steps = self.schedule_steps.ok_or_else(|| {
            RlError::Config("PPO: learning_rate_final needs the run's length (Ppo::set_schedule_steps)".into())
        })?;
        let done = (self.num_timesteps as f64 / steps.max(1) as f64).min(1.0);
        Ok(Some(self.cfg.learning_rate + done * (last - self.cfg.learning_rate)))
    }

    /// The configuration.
    pub fn config(&self) -> &PpoConfig {
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

    fn normalized(&self, obs: &[f32]) -> Vec<f32> {
        let mut x = obs.to_vec();
        if let Some(n) = &self.normalizer {
            n.normalize_rows(&mut x, self.obs_dim);
        }
        x
    }

    /// Width of a network input row: the observation, then the critic observation.
    pub(crate) fn row_dim(&self) -> usize {
        self.obs_dim + self.critic_dim
    }

    /// Normalised observation rows with each env's critic observation (from `critic`, the
    /// rows' critic values in order) after them.
    fn input_rows(&self, obs: &[f32], critic: &[f32]) -> Vec<f32> {
        let x = self.normalized(obs);
        if self.critic_dim == 0 {
            return x;
        }
        let (o, c) = (self.obs_dim, self.critic_dim);
        x.chunks_exact(o)
            .zip(critic.chunks_exact(c))
            .flat_map(|(x, c)| x.iter().chain(c).copied())
            .collect()
    }

    /// The critic observations of `infos` (the final ones where an env auto-reset, if
    /// `final_obs`), in env order; empty without critic observations.
    fn critic_rows<'a>(&self, infos: impl Iterator<Item = &'a agvrl_envs::Info>, final_obs: bool) -> Result<Vec<f32>> {
        let mut out = Vec::new();
        if self.critic_dim == 0 {
            return Ok(out);
        }
        for info in infos {
            let c = match (final_obs, &info.final_critic_obs) {
                (true, Some(c)) => Some(c),
                _ => info.critic_obs.as_ref(),
            };
            match c.filter(|c| c.len() == self.critic_dim) {
                Some(c) => out.extend_from_slice(c),
                None => {
                    return Err(RlError::Config(format!(
                        "an env gave no critic observation of {} values",
                        self.critic_dim
                    )));
                }
            }
        }
        Ok(out)
    }

    /// Zero the actor's gradients from the critic observation, so the actor never reads it.
    fn mask_critic_inputs(&self, grads: &mut [Vec<f32>]) {
        if self.critic_dim > 0 {
            let cols = self.params.shapes[0][2];
            let from = self.params.shapes[0][1] - self.critic_dim;
            grads[0][from * cols..(from + self.critic_dim) * cols].fill(0.0);
        }
    }

    /// Run rollouts and updates until `steps` more env steps are taken (whole rollouts);
    /// `callback` sees progress after every rollout + update and can stop early.
    pub fn learn(&mut self, steps: u64, callback: &mut dyn FnMut(&Progress<'_>) -> Control) -> Result<()> {
        let target = self.num_timesteps + steps;
        // A schedule without the run's length fails here, before any env step.
        self.scheduled_learning_rate()?;
        while self.num_timesteps < target {
            let rollout = self.collect_rollout()?;
            // As SB3: the rate at the progress after the rollout just collected.
            if let Some(lr) = self.scheduled_learning_rate()? {
                self.opt.lr = lr;
            }
            self.update(&rollout)?;
            let progress = Progress {
                algorithm: Algorithm::Ppo,
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

    fn collect_rollout(&mut self) -> Result<Rollout> {
        let (n_envs, o, a, n_steps) = (self.env.n_envs(), self.obs_dim, self.act_dim, self.cfg.n_steps);
        let total = n_steps * n_envs;
        let log_std = &self.params.data[Layout::of(&self.cfg).log_std];
        let latent_dim = *self.cfg.net_arch.last().unwrap_or(&o);
        let dist = ActionDist::new(log_std, a, self.cfg.use_sde.then_some(latent_dim));
        let mut expl = vec![0.0f32; n_envs * latent_dim * a];
        let mut var = vec![0.0f64; a];
        let (mut obs, mut starts, mut critic) = match self.last.take() {
            Some(l) => l,
            None => {
                let seed = self.seed.wrapping_add(self.num_timesteps.wrapping_mul(0x9E37_79B9));
                let (o0, infos) = self.env.reset(Some(seed))?;
                let c0 = self.critic_rows(infos.iter(), false)?;
                // After a resume (or `restart_episodes`) the normaliser has already counted the
                // observations the run stood on, which these replace: counting them too would
                // leave it a batch ahead of the run that never stopped.
                if let Some(n) = self.normalizer.as_mut().filter(|_| self.num_timesteps == 0) {
                    n.update_rows(&o0, o);
                }
                (o0, vec![true; n_envs], c0)
            }
        };
        let mut r = Rollout {
            obs: Vec::with_capacity(total * o),
            actions: Vec::with_capacity(total * a),
            log_probs: Vec::with_capacity(total),
            advantages: vec![0.0; total],
            returns: vec![0.0; total],
            corrected_actions: Vec::with_capacity(total * a),
            corrected: Vec::with_capacity(total),
            gae_inputs: Default::default(),
        };
        let mut rewards = Vec::with_capacity(total);
        let mut corrected_per_env = vec![0usize; n_envs];
        let mut values = Vec::with_capacity(total);
        let mut episode_starts = Vec::with_capacity(total);
        let space = self.env.action_space().clone();
        let sde = self.cfg.use_sde;
        let (host_params, layout) = (&self.params, Layout::of(&self.cfg));
        let burn = self.net_path == NetPath::Burn;
        let encoder = if burn { None } else { self.encoder() };
        // The weights stay the same over a rollout: on the Burn path they go up once.
        let dev_params = if burn {
            self.params.to_device(&self.device)
        } else {
            vec![]
        };
        let device = &self.device;
        let value_of = |x: Vec<f32>, n: usize, cfg: &PpoConfig| -> Result<(Vec<f32>, Vec<f32>, Vec<f32>)> {
            if burn {
                let w = x.len() / n.max(1);
                let x = Tensor::<3>::from_data(TensorData::new(x, [1, n, w]), device);
                let (mean, value, latent) = forward(&dev_params, x, cfg);
                let latent = if sde { to_vec(latent)? } else { vec![] };
                return Ok((to_vec(mean)?, to_vec(value)?, latent));
            }
            let f = host::forward(host_params, &layout, cfg.activation_fn, encoder.as_ref(), &x, n);
            let latent = if sde { f.latent(&x).to_vec() } else { vec![] };
            Ok((f.mean, f.value, latent))
        };
        for step in 0..n_steps {
            let freq = self.cfg.sde_sample_freq;
            if sde && (step == 0 || (freq > 0 && step as i64 % freq == 0)) {
                dist.draw_exploration(&mut self.rng, &mut expl);
            }
            let x = self.input_rows(&obs, &critic);
            let (mean, value, latent) = value_of(x.clone(), n_envs, &self.cfg)?;
            let mut actions = Vec::with_capacity(n_envs * a);
            let mut clipped = Vec::with_capacity(n_envs * a);
            for e in 0..n_envs {
                let sde = sde.then(|| {
                    (
                        &latent[e * latent_dim..(e + 1) * latent_dim],
                        &expl[e * latent_dim * a..(e + 1) * latent_dim * a],
                    )
                });
                let lp = dist.sample(&mean[e * a..(e + 1) * a], sde, &mut self.rng, &mut var, &mut actions);
                let act = &actions[e * a..];
                clipped.extend((0..a).map(|j| act[j].clamp(space.low[j], space.high[j])));
                r.log_probs.push(lp);
            }
            let st = self.env.step(&clipped)?;
            let mut rew: Vec<f32> = st.rewards.iter().map(|v| *v as f32).collect();
            // Truncated episodes bootstrap: r += gamma V(final_obs).
            let trunc: Vec<usize> = (0..n_envs).filter(|&e| st.truncated[e] && !st.terminated[e]).collect();
            if !trunc.is_empty() {
                let mut fx = Vec::with_capacity(trunc.len() * o);
                for &e in &trunc {
                    let f = st.infos[e].final_obs.as_deref().unwrap_or(&st.obs[e * o..(e + 1) * o]);
                    fx.extend_from_slice(f);
                }
                let fc = self.critic_rows(trunc.iter().map(|&e| &st.infos[e]), true)?;
                let fx = self.input_rows(&fx, &fc);
                let (_, fv, _) = value_of(fx, trunc.len(), &self.cfg)?;
                for (k, &e) in trunc.iter().enumerate() {
                    rew[e] += (self.cfg.gamma as f32) * fv[k];
                }
            }
            r.obs.extend_from_slice(&x);
            r.actions.extend_from_slice(&actions);
            for (e, info) in st.infos.iter().enumerate() {
                match info.corrected_action.as_deref().filter(|c| c.len() == a) {
                    Some(c) => {
                        r.corrected_actions.extend_from_slice(c);
                        r.corrected.push(1.0);
                        corrected_per_env[e] += 1;
                    }
                    None => {
                        r.corrected_actions.extend(std::iter::repeat_n(0.0, a));
                        r.corrected.push(0.0);
                    }
                }
            }
            if self.cfg.correction_limit.is_some() {
                charge_corrections(&mut rew, &r.corrected[r.corrected.len() - n_envs..], &self.lambdas);
            }
            rewards.extend_from_slice(&rew);
            values.extend_from_slice(&value);
            episode_starts.extend(starts.iter().map(|s| *s as u8 as f32));
            if let Some(n) = &mut self.normalizer {
                n.update_rows(&st.obs, o);
            }
            self.episodes.record(&st.infos);
            self.num_timesteps += n_envs as u64;
            starts = (0..n_envs).map(|e| st.terminated[e] || st.truncated[e]).collect();
            critic = self.critic_rows(st.infos.iter(), false)?;
            obs = st.obs;
        }
        let (_, last_values, _) = value_of(self.input_rows(&obs, &critic), n_envs, &self.cfg)?;
        let dones = starts.iter().map(|s| *s as u8 as f32).collect();
        r.compute_gae(
            [rewards, values, episode_starts, last_values, dones],
            self.cfg.gamma as f32,
            self.cfg.gae_lambda as f32,
        );
        self.last = Some((obs, starts, critic));
        if let Some(limit) = self.cfg.correction_limit {
            step_multipliers(
                &mut self.lambdas,
                &corrected_per_env,
                n_steps,
                limit,
                self.cfg.correction_lambda_lr,
            );
            self.losses.correction_lambda = self.lambdas.iter().sum::<f64>() / n_envs.max(1) as f64;
        }
        Ok(r)
    }

    /// The current policy (actor member, log std, normaliser) as host data.
    pub fn policy_data(&self) -> PolicyData {
        let l = Layout::of(&self.cfg);
        let mut params = HostParams {
            shapes: vec![],
            data: vec![],
        };
        // Member 0 of each trunk tensor is the actor's; it never reads the critic observation.
        for (k, (s, d)) in l
            .trunk_of(&self.params.shapes)
            .iter()
            .zip(l.trunk_of(&self.params.data))
            .enumerate()
        {
            let rows = if k == 0 { s[1] - self.critic_dim } else { s[1] };
            params.push([1, rows, s[2]], d[..rows * s[2]].to_vec());
        }
        for i in [l.pi_w, l.pi_b] {
            params.push(self.params.shapes[i], self.params.data[i].clone());
        }
        let encoder = self.cfg.image.map(|spec| EncoderData {
            spec,
            params: HostParams {
                shapes: l.encoder_of(&self.params.shapes).to_vec(),
                data: l.encoder_of(&self.params.data).to_vec(),
            },
        });
        let mut sizes = vec![self.params.shapes[0][1] - self.critic_dim];
        sizes.extend(&self.cfg.net_arch);
        sizes.push(self.act_dim);
        PolicyData {
            algorithm: Algorithm::Ppo,
            observation_space: self.env.observation_space().clone(),
            action_space: self.env.action_space().clone(),
            net: MlpSpec {
                n_members: 1,
                sizes,
                activation: self.cfg.activation_fn,
                activate_last: false,
            },
            params,
            head: if self.cfg.use_sde {
                ActionHead::StateDependent {
                    log_std: self.params.data[l.log_std].clone(),
                }
            } else {
                ActionHead::Gaussian {
                    log_std: self.params.data[l.log_std].clone(),
                }
            },
            normalizer: self.normalizer.clone(),
            config_toml: self.cfg_toml.clone(),
            encoder,
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

    /// Write a checkpoint (weights, optimiser, normaliser, RNG, counters).
    pub fn save_checkpoint(&self, path: &Path) -> Result<()> {
        let mut w = ArrayWriter::default();
        w.params(&self.params);
        let opt = w.adam(&self.opt);
        let header = Header {
            algorithm: Algorithm::Ppo,
            config: self.cfg.clone(),
            common: Common::new(
                (self.env.observation_space(), self.env.action_space()),
                self.seed,
                (self.num_timesteps, self.n_updates),
                &self.episodes,
                &self.rng,
                &self.normalizer,
            ),
            opt,
            correction_lambdas: if self.cfg.correction_limit.is_some() {
                self.lambdas.clone()
            } else {
                vec![]
            },
            critic_obs_dim: self.critic_dim,
        };
        checkpoint::write(path, &header, &w)
    }

    /// Resume from a checkpoint with `env` (whose spaces must match); episodes restart.
    pub fn load_checkpoint(path: &Path, env: VecEnv<E>, device: &Device) -> Result<Self> {
        let spaces = (env.observation_space(), env.action_space());
        let (h, mut r) = checkpoint::read::<Header>(path, Algorithm::Ppo, spaces)?;
        let mut s = Self::new(h.config.clone(), env, device, h.common.seed)?;
        let shapes = s.params.shapes.clone();
        s.params = r.params(&shapes)?;
        s.opt = r.adam(&h.opt, &shapes)?;
        r.finish()?;
        s.episodes = h.common.episodes();
        s.rng = h.common.rng;
        s.num_timesteps = h.common.num_timesteps;
        s.n_updates = h.common.n_updates;
        s.normalizer = h.common.normalizer;
        if h.correction_lambdas.len() == s.lambdas.len() {
            s.lambdas = h.correction_lambdas;
        }
        Ok(s)
    }

    /// Start from the weights (and correction multipliers) of another run's checkpoint, whose
    /// observation lacked the inputs at `added` (indices into this env's observation). Those
    /// inputs get zero weights, so the policy starts out acting and valuing exactly as the
    /// checkpoint's; so do critic observation values the checkpoint's critic did not read. The
    /// optimiser, counters and schedule start afresh. A warm start may switch gSDE on or off:
    /// the mean action is the checkpoint's, its exploration starts afresh at `log_std_init`.
    pub fn warm_start(&mut self, path: &Path, added: &[usize]) -> Result<()> {
        let new_space = self.env.observation_space().clone();
        let keep: Vec<usize> = (0..new_space.dim()).filter(|i| !added.contains(i)).collect();
        let old_space = BoxSpace {
            low: keep.iter().map(|&i| new_space.low[i]).collect(),
            high: keep.iter().map(|&i| new_space.high[i]).collect(),
        };
        let spaces = (&old_space, self.env.action_space());
        let (h, mut r) = checkpoint::read::<Header>(path, Algorithm::Ppo, spaces)?;
        let plain = |c: &PpoConfig| c.image.is_none() && !c.normalize_obs;
        let same = h.config.net_arch == self.cfg.net_arch && h.config.activation_fn == self.cfg.activation_fn;
        if !same || !plain(&h.config) || !plain(&self.cfg) {
            return Err(RlError::Mismatch {
                what: "network (a warm start needs the same layers and activation, and no image or observation normaliser)",
                file: format!("{:?} {:?}", h.config.net_arch, h.config.activation_fn),
                env: format!("{:?} {:?}", self.cfg.net_arch, self.cfg.activation_fn),
            });
        }
        let mut shapes = self.params.shapes.clone();
        let old_rows = keep.len() + h.critic_obs_dim;
        shapes[0][1] = old_rows;
        let log_std = Layout::of(&self.cfg).log_std;
        let sde_changed = h.config.use_sde != self.cfg.use_sde;
        if sde_changed {
            let Some(&latent) = self.cfg.net_arch.last() else {
                return Err(RlError::Mismatch {
                    what: "gSDE (a warm start switches it only with hidden layers)",
                    file: format!("use_sde = {}", h.config.use_sde),
                    env: format!("use_sde = {}", self.cfg.use_sde),
                });
            };
            // gSDE's log std has a row per latent feature, the plain one a single row.
            shapes[log_std][1] = if h.config.use_sde { latent } else { 1 };
        }
        let mut old = r.params(&shapes)?;
        if sde_changed {
            // Switching gSDE starts exploration afresh at log_std_init; the mean is the run's.
            old.shapes[log_std] = self.params.shapes[log_std];
            old.data[log_std] = self.params.data[log_std].clone();
        }
        let [members, rows, cols] = self.params.shapes[0];
        // Where each old input row goes: the observation's kept inputs, then the critic's.
        let to: Vec<Option<usize>> = keep
            .iter()
            .map(|&i| Some(i))
            .chain((0..h.critic_obs_dim).map(|c| (c < self.critic_dim).then_some(new_space.dim() + c)))
            .collect();
        let mut first = vec![0.0f32; members * rows * cols];
        for m in 0..members {
            for (k, i) in to.iter().enumerate() {
                if let Some(i) = i {
                    let src = &old.data[0][(m * old_rows + k) * cols..][..cols];
                    first[(m * rows + i) * cols..][..cols].copy_from_slice(src);
                }
            }
        }
        old.shapes[0] = self.params.shapes[0];
        old.data[0] = first;
        self.params = old;
        if h.correction_lambdas.len() == self.lambdas.len() {
            self.lambdas = h.correction_lambdas;
        }
        Ok(())
    }

    /// Mean return of `n_episodes` deterministic episodes on `env` (seeded `seed`, `seed + 1`, ...).
    pub fn evaluate<F: Env>(&self, env: &mut F, n_episodes: usize, seed: u64) -> Result<f64> {
        crate::eval::evaluate(&mut self.policy(&self.device), env, n_episodes, seed)
    }
}

#[cfg(test)]
mod tests {
    use super::Rollout;

    /// A learner on as many threads as its VecEnv runs its minibatches on the env's pool (one
    /// set of helpers for both); on another count, on a pool of its own with that many.
    #[test]
    fn the_learner_shares_its_vec_envs_worker_pool() {
        use super::{Ppo, PpoConfig};
        let make = || agvrl_envs::registry::make("pendulum", &agvrl_envs::EnvConfig::default()).unwrap();
        let env = agvrl_envs::VecEnv::new(vec![make(), make()], 2).unwrap();
        let device = crate::device::default_device();
        let mut ppo = Ppo::new(PpoConfig::default(), env, &device, 0).unwrap();
        ppo.set_threads(2).unwrap();
        let pool = ppo.workers.clone().expect("a pool on 2 threads");
        assert!(std::sync::Arc::ptr_eq(&pool, ppo.env.workers()));
        ppo.set_threads(3).unwrap();
        let own = ppo.workers.clone().expect("a pool on 3 threads");
        assert!(!std::sync::Arc::ptr_eq(&own, ppo.env.workers()));
        assert_eq!(own.len(), 2);
    }

    #[test]
    fn gae_by_hand_stops_at_episode_ends_and_bootstraps_the_last_value() {
        // Two envs, three steps, gamma = lambda = 0.5. Env 0: its third step starts a new
        // episode; after the last step it runs on (V = 2). Env 1: done after the last step
        // (its V = 5 must not count).
        let mut r = Rollout {
            obs: vec![],
            actions: vec![],
            log_probs: vec![],
            advantages: vec![0.0; 6],
            returns: vec![0.0; 6],
            corrected_actions: vec![],
            corrected: vec![],
            gae_inputs: Default::default(),
        };
        let rewards = vec![1.0, 0.0, 2.0, 0.0, 3.0, 1.0];
        let values = vec![0.5, 0.0, 1.0, 0.0, 1.5, 0.0];
        let starts = vec![1.0, 1.0, 0.0, 0.0, 1.0, 0.0];
        r.compute_gae([rewards, values, starts, vec![2.0, 5.0], vec![0.0, 1.0]], 0.5, 0.5);
        // Env 0, backwards: 3 + 0.5 * 2 - 1.5 = 2.5; 2 - 1 = 1 (the episode ends); 1 + 0.5 * 1 -
        // 0.5 + 0.25 * 1 = 1.25. Env 1: 1; 0 + 0.25 * 1; 0.25 * 0.25.
        assert_eq!(r.advantages, vec![1.25, 0.0625, 1.0, 0.25, 2.5, 1.0]);
        assert_eq!(r.returns, vec![1.75, 0.0625, 2.0, 0.25, 4.0, 1.0]);
        assert_eq!(r.gae_inputs[3], vec![2.0, 5.0]);
    }

    /// RCPO's multiplier step, by hand: the excess corrected fraction times the rate, floored
    /// at 0.
    #[test]
    fn multipliers_step_by_the_excess_corrected_fraction_and_stay_non_negative() {
        let mut l = vec![0.0, 0.5, 0.01];
        // 8 steps: fractions 0.5, 0, 0; limit 0.25, rate 2.
        super::step_multipliers(&mut l, &[4, 0, 0], 8, 0.25, 2.0);
        assert_eq!(l, vec![0.5, 0.0, 0.0]);
        let mut r = vec![1.0f32, 1.0, 1.0];
        super::charge_corrections(&mut r, &[1.0, 0.0, 1.0], &[0.5, 3.0, 0.0]);
        assert_eq!(r, vec![0.5, 1.0, 1.0]);
    }

    /// Corrects every action of the wrapped env (the action sent stays the policy's).
    struct AlwaysCorrected(Box<dyn agvrl_envs::Env>);

    impl agvrl_envs::Env for AlwaysCorrected {
        fn observation_space(&self) -> agvrl_envs::BoxSpace {
            self.0.observation_space()
        }
        fn action_space(&self) -> agvrl_envs::BoxSpace {
            self.0.action_space()
        }
        fn reset(&mut self, seed: Option<u64>) -> Result<(Vec<f32>, agvrl_envs::Info), agvrl_envs::EnvError> {
            self.0.reset(seed)
        }
        fn step(&mut self, action: &[f32]) -> Result<agvrl_envs::Step, agvrl_envs::EnvError> {
            let mut st = self.0.step(action)?;
            st.info.corrected_action = Some(action.to_vec());
            Ok(st)
        }
        fn dt_s(&self) -> f64 {
            self.0.dt_s()
        }
    }

    /// With `correction_limit`, a rollout charges each env's reward its multiplier on every
    /// corrected step and nothing else (the same seed without the limit gives the uncharged
    /// rewards), then steps the multipliers by the envs' corrected fractions; a checkpoint
    /// keeps them.
    #[test]
    fn correction_limit_charges_corrected_steps_and_steps_each_envs_multiplier() {
        use super::{Ppo, PpoConfig};
        let envs = || {
            let make = || agvrl_envs::registry::make("pendulum", &agvrl_envs::EnvConfig::default()).unwrap();
            let v: Vec<Box<dyn agvrl_envs::Env>> = vec![Box::new(AlwaysCorrected(make())), make()];
            agvrl_envs::VecEnv::new(v, 1).unwrap()
        };
        let cfg = PpoConfig {
            n_steps: 8,
            batch_size: 16,
            n_epochs: 1,
            ..Default::default()
        };
        let limited = PpoConfig {
            correction_limit: Some(0.25),
            correction_lambda_lr: 0.5,
            ..cfg.clone()
        };
        let device = crate::device::default_device();
        let mut plain = Ppo::new(cfg, envs(), &device, 7).unwrap();
        let mut rcpo = Ppo::new(limited, envs(), &device, 7).unwrap();
        rcpo.lambdas = vec![2.0, 0.1];
        let (a, b) = (plain.collect_rollout().unwrap(), rcpo.collect_rollout().unwrap());
        assert_eq!(a.actions, b.actions);
        for (k, (ra, rb)) in a.gae_inputs[0].iter().zip(&b.gae_inputs[0]).enumerate() {
            let want = if k % 2 == 0 { ra - 2.0 } else { *ra };
            assert!((rb - want).abs() < 1e-5, "step {k}: {rb} against {want}");
        }
        // Env 0: 2 + 0.5 * (1 - 0.25); env 1: 0.1 + 0.5 * (0 - 0.25) floors at 0.
        assert_eq!(rcpo.lambdas, vec![2.375, 0.0]);
        assert_eq!(rcpo.losses.correction_lambda, 2.375 / 2.0);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("ppo.ckpt");
        rcpo.save_checkpoint(&path).unwrap();
        let back = Ppo::load_checkpoint(&path, envs(), &device).unwrap();
        assert_eq!(back.lambdas, vec![2.375, 0.0]);
    }

    /// `learning_rate_final` anneals the rate linearly over the run's length: each update uses
    /// the rate at the steps taken after its rollout (SB3's progress), and past the length the
    /// final rate; without the length it is an error, not a silently constant rate.
    #[test]
    fn learning_rate_final_anneals_linearly_over_the_schedule_steps() {
        use super::{Control, Ppo, PpoConfig};
        let cfg = PpoConfig {
            n_steps: 16,
            batch_size: 16,
            n_epochs: 1,
            learning_rate: 1e-3,
            learning_rate_final: Some(2e-4),
            ..Default::default()
        };
        let device = crate::device::default_device();
        let envs = || crate::learning::pendulum_envs(2).unwrap();
        let mut unset = Ppo::new(cfg.clone(), envs(), &device, 1).unwrap();
        assert!(unset.learn(32, &mut |_| Control::Continue).is_err());

        let mut ppo = Ppo::new(cfg, envs(), &device, 1).unwrap();
        ppo.set_schedule_steps(128);
        // 32 steps a rollout (2 envs x 16): the updates see 32, 64, ..., 192 steps taken.
        for k in 1..=6u64 {
            ppo.learn(32, &mut |_| Control::Continue).unwrap();
            let done = ((32 * k) as f64 / 128.0).min(1.0);
            let want = 1e-3 + done * (2e-4 - 1e-3);
            assert!(
                (ppo.opt.lr - want).abs() < 1e-15,
                "update {k}: {} against {want}",
                ppo.opt.lr
            );
        }
    }
}

#[cfg(test)]
mod critic_obs_tests {
    use super::*;
    use crate::Control;
    use agvrl_envs::{EnvError, Info, Step};

    /// Two observed values; with `critic`, two critic values, the first of which is the next
    /// reward (so the critic has something to learn from them). Episodes last five steps.
    struct Peek {
        t: u32,
        critic: bool,
    }

    impl Peek {
        fn critic_values(&self) -> Option<Vec<f32>> {
            self.critic.then(|| vec![(self.t % 3) as f32 - 1.0, 0.5])
        }
    }

    impl Env for Peek {
        fn observation_space(&self) -> BoxSpace {
            BoxSpace::uniform(2, -1.0, 1.0)
        }
        fn action_space(&self) -> BoxSpace {
            BoxSpace::uniform(1, -1.0, 1.0)
        }
        fn reset(&mut self, _: Option<u64>) -> std::result::Result<(Vec<f32>, Info), EnvError> {
            self.t = 0;
            let info = Info {
                critic_obs: self.critic_values(),
                ..Info::default()
            };
            Ok((vec![0.0, 0.1], info))
        }
        fn step(&mut self, a: &[f32]) -> std::result::Result<Step, EnvError> {
            let reward = self.critic_values().map_or(0.0, |c| c[0] as f64) - (a[0] as f64).powi(2);
            self.t += 1;
            Ok(Step {
                obs: vec![(self.t as f32 * 0.3).sin(), a[0]],
                reward,
                terminated: self.t == 5,
                truncated: false,
                info: Info {
                    critic_obs: self.critic_values(),
                    ..Info::default()
                },
            })
        }
        fn dt_s(&self) -> f64 {
            0.1
        }
        fn critic_obs_dim(&self) -> usize {
            if self.critic { 2 } else { 0 }
        }
    }

    fn learner(critic: bool) -> Ppo<Peek> {
        let cfg = PpoConfig {
            n_steps: 32,
            batch_size: 16,
            n_epochs: 2,
            net_arch: vec![8, 8],
            ..Default::default()
        };
        let envs = VecEnv::new(vec![Peek { t: 0, critic }, Peek { t: 0, critic }], 1).unwrap();
        Ppo::new(cfg, envs, &crate::default_device(), 1).unwrap()
    }

    /// `(mean, value)` of the learner's networks on one observation with critic values `c`.
    fn outputs(p: &Ppo<Peek>, obs: &[f32], c: &[f32]) -> (f32, f32) {
        let x = p.input_rows(obs, c);
        let f = host::forward(&p.params, &Layout::of(&p.cfg), p.cfg.activation_fn, None, &x, 1);
        (f.mean[0], f.value[0])
    }

    /// On either network path the critic learns from the critic values and the actor never
    /// reads them: its weights from them stay 0 through training, its action does not move
    /// with them, and the policy file reads the observation alone and acts as the actor.
    #[test]
    fn a_critic_observation_reaches_the_critic_and_never_the_actor() {
        for path in [NetPath::Host, NetPath::Burn] {
            let mut p = learner(true);
            p.set_net_path(path);
            let before = p.params.data[0].clone();
            p.learn(256, &mut |_| Control::Continue).unwrap();
            let [_, rows, cols] = p.params.shapes[0];
            assert_eq!(rows, 4);
            let w = &p.params.data[0];
            let member = |m: usize, r: usize| &w[(m * rows + r) * cols..(m * rows + r + 1) * cols];
            for r in 2..4 {
                assert!(member(0, r).iter().all(|v| *v == 0.0), "{path:?}: actor row {r}");
                let old = &before[(rows + r) * cols..(rows + r + 1) * cols];
                assert!(member(1, r) != old, "{path:?}: critic row {r} did not learn");
            }
            let obs = [0.3, -0.7];
            let (m0, v0) = outputs(&p, &obs, &[1.0, 0.5]);
            let (m1, v1) = outputs(&p, &obs, &[-1.0, 0.5]);
            assert_eq!(m0, m1, "{path:?}");
            assert!(v0 != v1, "{path:?}");
            let data = p.policy_data();
            assert_eq!((data.net.sizes[0], data.observation_space.dim()), (2, 2));
            let act = Policy::new(data, &p.device).act(&obs, true).unwrap();
            assert!((act[0] - m0.clamp(-1.0, 1.0)).abs() < 1e-5, "{path:?}: {act:?} vs {m0}");
        }
    }

    /// `Policy::act` on the host path is the rollout's forward pass: its deterministic action
    /// is the rollout's action mean (clipped to the box), bit for bit.
    #[test]
    fn the_policy_on_the_host_path_acts_with_the_rollouts_forward_pass() {
        let mut p = learner(false);
        p.learn(64, &mut |_| Control::Continue).unwrap();
        let mut policy = Policy::new(p.policy_data(), &p.device);
        policy.set_net_path(NetPath::Host);
        for obs in [[0.3f32, -0.7], [0.9, 0.05], [-1.0, 1.0]] {
            let (mean, _) = outputs(&p, &obs, &[]);
            assert_eq!(policy.act(&obs, true).unwrap(), vec![mean.clamp(-1.0, 1.0)]);
        }
    }

    /// A learner with critic values warm-started from a checkpoint without them acts and
    /// values as that checkpoint's learner, whatever the critic values, until it trains.
    #[test]
    fn a_warm_start_gives_added_critic_values_zero_weights() {
        let dir = tempfile::tempdir().unwrap();
        let ckpt = dir.path().join("plain.ckpt");
        let mut plain = learner(false);
        plain.learn(64, &mut |_| Control::Continue).unwrap();
        plain.save_checkpoint(&ckpt).unwrap();
        let mut seeing = learner(true);
        seeing.warm_start(&ckpt, &[]).unwrap();
        let obs = [0.2, 0.4];
        let want = outputs(&plain, &obs, &[]);
        for c in [[0.0, 0.0], [1.0, -3.0]] {
            assert_eq!(outputs(&seeing, &obs, &c), want);
        }
        // And back: a checkpoint with critic values warm-starts a learner without them.
        seeing.learn(64, &mut |_| Control::Continue).unwrap();
        seeing.save_checkpoint(&ckpt).unwrap();
        let mut again = learner(false);
        again.warm_start(&ckpt, &[]).unwrap();
        assert_eq!(outputs(&again, &obs, &[]).0, outputs(&seeing, &obs, &[0.0, 0.0]).0);
    }
}
