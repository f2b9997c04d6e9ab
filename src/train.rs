//! `agvrl train` and `agvrl eval`.

use crate::config::{DEFAULT_TOML, RunConfig};
use crate::episode::{Observer, RandomActions, StepView, drive, make_sim_env};
use crate::plots::{self, Path2};
use crate::runs::{RunDir, stamp, write_atomic};
use crate::viz::{self, Recorder, Sink};
use agvrl_envs::{Env, EnvConfig, Step, VecEnv, make};
use agvrl_rl::{Algorithm, Control, Policy, Ppo, Progress, Sac};
use anyhow::{Context, Result, bail};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use std::fmt::Write as _;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

/// Name of the policy file in a run directory.
pub const POLICY_FILE: &str = "policy.agvrl";

/// `--device`: the Burn device learners train on.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum DeviceArg {
    /// burn-flex on the CPU.
    #[default]
    Flex,
    /// burn-ndarray on the CPU (agvrl-rl's `ndarray` feature).
    Ndarray,
    /// CUDA GPU (the `cuda` feature).
    Cuda,
    /// wgpu GPU (the `wgpu` feature).
    Wgpu,
}

impl DeviceArg {
    /// The name `agvrl_rl::device_by_name` takes.
    pub fn name(self) -> &'static str {
        match self {
            Self::Flex => "flex",
            Self::Ndarray => "ndarray",
            Self::Cuda => "cuda",
            Self::Wgpu => "wgpu",
        }
    }
}

#[derive(Args, Default)]
pub struct TrainArgs {
    /// Environment id (see `agvrl envs`).
    #[arg(long)]
    pub env: Option<String>,
    /// Algorithm: ppo or sac. SAC takes one gradient step per env step collected, however
    /// many envs run (`sac.gradient_steps = -1`, Stable-Baselines3's ratio on one env).
    #[arg(long)]
    pub algo: Option<Algorithm>,
    /// Environment steps to train.
    #[arg(long)]
    pub steps: Option<u64>,
    /// Seed of the whole run.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Number of parallel environments (default: the config's n_envs, 8 in
    /// configs/default.toml).
    #[arg(long)]
    pub n_envs: Option<usize>,
    /// Run configuration TOML (default: configs/default.toml).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Run directory to create (default: runs/<date-time>-<env>-<algo>).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Compute device: flex or ndarray (CPU), cuda or wgpu (builds with that feature).
    #[arg(long, value_enum, default_value_t = DeviceArg::Flex)]
    pub device: DeviceArg,
    /// Continue an interrupted (or finished) run directory up to its configured steps, or
    /// --steps more.
    #[arg(long, conflicts_with_all = ["env", "algo", "seed", "n_envs", "config", "out", "set"])]
    pub resume: Option<PathBuf>,
    /// Set one key of the run config, KEY=VALUE with a TOML value and a dotted key
    /// (`--set ppo.learning_rate=1e-4 --set env_config.max_steps=500 --set threads=1`); applied
    /// after --config, before --env/--algo/--steps/--seed/--n-envs.
    #[arg(long, value_name = "KEY=VALUE")]
    pub set: Vec<String>,
    /// Progress output: a bar on stderr (bar), none, or JSON lines on stdout (json: one
    /// `{"event":"progress",...}` object per update and a last `{"event":"done",...}` with the
    /// run directory and the evaluation; for drivers such as sweeps, and the process then also
    /// stops, with a complete run directory, when the process that started it exits).
    #[arg(long, value_enum, default_value_t = ProgressMode::Bar)]
    pub progress: ProgressMode,
}

/// How training reports progress.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum ProgressMode {
    /// A progress bar on stderr.
    #[default]
    Bar,
    /// Nothing until the end.
    None,
    /// JSON lines on stdout.
    Json,
}

/// Set by Ctrl-C: the CLI's training finishes the current update and writes its run directory.
static STOP: AtomicBool = AtomicBool::new(false);

