//! `agvrl eval`: deterministic evaluation of a policy on held-out episodes, its summary lines,
//! trajectory plot and recording (training runs it at the end too).

use crate::episode::{Observer, RandomActions, StepView, drive, make_sim_env};
use crate::eval_bag::EpisodeBags;
use crate::planner;
use crate::plots::{self, Path2};
use crate::viz::{self, Recorder};
use agvrl_envs::{Env, EnvConfig, Step, Vehicle as _, make};
use agvrl_rl::Policy;
use agvrl_run::stats::quantile;
use agvrl_run::{EvalReport, FilterReport, PolicySettings, RacingReport, SearchReport, SubjectsReport, files};
use anyhow::{Context, Result, bail};
use clap::Args;
use std::path::PathBuf;

/// `eval --layouts`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Layouts {
    /// The env's own map.
    Builtin,
    /// A new held-out procedural layout of the env's kind and size every episode.
    Procedural,
}

/// `eval --preset`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Preset {
    /// Sensor noise, latency and domain randomisation (`EnvConfig::sim2real`).
    Sim2real,
}

/// `eval --safety-filter`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Switch {
    /// On.
    On,
    /// Off.
    Off,
    /// The training envs' filter (`train_safety_filter`, else the policy's own): the one the
    /// planners were tuned behind.
    Train,
}

/// The name a value enum has on the command line (and in eval's output).
fn arg_name(v: impl clap::ValueEnum) -> String {
    v.to_possible_value()
        .map_or_else(String::new, |p| p.get_name().to_string())
}

