//! `agvrl train`: run configurations resolved from flags, training into a run directory,
//! checkpoints, progress, and the evaluation at the end (`crate::eval`).

use crate::config::{DEFAULT_TOML, RunConfig, TRACK_TOML};
use crate::eval::{Driver, Summary, Watch, evaluate};
use crate::plots::{self};
use crate::selfplay::{Pool, SelfPlayEnv};
use crate::viz::{self, Recorder, Sink};
use agvrl_envs::wrappers::TimeLimit;
use agvrl_envs::{Env, VecEnv, make};
use agvrl_rl::{Algorithm, Control, Device, DeviceChoice, Learner, NetPath, Policy, Ppo, Progress, Sac};
use agvrl_run::{Run, RunDir, RunReport, files, stamp, write_atomic};
use anyhow::{Context, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use std::fmt::Write as _;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

/// `--device`: the Burn device learners train on.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum DeviceArg {
    /// burn-flex on the CPU.
    #[default]
    Flex,
    /// burn-ndarray on the CPU (the `ndarray` feature).
    Ndarray,
    /// CUDA GPU (the `cuda` feature).
    Cuda,
    /// wgpu GPU (the `wgpu` feature).
    Wgpu,
}

impl From<DeviceArg> for DeviceChoice {
    fn from(d: DeviceArg) -> Self {
        match d {
            DeviceArg::Flex => Self::Flex,
            DeviceArg::Ndarray => Self::NdArray,
            DeviceArg::Cuda => Self::Cuda,
            DeviceArg::Wgpu => Self::Wgpu,
        }
    }
}

/// What a learner trains on: the device, and the path its networks take there (the device's
/// own when `None`: the host kernels on the CPU, Burn on a GPU; see [`NetPath`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Compute {
    pub device: DeviceChoice,
    pub net_path: Option<NetPath>,
}

impl From<DeviceChoice> for Compute {
    fn from(device: DeviceChoice) -> Self {
        Self { device, net_path: None }
    }
}

impl Compute {
    /// Set the learner's network path, when one was asked for, and say which it takes.
    fn apply(&self, learner: &mut dyn Learner) {
        if let Some(path) = self.net_path {
            learner.set_net_path(path);
        }
        eprintln!(
            "networks: {} path on {}",
            learner.net_path().name(),
            format!("{:?}", self.device).to_lowercase()
        );
    }
}

/// `--net-path`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum NetPathArg {
    /// The host kernels (the CPU fast path).
    Host,
    /// Burn's tensors and autodiff on the device (what a GPU runs).
    Burn,
}

