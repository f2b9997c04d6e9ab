//! Self-play: a race seen from one car. `SelfPlayEnv` is a single-agent `Env` over a
//! `RaceEnv` whose car 0 the learner drives; the other cars are driven in-process by
//! opponents drawn per race from a pool of the learner's snapshots (the newest half the time,
//! else any earlier one, so the policy keeps beating its past selves), or, as the run's
//! `opponents` say, classical racers at a share of their speed. The training loop adds a
//! snapshot after every chunk, saved in the run directory's `pool/` for a resume; draws come
//! from each env's own seeded stream, so a run replays bit for bit on the same CPU.

use agvrl_envs::drivers::{Driver, RacerKind, make_racer};
use agvrl_envs::{BoxSpace, CarInput, Env, EnvConfig, EnvError, Info, MultiEnv as _, RaceEnv, Step};
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

/// What drives an opponent car for one race.
enum Opponent {
    /// A snapshot of the learner (None before the first snapshot: the car waits).
    Snapshot(Option<Box<Policy>>),
    /// A classical racer, controls applied as they are.
    Racer(Box<dyn Driver>),
}

/// A race seen from car 0; the other cars are opponents: snapshots from the pool, or classical
/// racers, as the run's `opponents` say.
pub struct SelfPlayEnv {
    race: RaceEnv,
    cfg: EnvConfig,
    pool: Pool,
    /// The run's `opponents`, parsed: None for `self`.
    choices: Vec<Option<(RacerKind, f64)>>,
    opponents: Vec<Opponent>,
    rng: StdRng,
    device: agvrl_rl::Device,
}

impl SelfPlayEnv {
    /// Self-play on env `id` (a race) with `cfg`, opponents from `pool`, or drawn per race from
    /// `opponents` (`self`, `pure-pursuit[@SCALE]`, `follow-the-gap[@SCALE]`; empty: `self`).
    pub fn new(id: &str, cfg: &EnvConfig, pool: Pool, opponents: &[String]) -> Result<Self, EnvError> {
        let race = agvrl_envs::make_race(id, cfg)?;
        let n = race.n_agents();
        let choices = opponents
            .iter()
            .map(|o| match o.as_str() {
                "self" => Ok(None),
                o => agvrl_envs::drivers::parse_racer(o).map(Some),
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self {
            race,
            cfg: cfg.clone(),
            pool,
            choices,
            opponents: (1..n).map(|_| Opponent::Snapshot(None)).collect(),
            rng: StdRng::seed_from_u64(0),
            device: agvrl_rl::default_device(),
        })
    }

    /// Car 0's critic values, when the race gives them.
    fn critic_obs(&self) -> Option<Vec<f32>> {
        (self.race.critic_obs_dim() > 0).then(|| self.race.critic_obs_of(0))
    }

    fn inputs(&mut self, action: &[f32]) -> Result<Vec<Input>, EnvError> {
        let mut inputs = vec![Input::Action(action.to_vec())];
        for (k, o) in self.opponents.iter_mut().enumerate() {
            let car = k + 1;
            let done = self.race.done(car);
            inputs.push(match o {
                Opponent::Snapshot(Some(p)) if !done => Input::Action(
                    p.act(&self.race.observation_of(car), false)
                        .map_err(|e| EnvError::Vehicle(format!("opponent {car}: {e}")))?,
                ),
                Opponent::Racer(d) if !done => {
                    Input::Control(d.control(self.race.frame_of(car), Some(self.race.map())))
                }
                // Before the first snapshot, or once out of the race: the car waits.
                _ => Input::Action(vec![-1.0, 0.0]),
            });
        }
        Ok(inputs)
    }
}

/// One car's input, owned.
enum Input {
    Action(Vec<f32>),
    Control(agvrl_envs::Control),
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
        for k in 0..self.opponents.len() {
            let choice = match self.choices.len() {
                0 => None,
                n => self.choices[self.rng.random_range(0..n)],
            };
            self.opponents[k] = match choice {
                None => Opponent::Snapshot(self.pool.draw(&mut self.rng).map(|d| {
                    let mut policy = Policy::new((*d).clone(), &self.device);
                    policy.seed(self.rng.random());
                    Box::new(policy)
                })),
                Some((kind, scale)) => {
                    let mut d = make_racer(kind, &self.cfg, scale, None)?;
                    d.reset(self.race.frame_of(k + 1), Some(self.race.map()));
                    Opponent::Racer(d)
                }
            };
        }
        let info = Info {
            critic_obs: self.critic_obs(),
            ..Info::default()
        };
        Ok((obs.into_iter().next().unwrap_or_default(), info))
    }

