//! N envs stepped in parallel, with same-step auto-reset (Stable-Baselines3's convention): when an
//! episode ends, `obs` holds the first observation of the next episode and `infos[i].final_obs`
//! the last one of the episode that ended.
//!
//! Threads: the envs are split into `threads` contiguous chunks; the caller's thread steps the
//! first, and each other chunk lives on a persistent worker thread. A step costs tens of
//! microseconds, so handing work over must cost far less: workers spin briefly for the next
//! command before they park (on this class of machine a park/unpark round trip took ~100 us,
//! which ate the whole gain of a second core with a sleeping thread pool).

use crate::Env;
use crate::api::{BoxSpace, EnvError, EpisodeSummary, Info, Step};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
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

struct Slot<E> {
    env: E,
    ret: f64,
    len: u64,
}

enum Cmd {
    Reset(Option<u64>),
    Step(Vec<f32>),
}

type Out = Result<Vec<(Vec<f32>, Step)>, EnvError>;

/// A chunk of envs and what to do with it.
struct Chunk<E> {
    first: usize,
    act_dim: usize,
    slots: Vec<Slot<E>>,
}

impl<E: Env> Chunk<E> {
    fn run(&mut self, cmd: Cmd) -> Out {
        match cmd {
            Cmd::Reset(seed) => self
                .slots
                .iter_mut()
                .enumerate()
                .map(|(i, s)| {
                    s.ret = 0.0;
                    s.len = 0;
                    let (obs, info) = s.env.reset(seed.map(|x| x.wrapping_add((self.first + i) as u64)))?;
                    let st = Step {
                        obs: obs.clone(),
                        reward: 0.0,
                        terminated: false,
                        truncated: false,
                        info,
                    };
                    Ok((obs, st))
                })
                .collect(),
            Cmd::Step(actions) => self
                .slots
                .iter_mut()
                .zip(actions.chunks(self.act_dim))
                .map(|(s, a)| {
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
                    Ok((Vec::new(), st))
                })
                .collect(),
        }
    }
}

#[derive(Default)]
struct Mailbox {
    cmd: Option<Cmd>,
    out: Option<Out>,
}

struct Shared {
    posted: AtomicU64,
    done: AtomicU64,
    quit: AtomicBool,
    mail: Mutex<Mailbox>,
}

struct Worker {
    /// Index of the worker's first env, and how many it steps.
    first: usize,
    len: usize,
    shared: Arc<Shared>,
    handle: Option<JoinHandle<()>>,
}

/// How long a worker spins for its next command before parking.
const SPIN: Duration = Duration::from_micros(300);

fn wait_until(flag: impl Fn() -> bool, park: bool) {
    let t0 = Instant::now();
    while !flag() {
        if t0.elapsed() < SPIN {
            std::hint::spin_loop();
        } else if park {
            std::thread::park_timeout(Duration::from_millis(1));
        } else {
            std::thread::yield_now();
        }
    }
}

/// Envs that step together. Env `i` is seeded with `seed + i` on `reset(Some(seed))`, so the
/// results do not depend on the number of threads.
pub struct VecEnv<E: Env> {
    local: Chunk<E>,
    workers: Vec<Worker>,
    n_envs: usize,
    obs_dim: usize,
    act_dim: usize,
    obs_space: BoxSpace,
    act_space: BoxSpace,
    dt_s: f64,
}

