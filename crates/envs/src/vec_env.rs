//! N envs stepped in parallel. By default with same-step auto-reset (Stable-Baselines3's
//! convention): when an episode ends, `obs` holds the first observation of the next episode and
//! `infos[i].final_obs` the last one of the episode that ended. [`Autoreset`] selects Gymnasium's
//! other two modes (reset on the next step, or never).
//!
//! Threads: the envs are split into `threads` contiguous chunks, one per thread of a
//! [`Workers`] pool (the caller's thread steps the first). A thread that finishes its chunk
//! takes over the unclaimed envs at the ends of the others (a per-env claim), so one slow step
//! (a reset, a crowded scan) does not leave a core idle. A step costs tens of microseconds, so
//! handing work over must cost far less: the pool's helpers wait for the next round by spinning,
//! then yielding, before they park. Rounds cheaper than handing one over (tiny envs like pendulum) run on the
//! caller's thread alone. A learner that owns the VecEnv runs its gradient steps on the same
//! pool ([`VecEnv::workers`]).

use crate::Env;
use crate::api::{BoxSpace, EnvError, EpisodeSummary, Info, Step};
use crate::workers::Workers;
use std::ops::Range;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

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

/// What a `VecEnv` does with an env whose episode ended (Gymnasium's autoreset modes).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Autoreset {
    /// Reset within the step that ended the episode: `obs` is the next episode's first
    /// observation and `info.final_obs` the ended one's last (Stable-Baselines3; Gymnasium's
    /// `SAME_STEP`).
    #[default]
    SameStep,
    /// The env's next step resets it instead of stepping (its action is ignored) and reports
    /// the first observation with reward 0, neither terminated nor truncated (Gymnasium's
    /// `NEXT_STEP`, its default).
    NextStep,
    /// Never: stepping an ended env is an error until `reset_envs` resets it (Gymnasium's
    /// `DISABLED`).
    Disabled,
}

struct Slot<E> {
    env: E,
    ret: f64,
    len: u64,
    /// The episode ended and the env has not been reset since (`NextStep`, `Disabled`).
    ended: bool,
    /// The last observation handed out (what a masked reset reports for an env it skips).
    last_obs: Vec<f32>,
    out: Option<Result<Step, EnvError>>,
}

impl<E: Env> Slot<E> {
    fn reset(&mut self, seed: Option<u64>) -> Result<Step, EnvError> {
        self.ret = 0.0;
        self.len = 0;
        self.ended = false;
        let (obs, info) = self.env.reset(seed)?;
        self.last_obs.clone_from(&obs);
        Ok(Step {
            obs,
            reward: 0.0,
            terminated: false,
            truncated: false,
            info,
        })
    }

    fn run(&mut self, index: usize, cmd: &Cmd, act_dim: usize, mode: Autoreset) -> Result<Step, EnvError> {
        match cmd {
            Cmd::Reset(seeds, mask) => {
                if mask.as_ref().is_some_and(|m| !m[index]) {
                    return Ok(Step {
                        obs: self.last_obs.clone(),
                        reward: 0.0,
                        terminated: false,
                        truncated: false,
                        info: Info::default(),
                    });
                }
                self.reset(seeds[index])
            }
            Cmd::Step(actions) => {
                if self.ended {
                    return match mode {
                        Autoreset::NextStep => self.reset(None),
                        _ => Err(EnvError::NeedsReset),
                    };
                }
                let mut st = self.env.step(&actions[index * act_dim..(index + 1) * act_dim])?;
                self.ret += st.reward;
                self.len += 1;
                if st.done() {
                    st.info.episode = Some(EpisodeSummary {
                        ret: self.ret,
                        len: self.len,
                    });
                    if mode == Autoreset::SameStep {
                        let first = self.reset(None)?;
                        st.info.final_obs = Some(std::mem::replace(&mut st.obs, first.obs));
                        st.info.final_critic_obs = std::mem::replace(&mut st.info.critic_obs, first.info.critic_obs);
                    } else {
                        self.ended = true;
                    }
                }
                self.last_obs.clone_from(&st.obs);
                Ok(st)
            }
        }
    }
}

enum Cmd {
    /// A seed per env, and which envs to reset (all without a mask).
    Reset(Vec<Option<u64>>, Option<Vec<bool>>),
    Step(Vec<f32>),
}

/// What every thread sees: the envs and which round each was last claimed in.
struct Shared<E> {
    slots: Vec<Mutex<Slot<E>>>,
    claimed: Vec<AtomicU64>,
    /// Contiguous env ranges, one per thread; thread 0 is the caller's.
    chunks: Vec<Range<usize>>,
    act_dim: usize,
    autoreset: Autoreset,
}