/// The two learners, as the training loop sees them.
trait Learner {
    fn learn(&mut self, steps: u64, cb: &mut dyn FnMut(&Progress<'_>) -> Control) -> agvrl_rl::Result<()>;
    fn num_timesteps(&self) -> u64;
    fn save_checkpoint(&self, p: &std::path::Path) -> agvrl_rl::Result<()>;
    fn save_policy(&self, p: &std::path::Path) -> agvrl_rl::Result<()>;
}

macro_rules! learner {
    ($t:ty) => {
        impl Learner for $t {
            fn learn(&mut self, steps: u64, cb: &mut dyn FnMut(&Progress<'_>) -> Control) -> agvrl_rl::Result<()> {
                <$t>::learn(self, steps, cb)
            }
            fn num_timesteps(&self) -> u64 {
                <$t>::num_timesteps(self)
            }
            fn save_checkpoint(&self, p: &std::path::Path) -> agvrl_rl::Result<()> {
                <$t>::save_checkpoint(self, p)
            }
            fn save_policy(&self, p: &std::path::Path) -> agvrl_rl::Result<()> {
                <$t>::save_policy(self, p)
            }
        }
    };
}
learner!(Ppo<Box<dyn Env>>);
learner!(Sac<Box<dyn Env>>);

#[derive(Args)]
pub struct EvalArgs {
    /// A run directory written by `agvrl train` (its policy, env and env settings).
    #[arg(long, required_unless_present = "policy", conflicts_with = "policy")]
    pub run: Option<PathBuf>,
    /// A policy file; env and env settings come from FILE.toml beside it when present (a run's
    /// config.toml, as shipped in assets/policies), else from the config.toml of the run
    /// directory holding it (runs/<dir>/policy.agvrl), else --env with the default settings.
    #[arg(long)]
    pub policy: Option<PathBuf>,
    /// Base of the evaluation episodes' seeds: episode k resets with seed S + k, drawn from the
    /// held-out half of the seed space that training never uses (default: the run's seed +
    /// 2,000,000, or 0 for --policy).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Maps: builtin (the env's own map) or procedural (a new held-out layout of the env's kind
    /// and size every episode, never one a training run drew).
    #[arg(long, default_value = "builtin", value_parser = ["builtin", "procedural"])]
    pub layouts: String,
    /// Env preset applied on top of the policy's env settings: sim2real adds sensor noise,
    /// latency and domain randomisation.
    #[arg(long, value_parser = ["sim2real"])]
    pub preset: Option<String>,
    /// Episode length limit, control steps (default: the run's evaluation limit).
    #[arg(long)]
    pub max_steps: Option<u64>,
    /// Number of deterministic episodes.
    #[arg(long, default_value_t = 5)]
    pub episodes: usize,
    /// Record the episodes into this rerun file (.rrd; open it with `rerun FILE`).
    #[arg(long, value_name = "FILE.rrd", conflicts_with = "spawn_viewer")]
    pub rerun: Option<PathBuf>,
    /// Stream the episodes to a rerun viewer started from `rerun` on your PATH.
    #[arg(long)]
    pub spawn_viewer: bool,
    /// Also draw the evaluated paths over the map into this PNG.
    #[arg(long, value_name = "FILE.png")]
    pub plot: Option<PathBuf>,
    /// Evaluate on another env with the same spaces (a generalisation test, e.g. a policy
    /// trained on search-outdoor-20 run on search-urban-50); the run's env settings are kept.
    #[arg(long, value_name = "ID")]
    pub env: Option<String>,
    /// Drive uniform random actions instead of the policy, on the same episodes: the baseline
    /// the policy should beat (e.g. its coverage).
    #[arg(long)]
    pub random: bool,
}

#[derive(Args)]
pub struct ViewArgs {
    /// Environment id (see `agvrl envs`).
    #[arg(long, required_unless_present = "run")]
    pub env: Option<String>,
    /// Drive with this policy file (default: uniform random actions).
    #[arg(long)]
    pub policy: Option<PathBuf>,
    /// Take env, env settings and policy from a run directory.
    #[arg(long, conflicts_with_all = ["env"])]
    pub run: Option<PathBuf>,
    /// Seed of the episode (spawn, random actions).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Episode length limit, control steps (default: the env's).
    #[arg(long)]
    pub steps: Option<u64>,
    /// Write the recording here (default: view-<env>.rrd).
    #[arg(long, value_name = "FILE.rrd", conflicts_with = "spawn_viewer")]
    pub rerun: Option<PathBuf>,
    /// Stream to a rerun viewer started from `rerun` on your PATH instead of a file.
    #[arg(long)]
    pub spawn_viewer: bool,
    /// Mount the vehicle camera (160x120, 80 degrees) and record its RGB, depth and
    /// segmentation images.
    #[arg(long)]
    pub camera: bool,
}

struct Row {
    step: u64,
    episodes: u64,
    mean_return: Option<f64>,
    policy_loss: f64,
    value_loss: f64,
    entropy: f64,
    steps_per_s: f64,
}

fn resolve(a: &TrainArgs) -> Result<RunConfig> {
    let (text, origin) = match &a.config {
        Some(p) => (
            std::fs::read_to_string(p).with_context(|| format!("cannot read {}", p.display()))?,
            p.display().to_string(),
        ),
        None => (DEFAULT_TOML.to_string(), "configs/default.toml (built in)".to_string()),
    };
    let mut cfg = RunConfig::from_toml_with(&text, &origin, &a.set)?;
    if let Some(v) = &a.env {
        cfg.env = v.clone();
    }
    if let Some(v) = a.algo {
        cfg.algo = v;
    }
    if let Some(v) = a.steps {
        cfg.steps = v;
    }
    if let Some(v) = a.seed {
        cfg.seed = v;
    }
    if let Some(v) = a.n_envs {
        cfg.n_envs = v;
    }
    Ok(cfg)
}

/// An env that appends camera channels gets the CNN encoder in both learners, sized to the
/// image, unless the config already names one (its `features_dim` is kept).
fn image_spec_from_env(cfg: &mut RunConfig) {
    let img = &cfg.env_config.observation.image;
    if img.is_empty() {
        return;
    }
    let (h, w) = (img.height as usize, img.width as usize);
    let spec = agvrl_rl::ImageSpec::new(img.len() / (h * w), h, w);
    let keep = |s: Option<agvrl_rl::ImageSpec>| {
        Some(agvrl_rl::ImageSpec {
            features_dim: s.map_or(spec.features_dim, |s| s.features_dim),
            ..spec
        })
    };
    cfg.ppo.image = keep(cfg.ppo.image);
    cfg.sac.image = keep(cfg.sac.image);
}

fn vec_env(cfg: &RunConfig) -> Result<VecEnv<Box<dyn Env>>> {
    let envs = (0..cfg.n_envs)
        .map(|i| make(cfg.train_env_id(i), &cfg.train_env_config(i)))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(VecEnv::new(envs, cfg.threads)?)
}

pub fn train(a: TrainArgs) -> Result<()> {
    if STOP_HANDLER.set(()).is_ok() {
        // A second Ctrl-C falls through to the default (kill) only after this one is handled.
        let _ = ctrlc::set_handler(|| {
            if STOP.swap(true, Ordering::SeqCst) {
                std::process::exit(130);
            }
            eprintln!("\ninterrupt: finishing the current update, then writing a checkpoint and the run directory");
        });
    }
    if let Some(dir) = &a.resume {
        let device = agvrl_rl::device_by_name(a.device.name())?;
        let cfg = RunConfig::load(&dir.join("config.toml"))
            .with_context(|| format!("{} is not a run directory", dir.display()))?;
        let ckpt = dir.join("checkpoint.ckpt");
        let mut learner: Box<dyn Learner> = if cfg.algo == Algorithm::Ppo {
            Box::new(Ppo::load_checkpoint(&ckpt, vec_env(&cfg)?, &device)?)
        } else {
            Box::new(Sac::load_checkpoint(&ckpt, vec_env(&cfg)?, &device)?)
        };
        let target = match a.steps {
            Some(more) => learner.num_timesteps() + more,
            None => cfg.steps,
        };
        let previous = std::fs::read_to_string(dir.join("metrics.csv")).unwrap_or_default();
        eprintln!(
            "resuming {} at step {} up to {target}",
            dir.display(),
            learner.num_timesteps()
        );
        let files = |name: &str| dir.join(name);
        let text = run_learner(learner.as_mut(), &cfg, target, &files, &previous, &STOP, a.progress)?;
        println!("run_dir={}", dir.display());
        print!("{text}");
        return Ok(());
    }
    let cfg = resolve(&a)?;
    if a.progress == ProgressMode::Json {
        stop_with_parent(&STOP);
    }
    let (dir, text) = train_run(cfg, a.out.clone(), a.device.name(), &STOP, a.progress)?;
    if a.progress == ProgressMode::Json {
        println!("{}", done_json(&dir, &text));
    } else {
        println!("run_dir={}", dir.display());
        print!("{text}");
    }
    Ok(())
}

/// Stop (as Ctrl-C does) once the process that started this one exits, so a killed driver
/// leaves no training behind. Polled: a reparented process sees another parent id.
fn stop_with_parent(stop: &'static AtomicBool) {
    let parent = std::os::unix::process::parent_id();
    let _ = std::thread::Builder::new()
        .name("agvrl-parent-watch".into())
        .spawn(move || {
            loop {
                std::thread::sleep(std::time::Duration::from_millis(200));
                if std::os::unix::process::parent_id() != parent {
                    eprintln!(
                        "the parent process exited: finishing the current update, then writing the run directory"
                    );
                    stop.store(true, Ordering::SeqCst);
                    return;
                }
            }
        });
}

/// The last JSON progress line: the run directory and eval.txt's key=value pairs (numbers as
/// numbers).
fn done_json(dir: &std::path::Path, eval_text: &str) -> String {
    let metrics: serde_json::Map<String, serde_json::Value> = eval_text
        .lines()
        .filter_map(|l| l.split_once('='))
        .map(|(k, v)| {
            let v = match v.parse::<f64>() {
                Ok(x) if x.is_finite() => serde_json::json!(x),
                _ if v == "true" || v == "false" => serde_json::json!(v == "true"),
                _ => serde_json::json!(v),
            };
            (k.to_string(), v)
        })
        .collect();
    serde_json::json!({
        "event": "done",
        "run_dir": dir.display().to_string(),
        "interrupted": metrics.get("interrupted").is_some_and(|v| v == &serde_json::json!(true)),
        "metrics": metrics,
    })
    .to_string()
}

/// Train `cfg` into a new run directory (`out`, or runs/<date-time>-<env>-<algo>), stopping
/// early, with a complete run directory, once `stop` is set. `device` as `--device` (empty:
/// flex). Returns the directory and the text of its eval.txt.
pub fn train_run(
    cfg: RunConfig,
    out: Option<PathBuf>,
    device: &str,
    stop: &AtomicBool,
    progress: ProgressMode,
) -> Result<(PathBuf, String)> {
    let device = agvrl_rl::device_by_name(if device.is_empty() { "flex" } else { device })?;
    let device = &device;
    let mut cfg = cfg;
    image_spec_from_env(&mut cfg);
    cfg.validate()?;
    let run = match out {
        Some(out) => RunDir::create(out)?,
        None => RunDir::create_unique(PathBuf::from("runs").join(format!("{}-{}-{}", stamp(), cfg.env, cfg.algo)))?,
    };
    write_atomic(&run.file("config.toml"), cfg.to_toml()?.as_bytes())?;
    eprintln!(
        "training {} on {} for {} steps (seed {}, {} envs)",
        cfg.algo, cfg.env, cfg.steps, cfg.seed, cfg.n_envs
    );
    let mut learner: Box<dyn Learner> = if cfg.algo == Algorithm::Ppo {
        Box::new(Ppo::new(cfg.ppo.clone(), vec_env(&cfg)?, device, cfg.seed)?)
    } else {
        Box::new(Sac::new(cfg.sac.clone(), vec_env(&cfg)?, device, cfg.seed)?)
    };
    let files = |name: &str| run.file(name);
    let text = run_learner(learner.as_mut(), &cfg, cfg.steps, &files, "", stop, progress)?;
    let dir = run.finish()?;
    Ok((dir, text))
}

static STOP_HANDLER: std::sync::OnceLock<()> = std::sync::OnceLock::new();

/// Train `learner` up to `target` steps (or a Ctrl-C), checkpointing every tenth; write
/// checkpoint, policy, metrics (after `previous_csv`) and the evaluation. Returns eval.txt.
fn run_learner(
    learner: &mut dyn Learner,
    cfg: &RunConfig,
    target: u64,
    file: &dyn Fn(&str) -> PathBuf,
    previous_csv: &str,
    stop: &AtomicBool,
    progress: ProgressMode,
) -> Result<String> {
    let start = learner.num_timesteps();
    let bar = match progress {
        ProgressMode::Bar => ProgressBar::new(target),
        _ => ProgressBar::hidden(),
    };
    bar.set_position(start.min(target));
    bar.set_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} steps  {per_sec}  ETA {eta}  {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let t0 = Instant::now();
    let mut rows: Vec<Row> = Vec::new();
    let mut on_progress = |p: &Progress<'_>| {
        bar.set_position(p.steps.min(target));
        let mean = p.mean_return();
        if let Some(m) = mean {
            bar.set_message(format!("mean return {m:.1}"));
        }
        if progress == ProgressMode::Json {
            println!(
                "{}",
                serde_json::json!({
                    "event": "progress",
                    "steps": p.steps,
                    "target_steps": target,
                    "updates": p.updates,
                    "episodes": p.episodes,
                    "mean_return": mean.filter(|m| m.is_finite()),
                    "wall_s": t0.elapsed().as_secs_f64(),
                })
            );
        }
        rows.push(Row {
            step: p.steps,
            episodes: p.episodes,
            mean_return: mean,
            policy_loss: p.losses.policy,
            value_loss: p.losses.value,
            entropy: p.losses.entropy,
            steps_per_s: (p.steps - start) as f64 / t0.elapsed().as_secs_f64().max(1e-9),
        });
        if stop.load(Ordering::SeqCst) {
            Control::Stop
        } else {
            Control::Continue
        }
    };
    // Checkpoint at least every tenth of the run and every 50,000 steps.
    let per_chunk = cfg.steps.div_ceil(10).clamp(1, 50_000);
    while learner.num_timesteps() < target && !stop.load(Ordering::SeqCst) {
        learner.learn(per_chunk.min(target - learner.num_timesteps()), &mut on_progress)?;
        learner.save_checkpoint(&file("checkpoint.ckpt"))?;
    }
    learner.save_checkpoint(&file("checkpoint.ckpt"))?;
    let policy_path = file(POLICY_FILE);
    learner.save_policy(&policy_path)?;
    bar.finish_and_clear();
    let interrupted = learner.num_timesteps() < target;
    let train_s = t0.elapsed().as_secs_f64();
    let mut csv = if previous_csv.is_empty() {
        String::from("step,episodes,mean_return,policy_loss,value_loss,entropy,steps_per_s\n")
    } else {
        previous_csv.to_string()
    };
    for r in &rows {
        let mean = r.mean_return.map(|m| format!("{m:.4}")).unwrap_or_default();
        let _ = writeln!(
            csv,
            "{},{},{mean},{:.6},{:.6},{:.6},{:.1}",
            r.step, r.episodes, r.policy_loss, r.value_loss, r.entropy, r.steps_per_s
        );
    }
    write_atomic(&file("metrics.csv"), csv.as_bytes())?;
    let mut policy = Policy::load(&policy_path)?;
    let mut watch = Watch {
        rec_episodes: 1,
        plot_episodes: usize::MAX,
        ..Watch::default()
    };
    if viz::ENABLED && agvrl_envs::registry::scene_of(&cfg.env).is_some() {
        watch.rec = Some(Recorder::new(
            Sink::File(file("eval.rrd")),
            &format!("{} {} eval", cfg.env, cfg.algo),
        )?);
    }
    let summary = evaluate(
        Some(&mut policy),
        &cfg.env,
        &cfg.eval_env_config(),
        cfg.eval_episodes,
        cfg.seed + 1_000_000,
        &mut |v| watch.see(v),
    )?;
    if let Some(r) = watch.rec.take() {
        r.finish()?;
    }
    let title = format!("{} {} seed {}", cfg.env, cfg.algo, cfg.seed);
    watch.plot(&file("trajectory.png"), &format!("{title}: deterministic evaluation"))?;
    plots::learning_curve(&file("learning_curve.png"), &plots::curve_of_csv(&csv), &title)?;
    let mut text = format!(
        "train_s={:.1}\neval_s={:.1}\nsteps={}\n",
        train_s,
        t0.elapsed().as_secs_f64() - train_s,
        learner.num_timesteps()
    );
    if interrupted {
        text.push_str("interrupted=true\n");
    }
    for l in summary.lines() {
        let _ = writeln!(text, "{l}");
    }
    write_atomic(&file("eval.txt"), text.as_bytes())?;
    Ok(text)
}

/// What deterministic evaluation found.
pub struct Summary {
    pub episodes: usize,
    pub mean_return: f64,
    pub collisions: usize,
    pub laps: u32,
    pub best_lap_s: Option<f64>,
    pub coverage: Option<f64>,
    /// Subjects found / placed, summed over episodes, and the find times.
    pub subjects: (usize, usize, Vec<f64>),
    pub racing: bool,
    /// Why each episode ended, in order.
    pub ended: Vec<&'static str>,
}

impl Summary {
    pub fn lines(&self) -> Vec<String> {
        let mut v = vec![
            format!("mean_return={:.2}", self.mean_return),
            format!("episodes={}", self.episodes),
            format!("collisions={}", self.collisions),
            format!("ended={}", self.ended.join(",")),
        ];
        if self.subjects.1 > 0 {
            v.push(format!("subjects_found={}/{}", self.subjects.0, self.subjects.1));
            let t = &self.subjects.2;
            if !t.is_empty() {
                v.push(format!("mean_find_s={:.2}", t.iter().sum::<f64>() / t.len() as f64));
            }
        }
        if let Some(c) = self.coverage {
            v.push(format!("coverage={c:.3}"));
        }
        if self.racing {
            v.push(format!("laps={}", self.laps));
            v.push(format!(
                "best_lap_s={}",
                self.best_lap_s
                    .map(|b| format!("{b:.2}"))
                    .unwrap_or_else(|| "none".into())
            ));
        }
        v
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
        s.laps += r.laps;
        if let Some(b) = r.best_lap_s {
            s.best_lap_s = Some(s.best_lap_s.map_or(b, |x: f64| x.min(b)));
        }
    }
    if let Some(c) = &st.info.search {
        *cov_sum += c.coverage;
        s.subjects.0 += c.subjects_found;
        s.subjects.1 += c.subjects_total;
        s.subjects.2.extend(&c.find_times_s);
    }
}

/// Deterministic evaluation; `obs` sees every step of vehicle envs.
pub fn evaluate(
    mut policy: Option<&mut Policy>,
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
        coverage: None,
        subjects: (0, 0, Vec::new()),
        racing: false,
        ended: Vec::new(),
    };
    let mut cov_sum = 0.0;
    let check = |o: &agvrl_envs::BoxSpace, a: &agvrl_envs::BoxSpace, p: &Option<&mut Policy>| match p {
        Some(p) => p.check_spaces(o, a).context("the policy does not fit this env"),
        None => Ok(()),
    };
    // Without a policy: uniform random actions, the baseline a policy should beat.
    let mut random = RandomActions::new(seed);
    let mut act_of = |policy: &mut Option<&mut Policy>, space: &agvrl_envs::BoxSpace, o: &[f32]| -> Result<Vec<f32>> {
        Ok(match policy {
            Some(p) => p.act(o, true)?,
            None => random.sample(&space.low, &space.high),
        })
    };
    match make_sim_env(env_id, env_cfg)? {
        Some(mut env) => {
            check(&env.observation_space(), &env.action_space(), &policy)?;
            let space = env.action_space();
            for k in 0..episodes {
                let mut act = |o: &[f32]| act_of(&mut policy, &space, o);
                let (ret, last) = drive(&mut env, seed + k as u64, k, &mut act, obs)?;
                s.mean_return += ret;
                account(&mut s, &last, &mut cov_sum);
            }
        }
        None => {
            let mut env = make(env_id, env_cfg)?;
            check(&env.observation_space(), &env.action_space(), &policy)?;
            let space = env.action_space();
            for k in 0..episodes {
                let (mut o, _) = env.reset(Some(seed + k as u64))?;
                loop {
                    let st = env.step(&act_of(&mut policy, &space, &o)?)?;
                    s.mean_return += st.reward;
                    if st.done() {
                        account(&mut s, &st, &mut cov_sum);
                        break;
                    }
                    o = st.obs;
                }
            }
        }
    }
    s.mean_return /= episodes.max(1) as f64;
    if agvrl_envs::registry::spec(env_id).is_some_and(|s| s.task == agvrl_envs::TaskKind::Search) {
        s.coverage = Some(cov_sum / episodes.max(1) as f64);
    }
    Ok(s)
}

/// Collects evaluated paths (and the scene) for trajectory.png, and records into rerun.
#[derive(Default)]
struct Watch {
    paths: Vec<Path2>,
    scene: Option<agvrl_sim::Scene>,
    rec: Option<Recorder>,
    /// Record only episodes below this index.
    rec_episodes: usize,
    /// Draw only the paths of episodes below this index.
    plot_episodes: usize,
}

impl Watch {
    fn see(&mut self, v: &StepView<'_>) -> Result<()> {
        if self.scene.is_none() {
            self.scene = Some(v.sim.scene().clone());
        }
        if v.step == 0 && v.episode < self.plot_episodes {
            self.paths.push(Path2 {
                xy: Vec::new(),
                collided: false,
            });
        }
        if v.episode < self.plot_episodes
            && let Some(p) = self.paths.last_mut()
        {
            let t = v.sim.base_pose().translation;
            p.xy.push((t.x, t.y));
            p.collided |= v.terminated;
        }
        if v.episode < self.rec_episodes
            && let Some(r) = &mut self.rec
        {
            r.step(v)?;
        }
        Ok(())
    }