#[derive(Args)]
pub struct EvalArgs {
    /// A run directory written by `agvrl train` (its policy, env and env settings).
    #[arg(long, required_unless_present_any = ["policy", "racer"], conflicts_with = "policy")]
    pub run: Option<PathBuf>,
    /// A policy file; env and env settings are the ones embedded in it (`agvrl policy FILE`
    /// prints them), or for files written before settings were embedded, FILE.toml beside it,
    /// else the config.toml of the run directory holding it, else --env with the defaults.
    #[arg(long)]
    pub policy: Option<PathBuf>,
    /// Override one of the policy's settings, KEY=VALUE as `agvrl train --set`
    /// (`--set env_config.safety_filter.clearance_m=0.7`).
    #[arg(long, value_name = "KEY=VALUE")]
    pub set: Vec<String>,
    /// Race on the track of a ROS map file (its YAML; a centre-line CSV beside it, or traced):
    /// `--set env_config.track=PATH`, loaded into the run config and policy file.
    #[arg(long, value_name = "MAP.yaml")]
    pub track: Option<PathBuf>,
    /// Base of the evaluation episodes' seeds: episode k resets with seed S + k, drawn from the
    /// held-out half of the seed space that training never uses (default: the run's seed +
    /// 2,000,000, or 0 for --policy).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Maps: builtin (the env's own map) or procedural (a new held-out layout of the env's kind
    /// and size every episode, never one a training run drew).
    #[arg(long, value_enum, default_value_t = Layouts::Builtin)]
    pub layouts: Layouts,
    /// Env preset applied on top of the policy's env settings: sim2real adds sensor noise,
    /// latency and domain randomisation.
    #[arg(long, value_enum)]
    pub preset: Option<Preset>,
    /// Turn the LiDAR safety filter between policy and drive on or off, whatever the policy's
    /// settings say (`off`: the network's own actions reach the drive), or drive behind the
    /// filter the policy was trained behind (`train`).
    #[arg(long, value_enum)]
    pub safety_filter: Option<Switch>,
    /// Episode length limit, control steps (default: the run's evaluation limit).
    #[arg(long)]
    pub max_steps: Option<u64>,
    /// Number of deterministic episodes.
    #[arg(long, default_value_t = 5)]
    pub episodes: usize,
    /// Sample the policy's actions as in training instead of taking their mean (episode k
    /// seeds the noise with S + k): does the deterministic policy behave as the one trained?
    #[arg(long, conflicts_with_all = ["random", "planner", "racer"])]
    pub sampled: bool,
    /// Record the episodes into this rerun file (.rrd; open it with `rerun FILE`).
    #[arg(long, value_name = "FILE.rrd", conflicts_with = "spawn_viewer")]
    pub rerun: Option<PathBuf>,
    /// Stream the episodes to a rerun viewer started from `rerun` on your PATH.
    #[arg(long)]
    pub spawn_viewer: bool,
    /// Record every episode as a rosbag2 bag, DIR/episode-000 ... (the topics of `agvrl-drive
    /// --record`, in simulated time; `agvrl-drive --replay` and the ROS 2 tools read them).
    #[arg(long, value_name = "DIR")]
    pub record: Option<PathBuf>,
    /// Also draw the evaluated paths over the map into this PNG.
    #[arg(long, value_name = "FILE.png")]
    pub plot: Option<PathBuf>,
    /// Evaluate on another env with the same spaces (a generalisation test, e.g. a policy
    /// trained on search-outdoor-20 run on search-urban-50); the run's env settings are kept.
    #[arg(long, value_name = "ID")]
    pub env: Option<String>,
    /// Drive uniform random actions instead of the policy, on the same episodes: the baseline
    /// the policy should beat (e.g. its coverage).
    #[arg(long, conflicts_with_all = ["planner", "racer"])]
    pub random: bool,
    /// Drive a coverage planner instead of the policy, on the same episodes and car (search
    /// envs): `map` knows the map and its exact pose (how much ground there is to cover),
    /// `frontier` is a frontier explorer that builds its map from the LiDAR (the classic
    /// exploration baseline). A bare `--planner` is `map`.
    #[arg(long, value_enum, num_args = 0..=1, default_missing_value = "map", value_name = "KIND",
          conflicts_with = "racer")]
    pub planner: Option<planner::Knowledge>,
    /// Drive a classical racer instead of the policy, on the same episodes and car (racing
    /// envs): pure pursuit along `--raceline` or the centre line, or follow-the-gap from the
    /// LiDAR alone. The lap times a policy should beat.
    #[arg(long, value_enum, value_name = "KIND")]
    pub racer: Option<crate::racer::RacerKind>,
    /// Pure pursuit's path: F1TENTH's raceline CSV (`s_m; x_m; y_m; psi_rad; ...`) or an x, y
    /// CSV (default: the track's centre line).
    #[arg(long, value_name = "FILE.csv", requires = "racer")]
    pub raceline: Option<PathBuf>,
    /// The racer's speed: a scale of pure pursuit's speed profile or of follow-the-gap's top
    /// speed.
    #[arg(long, default_value_t = 1.0, value_name = "SCALE")]
    pub speed_scale: f64,
    /// Write every episode's coverage after each control to this CSV
    /// (`episode,step,time_s,coverage`; search envs); `agvrl coverage-plot` overlays several.
    #[arg(long, value_name = "FILE.csv")]
    pub coverage_csv: Option<PathBuf>,
    /// Write one line per episode to this CSV (`episode,seed,track,lap_m,width_m,min_radius_m,
    /// ended,laps,first_lap_s,best_lap_s,return`; racing envs): the per-circuit figures of a
    /// table by track.
    #[arg(long, value_name = "FILE.csv")]
    pub episodes_csv: Option<PathBuf>,
    /// Also write the evaluation as JSON into this file: the typed report a run directory keeps
    /// as eval.json.
    #[arg(long, value_name = "FILE.json")]
    pub json: Option<PathBuf>,
}