impl From<NetPathArg> for NetPath {
    fn from(p: NetPathArg) -> Self {
        match p {
            NetPathArg::Host => Self::Host,
            NetPathArg::Burn => Self::Burn,
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
    /// Where the networks run on the device: host (the CPU's fast kernels, the default on
    /// flex and ndarray) or burn (Burn's autodiff, the default on cuda and wgpu; on a CPU
    /// device, a check of the GPU's path).
    #[arg(long, value_enum)]
    pub net_path: Option<NetPathArg>,
    /// Continue an interrupted (or finished) run directory up to its configured steps, or
    /// --steps more.
    #[arg(long, conflicts_with_all = ["env", "algo", "seed", "n_envs", "config", "out", "set", "track"])]
    pub resume: Option<PathBuf>,
    /// Set one key of the run config, KEY=VALUE with a TOML value and a dotted key
    /// (`--set ppo.learning_rate=1e-4 --set env_config.max_steps=500 --set threads=1`); applied
    /// after --config, before --env/--algo/--steps/--seed/--n-envs.
    #[arg(long, value_name = "KEY=VALUE")]
    pub set: Vec<String>,
    /// Race on the track of a ROS map file (its YAML; a centre-line CSV beside it, or traced):
    /// `--set env_config.track=PATH`, loaded into the run config and policy file. Without
    /// --config this trains the per-track recipe, configs/racing-track.toml (built in).
    #[arg(long, value_name = "MAP.yaml")]
    pub track: Option<PathBuf>,
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

struct Row {
    step: u64,
    episodes: u64,
    mean_return: Option<f64>,
    policy_loss: f64,
    value_loss: f64,
    entropy: f64,
    steps_per_s: f64,
    /// PPO's correction constraint: the fraction of the rollout's steps the filter corrected,
    /// and the mean multiplier (NaN without the constraint).
    corrected_fraction: f64,
    correction_lambda: f64,
}

fn resolve(a: &TrainArgs) -> Result<RunConfig> {
    let (text, origin) = match &a.config {
        Some(p) => (
            std::fs::read_to_string(p).with_context(|| format!("cannot read {}", p.display()))?,
            p.display().to_string(),
        ),
        None if a.track.is_some() => (
            TRACK_TOML.to_string(),
            "configs/racing-track.toml (built in)".to_string(),
        ),
        None => (DEFAULT_TOML.to_string(), "configs/default.toml (built in)".to_string()),
    };
    let sets = [a.set.clone(), a.track.iter().map(|p| agvrl_run::track_set(p)).collect()].concat();
    let mut cfg = RunConfig::from_toml_with(&text, &origin, &sets)?;
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

/// The training envs; a race's are self-play envs drawing opponents from `pool`.
fn vec_env(cfg: &RunConfig, pool: &Pool) -> Result<VecEnv<Box<dyn Env>>> {
    let envs = (0..cfg.n_envs)
        .map(|i| -> Result<Box<dyn Env>> {
            let (id, env_cfg) = (cfg.train_env_id(i), cfg.train_env_config(i));
            Ok(match agvrl_envs::MULTI_ENV_IDS.contains(&id) {
                true => Box::new(TimeLimit::new(
                    SelfPlayEnv::new(id, &env_cfg, pool.clone(), &cfg.opponents)?,
                    env_cfg.max_steps,
                )),
                false => make(id, &env_cfg)?,
            })
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(VecEnv::new(envs, cfg.threads)?)
}

/// The opponent pool of a self-play run; `None` for other runs.
fn pool_of(cfg: &RunConfig, pool: Pool) -> Option<Pool> {
    agvrl_envs::MULTI_ENV_IDS.contains(&cfg.env.as_str()).then_some(pool)
}

/// A new learner for `cfg` (warm-started from `cfg.init_from`, a run directory, when set) and
/// its self-play pool, still empty.
fn new_learner(cfg: &RunConfig, device: &Device) -> Result<(Box<dyn Learner>, Option<Pool>)> {
    let pool = Pool::default();
    let learner: Box<dyn Learner> = if cfg.algo == Algorithm::Ppo {
        let mut ppo = Ppo::new(cfg.ppo.clone(), vec_env(cfg, &pool)?, device, cfg.seed)?;
        if let Some(from) = &cfg.init_from {
            let added = inputs_added_since(cfg, from)?;
            ppo.warm_start(&from.join(files::CHECKPOINT), &added)
                .with_context(|| format!("init_from = {}", from.display()))?;
            eprintln!(
                "starting from the weights of {} ({} observation inputs added)",
                from.display(),
                added.len()
            );
        }
        Box::new(ppo_with_threads(ppo, cfg)?)
    } else {
        Box::new(sac_with_threads(
            Sac::new(cfg.sac.clone(), vec_env(cfg, &pool)?, device, cfg.seed)?,
            cfg,
        )?)
    };
    Ok((learner, pool_of(cfg, pool)))
}

/// The learner of the run whose files `file` names, at its checkpoint, on new envs, and its
/// self-play pool as the run held it then (saved in `pool/`).
fn resumed_learner(
    cfg: &RunConfig,
    file: &dyn Fn(&str) -> PathBuf,
    device: &Device,
) -> Result<(Box<dyn Learner>, Option<Pool>)> {
    let ckpt = file(files::CHECKPOINT);
    let pool = Pool::default();
    let learner: Box<dyn Learner> = if cfg.algo == Algorithm::Ppo {
        Box::new(ppo_with_threads(
            Ppo::load_checkpoint(&ckpt, vec_env(cfg, &pool)?, device)?,
            cfg,
        )?)
    } else {
        Box::new(sac_with_threads(
            Sac::load_checkpoint(&ckpt, vec_env(cfg, &pool)?, device)?,
            cfg,
        )?)
    };
    let pool = pool_of(cfg, pool);
    if let Some(p) = &pool {
        p.restore(&file(files::POOL), learner.num_timesteps())?;
    }
    Ok((learner, pool))
}

impl TrainArgs {
    fn compute(&self) -> Compute {
        Compute {
            device: self.device.into(),
            net_path: self.net_path.map(NetPath::from),
        }
    }
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
        let device = DeviceChoice::from(a.device).device()?;
        let ckpt = dir.join(files::CHECKPOINT);
        if dir.is_dir() && !ckpt.is_file() {
            anyhow::bail!(
                "{} has no checkpoint: its training stopped before the first one; start it again",
                dir.display()
            );
        }
        Run::open(dir)?;
        // The run stays as it was until the continued one is complete (see RunDir::resume).
        let run = RunDir::resume(dir)?;
        let cfg = RunConfig::load(&run.file(files::CONFIG))?;
        let (mut learner, pool) = resumed_learner(&cfg, &|name: &str| run.file(name), &device)?;
        a.compute().apply(learner.as_mut());
        let target = match a.steps {
            Some(more) => learner.num_timesteps() + more,
            None => cfg.steps,
        };
        // A run stopped before its first chunk has no metrics yet; any other failure keeps the
        // history from being overwritten. Rows past the checkpoint (a kill between the metrics
        // and the checkpoint write) are learnt again, so they go.
        let previous = match std::fs::read_to_string(run.file(files::METRICS)) {
            Ok(text) => metrics_up_to(&text, learner.num_timesteps()),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => String::new(),
            Err(e) => return Err(anyhow::Error::new(e).context(format!("reading {}/metrics.csv", dir.display()))),
        };
        eprintln!(
            "resuming {} at step {} up to {target}",
            dir.display(),
            learner.num_timesteps()
        );
        let files = |name: &str| run.file(name);
        let report = run_learner(
            learner.as_mut(),
            &cfg,
            target,
            &files,
            &previous,
            &STOP,
            a.progress,
            pool.as_ref(),
        )?;
        let dir = run.finish()?;
        println!("run_dir={}", dir.display());
        print!("{}", report.text());
        return Ok(());
    }
    let cfg = resolve(&a)?;
    if a.progress == ProgressMode::Json {
        stop_with_parent(&STOP);
    }
    let share = cfg.attempts_lapped_share;
    let (dir, report, attempts) = match cfg.attempts {
        1 => {
            let (dir, report) = train_run(cfg, a.out.clone(), a.compute(), &STOP, a.progress)?;
            (dir, report, Vec::new())
        }
        _ => train_attempts(cfg, a.out.clone(), a.compute(), &STOP, a.progress)?,
    };
    if a.progress == ProgressMode::Json {
        println!("{}", done_json(&dir, &report));
    } else {
        println!("run_dir={}", dir.display());
        if let Some(k) = kept_attempt(&attempts, share) {
            let kept = &attempts[k];
            println!(
                "attempts={} kept_seed={} validation_lapped={}/{}",
                attempts.len(),
                kept.seed,
                kept.lapped,
                kept.episodes
            );
        }
        print!("{}", report.text());
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

/// The last JSON progress line: the run directory and its evaluation (eval.json's object).
fn done_json(dir: &std::path::Path, report: &RunReport) -> String {
    serde_json::json!({
        "event": "done",
        "run_dir": dir.display().to_string(),
        "interrupted": report.interrupted,
        "metrics": report,
    })
    .to_string()
}

/// Train `cfg` into a new run directory (`out`, or runs/<date-time>-<env>-<algo>), stopping
/// early, with a complete run directory, once `stop` is set. Returns the directory and its
/// evaluation. With `attempts` above 1, see [`train_attempts`].
pub fn train_run(
    cfg: RunConfig,
    out: Option<PathBuf>,
    compute: Compute,
    stop: &AtomicBool,
    progress: ProgressMode,
) -> Result<(PathBuf, RunReport)> {
    if cfg.attempts > 1 {
        let (dir, report, _) = train_attempts(cfg, out, compute, stop, progress)?;
        return Ok((dir, report));
    }
    train_once(cfg, out, compute, stop, progress)
}

/// One run of [`train_attempts`]: its seed, and how its validation episodes ended.
#[derive(Clone, Debug, PartialEq)]
pub struct Attempt {
    pub seed: u64,
    pub train_s: f64,
    /// Validation episodes lapped without a crash, of `episodes`.
    pub lapped: usize,
    pub episodes: usize,
    pub ended: Vec<&'static str>,
}

impl Attempt {
    /// Whether it lapped at least `share` of its validation episodes.
    fn validated(&self, share: f64) -> bool {
        self.lapped as f64 >= share * self.episodes as f64 - 1e-9
    }
}

/// The attempt a run of several keeps: the first that lapped at least `share` of its validation
/// episodes, else the one that lapped most, the earliest of equals.
fn kept_attempt(attempts: &[Attempt], share: f64) -> Option<usize> {
    attempts.iter().position(|a| a.validated(share)).or_else(|| {
        let most = attempts.iter().map(|a| a.lapped).max()?;
        attempts.iter().position(|a| a.lapped == most)
    })
}

/// `attempts.csv`: one line per attempt, the kept one marked.
fn attempts_csv(attempts: &[Attempt], kept: usize) -> String {
    let mut out = String::from("attempt,seed,train_s,validation_lapped,validation_episodes,validation_ended,kept\n");
    for (k, a) in attempts.iter().enumerate() {
        let _ = writeln!(
            out,
            "{},{},{:.1},{},{},{},{}",
            k + 1,
            a.seed,
            a.train_s,
            a.lapped,
            a.episodes,
            a.ended.join(" "),
            k == kept
        );
    }
    out
}

/// Train `cfg` at seeds `seed`, `seed + 1`, ... (at most `attempts` runs) until a run's policy
/// laps `attempts_lapped_share` of the validation episodes ([`agvrl_run::Seeds::validation`])
/// without a crash. The kept run ([`kept_attempt`]) fills the run directory; the others stay in
/// its `attempts/`, and `attempts.csv` lists them all.
pub fn train_attempts(
    cfg: RunConfig,
    out: Option<PathBuf>,
    compute: Compute,
    stop: &AtomicBool,
    progress: ProgressMode,
) -> Result<(PathBuf, RunReport, Vec<Attempt>)> {
    cfg.validate()?;
    let run = match out {
        Some(out) => RunDir::create(out)?,
        None => RunDir::create_unique(default_run_path(&cfg))?,
    };
    let tried = run.file("attempts");
    let mut attempts = Vec::new();
    let mut runs = Vec::new();
    for k in 0..cfg.attempts {
        let mut c = cfg.clone();
        c.seed = cfg.seed + u64::from(k);
        eprintln!("attempt {} of {} (seed {})", k + 1, cfg.attempts, c.seed);
        let (dir, report) = train_once(
            c.clone(),
            Some(tried.join(format!("seed-{}", c.seed))),
            compute,
            stop,
            progress,
        )?;
        let mut policy = Policy::load(&dir.join(files::POLICY))?;
        let v = evaluate(
            Driver::Policy(&mut policy),
            c.eval_env_id(),
            &c.eval_env_config(),
            c.eval_episodes,
            c.seeds().validation(),
            &mut |_| Ok(()),
        )?;
        let a = Attempt {
            seed: c.seed,
            train_s: report.train_s,
            lapped: v.lapped,
            episodes: v.episodes,
            ended: v.ended,
        };
        eprintln!(
            "attempt {}: {}/{} validation episodes lapped without a crash ({})",
            k + 1,
            a.lapped,
            a.episodes,
            a.ended.join(",")
        );
        let done = a.validated(cfg.attempts_lapped_share) || report.interrupted || stop.load(Ordering::SeqCst);
        attempts.push(a);
        runs.push((dir, report));
        if done {
            break;
        }
    }
    let kept = kept_attempt(&attempts, cfg.attempts_lapped_share).context("no attempt trained")?;
    let (dir, report) = runs.swap_remove(kept);
    for entry in std::fs::read_dir(&dir).with_context(|| format!("reading {}", dir.display()))? {
        let from = entry?.path();
        let to = run.file(&from.file_name().unwrap_or_default().to_string_lossy());
        std::fs::rename(&from, &to).with_context(|| format!("moving {} to {}", from.display(), to.display()))?;
    }
    std::fs::remove_dir(&dir).with_context(|| format!("removing {}", dir.display()))?;
    // Nothing left of the other attempts when the first was kept.
    let _ = std::fs::remove_dir(&tried);
    write_atomic(&run.file("attempts.csv"), attempts_csv(&attempts, kept).as_bytes())?;
    let dir = run.finish()?;
    Ok((dir, report, attempts))
}

/// [`train_run`] for one seed.
fn train_once(
    cfg: RunConfig,
    out: Option<PathBuf>,
    compute: Compute,
    stop: &AtomicBool,
    progress: ProgressMode,
) -> Result<(PathBuf, RunReport)> {
    let mut cfg = cfg;
    if let Some(first) = cfg.init_config().map(PathBuf::from) {
        let out = out.clone().unwrap_or_else(|| default_run_path(&cfg));
        let (dir, report) = first_stage(&first, cfg.seed, &out, compute, stop, progress)?;
        if report.interrupted {
            eprintln!("interrupted in the first stage; the fine-tuning did not start");
            return Ok((dir, report));
        }
        cfg.init_from = Some(dir);
    }
    let device = compute.device.device()?;
    let device = &device;
    image_spec_from_env(&mut cfg);
    cfg.validate()?;
    eprintln!(
        "training {} on {} for {} steps (seed {}, {} envs)",
        cfg.algo, cfg.env, cfg.steps, cfg.seed, cfg.n_envs
    );
    let (mut learner, pool) = new_learner(&cfg, device)?;
    compute.apply(learner.as_mut());
    // Created once the learner stands, so a setting it refuses leaves no run directory behind.
    let run = match out {
        Some(out) => RunDir::create(out)?,
        None => RunDir::create_unique(default_run_path(&cfg))?,
    };
    write_atomic(&run.file(files::CONFIG), cfg.to_toml()?.as_bytes())?;
    let files = |name: &str| run.file(name);
    let report = run_learner(
        learner.as_mut(),
        &cfg,
        cfg.steps,
        &files,
        "",
        stop,
        progress,
        pool.as_ref(),
    )?;
    let dir = run.finish()?;
    Ok((dir, report))
}

fn default_run_path(cfg: &RunConfig) -> PathBuf {
    PathBuf::from("runs").join(format!("{}-{}-{}", stamp(), cfg.env, cfg.algo))
}

/// Train the run config `first` at `seed` into `<out>-init`, the first stage of the training
/// into `out`; a finished first stage of the same config there is used as it is, so a
/// command run again after its fine-tuning failed does not train it again.
fn first_stage(
    first: &std::path::Path,
    seed: u64,
    out: &std::path::Path,
    compute: Compute,
    stop: &AtomicBool,
    progress: ProgressMode,
) -> Result<(PathBuf, RunReport)> {
    let mut cfg = RunConfig::load(first).with_context(|| format!("init_from = {}", first.display()))?;
    cfg.seed = seed;
    let dir = PathBuf::from(format!("{}-init", out.display()));
    if dir.exists() {
        let mut expected = cfg.clone();
        image_spec_from_env(&mut expected);
        let run = Run::open(&dir)?;
        let report = run.report().ok();
        if run.config() != &expected || report.as_ref().is_none_or(|r| r.interrupted) {
            anyhow::bail!(
                "{} exists and is not a finished training of {} at seed {seed}: resume it \
                 (agvrl train --resume {}) or remove it",
                dir.display(),
                first.display(),
                dir.display()
            );
        }
        eprintln!(
            "first stage: {} is {} at seed {seed}, trained",
            dir.display(),
            first.display()
        );
        return Ok((dir, report.unwrap_or_default()));
    }
    eprintln!("first stage: {} at seed {seed} into {}", first.display(), dir.display());
    train_run(cfg, Some(dir), compute, stop, progress)
}

/// The observation inputs of `cfg` that the run in `from` (a run directory) did not have.
fn inputs_added_since(cfg: &RunConfig, from: &std::path::Path) -> Result<Vec<usize>> {
    let before = RunConfig::load(&from.join(files::CONFIG))
        .with_context(|| format!("init_from = {}: not a run directory", from.display()))?;
    let rays = cfg.env_config.sim.lidar.n_rays;
    if before.env_config.sim.lidar.n_rays != rays {
        anyhow::bail!(
            "init_from = {}: its LiDAR has {} rays, this run's {rays}",
            from.display(),
            before.env_config.sim.lidar.n_rays
        );
    }
    cfg.env_config
        .observation
        .inputs_added_since(&before.env_config.observation, rays)
        .map_err(|e| anyhow::anyhow!("init_from = {}: {e}", from.display()))
}

/// `sac` splitting each gradient step over the run's `threads` (between the env rounds the
/// cores are the learner's).
fn sac_with_threads<E: Env>(mut sac: Sac<E>, cfg: &RunConfig) -> Result<Sac<E>> {
    sac.set_threads(cfg.threads)?;
    Ok(sac)
}

/// `ppo` splitting each image minibatch over the run's `threads`, its learning rate scheduled
/// over the run's `steps` (`ppo.learning_rate_final`).
fn ppo_with_threads<E: Env>(mut ppo: Ppo<E>, cfg: &RunConfig) -> Result<Ppo<E>> {
    ppo.set_threads(cfg.threads)?;
    ppo.set_schedule_steps(cfg.steps);
    Ok(ppo)
}

static STOP_HANDLER: std::sync::OnceLock<()> = std::sync::OnceLock::new();

/// Train `learner` up to `target` steps (or a Ctrl-C), checkpointing every tenth (and adding
/// a snapshot to a self-play run's opponent `pool`); write checkpoint.ckpt, policy.agvrl,
/// metrics.csv (after `previous_csv`), the deterministic evaluation (plots, recording),
/// eval.txt and eval.json; returns the evaluation.
#[allow(clippy::too_many_arguments)]
fn run_learner(
    learner: &mut dyn Learner,
    cfg: &RunConfig,
    target: u64,
    file: &dyn Fn(&str) -> PathBuf,
    previous_csv: &str,
    stop: &AtomicBool,
    progress: ProgressMode,
    pool: Option<&Pool>,
) -> Result<RunReport> {
    let t0 = Instant::now();
    let rows = learn_in_chunks(learner, cfg, target, file, previous_csv, stop, progress, pool)?;
    let policy_path = file(files::POLICY);
    // The policy file carries the settings it drives with: the run config.
    let mut policy_data = learner.policy_data();
    policy_data.settings_toml = Some(cfg.to_toml()?);
    policy_data.save(&policy_path)?;
    let interrupted = learner.num_timesteps() < target;
    let train_s = t0.elapsed().as_secs_f64();
    let csv = metrics_csv(previous_csv, &rows);
    write_atomic(&file(files::METRICS), csv.as_bytes())?;
    let summary = evaluate_run(cfg, &policy_path, file)?;
    let title = run_title(cfg);
    plots::learning_curve(&file(files::LEARNING_CURVE), &plots::curve_of_csv(&csv), &title)?;
    let report = RunReport {
        train_s,
        eval_s: t0.elapsed().as_secs_f64() - train_s,
        steps: learner.num_timesteps(),
        interrupted,
        eval: summary.report(),
    };
    write_atomic(&file(files::EVAL), report.text().as_bytes())?;
    write_atomic(&file(files::EVAL_JSON), report.to_json().as_bytes())?;
    Ok(report)
}

/// `learn` in chunks up to `target` (at least every tenth of the run and every 50,000 steps a
/// checkpoint and a snapshot into `pool`), reporting progress as `progress` asks; stops early
/// once `stop` is set. Returns a metrics row per update.
#[allow(clippy::too_many_arguments)]
fn learn_in_chunks(
    learner: &mut dyn Learner,
    cfg: &RunConfig,
    target: u64,
    file: &dyn Fn(&str) -> PathBuf,
    previous_csv: &str,
    stop: &AtomicBool,
    progress: ProgressMode,
    pool: Option<&Pool>,
) -> Result<Vec<Row>> {
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
    let rows = std::cell::RefCell::new(Vec::<Row>::new());
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
                    "corrected_fraction": Some(p.losses.corrected_fraction).filter(|v| v.is_finite()),
                    "correction_lambda": Some(p.losses.correction_lambda).filter(|v| v.is_finite()),
                    "wall_s": t0.elapsed().as_secs_f64(),
                })
            );
        }
        rows.borrow_mut().push(Row {
            step: p.steps,
            episodes: p.episodes,
            mean_return: mean,
            policy_loss: p.losses.policy,
            value_loss: p.losses.value,
            entropy: p.losses.entropy,
            steps_per_s: (p.steps - start) as f64 / t0.elapsed().as_secs_f64().max(1e-9),
            corrected_fraction: p.losses.corrected_fraction,
            correction_lambda: p.losses.correction_lambda,
        });
        if stop.load(Ordering::SeqCst) {
            Control::Stop
        } else {
            Control::Continue
        }
    };
    // A new run's first opponent is its first policy (a run resumed from before pools were
    // saved starts its pool again from the resumed policy).
    if let Some(p) = pool.filter(|p| p.is_empty()) {
        p.push_saved(learner.policy_data(), &file(files::POOL), learner.num_timesteps())?;
    }
    let per_chunk = cfg.steps.div_ceil(10).clamp(1, 50_000);
    while learner.num_timesteps() < target && !stop.load(Ordering::SeqCst) {
        learner.learn(per_chunk.min(target - learner.num_timesteps()), &mut on_progress)?;
        // The history and the snapshot first, then the checkpoint: a kill between them leaves
        // rows and a snapshot past the checkpoint, which a resume drops (`metrics_up_to`,
        // `Pool::restore`), never a gap.
        let csv = metrics_csv(previous_csv, &rows.borrow());
        write_atomic(&file(files::METRICS), csv.as_bytes())?;
        if let Some(p) = pool {
            p.push_saved(learner.policy_data(), &file(files::POOL), learner.num_timesteps())?;
        }
        learner.save_checkpoint(&file(files::CHECKPOINT))?;
        if cfg.restart_episodes_at_checkpoints {
            learner.restart_episodes();
        }
    }
    learner.save_checkpoint(&file(files::CHECKPOINT))?;
    bar.finish_and_clear();
    Ok(rows.into_inner())
}

/// The metrics CSV `text` without the rows past step `steps`.
fn metrics_up_to(text: &str, steps: u64) -> String {
    let mut out = String::new();
    for (i, line) in text.lines().enumerate() {
        let step = line.split(',').next().and_then(|s| s.parse::<u64>().ok());
        if i == 0 || step.is_some_and(|s| s <= steps) {
            out.push_str(line);
            out.push('\n');
        }
    }
    out
}

/// metrics.csv's header; a run's earlier rows under an older header, a prefix of this one, get
/// empty fields for the columns added since.
const METRICS_HEADER: &str =
    "step,episodes,mean_return,policy_loss,value_loss,entropy,steps_per_s,corrected_fraction,correction_lambda";

/// metrics.csv: the rows of earlier sessions of the run (`previous`, header included), then
/// these.
fn metrics_csv(previous: &str, rows: &[Row]) -> String {
    let mut csv = format!("{METRICS_HEADER}\n");
    let mut lines = previous.lines();
    if let Some(header) = lines.next() {
        let missing = METRICS_HEADER
            .split(',')
            .count()
            .saturating_sub(header.split(',').count());
        for line in lines {
            let _ = writeln!(csv, "{line}{}", ",".repeat(missing));
        }
    }
    let finite = |v: f64| {
        if v.is_finite() {
            format!("{v:.6}")
        } else {
            String::new()
        }
    };
    for r in rows {
        let mean = r.mean_return.map(|m| format!("{m:.4}")).unwrap_or_default();
        let _ = writeln!(
            csv,
            "{},{},{mean},{:.6},{:.6},{:.6},{:.1},{},{}",
            r.step,
            r.episodes,
            r.policy_loss,
            r.value_loss,
            r.entropy,
            r.steps_per_s,
            finite(r.corrected_fraction),
            finite(r.correction_lambda)
        );
    }
    csv
}

/// The run's own deterministic evaluation of the policy at `policy_path`: eval.rrd (first
/// episode) and trajectory.png; returns the evaluation's key=value lines.
fn evaluate_run(cfg: &RunConfig, policy_path: &std::path::Path, file: &dyn Fn(&str) -> PathBuf) -> Result<Summary> {
    let mut policy = Policy::load(policy_path)?;
    let mut watch = Watch {
        rec_episodes: 1,
        plot_episodes: usize::MAX,
        ..Watch::default()
    };
    if viz::ENABLED && agvrl_envs::registry::scene_of(cfg.eval_env_id()).is_some() {
        watch.rec = Some(Recorder::new(
            Sink::File(file(files::RECORDING)),
            &format!("{}{} {} eval", cfg.env, cfg.env_config.track_suffix(), cfg.algo),
            cfg.eval_env_config().sim.camera.as_ref(),
        )?);
    }
    let summary = evaluate(
        Driver::Policy(&mut policy),
        cfg.eval_env_id(),
        &cfg.eval_env_config(),
        cfg.eval_episodes,
        cfg.seeds().run_evaluation(),
        &mut |v| watch.see(v),
    )?;
    if let Some(r) = watch.rec.take() {
        r.finish()?;
    }
    let title = run_title(cfg);
    watch.plot(&file(files::TRAJECTORY), &format!("{title}: deterministic evaluation"))?;
    Ok(summary)
}

/// `ENV[ on TRACK] ALGO seed S`: the title of a run's plots.
fn run_title(cfg: &RunConfig) -> String {
    format!(
        "{}{} {} seed {}",
        cfg.env,
        cfg.env_config.track_suffix(),
        cfg.algo,
        cfg.seed
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use agvrl_envs::task::ImageChannels;

    #[test]
    fn the_first_attempt_to_lap_its_share_of_validation_episodes_is_kept_else_the_one_that_lapped_most() {
        let a = |seed, lapped| Attempt {
            seed,
            train_s: 1.0,
            lapped,
            episodes: 3,
            ended: vec!["time_limit"; 3],
        };
        assert_eq!(kept_attempt(&[], 1.0), None);
        assert_eq!(kept_attempt(&[a(0, 3)], 1.0), Some(0));
        assert_eq!(kept_attempt(&[a(0, 2), a(1, 3), a(2, 3)], 1.0), Some(1));
        // None lapped all: the most laps, the earliest of equals.
        assert_eq!(kept_attempt(&[a(0, 1), a(1, 2), a(2, 2), a(3, 0)], 1.0), Some(1));
        assert_eq!(kept_attempt(&[a(0, 0), a(1, 0)], 1.0), Some(0));
        // Two of three is enough at a share of 2/3, not at 0.7.
        assert_eq!(kept_attempt(&[a(0, 1), a(1, 2), a(2, 3)], 2.0 / 3.0), Some(1));
        assert_eq!(kept_attempt(&[a(0, 1), a(1, 2), a(2, 3)], 0.7), Some(2));
        let csv = attempts_csv(&[a(5, 1), a(6, 3)], 1);
        let lines: Vec<&str> = csv.lines().collect();
        assert_eq!(lines.len(), 3, "{csv}");
        assert_eq!(lines[1], "1,5,1.0,1,3,time_limit time_limit time_limit,false");
        assert_eq!(lines[2], "2,6,1.0,3,3,time_limit time_limit time_limit,true");
    }

    #[test]
    fn metrics_csv_keeps_an_older_runs_rows_under_the_new_header() {
        let row = |step, lambda| Row {
            step,
            episodes: 2,
            mean_return: Some(1.5),
            policy_loss: 0.1,
            value_loss: 0.2,
            entropy: -0.3,
            steps_per_s: 100.0,
            corrected_fraction: 0.05,
            correction_lambda: lambda,
        };
        let old = "step,episodes,mean_return,policy_loss,value_loss,entropy,steps_per_s\n100,1,,0.1,0.2,0.3,50.0\n";
        let csv = metrics_csv(old, &[row(200, 0.7), row(300, f64::NAN)]);
        let lines: Vec<&str> = csv.lines().collect();
        assert_eq!(lines[0], METRICS_HEADER);
        assert_eq!(lines[1], "100,1,,0.1,0.2,0.3,50.0,,");
        assert_eq!(
            lines[2],
            "200,2,1.5000,0.100000,0.200000,-0.300000,100.0,0.050000,0.700000"
        );
        assert!(lines[3].ends_with(",0.050000,"), "{}", lines[3]);
        let n = METRICS_HEADER.split(',').count();
        assert!(lines.iter().all(|l| l.split(',').count() == n), "{csv}");
        // A resume of a run with this header keeps its rows as they are.
        assert_eq!(metrics_csv(&csv, &[]), csv);
        assert_eq!(plots::curve_of_csv(&csv), [(200.0, 1.5), (300.0, 1.5)]);
    }

    /// A self-play run resumed from its run directory trains on as the run that never stopped,
    /// opponent pool included. What no file holds: the races under way and the envs' random
    /// streams (the `Env` trait has no snapshot), so the resumed run starts new races; the run
    /// that never stopped starts new ones at the same step (`Learner::restart_episodes`), and
    /// everything else, the learner from checkpoint.ckpt and the opponents from pool/, must
    /// come back bit for bit.
    #[test]
    fn a_resumed_self_play_run_trains_as_if_never_stopped_opponent_pool_included() {
        let sets = [
            "steps=640",
            "n_envs=2",
            "threads=1",
            "ppo.n_steps=32",
            "ppo.batch_size=32",
            "ppo.n_epochs=1",
            "ppo.net_arch=[16]",
            "env_config.max_steps=100",
        ]
        .map(String::from);
        let cfg = RunConfig::from_toml_with(include_str!("../configs/duel.toml"), "duel.toml", &sets).unwrap();
        let device = agvrl_rl::default_device();
        // A chunk is one rollout (64 steps); the run stops after five of its ten.
        let (n, end) = (cfg.steps / 2, cfg.steps);
        let dir = tempfile::tempdir().unwrap();
        let (straight_dir, resumed_dir) = (dir.path().join("straight"), dir.path().join("resumed"));
        let in_dir = |d: &std::path::Path| {
            let d = d.to_path_buf();
            move |name: &str| d.join(name)
        };
        let (straight_file, resumed_file) = (in_dir(&straight_dir), in_dir(&resumed_dir));
        let no_stop = AtomicBool::new(false);
        let chunks = |l: &mut dyn Learner, pool: Option<&Pool>, file: &dyn Fn(&str) -> PathBuf, target| {
            learn_in_chunks(l, &cfg, target, file, "", &no_stop, ProgressMode::None, pool).unwrap();
        };

        let (mut straight, straight_pool) = new_learner(&cfg, &device).unwrap();
        chunks(straight.as_mut(), straight_pool.as_ref(), &straight_file, n);
        straight.restart_episodes();
        chunks(straight.as_mut(), straight_pool.as_ref(), &straight_file, end);

        let (mut first, first_pool) = new_learner(&cfg, &device).unwrap();
        chunks(first.as_mut(), first_pool.as_ref(), &resumed_file, n);
        let at_n = first.policy_data();
        drop((first, first_pool));
        let (mut resumed, resumed_pool) = resumed_learner(&cfg, &resumed_file, &device).unwrap();
        assert_eq!(resumed.num_timesteps(), n);
        let pool_at_n = resumed_pool.as_ref().unwrap().snapshots();
        assert_eq!(pool_at_n.len(), 6, "the first policy and five chunks' snapshots");
        chunks(resumed.as_mut(), resumed_pool.as_ref(), &resumed_file, end);

        assert_ne!(
            resumed.policy_data().params,
            at_n.params,
            "no training after the resume"
        );
        let bytes = |p: &agvrl_rl::PolicyData| p.to_bytes().unwrap();
        assert!(
            bytes(&straight.policy_data()) == bytes(&resumed.policy_data()),
            "the resumed run's policy differs from the one never stopped"
        );
        let read = |f: &dyn Fn(&str) -> PathBuf, name: &str| std::fs::read(f(name)).unwrap();
        assert!(
            read(&straight_file, files::CHECKPOINT) == read(&resumed_file, files::CHECKPOINT),
            "the checkpoints differ"
        );
        let (a, b) = (straight_pool.unwrap().snapshots(), resumed_pool.unwrap().snapshots());
        assert_eq!((a.len(), b.len()), (11, 11));
        for (k, (x, y)) in a.iter().zip(&b).enumerate() {
            assert!(bytes(x) == bytes(y), "opponent snapshot {k} differs");
        }
    }

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
