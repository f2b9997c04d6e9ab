//! Self-play: a race seen from one car. `SelfPlayEnv` is a single-agent `Env` over a
//! `RaceEnv` whose car 0 the learner drives; the other cars are driven in-process by
//! opponents drawn per race from a pool of the learner's snapshots (the newest half the time,
//! else any earlier one, so the policy keeps beating its past selves). The training loop adds
//! a snapshot after every chunk, saved in the run directory's `pool/` for a resume; draws come
//! from each env's own seeded stream, so a run replays bit for bit on the same CPU.

use agvrl_envs::{BoxSpace, Env, EnvConfig, EnvError, Info, MultiEnv as _, RaceEnv, Step};
use agvrl_rl::{Policy, PolicyData};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use std::path::{Path, PathBuf};
use std::sync::{Arc, RwLock};

/// Probability that an opponent is the newest snapshot rather than an earlier one.
const NEWEST_P: f64 = 0.5;

/// The learner's snapshots, oldest first, shared by every self-play env of a run.
#[derive(Clone, Default)]
pub struct Pool(Arc<RwLock<Vec<Arc<PolicyData>>>>);

impl Pool {
    /// Add a snapshot (the training loop, between chunks).
    pub fn push(&self, data: PolicyData) {
        if let Ok(mut g) = self.0.write() {
            g.push(Arc::new(data));
        }
    }

    /// Add the snapshot taken at `steps`, first saved as `dir/<steps>.agvrl`.
    pub fn push_saved(&self, data: PolicyData, dir: &Path, steps: u64) -> agvrl_rl::Result<()> {
        data.save(&dir.join(format!("{steps}.agvrl")))?;
        self.push(data);
        Ok(())
    }

    /// Add the snapshots saved in `dir` up to `steps` (a resumed run's checkpoint), oldest
    /// first: the pool the run held then. Later ones (a kill between a snapshot and the
    /// checkpoint) are removed, as the resumed run takes them again. Nothing when `dir` does not
    /// exist (a run from before pools were saved).
    pub fn restore(&self, dir: &Path, steps: u64) -> anyhow::Result<()> {
        let entries = match std::fs::read_dir(dir) {
            Ok(e) => e,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
            Err(e) => return Err(anyhow::Error::new(e).context(format!("reading {}", dir.display()))),
        };
        let mut saved: Vec<(u64, PathBuf)> = vec![];
        for entry in entries {
            let path = entry?.path();
            let step = path
                .file_name()
                .and_then(|n| n.to_str())
                .and_then(|n| n.strip_suffix(".agvrl"))
                .and_then(|n| n.parse::<u64>().ok());
            match step {
                Some(s) if s <= steps => saved.push((s, path)),
                Some(_) => std::fs::remove_file(&path)?,
                None => {}
            }
        }
        saved.sort();
        for (_, path) in saved {
            self.push(PolicyData::load(&path)?);
        }
        Ok(())
    }

    /// The snapshots, oldest first.
    pub fn snapshots(&self) -> Vec<Arc<PolicyData>> {
        self.0.read().map_or(vec![], |g| g.clone())
    }

    /// Snapshots held.
    pub fn len(&self) -> usize {
        self.0.read().map_or(0, |g| g.len())
    }

    /// Whether no snapshot is held yet.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    fn draw(&self, rng: &mut StdRng) -> Option<Arc<PolicyData>> {
        let g = self.0.read().ok()?;
        let n = g.len();
        if n == 0 {
            return None;
        }
        let k = if n == 1 || rng.random_bool(NEWEST_P) {
            n - 1
        } else {
            rng.random_range(0..n - 1)
        };
        Some(g[k].clone())
    }
}

/// A race seen from car 0; the other cars are opponents from the pool.
pub struct SelfPlayEnv {
    race: RaceEnv,
    pool: Pool,
    opponents: Vec<Option<Policy>>,
    rng: StdRng,
    device: agvrl_rl::Device,
}

impl SelfPlayEnv {
    /// Self-play on env `id` (a race) with `cfg`, opponents from `pool`.
    pub fn new(id: &str, cfg: &EnvConfig, pool: Pool) -> Result<Self, EnvError> {
        let race = agvrl_envs::make_race(id, cfg)?;
        let n = race.n_agents();
        Ok(Self {
            race,
            pool,
            opponents: (1..n).map(|_| None).collect(),
            rng: StdRng::seed_from_u64(0),
            device: agvrl_rl::default_device(),
        })
    }

    fn opponent_actions(&mut self) -> Result<Vec<Vec<f32>>, EnvError> {
        let mut actions = vec![vec![0.0, 0.0]];
        for (k, p) in self.opponents.iter_mut().enumerate() {
            let car = k + 1;
            let a = match p {
                Some(p) if !self.race.done(car) => p
                    .act(&self.race.observation_of(car), false)
                    .map_err(|e| EnvError::Vehicle(format!("opponent {car}: {e}")))?,
                // Before the first snapshot, or once out of the race: the car waits.
                _ => vec![-1.0, 0.0],
            };
            actions.push(a);
        }
        Ok(actions)
    }
}

impl Env for SelfPlayEnv {
    fn observation_space(&self) -> BoxSpace {
        self.race.observation_space()
    }

    fn action_space(&self) -> BoxSpace {
        self.race.action_space()
    }

    fn reset(&mut self, seed: Option<u64>) -> Result<(Vec<f32>, Info), EnvError> {
        if let Some(s) = seed {
            self.rng = StdRng::seed_from_u64(s ^ 0x5e1f_91a7);
        }
        let obs = self.race.reset(seed)?;
        for p in self.opponents.iter_mut() {
            *p = self.pool.draw(&mut self.rng).map(|d| {
                let mut policy = Policy::new((*d).clone(), &self.device);
                policy.seed(self.rng.random());
                policy
            });
        }
        Ok((obs.into_iter().next().unwrap_or_default(), Info::default()))
    }

    fn step(&mut self, action: &[f32]) -> Result<Step, EnvError> {
        let mut actions = self.opponent_actions()?;
        actions[0] = action.to_vec();
        let st = self.race.step(&actions)?;
        // The learner's episode is its car's: once it crashes the race is over for it (the
        // next call is a reset).
        st.agents.into_iter().next().flatten().ok_or(EnvError::NeedsReset)
    }

    fn dt_s(&self) -> f64 {
        self.race.dt_s()
    }
}