/// Who drives an evaluation.
pub enum Driver<'a> {
    /// The policy, deterministic actions.
    Policy(&'a mut Policy),
    /// The policy, actions sampled as in training; episode k seeds the noise with S + k.
    Sampled(&'a mut Policy),
    /// Uniform random actions, the baseline a policy should beat.
    Random,
    /// A coverage planner (`crate::planner`), search envs only.
    Planner(planner::Knowledge),
    /// A classical racer (`crate::racer`), racing envs only.
    Racer(Box<dyn agvrl_envs::drivers::Driver>),
}

/// What deterministic evaluation found.
pub struct Summary {
    pub episodes: usize,
    pub mean_return: f64,
    pub collisions: usize,
    pub laps: u32,
    pub best_lap_s: Option<f64>,
    /// Episodes that lapped without a crash, and each lapping episode's first lap, s.
    pub lapped: usize,
    pub first_laps_s: Vec<f64>,
    pub coverage: Option<f64>,
    /// Subjects found / placed, summed over episodes, and the find times.
    pub subjects: (usize, usize, Vec<f64>),
    pub racing: bool,
    /// Why each episode ended, in order.
    pub ended: Vec<&'static str>,
    /// Steps whose control the safety filter changed, summed over episodes (`None`: no filter).
    pub filter_interventions: Option<u64>,
    /// Path length, summed over episodes (search envs).
    pub distance_m: f64,
    /// One row per episode of a racing env (`--episodes-csv`).
    pub episode_rows: Vec<EpisodeRow>,
    /// Per-step figures of search envs.
    pub search: SearchStats,
}

/// One racing episode: where it drove and how it ended.
#[derive(Clone, Debug, Default)]
pub struct EpisodeRow {
    pub seed: u64,
    pub track: String,
    pub lap_m: f64,
    /// A generated circuit's width and tightest centre-line radius, metres (None elsewhere).
    pub circuit: Option<(f32, f32)>,
    pub ended: &'static str,
    pub laps: u32,
    pub first_lap_s: Option<f64>,
    pub best_lap_s: Option<f64>,
    pub ret: f64,
}

/// `--episodes-csv`: a header and one line per episode.
pub fn episodes_csv(rows: &[EpisodeRow]) -> String {
    let opt = |v: Option<f64>| v.map_or_else(String::new, |x| format!("{x:.3}"));
    let mut out =
        String::from("episode,seed,track,lap_m,width_m,min_radius_m,ended,laps,first_lap_s,best_lap_s,return\n");
    for (k, r) in rows.iter().enumerate() {
        let (w, rad) = r.circuit.map_or_else(
            || (String::new(), String::new()),
            |(w, m)| (format!("{w:.3}"), format!("{m:.3}")),
        );
        out.push_str(&format!(
            "{k},{},{},{:.2},{w},{rad},{},{},{},{},{:.3}\n",
            r.seed,
            r.track,
            r.lap_m,
            r.ended,
            r.laps,
            opt(r.first_lap_s),
            opt(r.best_lap_s),
            r.ret
        ));
    }
    out
}

/// The row of a racing episode that ended with `last` on `env`'s track.
fn episode_row(
    env: &crate::episode::SimEnv,
    env_cfg: &EnvConfig,
    seed: u64,
    ret: f64,
    last: &Step,
    ended: &'static str,
) -> Option<EpisodeRow> {
    let r = last.info.racing.as_ref()?;
    let inner = env.inner();
    let scene = inner.vehicle().sim().scene();
    let track = scene.file.name.clone();
    let lap_m = inner
        .vehicle()
        .map()
        .and_then(|m| m.track.as_ref())
        .map_or(0.0, |t| t.lap_length_m() as f64);
    // A generated circuit's name carries its seed: its width and radius come from regenerating it.
    let circuit = track
        .strip_prefix("circuit-")
        .and_then(|s| s.parse::<u64>().ok())
        .and_then(|s| agvrl_sim::MapTrack::generated(s, &env_cfg.circuit.unwrap_or_default()).ok())
        .map(|(_, info)| (info.width_m, info.min_radius_m));
    Some(EpisodeRow {
        seed,
        track,
        lap_m,
        circuit,
        ended,
        laps: r.laps,
        first_lap_s: r.first_lap_s,
        best_lap_s: r.best_lap_s,
        ret,
    })
}

/// What a search evaluation measures step by step: the filter's corrections by kind, the ride
/// (clearance, steering changes) and coverage over time.
#[derive(Default)]
pub struct SearchStats {
    /// The filter's steered and braked controls, reversing ticks and back-outs begun, summed
    /// over episodes.
    pub filter: [u64; 4],
    /// r_m after every step of every episode (the finite ones), metres.
    pub clearance_m: Vec<f64>,
    /// |change of the steering sent| from one control to the next, summed, rad; and how many
    /// changes were summed.
    pub steering_change_rad: f64,
    pub steering_changes: u64,
    /// Per episode, the coverage after each control (not after reset).
    pub coverage: Vec<Vec<f64>>,
    /// The control period, s.
    pub dt_s: f64,
    last_steering: Option<f64>,
}

impl SearchStats {
    fn see(&mut self, v: &StepView<'_>) {
        if v.step == 0 {
            self.coverage.push(Vec::new());
            self.last_steering = None;
            return;
        }
        let Some(info) = v.info.and_then(|i| i.search.as_ref()) else {
            return;
        };
        if let Some(c) = self.coverage.last_mut() {
            c.push(info.coverage);
        }
        if info.clearance_m.is_finite() {
            self.clearance_m.push(info.clearance_m);
        }
        let steer = v.frame.applied.steering_rad;
        if let Some(p) = self.last_steering {
            self.steering_change_rad += (steer - p).abs();
            self.steering_changes += 1;
        }
        self.last_steering = Some(steer);
    }

    /// Per level, the mean time to reach it over the episodes that did, and how many did.
    pub fn time_to(&self, level: f64) -> (Option<f64>, usize) {
        let times: Vec<f64> = self
            .coverage
            .iter()
            .filter_map(|c| c.iter().position(|v| *v >= level))
            .map(|k| (k + 1) as f64 * self.dt_s)
            .collect();
        let mean = (!times.is_empty()).then(|| times.iter().sum::<f64>() / times.len() as f64);
        (mean, times.len())
    }

    /// The coverage curves as CSV: `episode,step,time_s,coverage`.
    pub fn coverage_csv(&self) -> String {
        let mut out = String::from("episode,step,time_s,coverage\n");
        for (e, c) in self.coverage.iter().enumerate() {
            for (k, v) in c.iter().enumerate() {
                let step = k + 1;
                out.push_str(&format!("{e},{step},{:.4},{v:.5}\n", step as f64 * self.dt_s));
            }
        }
        out
    }
}

impl Summary {
    /// The figures: per-episode means, clearance quantiles, coverage milestones.
    pub fn report(&self) -> EvalReport {
        let per_episode = |n: u64| n as f64 / self.episodes.max(1) as f64;
        let st = &self.search;
        let c = &st.clearance_m;
        EvalReport {
            mean_return: self.mean_return,
            episodes: self.episodes,
            collisions: self.collisions,
            ended: self.ended.iter().map(|e| e.to_string()).collect(),
            subjects: (self.subjects.1 > 0).then(|| {
                let t = &self.subjects.2;
                SubjectsReport {
                    subjects_found: self.subjects.0,
                    subjects_placed: self.subjects.1,
                    mean_find_s: (!t.is_empty()).then(|| t.iter().sum::<f64>() / t.len() as f64),
                }
            }),
            search: self.coverage.map(|coverage| {
                let (t25, n25) = st.time_to(0.25);
                let (t50, n50) = st.time_to(0.5);
                SearchReport {
                    coverage,
                    distance_m_per_episode: self.distance_m / self.episodes.max(1) as f64,
                    clearance_mean_m: (!c.is_empty()).then(|| c.iter().sum::<f64>() / c.len() as f64),
                    clearance_p5_m: (!c.is_empty()).then(|| quantile(c, 0.05)),
                    steering_change_mean_rad: st.steering_change_rad / st.steering_changes.max(1) as f64,
                    time_to_coverage_25_s: t25,
                    coverage_25_reached: n25,
                    time_to_coverage_50_s: t50,
                    coverage_50_reached: n50,
                }
            }),
            filter: self.filter_interventions.map(|n| {
                let f = &st.filter;
                FilterReport {
                    filter_interventions_per_episode: per_episode(n),
                    filter_corrections_per_episode: per_episode(f[0] + f[1]),
                    filter_steered_per_episode: per_episode(f[0]),
                    filter_braked_per_episode: per_episode(f[1]),
                    filter_backouts_per_episode: per_episode(f[3]),
                    filter_backout_ticks_per_episode: per_episode(f[2]),
                }
            }),
            racing: self.racing.then_some(RacingReport {
                laps: self.laps,
                best_lap_s: self.best_lap_s,
                lapped: self.lapped,
                mean_first_lap_s: (!self.first_laps_s.is_empty())
                    .then(|| self.first_laps_s.iter().sum::<f64>() / self.first_laps_s.len() as f64),
            }),
        }
    }
}

fn account(s: &mut Summary, st: &Step, cov_sum: &mut f64) {
    if st.terminated {
        s.collisions += 1;
    }
    use agvrl_envs::api::TerminationCause as C;
    s.ended.push(match (st.terminated, st.info.termination) {
        (false, _) => "time_limit",
        (true, Some(C::Contact)) => "contact",
        (true, Some(C::TooClose)) => "too_close",
        (true, Some(C::Flipped)) => "flipped",
        (true, Some(C::OutOfBounds)) => "out_of_bounds",
        (true, None) => "terminated",
    });
    if let Some(r) = &st.info.racing {
        s.racing = true;
        if let Some(first) = r.first_lap_s {
            s.first_laps_s.push(first);
        }
        if r.laps >= 1 && !st.terminated {
            s.lapped += 1;
        }
        s.laps += r.laps;
        if let Some(b) = r.best_lap_s {
            s.best_lap_s = Some(s.best_lap_s.map_or(b, |x: f64| x.min(b)));
        }
    }
    if let Some(c) = &st.info.search {
        *cov_sum += c.coverage;
        s.distance_m += c.distance_m;
        s.subjects.0 += c.subjects_found;
        s.subjects.1 += c.subjects_total;
        s.subjects.2.extend(&c.find_times_s);
        if let Some(n) = &mut s.filter_interventions {
            *n += c.filter_interventions;
        }
        let f = &mut s.search.filter;
        for (k, n) in [c.filter_steered, c.filter_braked, c.filter_reversed, c.filter_backouts]
            .into_iter()
            .enumerate()
        {
            f[k] += n;
        }
    }
}

/// Deterministic evaluation; `obs` sees every step of vehicle envs.
pub fn evaluate(
    mut driver: Driver<'_>,
    env_id: &str,
    env_cfg: &EnvConfig,
    episodes: usize,
    seed: u64,
    obs: &mut Observer<'_>,
) -> Result<Summary> {
    let mut s = Summary {
        episodes,
        mean_return: 0.0,
        collisions: 0,
        laps: 0,
        best_lap_s: None,
        lapped: 0,
        first_laps_s: Vec::new(),
        coverage: None,
        subjects: (0, 0, Vec::new()),
        racing: false,
        ended: Vec::new(),
        filter_interventions: None,
        distance_m: 0.0,
        episode_rows: Vec::new(),
        search: SearchStats::default(),
    };
    let search = agvrl_envs::registry::spec(env_id).is_some_and(|s| s.task == agvrl_envs::TaskKind::Search);
    if matches!(driver, Driver::Planner(_)) && !search {
        bail!("the planner covers ground: it needs a search env, not {env_id}");
    }
    if matches!(driver, Driver::Racer(_))
        && agvrl_envs::registry::spec(env_id).is_none_or(|s| s.task != agvrl_envs::TaskKind::Racing)
    {
        bail!("a racer laps a track: it needs a racing env, not {env_id}");
    }
    if search && env_cfg.safety_filter.enabled {
        s.filter_interventions = Some(0);
    }
    let mut cov_sum = 0.0;
    let check = |o: &agvrl_envs::BoxSpace, a: &agvrl_envs::BoxSpace, d: &Driver<'_>| match d {
        Driver::Policy(p) | Driver::Sampled(p) => p.check_spaces(o, a).context("the policy does not fit this env"),
        _ => Ok(()),
    };
    let mut random = RandomActions::new(seed);
    let mut act_of = |driver: &mut Driver<'_>, space: &agvrl_envs::BoxSpace, o: &[f32]| -> Result<Vec<f32>> {
        Ok(match driver {
            Driver::Policy(p) => p.act(o, true)?,
            Driver::Sampled(p) => p.act(o, false)?,
            _ => random.sample(&space.low, &space.high),
        })
    };
    match make_sim_env(env_id, env_cfg)? {
        Some(mut env) => {
            check(&env.observation_space(), &env.action_space(), &driver)?;
            let space = env.action_space();
            let stats = std::cell::RefCell::new(SearchStats {
                dt_s: env.dt_s(),
                ..SearchStats::default()
            });
            let mut see = |v: &StepView<'_>| {
                if search {
                    stats.borrow_mut().see(v);
                }
                obs(v)
            };
            for k in 0..episodes {
                let (ret, last) = match &mut driver {
                    Driver::Planner(kind) => planner::drive(&mut env, *kind, seed + k as u64, k, &mut see)?,
                    Driver::Racer(r) => {
                        crate::racer::drive(&mut env, r.as_mut(), env_cfg, seed + k as u64, k, &mut see)?
                    }
                    _ => {
                        if let Driver::Sampled(p) = &mut driver {
                            p.seed(seed + k as u64);
                        }
                        let mut act = |o: &[f32]| act_of(&mut driver, &space, o);
                        drive(&mut env, seed + k as u64, k, &mut act, &mut see)?
                    }
                };
                s.mean_return += ret;
                account(&mut s, &last, &mut cov_sum);
                let ended = s.ended.last().copied().unwrap_or("");
                if let Some(row) = episode_row(&env, env_cfg, seed + k as u64, ret, &last, ended) {
                    s.episode_rows.push(row);
                }
            }
            let f = s.search.filter;
            s.search = SearchStats {
                filter: f,
                ..stats.into_inner()
            };
        }
        None => {
            let mut env = make(env_id, env_cfg)?;
            check(&env.observation_space(), &env.action_space(), &driver)?;
            let space = env.action_space();
            for k in 0..episodes {
                if let Driver::Sampled(p) = &mut driver {
                    p.seed(seed + k as u64);
                }
                let act = |o: &[f32]| act_of(&mut driver, &space, o);
                let (ret, last) = agvrl_rl::eval::run_episode(&mut *env, seed + k as u64, act, |_, _, _| Ok(()))?;
                s.mean_return += ret;
                account(&mut s, &last, &mut cov_sum);
            }
        }
    }
    s.mean_return /= episodes.max(1) as f64;
    if search {
        s.coverage = Some(cov_sum / episodes.max(1) as f64);
    }
    Ok(s)
}