    fn plot(&self, path: &std::path::Path, title: &str) -> Result<bool> {
        match &self.scene {
            Some(scene) => plots::trajectory(path, scene, &self.paths, title).map(|_| true),
            None => Ok(false),
        }
    }
}

/// Where `agvrl eval` takes its policy and settings from.
struct EvalSource {
    policy_path: PathBuf,
    env: Option<String>,
    env_config: EnvConfig,
    algo: String,
    seed: u64,
    /// Where the env settings came from (a TOML path, or `default`).
    settings: String,
}

fn eval_source(a: &EvalArgs) -> Result<EvalSource> {
    if let Some(dir) = &a.run {
        let cfg = RunConfig::load(&dir.join("config.toml"))
            .with_context(|| format!("{} is not a run directory", dir.display()))?;
        return Ok(EvalSource {
            policy_path: dir.join(POLICY_FILE),
            env: Some(cfg.env.clone()),
            env_config: cfg.eval_env_config(),
            algo: cfg.algo.to_string(),
            seed: cfg.seed + 2_000_000,
            settings: dir.join("config.toml").display().to_string(),
        });
    }
    let Some(path) = &a.policy else {
        bail!("give --run DIR or --policy FILE");
    };
    let (env, env_config, algo, settings) = match agvrl_deploy::settings_beside(path) {
        Some(side) => {
            let cfg = RunConfig::load(&side).with_context(|| format!("reading {}", side.display()))?;
            (
                Some(cfg.env.clone()),
                cfg.eval_env_config(),
                cfg.algo.to_string(),
                side.display().to_string(),
            )
        }
        None => (None, EnvConfig::default(), "policy".to_string(), "default".to_string()),
    };
    Ok(EvalSource {
        policy_path: path.clone(),
        env,
        env_config,
        algo,
        seed: 0,
        settings,
    })
}

pub fn eval(a: EvalArgs) -> Result<()> {
    if a.episodes == 0 {
        bail!("--episodes must be at least 1");
    }
    let src = eval_source(&a)?;
    let mut policy = match a.random {
        true => None,
        false => {
            Some(Policy::load(&src.policy_path).with_context(|| format!("loading {}", src.policy_path.display()))?)
        }
    };
    let env_id = a
        .env
        .clone()
        .or(src.env.clone())
        .context("--env is needed: the policy has no FILE.toml beside it naming its env")?;
    let mut env_cfg = src.env_config.clone();
    // Every evaluation draws held-out episodes, whatever the settings came from.
    env_cfg.held_out = true;
    if a.layouts == "procedural" {
        if agvrl_envs::registry::spec(&env_id).is_none_or(|s| s.procedural.is_none()) {
            bail!("--layouts procedural needs a search env (outdoor or urban)");
        }
        env_cfg.layout_seed = Some(0);
        env_cfg.new_layout_each_episode = true;
    }
    if a.preset.as_deref() == Some("sim2real") {
        let s2r = EnvConfig::sim2real();
        env_cfg.noise = s2r.noise;
        env_cfg.randomisation = s2r.randomisation;
    }
    if let Some(n) = a.max_steps {
        if n == 0 {
            bail!("--max-steps must be at least 1");
        }
        env_cfg.max_steps = n;
    }
    let seed = a.seed.unwrap_or(src.seed);
    let mut watch = Watch {
        rec_episodes: a.episodes,
        // Every episode of procedural layouts drives another map: draw the first one only.
        plot_episodes: if a.layouts == "procedural" { 1 } else { usize::MAX },
        ..Watch::default()
    };
    if let Some(sink) = viz::sink_of(a.rerun.as_deref(), a.spawn_viewer) {
        watch.rec = Some(Recorder::new(sink, &format!("{} eval", src.policy_path.display()))?);
    }
    let s = evaluate(policy.as_mut(), &env_id, &env_cfg, a.episodes, seed, &mut |v| {
        watch.see(v)
    })?;
    println!("env={env_id}");
    println!(
        "policy={}",
        if a.random {
            "random".to_string()
        } else if a.run.is_some() {
            POLICY_FILE.to_string()
        } else {
            src.policy_path.display().to_string()
        }
    );
    println!("settings={}", src.settings);
    println!("seed={seed}");
    println!("layouts={}", a.layouts);
    println!("preset={}", a.preset.as_deref().unwrap_or("none"));
    for l in s.lines() {
        println!("{l}");
    }
    if let Some(r) = watch.rec.take()
        && let Some(p) = r.finish()?
    {
        println!("rrd={}", p.display());
    }
    if let Some(p) = &a.plot {
        if !watch.plot(p, &format!("{env_id} {}: deterministic evaluation", src.algo))? {
            bail!("{env_id} has no map to draw");
        }
        println!("plot={}", p.display());
    }
    Ok(())
}

/// Drive one episode (policy or random actions) into rerun.
pub fn view(a: ViewArgs) -> Result<()> {
    let (env_id, mut env_cfg, policy_path) = match &a.run {
        Some(dir) => {
            let cfg = RunConfig::load(&dir.join("config.toml"))
                .with_context(|| format!("{} is not a run directory", dir.display()))?;
            let p = a.policy.clone().unwrap_or_else(|| dir.join(POLICY_FILE));
            (cfg.env.clone(), cfg.eval_env_config(), Some(p))
        }
        None => (
            a.env.clone().unwrap_or_default(),
            EnvConfig::default(),
            a.policy.clone(),
        ),
    };
    if let Some(n) = a.steps {
        env_cfg.max_steps = n;
    }
    if a.camera && env_cfg.camera.is_none() {
        env_cfg.camera = Some(Default::default());
    }
    let mut env = make_sim_env(&env_id, &env_cfg)?.with_context(|| format!("{env_id} has no vehicle to view"))?;
    let mut policy = match &policy_path {
        Some(p) => {
            let pol = Policy::load(p).with_context(|| format!("loading {}", p.display()))?;
            pol.check_spaces(&env.observation_space(), &env.action_space())
                .context("the policy does not fit this env")?;
            Some(pol)
        }
        None => None,
    };
    let sink = viz::sink_of(a.rerun.as_deref(), a.spawn_viewer)
        .unwrap_or_else(|| Sink::File(PathBuf::from(format!("view-{env_id}.rrd"))));
    let mut rec = Recorder::new(sink, &format!("{env_id} view"))?;
    let space = env.action_space();
    let mut rng = RandomActions::new(a.seed);
    let mut act = |o: &[f32]| -> Result<Vec<f32>> {
        match &mut policy {
            Some(p) => Ok(p.act(o, true)?),
            None => Ok(rng.sample(&space.low, &space.high)),
        }
    };
    let (ret, last) = drive(&mut env, a.seed, 0, &mut act, &mut |v| rec.step(v))?;
    println!("env={env_id}");
    println!(
        "policy={}",
        policy_path.map_or("random".into(), |p| p.display().to_string())
    );
    println!("steps={}", env.elapsed());
    println!("return={ret:.2}");
    println!("terminated={}", last.terminated);
    if let Some(p) = rec.finish()? {
        println!("rrd={}", p.display());
        eprintln!("open it with: rerun {}", p.display());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use agvrl_envs::task::ImageChannels;

    #[test]
    fn camera_channels_in_the_env_give_both_learners_a_cnn_of_that_shape() {
        let mut cfg = RunConfig::default();
        image_spec_from_env(&mut cfg);
        assert_eq!((cfg.ppo.image, cfg.sac.image), (None, None));

        cfg.env_config.observation.image.channels = ImageChannels::DepthRgb;
        cfg.env_config.observation.image.width = 64;
        cfg.env_config.observation.image.height = 48;
        cfg.sac.image = Some(agvrl_rl::ImageSpec {
            features_dim: 128,
            ..agvrl_rl::ImageSpec::new(1, 1, 1)
        });
        image_spec_from_env(&mut cfg);
        let want = agvrl_rl::ImageSpec::new(4, 48, 64);
        assert_eq!(cfg.ppo.image, Some(want));
        assert_eq!(
            cfg.sac.image,
            Some(agvrl_rl::ImageSpec {
                features_dim: 128,
                ..want
            })
        );
    }
}
