//! N envs stepped in parallel on rayon threads, with same-step auto-reset (Stable-Baselines3's
//! convention): when an episode ends, `obs` holds the first observation of the next episode
//! and `infos[i].final_obs` the last one of the episode that ended.

use crate::Env;
use crate::api::{BoxSpace, EnvError, EpisodeSummary, Info};
use rayon::prelude::*;

/// The result of stepping every env once. Observations are flat, row `i` belongs to env `i`.
#[derive(Clone, Debug)]
pub struct VecStep {
    /// `n_envs * obs_dim` observations, row-major.
    pub obs: Vec<f32>,
    /// Reward per env.
    pub rewards: Vec<f64>,
    /// Whether env `i`'s episode terminated on this step.
    pub terminated: Vec<bool>,
    /// Whether env `i`'s episode was truncated on this step.
    pub truncated: Vec<bool>,
    /// Info per env (`final_obs` and `episode` set where an episode ended).
    pub infos: Vec<Info>,
}

struct Slot<E> {
    env: E,
    ret: f64,
    len: u64,
}

/// Envs that step together. Env `i` is seeded with `seed + i` on `reset(Some(seed))`, so the
/// results do not depend on the number of threads.
pub struct VecEnv<E: Env> {
    slots: Vec<Slot<E>>,
    obs_dim: usize,
    act_dim: usize,
    obs_space: BoxSpace,
    act_space: BoxSpace,
    pool: Option<rayon::ThreadPool>,
}

impl<E: Env> VecEnv<E> {
    /// Wrap `envs` (all with the same spaces); `threads` = 1 steps them serially on the
    /// caller's thread, more uses a rayon pool of that size.
    pub fn new(envs: Vec<E>, threads: usize) -> Result<Self, EnvError> {
        let first = envs
            .first()
            .ok_or_else(|| EnvError::Config("VecEnv needs at least one env".into()))?;
        let obs_space = first.observation_space();
        let act_space = first.action_space();
        if envs
            .iter()
            .any(|e| e.observation_space() != obs_space || e.action_space() != act_space)
        {
            return Err(EnvError::Config(
                "VecEnv envs must share observation and action spaces".into(),
            ));
        }
        let pool = if threads > 1 {
            Some(
                rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .map_err(|e| EnvError::Config(format!("thread pool: {e}")))?,
            )
        } else {
            None
        };
        Ok(Self {
            obs_dim: obs_space.dim(),
            act_dim: act_space.dim(),
            obs_space,
            act_space,
            slots: envs.into_iter().map(|env| Slot { env, ret: 0.0, len: 0 }).collect(),
            pool,
        })
    }

    /// Number of envs.
    pub fn n_envs(&self) -> usize {
        self.slots.len()
    }

    /// Observation space of one env.
    pub fn observation_space(&self) -> &BoxSpace {
        &self.obs_space
    }

    /// Action space of one env.
    pub fn action_space(&self) -> &BoxSpace {
        &self.act_space
    }

    /// Control period of the envs, seconds.
    pub fn dt_s(&self) -> f64 {
        self.slots[0].env.dt_s()
    }

    /// The envs, for inspection.
    pub fn envs(&self) -> impl Iterator<Item = &E> {
        self.slots.iter().map(|s| &s.env)
    }

    /// Reset every env; env `i` gets `seed + i`. Returns `n_envs * obs_dim` observations.
    pub fn reset(&mut self, seed: Option<u64>) -> Result<(Vec<f32>, Vec<Info>), EnvError> {
        let run = |slots: &mut [Slot<E>]| -> Result<Vec<(Vec<f32>, Info)>, EnvError> {
            slots
                .par_iter_mut()
                .enumerate()
                .map(|(i, s)| {
                    s.ret = 0.0;
                    s.len = 0;
                    s.env.reset(seed.map(|x| x.wrapping_add(i as u64)))
                })
                .collect()
        };
        let out = match &self.pool {
            Some(pool) => pool.install(|| run(&mut self.slots))?,
            None => self
                .slots
                .iter_mut()
                .enumerate()
                .map(|(i, s)| {
                    s.ret = 0.0;
                    s.len = 0;
                    s.env.reset(seed.map(|x| x.wrapping_add(i as u64)))
                })
                .collect::<Result<Vec<_>, _>>()?,
        };
        let mut obs = Vec::with_capacity(self.n_envs() * self.obs_dim);
        let mut infos = Vec::with_capacity(self.n_envs());
        for (o, info) in out {
            obs.extend_from_slice(&o);
            infos.push(info);
        }
        Ok((obs, infos))
    }

    /// Step env `i` with `actions[i * act_dim..(i + 1) * act_dim]`, auto-resetting ended episodes.
    pub fn step(&mut self, actions: &[f32]) -> Result<VecStep, EnvError> {
        let n = self.n_envs();
        if actions.len() != n * self.act_dim {
            return Err(EnvError::ActionShape {
                expected: n * self.act_dim,
                got: actions.len(),
            });
        }
        let act_dim = self.act_dim;
        let step_one = |(s, a): (&mut Slot<E>, &[f32])| -> Result<crate::api::Step, EnvError> {
            let mut st = s.env.step(a)?;
            s.ret += st.reward;
            s.len += 1;
            if st.done() {
                st.info.episode = Some(EpisodeSummary { ret: s.ret, len: s.len });
                let (obs, _) = s.env.reset(None)?;
                st.info.final_obs = Some(std::mem::replace(&mut st.obs, obs));
                s.ret = 0.0;
                s.len = 0;
            }
            Ok(st)
        };
        let steps: Vec<crate::api::Step> = match &self.pool {
            Some(pool) => pool.install(|| {
                self.slots
                    .par_iter_mut()
                    .zip(actions.par_chunks(act_dim))
                    .map(step_one)
                    .collect::<Result<Vec<_>, EnvError>>()
            })?,
            None => self
                .slots
                .iter_mut()
                .zip(actions.chunks(act_dim))
                .map(step_one)
                .collect::<Result<_, _>>()?,
        };
        let mut out = VecStep {
            obs: Vec::with_capacity(n * self.obs_dim),
            rewards: Vec::with_capacity(n),
            terminated: Vec::with_capacity(n),
            truncated: Vec::with_capacity(n),
            infos: Vec::with_capacity(n),
        };
        for st in steps {
            out.obs.extend_from_slice(&st.obs);
            out.rewards.push(st.reward);
            out.terminated.push(st.terminated);
            out.truncated.push(st.truncated);
            out.infos.push(st.info);
        }
        Ok(out)
    }
}