/// Collects evaluated paths (and the scene) for trajectory.png, and records into rerun.
#[derive(Default)]
pub(crate) struct Watch {
    pub(crate) paths: Vec<Path2>,
    pub(crate) scene: Option<agvrl_sim::Scene>,
    pub(crate) rec: Option<Recorder>,
    /// Record only episodes below this index.
    pub(crate) rec_episodes: usize,
    /// Draw only the paths of episodes below this index.
    pub(crate) plot_episodes: usize,
    /// One bag per episode.
    pub(crate) bags: Option<EpisodeBags>,
}

impl Watch {
    pub(crate) fn see(&mut self, v: &StepView<'_>) -> Result<()> {
        if self.scene.is_none() {
            self.scene = Some(v.sim.scene().clone());
        }
        if v.step == 0 && v.episode < self.plot_episodes {
            self.paths.push(Path2 {
                xy: Vec::new(),
                collided: false,
                label: None,
            });
        }
        if v.episode < self.plot_episodes
            && let Some(p) = self.paths.last_mut()
        {
            let t = v.sim.car(0).pose().position_m;
            p.xy.push((t[0], t[1]));
            p.collided |= v.terminated;
        }
        if v.episode < self.rec_episodes
            && let Some(r) = &mut self.rec
        {
            r.step(v)?;
        }
        if let Some(b) = &mut self.bags {
            b.see(v)?;
        }
        Ok(())
    }