impl<E: Env> Shared<E> {
    /// Step this thread's own chunk in order, then help with the others from their ends, so a
    /// thread that finishes early takes over the last envs of a slower one without moving envs
    /// between cores in the common case.
    /// Returns how many envs this thread stepped.
    fn work(&self, thread: usize, round: u64, cmd: &Cmd) -> usize {
        let n = self.chunks.len();
        let mut done = 0;
        for i in self.chunks[thread].clone() {
            done += usize::from(self.try_run(i, round, cmd));
        }
        for k in 1..n {
            for i in self.chunks[(thread + k) % n].clone().rev() {
                done += usize::from(self.try_run(i, round, cmd));
            }
        }
        done
    }

    fn try_run(&self, i: usize, round: u64, cmd: &Cmd) -> bool {
        if self.claimed[i]
            .compare_exchange(round - 1, round, Ordering::AcqRel, Ordering::Relaxed)
            .is_err()
        {
            return false;
        }
        self.run_one(i, cmd);
        true
    }

    fn run_one(&self, i: usize, cmd: &Cmd) {
        if let Ok(mut slot) = self.slots[i].lock() {
            slot.out = Some(slot.run(i, cmd, self.act_dim, self.autoreset));
        }
    }
}

/// Below this much work per round (all envs, one thread) the caller's thread steps every env
/// itself: handing a round over costs a few microseconds, more than tiny envs (pendulum, 0.3 us a
/// step) save on a second core.
const SOLO_BELOW: Duration = Duration::from_micros(25);

/// Envs that step together. Env `i` is seeded with `seed + i` on `reset(Some(seed))`, so the
/// results do not depend on the number of threads.
pub struct VecEnv<E: Env> {
    shared: Shared<E>,
    workers: Arc<Workers>,
    /// Rounds run on more than one thread so far (what a claim compares against).
    round: u64,
    n_envs: usize,
    obs_dim: usize,
    act_dim: usize,
    obs_space: BoxSpace,
    act_space: BoxSpace,
    dt_s: f64,
    critic_obs_dim: usize,
    /// Estimated time of one round on one thread, from the last round.
    round_cost: Duration,
}

impl<E: Env + 'static> VecEnv<E> {
    /// Wrap `envs` (all with the same spaces) on `threads` threads (the caller's included),
    /// with same-step auto-reset.
    pub fn new(envs: Vec<E>, threads: usize) -> Result<Self, EnvError> {
        Self::with_autoreset(envs, threads, Autoreset::SameStep)
    }

    /// [`VecEnv::new`] with the given auto-reset mode.
    pub fn with_autoreset(envs: Vec<E>, threads: usize, autoreset: Autoreset) -> Result<Self, EnvError> {
        let first = envs
            .first()
            .ok_or_else(|| EnvError::Config("VecEnv needs at least one env".into()))?;
        let obs_space = first.observation_space();
        let act_space = first.action_space();
        let dt_s = first.dt_s();
        let critic_obs_dim = first.critic_obs_dim();
        if envs.iter().any(|e| {
            e.observation_space() != obs_space || e.action_space() != act_space || e.critic_obs_dim() != critic_obs_dim
        }) {
            return Err(EnvError::Config(
                "VecEnv envs must share observation and action spaces (and critic observations)".into(),
            ));
        }
        let n_envs = envs.len();
        let act_dim = act_space.dim();
        let threads = threads.clamp(1, n_envs);
        let mut chunks = Vec::with_capacity(threads);
        let mut start = 0;
        for t in 0..threads {
            let size = n_envs / threads + usize::from(t < n_envs % threads);
            chunks.push(start..start + size);
            start += size;
        }
        let shared = Shared {
            slots: envs
                .into_iter()
                .map(|env| {
                    Mutex::new(Slot {
                        env,
                        ret: 0.0,
                        len: 0,
                        ended: false,
                        last_obs: Vec::new(),
                        out: None,
                    })
                })
                .collect(),
            claimed: (0..n_envs).map(|_| AtomicU64::new(0)).collect(),
            chunks,
            act_dim,
            autoreset,
        };
        let workers = Workers::new(threads - 1)
            .map_err(|e| EnvError::Config(format!("starting the VecEnv's worker threads: {e}")))?;
        Ok(Self {
            shared,
            workers: Arc::new(workers),
            round: 0,
            n_envs,
            obs_dim: obs_space.dim(),
            act_dim,
            obs_space,
            act_space,
            dt_s,
            critic_obs_dim,
            round_cost: Duration::MAX,
        })
    }
}

impl<E: Env> VecEnv<E> {
    /// Number of envs.
    pub fn n_envs(&self) -> usize {
        self.n_envs
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
        self.dt_s
    }

    /// Length of each env's `Info::critic_obs` (0: none; see [`Env::critic_obs_dim`]).
    pub fn critic_obs_dim(&self) -> usize {
        self.critic_obs_dim
    }

    /// What happens to an env whose episode ended.
    pub fn autoreset(&self) -> Autoreset {
        self.shared.autoreset
    }

    /// Threads stepping the envs (the caller's included).
    pub fn threads(&self) -> usize {
        self.shared.chunks.len()
    }