impl<E: Env + 'static> VecEnv<E> {
    /// Wrap `envs` (all with the same spaces) on `threads` threads (the caller's included).
    pub fn new(envs: Vec<E>, threads: usize) -> Result<Self, EnvError> {
        let first = envs
            .first()
            .ok_or_else(|| EnvError::Config("VecEnv needs at least one env".into()))?;
        let obs_space = first.observation_space();
        let act_space = first.action_space();
        let dt_s = first.dt_s();
        if envs
            .iter()
            .any(|e| e.observation_space() != obs_space || e.action_space() != act_space)
        {
            return Err(EnvError::Config(
                "VecEnv envs must share observation and action spaces".into(),
            ));
        }
        let n_envs = envs.len();
        let act_dim = act_space.dim();
        let threads = threads.clamp(1, n_envs);
        let mut chunks: Vec<Chunk<E>> = Vec::new();
        let mut it = envs.into_iter();
        let mut first = 0;
        for t in 0..threads {
            let size = n_envs / threads + usize::from(t < n_envs % threads);
            let slots = it
                .by_ref()
                .take(size)
                .map(|env| Slot { env, ret: 0.0, len: 0 })
                .collect();
            chunks.push(Chunk { first, act_dim, slots });
            first += size;
        }
        let mut chunks = chunks.into_iter();
        let local = chunks.next().ok_or_else(|| EnvError::Config("no envs".into()))?;
        let mut workers = Vec::new();
        for mut chunk in chunks {
            let (first, len) = (chunk.first, chunk.slots.len());
            let shared = Arc::new(Shared {
                posted: AtomicU64::new(0),
                done: AtomicU64::new(0),
                quit: AtomicBool::new(false),
                mail: Mutex::new(Mailbox::default()),
            });
            let sh = shared.clone();
            let handle = std::thread::Builder::new()
                .name("agvrl-vecenv".into())
                .spawn(move || {
                    let mut seen = 0u64;
                    loop {
                        wait_until(
                            || sh.posted.load(Ordering::Acquire) > seen || sh.quit.load(Ordering::Acquire),
                            true,
                        );
                        if sh.quit.load(Ordering::Acquire) {
                            return;
                        }
                        seen += 1;
                        let cmd = sh.mail.lock().map(|mut m| m.cmd.take()).unwrap_or(None);
                        let out = match cmd {
                            Some(c) => chunk.run(c),
                            None => Err(EnvError::Config("VecEnv worker got no command".into())),
                        };
                        if let Ok(mut m) = sh.mail.lock() {
                            m.out = Some(out);
                        }
                        sh.done.store(seen, Ordering::Release);
                    }
                })
                .map_err(|e| EnvError::Config(format!("spawning a VecEnv thread: {e}")))?;
            workers.push(Worker {
                first,
                len,
                shared,
                handle: Some(handle),
            });
        }
        Ok(Self {
            local,
            workers,
            n_envs,
            obs_dim: obs_space.dim(),
            act_dim,
            obs_space,
            act_space,
            dt_s,
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

    /// Threads stepping the envs (the caller's included).
    pub fn threads(&self) -> usize {
        1 + self.workers.len()
    }

    /// Run `cmd_of(chunk_first, chunk_len)` on every chunk, the local one on this thread.
    fn run_all(&mut self, cmd_of: impl Fn(usize, usize) -> Cmd) -> Result<Vec<(Vec<f32>, Step)>, EnvError> {
        for w in &self.workers {
            if let Ok(mut m) = w.shared.mail.lock() {
                m.cmd = Some(cmd_of(w.first, w.len));
            }
            w.shared.posted.fetch_add(1, Ordering::Release);
            if let Some(h) = &w.handle {
                h.thread().unpark();
            }
        }
        let mut out = self.local.run(cmd_of(0, self.local.slots.len()))?;
        for w in &self.workers {
            let target = w.shared.posted.load(Ordering::Acquire);
            wait_until(|| w.shared.done.load(Ordering::Acquire) >= target, false);
            let got = w.shared.mail.lock().ok().and_then(|mut m| m.out.take());
            out.extend(got.ok_or_else(|| EnvError::Config("VecEnv worker lost its result".into()))??);
        }
        Ok(out)
    }

    /// Reset every env; env `i` gets `seed + i`. Returns `n_envs * obs_dim` observations.
    pub fn reset(&mut self, seed: Option<u64>) -> Result<(Vec<f32>, Vec<Info>), EnvError> {
        let out = self.run_all(|_, _| Cmd::Reset(seed))?;
        let mut obs = Vec::with_capacity(self.n_envs * self.obs_dim);
        let mut infos = Vec::with_capacity(self.n_envs);
        for (o, st) in out {
            obs.extend_from_slice(&o);
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
        let d = self.act_dim;
        let steps = self.run_all(|first, len| Cmd::Step(actions[first * d..(first + len) * d].to_vec()))?;
        let mut out = VecStep {
            obs: Vec::with_capacity(n * self.obs_dim),
            rewards: Vec::with_capacity(n),
            terminated: Vec::with_capacity(n),
            truncated: Vec::with_capacity(n),
            infos: Vec::with_capacity(n),
        };
        for (_, st) in steps {
            out.obs.extend_from_slice(&st.obs);
            out.rewards.push(st.reward);
            out.terminated.push(st.terminated);
            out.truncated.push(st.truncated);
            out.infos.push(st.info);
        }
        Ok(out)
    }
}

impl<E: Env> Drop for VecEnv<E> {
    fn drop(&mut self) {
        for w in &mut self.workers {
            w.shared.quit.store(true, Ordering::Release);
            if let Some(h) = w.handle.take() {
                h.thread().unpark();
                let _ = h.join();
            }
        }
    }
}