    pub(crate) fn plot(&self, path: &std::path::Path, title: &str) -> Result<bool> {
        match &self.scene {
            Some(scene) => plots::trajectory(path, scene, &self.paths, title).map(|_| true),
            None => Ok(false),
        }
    }
}

pub fn eval(a: EvalArgs) -> Result<()> {
    if a.episodes == 0 {
        bail!("--episodes must be at least 1");
    }
    let sets = [a.set.clone(), a.track.iter().map(|p| agvrl_run::track_set(p)).collect()].concat();
    let mut src = match (&a.run, &a.policy, a.racer) {
        // A racer without a policy drives with the default job's settings under --set.
        (None, None, Some(kind)) => PolicySettings::without_policy(
            kind.name(),
            agvrl_run::RunConfig::from_toml_with(crate::config::DEFAULT_TOML, "the default job", &sets)?,
        ),
        _ => PolicySettings::resolve(a.run.as_deref(), a.policy.as_deref(), &sets)?,
    };
    let mut policy = match a.random || a.planner.is_some() || a.racer.is_some() {
        true => None,
        false => Some(src.load_policy()?),
    };
    let env_id = src.env_id(a.env.as_deref())?;
    let mut env_cfg = src.eval_env_config();
    // Every evaluation draws held-out episodes, whatever the settings came from.
    env_cfg.held_out = true;
    if a.layouts == Layouts::Procedural {
        if agvrl_envs::registry::spec(&env_id).is_none_or(|s| s.procedural.is_none()) {
            bail!("--layouts procedural needs a search env (outdoor or urban)");
        }
        env_cfg.layout_seed = Some(0);
        env_cfg.new_layout_each_episode = true;
    }
    if a.preset == Some(Preset::Sim2real) {
        env_cfg = env_cfg.with_sim2real_noise();
    }
    match a.safety_filter {
        Some(Switch::Train) => {
            let Some(run) = &src.run else {
                bail!("--safety-filter train needs a policy that carries its training settings");
            };
            env_cfg.safety_filter = run.train_filter();
        }
        Some(f) => env_cfg.safety_filter.enabled = f == Switch::On,
        None => {}
    }
    env_cfg.safety_filter.advisory = false;
    if let Some(n) = a.max_steps {
        if n == 0 {
            bail!("--max-steps must be at least 1");
        }
        env_cfg.max_steps = n;
    }
    // `--run` takes the run's evaluation seeds (`Seeds::eval_command`), a policy file 0.
    let seed = a.seed.unwrap_or_else(|| match (&a.run, &src.run) {
        (Some(_), Some(run)) => run.seeds().eval_command(),
        _ => 0,
    });
    let mut watch = Watch {
        rec_episodes: a.episodes,
        // Every episode of procedural layouts drives another map: draw the first one only.
        plot_episodes: if a.layouts == Layouts::Procedural {
            1
        } else {
            usize::MAX
        },
        ..Watch::default()
    };
    if let Some(sink) = viz::sink_of(a.rerun.as_deref(), a.spawn_viewer) {
        watch.rec = Some(Recorder::new(
            sink,
            &format!("{} eval", src.policy.display()),
            env_cfg.sim.camera.as_ref(),
        )?);
    }
    if let Some(dir) = &a.record {
        if agvrl_envs::registry::scene_of(&env_id).is_none() {
            bail!("--record needs a vehicle env, not {env_id}");
        }
        let file = policy.as_ref().map(|_| src.policy.as_path());
        watch.bags = Some(EpisodeBags::new(dir, file, &env_id, &env_cfg)?);
    }
    if !(a.speed_scale.is_finite() && a.speed_scale > 0.0 && a.speed_scale <= 2.0) {
        bail!("--speed-scale must be in (0, 2], got {}", a.speed_scale);
    }
    let racer = a.racer.map(|kind| crate::racer::RacerSpec {
        kind,
        raceline: a.raceline.clone(),
        speed_scale: a.speed_scale,
    });
    let driver = match (&mut policy, a.planner, &racer) {
        (Some(p), _, _) if a.sampled => Driver::Sampled(p),
        (Some(p), _, _) => Driver::Policy(p),
        (None, Some(kind), _) => Driver::Planner(kind),
        (None, None, Some(r)) => Driver::Racer(crate::racer::make(r, &env_cfg)?),
        (None, None, None) => Driver::Random,
    };
    let s = evaluate(driver, &env_id, &env_cfg, a.episodes, seed, &mut |v| watch.see(v))?;
    println!("env={env_id}");
    println!(
        "policy={}",
        if a.random {
            "random".to_string()
        } else if let Some(r) = &racer {
            match &r.raceline {
                Some(p) => format!(
                    "{} raceline={} speed_scale={}",
                    r.kind.name(),
                    p.display(),
                    r.speed_scale
                ),
                None => format!("{} speed_scale={}", r.kind.name(), r.speed_scale),
            }
        } else if let Some(kind) = a.planner {
            match kind {
                planner::Knowledge::Map => "planner".to_string(),
                planner::Knowledge::Frontier => "frontier".to_string(),
            }
        } else if a.run.is_some() {
            files::POLICY.to_string()
        } else {
            src.policy.display().to_string()
        }
    );
    if a.sampled {
        println!("actions=sampled");
    }
    println!("settings={}", src.source);
    println!("seed={seed}");
    println!("layouts={}", arg_name(a.layouts));
    println!("preset={}", a.preset.map_or_else(|| "none".to_string(), arg_name));
    if let Some(t) = &env_cfg.track {
        let t = t.load()?;
        println!(
            "track={} track_crc32={} centreline={} lap_m={:.2} walls={}",
            t.name,
            t.crc32,
            t.centreline_source,
            t.lap_length_m(),
            t.walls.len()
        );
    }
    println!(
        "safety_filter={}",
        match (env_cfg.safety_filter.enabled, a.safety_filter) {
            (false, _) => "off",
            (true, Some(Switch::Train)) => "train",
            (true, _) => "on",
        }
    );
    let report = s.report();
    for l in report.lines() {
        println!("{l}");
    }
    if let Some(p) = &a.json {
        agvrl_run::write_atomic(p, report.to_json().as_bytes())?;
        println!("json={}", p.display());
    }
    if let Some(p) = &a.episodes_csv {
        if s.episode_rows.is_empty() {
            bail!("--episodes-csv needs a racing env, not {env_id}");
        }
        agvrl_run::write_atomic(p, episodes_csv(&s.episode_rows).as_bytes())?;
        println!("episodes_csv={}", p.display());
    }
    if let Some(p) = &a.coverage_csv {
        if s.coverage.is_none() {
            bail!("--coverage-csv needs a search env, not {env_id}");
        }
        agvrl_run::write_atomic(p, s.search.coverage_csv().as_bytes())?;
        println!("coverage_csv={}", p.display());
    }
    if let Some(r) = watch.rec.take()
        && let Some(p) = r.finish()?
    {
        println!("rrd={}", p.display());
    }
    if let Some(b) = watch.bags.take() {
        let written = b.finish()?;
        let messages: u64 = written.iter().map(|(_, n)| n).sum();
        if let Some(d) = &a.record {
            println!("bags={}", d.display());
        }
        println!("bag_episodes={}", written.len());
        println!("bag_messages={messages}");
    }
    if let Some(p) = &a.plot {
        let algo = src
            .run
            .as_ref()
            .map_or_else(|| "policy".to_string(), |r| r.algo.to_string());
        let driver = match (a.random, a.planner, a.racer) {
            (true, _, _) => "random actions",
            (_, Some(planner::Knowledge::Map), _) => "map-aware planner",
            (_, Some(planner::Knowledge::Frontier), _) => "frontier explorer",
            (_, _, Some(k)) => k.name(),
            _ => algo.as_str(),
        };
        let on = env_cfg.track_suffix();
        let how = if a.sampled {
            "sampled actions"
        } else {
            "deterministic evaluation"
        };
        if !watch.plot(p, &format!("{env_id}{on} {driver}: {how}"))? {
            bail!("{env_id} has no map to draw");
        }
        println!("plot={}", p.display());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::{SearchStats, quantile};

    #[test]
    fn quantile_takes_the_nearest_rank() {
        let v: Vec<f64> = (1..=100).rev().map(f64::from).collect();
        assert_eq!(quantile(&v, 0.05), 5.0);
        assert_eq!(quantile(&v, 0.0), 1.0);
        assert_eq!(quantile(&v, 1.0), 100.0);
        assert_eq!(quantile(&[2.5], 0.05), 2.5);
        assert!(quantile(&[], 0.05).is_nan());
    }

    #[test]
    fn time_to_a_coverage_level_counts_only_the_episodes_that_reach_it() {
        let s = SearchStats {
            coverage: vec![vec![0.1, 0.3, 0.6], vec![0.2, 0.2, 0.26], vec![0.1]],
            dt_s: 0.5,
            ..SearchStats::default()
        };
        // 0.25: after control 2 (1 s) and control 3 (1.5 s); the third episode never.
        assert_eq!(s.time_to(0.25), (Some(1.25), 2));
        assert_eq!(s.time_to(0.5), (Some(1.5), 1));
        assert_eq!(s.time_to(0.9), (None, 0));
        assert_eq!(s.coverage_csv().lines().nth(3), Some("0,3,1.5000,0.60000"));
    }
}