    /// The worker pool the envs step on (`threads() - 1` helpers), for a learner to share.
    pub fn workers(&self) -> &Arc<Workers> {
        &self.workers
    }

    /// Run `cmd` on every env once, on all threads; results in env order.
    fn run_all(&mut self, cmd: Cmd) -> Result<Vec<Step>, EnvError> {
        let sh = &self.shared;
        let threads = sh.chunks.len();
        if threads == 1 || self.round_cost < SOLO_BELOW {
            // Results do not depend on which thread steps an env, so this changes speed only.
            let t0 = Instant::now();
            for i in 0..self.n_envs {
                sh.run_one(i, &cmd);
            }
            self.round_cost = t0.elapsed();
            return self.collect();
        }
        self.round += 1;
        let (round, cmd) = (self.round, &cmd);
        let jobs = (0..threads)
            .map(|t| {
                Box::new(move || {
                    let t0 = Instant::now();
                    (sh.work(t, round, cmd), t0.elapsed())
                }) as Box<dyn FnOnce() -> (usize, Duration) + Send + '_>
            })
            .collect();
        // Every job has tried every env, and returned only once the ones it claimed are done;
        // an env whose step panicked reports a lost result in `collect`.
        let ran = self.workers.run(jobs);
        if let Some(Some((done, took))) = ran.first() {
            self.round_cost = *took * self.n_envs as u32 / (*done).max(1) as u32;
        }
        self.collect()
    }

    fn collect(&self) -> Result<Vec<Step>, EnvError> {
        let mut out = Vec::with_capacity(self.n_envs);
        let mut first_err = None;
        // Every result is taken, so none is left over for the next round.
        for (i, s) in self.shared.slots.iter().enumerate() {
            let r = s
                .lock()
                .ok()
                .and_then(|mut s| s.out.take())
                .unwrap_or(Err(EnvError::Internal("VecEnv lost a result (a panic in an env?)")));
            match r {
                Ok(st) => out.push(st),
                Err(e) => {
                    first_err.get_or_insert(EnvError::InEnv {
                        env: i,
                        source: Box::new(e),
                    });
                }
            }
        }
        first_err.map_or(Ok(out), Err)
    }

    /// Reset every env; env `i` gets `seed + i`. Returns `n_envs * obs_dim` observations.
    pub fn reset(&mut self, seed: Option<u64>) -> Result<(Vec<f32>, Vec<Info>), EnvError> {
        let seeds = (0..self.n_envs as u64)
            .map(|i| seed.map(|s| s.wrapping_add(i)))
            .collect();
        self.reset_envs(seeds, None)
    }

    /// Reset env `i` with `seeds[i]` (`None` continues its random stream) where `mask` is
    /// true, or every env without a mask. Rows of envs left alone hold their last observation
    /// (zeros for an env never reset) and their info is empty.
    pub fn reset_envs(
        &mut self,
        seeds: Vec<Option<u64>>,
        mask: Option<Vec<bool>>,
    ) -> Result<(Vec<f32>, Vec<Info>), EnvError> {
        let n = self.n_envs;
        if seeds.len() != n || mask.as_ref().is_some_and(|m| m.len() != n) {
            return Err(EnvError::Config(format!(
                "reset needs one seed{} per env ({n} envs)",
                if mask.is_some() { " and one mask entry" } else { "" }
            )));
        }
        let out = self.run_all(Cmd::Reset(seeds, mask))?;
        let mut obs = Vec::with_capacity(n * self.obs_dim);
        let mut infos = Vec::with_capacity(n);
        for st in out {
            if st.obs.is_empty() {
                obs.resize(obs.len() + self.obs_dim, 0.0);
            }
            obs.extend_from_slice(&st.obs);
            infos.push(st.info);
        }
        Ok((obs, infos))
    }

    /// Step env `i` with `actions[i * act_dim..(i + 1) * act_dim]`, auto-resetting ended episodes.
    pub fn step(&mut self, actions: &[f32]) -> Result<VecStep, EnvError> {
        let n = self.n_envs;
        if actions.len() != n * self.act_dim {
            return Err(EnvError::ActionShape {
                expected: n * self.act_dim,
                got: actions.len(),
            });
        }
        if self.autoreset() == Autoreset::Disabled
            && let Some(env) = self.shared.slots.iter().position(|s| s.lock().is_ok_and(|s| s.ended))
        {
            return Err(EnvError::InEnv {
                env,
                source: Box::new(EnvError::NeedsReset),
            });
        }
        // Nothing steps unless every action is valid, so a bad row leaves no env half-stepped.
        for (i, a) in actions.chunks_exact(self.act_dim.max(1)).enumerate() {
            crate::api::validate_action(&self.act_space, a).map_err(|e| EnvError::InEnv {
                env: i,
                source: Box::new(e),
            })?;
        }
        let steps = self.run_all(Cmd::Step(actions.to_vec()))?;
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