    fn step(&mut self, action: &[f32]) -> Result<Step, EnvError> {
        let inputs = self.inputs(action)?;
        let inputs: Vec<CarInput<'_>> = inputs
            .iter()
            .map(|i| match i {
                Input::Action(a) => CarInput::Action(a),
                Input::Control(c) => CarInput::Control(*c),
            })
            .collect();
        let st = self.race.step_inputs(&inputs)?;
        // The learner's episode is its car's: once it crashes the race is over for it (the
        // next call is a reset).
        let mut st = st.agents.into_iter().next().flatten().ok_or(EnvError::NeedsReset)?;
        st.info.critic_obs = self.critic_obs();
        Ok(st)
    }

    fn dt_s(&self) -> f64 {
        self.race.dt_s()
    }

    fn critic_obs_dim(&self) -> usize {
        self.race.critic_obs_dim()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use agvrl_envs::RaceSettings;

    fn race_cfg() -> EnvConfig {
        EnvConfig {
            track: Some(agvrl_envs::TrackSetting::Path(
                Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/tracks/sweepers.yaml"),
            )),
            race: Some(RaceSettings {
                cars: 2,
                ..RaceSettings::default()
            }),
            max_steps: 200,
            ..EnvConfig::default()
        }
    }

    /// With `critic_sees_opponents` the learner's car carries its critic values on every reset
    /// and step (what PPO's critic reads); without it, none.
    #[test]
    fn the_learners_car_carries_its_critic_values_on_every_reset_and_step() {
        let mut cfg = race_cfg();
        for on in [false, true] {
            cfg.race.as_mut().unwrap().critic_sees_opponents = on;
            let mut env =
                SelfPlayEnv::new("racing-duel", &cfg, Pool::default(), &["pure-pursuit@0.75".into()]).unwrap();
            assert_eq!(env.critic_obs_dim(), if on { 4 } else { 0 });
            let (_, info) = env.reset(Some(3)).unwrap();
            assert_eq!(info.critic_obs.is_some(), on);
            for _ in 0..20 {
                let st = env.step(&[0.5, 0.0]).unwrap();
                let want = on.then(|| env.race.critic_obs_of(0));
                assert_eq!(st.info.critic_obs, want);
            }
        }
    }

    /// The distance car 1 races in 150 steps while the learner's car brakes.
    fn opponent_distance(opponents: &[String]) -> f64 {
        let mut env = SelfPlayEnv::new("racing-duel", &race_cfg(), Pool::default(), opponents).unwrap();
        env.reset(Some(3)).unwrap();
        let start = env.race.frame_of(1).gps.as_ref().unwrap().position_m;
        for _ in 0..150 {
            env.step(&[-1.0, 0.0]).unwrap();
        }
        let end = env.race.frame_of(1).gps.as_ref().unwrap().position_m;
        ((end[0] - start[0]).powi(2) + (end[1] - start[1]).powi(2)).sqrt()
    }

    /// With a classical racer among the opponents, it drives car 1 round the track from the
    /// first race; self-play with an empty pool leaves car 1 waiting on the grid.
    #[test]
    fn a_classical_opponent_races_where_an_empty_pool_waits() {
        let waits = opponent_distance(&[]);
        assert!(waits < 0.05, "self-play before a snapshot: car 1 moved {waits} m");
        for o in ["pure-pursuit@0.75", "follow-the-gap@0.75"] {
            let d = opponent_distance(&[o.to_string()]);
            assert!(d > 2.0, "{o}: car 1 moved {d} m");
        }
        assert!(SelfPlayEnv::new("racing-duel", &race_cfg(), Pool::default(), &["stanley".into()]).is_err());
    }
}
