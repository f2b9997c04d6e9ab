//! The run TOML: which env, which algorithm, which settings. `agvrl train` writes it into every
//! run directory and every policy file; eval, view, agvrl-drive and Python read the same type,
//! so one file format serves them all. The learners' own settings (`PpoConfig`, `SacConfig`)
//! stay in agvrl-rl.

use crate::error::{Result, RunError};
use agvrl_envs::EnvConfig;
use agvrl_envs::task::SafetyFilterConfig;
use agvrl_rl::{Algorithm, PpoConfig, SacConfig};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// A training run.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct RunConfig {
    /// Env id (evaluation; training too unless `train_envs` is set).
    pub env: String,
    /// Env ids the training envs cycle through (env `i` drives `train_envs[i % len]`); all
    /// must share `env`'s spaces. Empty: every training env is `env`.
    pub train_envs: Vec<String>,
    /// `ppo` or `sac`.
    pub algo: Algorithm,
    /// Environment steps to train.
    pub steps: u64,
    /// Seed of everything.
    pub seed: u64,
    /// Parallel envs.
    pub n_envs: usize,
    /// Threads stepping the envs; SAC's gradient steps split their minibatch over as many.
    pub threads: usize,
    /// Start new episodes after every checkpoint, as a resumed run does (the envs' state is in
    /// no checkpoint), so a run killed and resumed, a preempted job, trains bit for bit as one
    /// that ran through (not one stopped by Ctrl-C or SIGTERM: its checkpoint falls where it
    /// stopped, between the others). Off: the episodes under way at a checkpoint run on, and
    /// only a resume cuts them (bootstrapped, as a time limit).
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub restart_episodes_at_checkpoints: bool,
    /// The opponents of a race's training (`env` a race): each opponent car draws one per race,
    /// uniformly: `self` (a snapshot of the learner from the self-play pool) or a classical
    /// racer, `pure-pursuit[@SCALE]` or `follow-the-gap[@SCALE]` (SCALE of its speed, in
    /// (0, 1]). Empty: self-play only.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub opponents: Vec<String>,
    /// How many of the `n_envs` training envs drive on seeded procedural layouts of the env's
    /// kind and size instead of its built-in map (layout randomisation; evaluation always uses
    /// the map of `env_config`).
    pub procedural_layouts: usize,
    /// Training envs (by index) whose safety filter only advises (`safety_filter.advisory`):
    /// the policy's own controls drive there and can end episodes, while the filter's
    /// corrections still reach the learner (`ppo.correction_coef`). Evaluation never advises.
    pub advisory_filter_envs: Vec<usize>,
    /// Training envs (by index) whose episodes start facing an obstacle 0.7-1.5 m ahead
    /// (`SpawnMode::NearObstacle`), so the policy practises recoveries. Evaluation never does.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub recovery_spawn_envs: Vec<usize>,
    /// Training envs (by index) that drive with the `sim2real` preset's sensor noise, latency
    /// and randomisation (domain randomisation). Evaluation never does: `--preset sim2real`
    /// adds them there.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub sim2real_envs: Vec<usize>,
    /// The safety filter of the training envs, where it differs from
    /// `env_config.safety_filter` (the one the policy drives behind: evaluation, the car). A
    /// wider filter in training (the shield) teaches the policy margins that a looser one
    /// behind it (the backstop) then seldom has to enforce. Evaluation never uses it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub train_safety_filter: Option<SafetyFilterConfig>,
    /// Start from the weights of another PPO run (its directory) instead of new ones: a
    /// fine-tuning. Its network must be this run's; this run's observation may add parts to
    /// its (`env_config.observation`), which start with zero weights, so the first policy acts
    /// and values exactly as that run's last. The optimiser, the step count and the learning
    /// rate's schedule start afresh; the correction multipliers carry over.
    ///
    /// A run config instead (a `.toml` file, see [`RunConfig::init_config`]) is the first
    /// stage: this config's keys go over that file's, and training trains that file first, at
    /// this run's seed, then fine-tunes from it, in one command.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub init_from: Option<std::path::PathBuf>,
    /// Runs to train at most, at seeds `seed`, `seed + 1`, ... (a single car on a map track or
    /// on generated circuits): a run is kept once its policy laps `attempts_lapped_share` of
    /// `eval_episodes` validation episodes without a crash (episodes of their own seeds, not
    /// the evaluation's); when none does, the one that lapped most. The kept run's config names
    /// its seed, so it trains again alone.
    #[serde(skip_serializing_if = "is_one")]
    pub attempts: u32,
    /// The share of the validation episodes an attempt must lap to be kept (1: every one); a
    /// generalist that laps 97 of 100 circuits misses one of 20 often enough.
    #[serde(skip_serializing_if = "is_whole")]
    pub attempts_lapped_share: f64,
    /// Deterministic episodes evaluated after training.
    pub eval_episodes: usize,
    /// Time limit of evaluation episodes, control steps (default: the training limit).
    pub eval_max_steps: Option<u64>,
    /// Env settings.
    pub env_config: EnvConfig,
    /// PPO settings (used when algo = "ppo").
    pub ppo: PpoConfig,
    /// SAC settings (used when algo = "sac").
    pub sac: SacConfig,
}

fn is_one(n: &u32) -> bool {
    *n == 1
}

fn is_whole(share: &f64) -> bool {
    *share == 1.0
}

fn is_config_file(p: &Path) -> bool {
    p.extension().is_some_and(|e| e == "toml")
}

/// A map-file track set over a run table: generated circuits give way to it (see
/// [`RunConfig::from_toml_with`]).
fn on_track(table: &mut toml::Table) {
    if let Some(env_config) = table.get_mut("env_config").and_then(|v| v.as_table_mut()) {
        env_config.remove("circuit");
        env_config.remove("layout_seed");
    }
    if table.get("env").and_then(|v| v.as_str()) == Some(agvrl_envs::registry::CIRCUIT_ENV) {
        table.insert("env".into(), toml::Value::String("racing-oval".into()));
    }
}

/// The keys of the run config that `table`'s `init_from` names, when it names one (a `.toml`
/// file, read from the working directory as run directories are).
fn first_stage_table(table: &toml::Table, origin: &str) -> Result<Option<toml::Table>> {
    let Some(path) = table.get("init_from").and_then(|v| v.as_str()).map(Path::new) else {
        return Ok(None);
    };
    if !is_config_file(path) {
        return Ok(None);
    }
    let err = |m: String| RunError::Config(format!("{origin}: init_from = {}: {m}", path.display()));
    let text = std::fs::read_to_string(path).map_err(|e| err(e.to_string()))?;
    let first: toml::Table = toml::from_str(&text).map_err(|e| err(e.message().trim().to_string()))?;
    if let Some(inner) = first
        .get("init_from")
        .and_then(|v| v.as_str())
        .filter(|p| is_config_file(Path::new(p)))
    {
        return Err(err(format!(
            "that config starts from another config ({inner}); a training has at most two stages"
        )));
    }
    Ok(Some(first))
}

/// `over`'s keys replace `base`'s; tables merge key by key, anything else is replaced whole.
fn merge_tables(base: &mut toml::Table, over: toml::Table) {
    for (key, value) in over {
        match (base.get_mut(&key), value) {
            (Some(toml::Value::Table(b)), toml::Value::Table(o)) => merge_tables(b, o),
            (_, value) => {
                base.insert(key, value);
            }
        }
    }
}

impl Default for RunConfig {
    fn default() -> Self {
        Self {
            env: "racing-oval".into(),
            train_envs: Vec::new(),
            algo: Algorithm::Ppo,
            steps: 100_000,
            seed: 0,
            n_envs: 8,
            threads: 2,
            restart_episodes_at_checkpoints: false,
            opponents: Vec::new(),
            procedural_layouts: 0,
            advisory_filter_envs: Vec::new(),
            recovery_spawn_envs: Vec::new(),
            sim2real_envs: Vec::new(),
            train_safety_filter: None,
            init_from: None,
            attempts: 1,
            attempts_lapped_share: 1.0,
            eval_episodes: 3,
            eval_max_steps: None,
            env_config: EnvConfig::default(),
            ppo: PpoConfig::default(),
            sac: SacConfig::default(),
        }
    }
}

impl RunConfig {
    /// Parse a run TOML; `origin` names it in errors.
    /// A track given by path (`env_config.track`) is loaded here, so that every config read
    /// carries the track itself: the run directory's and the policy file's copies need no files.
    /// A config whose `init_from` names a run config starts from that file's keys.
    pub fn from_toml(text: &str, origin: &str) -> Result<Self> {
        Self::from_toml_with(text, origin, &[])
    }

    /// The first stage of a two-stage training: `init_from` when it names a run config (a
    /// `.toml` file) rather than a run directory.
    pub fn init_config(&self) -> Option<&Path> {
        self.init_from.as_deref().filter(|p| is_config_file(p))
    }

    fn parse(text: &str, origin: &str) -> Result<Self> {
        let mut cfg: RunConfig =
            toml::from_str(text).map_err(|e| RunError::Config(format!("{origin}: {}", e.message().trim())))?;
        cfg.validate().map_err(|e| match e {
            RunError::Config(m) => RunError::Config(format!("{origin}: {m}")),
            other => other,
        })?;
        cfg.env_config.embed_track().map_err(|e| {
            RunError::Config(match e {
                agvrl_envs::EnvError::Config(m) => format!("{origin}: env_config.{m}"),
                other => format!("{origin}: env_config.track: {other}"),
            })
        })?;
        Ok(cfg)
    }

    /// Parse a run TOML with `sets` (`KEY=VALUE`, dotted keys, TOML values; a value that is
    /// not TOML is taken as a string) applied on top. A set `env_config.track` races on that
    /// map over settings of generated circuits: their `circuit` and `layout_seed` go, and
    /// `racing-circuit` becomes `racing-oval` (the env of a map-file track).
    pub fn from_toml_with(text: &str, origin: &str, sets: &[String]) -> Result<Self> {
        let mut table: toml::Table =
            toml::from_str(text).map_err(|e| RunError::Config(format!("{origin}: {}", e.message().trim())))?;
        let first = first_stage_table(&table, origin)?;
        if first.is_none() && sets.is_empty() {
            // Parsed from the text itself, so errors keep their line and column.
            return Self::parse(text, origin);
        }
        if let Some(mut first) = first {
            merge_tables(&mut first, table);
            table = first;
        }
        for s in sets {
            let (key, value) = s
                .split_once('=')
                .ok_or_else(|| RunError::Config(format!("--set {s}: expected KEY=VALUE")))?;
            let value: toml::Value = toml::from_str::<toml::Table>(&format!("v = {value}"))
                .ok()
                .and_then(|mut t| t.remove("v"))
                .unwrap_or_else(|| toml::Value::String(value.to_string()));
            let path: Vec<&str> = key.trim().split('.').collect();
            let mut t = &mut table;
            for part in &path[..path.len() - 1] {
                let next = t
                    .entry(part.to_string())
                    .or_insert_with(|| toml::Value::Table(toml::Table::new()));
                t = next
                    .as_table_mut()
                    .ok_or_else(|| RunError::Config(format!("--set {s}: '{part}' is not a table")))?;
            }
            t.insert(path[path.len() - 1].to_string(), value);
            if key.trim() == "env_config.track" {
                on_track(&mut table);
            }
        }
        let shown = match sets.is_empty() {
            true => origin.to_string(),
            false => format!("{origin} with --set"),
        };
        let text = toml::to_string(&table).map_err(|e| RunError::Config(format!("{shown}: {e}")))?;
        Self::parse(&text, &shown)
    }

    /// Load a run TOML file.
    pub fn load(path: &Path) -> Result<Self> {
        Self::load_with(path, &[])
    }

    /// [`Self::load`] with `sets` on top (see [`Self::from_toml_with`]).
    pub fn load_with(path: &Path, sets: &[String]) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|source| RunError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_toml_with(&text, &path.display().to_string(), sets)
    }

    /// Check values a typo would break.
    pub fn validate(&self) -> Result<()> {
        let multi = agvrl_envs::MULTI_ENV_IDS.contains(&self.env.as_str());
        if !agvrl_envs::ENV_IDS.contains(&self.env.as_str()) && !multi {
            return Err(RunError::Config(format!(
                "unknown env id '{}'; valid ids: {}, {}",
                self.env,
                agvrl_envs::ENV_IDS.join(", "),
                agvrl_envs::MULTI_ENV_IDS.join(", ")
            )));
        }
        if multi && (self.algo != Algorithm::Ppo || !self.train_envs.is_empty() || self.procedural_layouts > 0) {
            return Err(RunError::Config(format!(
                "{} trains one PPO policy by self-play: algo = \"ppo\", no train_envs, no procedural_layouts",
                self.env
            )));
        }
        if !multi && !self.opponents.is_empty() {
            return Err(RunError::Config(format!(
                "opponents are a race's ({}); {} drives alone",
                agvrl_envs::MULTI_ENV_IDS.join(", "),
                self.env
            )));
        }
        for o in self.opponents.iter().filter(|o| o.as_str() != "self") {
            agvrl_envs::drivers::parse_racer(o)
                .map_err(|e| RunError::Config(format!("opponents: {e}; or \"self\"")))?;
        }
        for id in &self.train_envs {
            if !agvrl_envs::ENV_IDS.contains(&id.as_str()) {
                return Err(RunError::Config(format!(
                    "unknown env id '{id}' in train_envs; valid ids: {}",
                    agvrl_envs::ENV_IDS.join(", ")
                )));
            }
        }
        if self.env_config.held_out {
            return Err(RunError::Config(
                "env_config.held_out is for evaluation only: training never draws held-out episodes".into(),
            ));
        }
        if self.n_envs == 0 || self.threads == 0 || self.steps == 0 {
            return Err(RunError::Config("steps, n_envs and threads must be at least 1".into()));
        }
        if self.attempts == 0 {
            return Err(RunError::Config("attempts must be at least 1".into()));
        }
        // Laps are what a run is validated on: a single car on a map track or on generated
        // circuits.
        let laps = self.env_config.track.is_some() || self.env == "racing-circuit";
        if self.attempts > 1 && (multi || !laps || self.eval_episodes == 0) {
            return Err(RunError::Config(format!(
                "attempts = {}: retrying seeds needs a single car on a map track (env_config.track) \
                 or on generated circuits (racing-circuit), and eval_episodes >= 1 to validate each \
                 run on",
                self.attempts
            )));
        }
        if !(self.attempts_lapped_share > 0.0 && self.attempts_lapped_share <= 1.0) {
            return Err(RunError::Config(format!(
                "attempts_lapped_share must be in (0, 1], got {}",
                self.attempts_lapped_share
            )));
        }
        if self.attempts > 1 && self.init_config().is_some() {
            return Err(RunError::Config(
                "attempts: a two-stage training (init_from a run config) trains its first stage once; \
                 train the first stage, then fine-tune from its run directory with attempts"
                    .into(),
            ));
        }
        if self.procedural_layouts > self.n_envs {
            return Err(RunError::Config(format!(
                "procedural_layouts ({}) cannot exceed n_envs ({})",
                self.procedural_layouts, self.n_envs
            )));
        }
        for (key, envs) in [
            ("advisory_filter_envs", &self.advisory_filter_envs),
            ("recovery_spawn_envs", &self.recovery_spawn_envs),
            ("sim2real_envs", &self.sim2real_envs),
        ] {
            if let Some(i) = envs.iter().find(|i| **i >= self.n_envs) {
                return Err(RunError::Config(format!(
                    "{key}: env {i} does not exist (n_envs = {})",
                    self.n_envs
                )));
            }
        }
        if self.init_from.is_some() && self.algo != Algorithm::Ppo {
            return Err(RunError::Config(
                "init_from fine-tunes a PPO run; algo must be \"ppo\"".into(),
            ));
        }
        if self.env_config.track.is_some() && self.procedural_layouts > 0 {
            return Err(RunError::Config(
                "procedural_layouts draws layouts of the env's own map; env_config.track is a fixed map".into(),
            ));
        }
        if let Some(f) = self.train_safety_filter {
            f.on_drive(self.env_config.sim.brake_mps2)
                .validate()
                .map_err(|e| RunError::Config(format!("train_safety_filter: {e}")))?;
        }
        if !self.advisory_filter_envs.is_empty() && !self.train_filter().enabled {
            return Err(RunError::Config(
                "advisory_filter_envs needs the training envs' safety filter enabled \
                 (env_config.safety_filter or train_safety_filter)"
                    .into(),
            ));
        }
        Ok(())
    }

    /// The fully resolved TOML (every default written out).
    pub fn to_toml(&self) -> Result<String> {
        toml::to_string_pretty(self).map_err(|e| RunError::Config(format!("writing the run config: {e}")))
    }

    /// Env settings of training env `i`: the last `procedural_layouts` envs get a layout seed
    /// drawn from the run's seed and their index (redrawn every episode with
    /// `env_config.new_layout_each_episode`); the others drive the built-in map.
    pub fn train_env_config(&self, i: usize) -> EnvConfig {
        let mut cfg = self.env_config.clone();
        if i + self.procedural_layouts >= self.n_envs {
            cfg.layout_seed = Some(self.seeds().training_layout(i));
        } else {
            cfg.new_layout_each_episode = false;
        }
        cfg.safety_filter = self.train_filter();
        cfg.safety_filter.advisory |= self.advisory_filter_envs.contains(&i);
        if self.recovery_spawn_envs.contains(&i) {
            cfg.spawn = agvrl_envs::SpawnMode::NearObstacle;
        }
        if self.sim2real_envs.contains(&i) {
            cfg = cfg.with_sim2real_noise();
        }
        cfg
    }

    /// The safety filter the training envs drive behind.
    pub fn train_filter(&self) -> SafetyFilterConfig {
        self.train_safety_filter.unwrap_or(self.env_config.safety_filter)
    }

    /// Env id of training env `i`.
    pub fn train_env_id(&self, i: usize) -> &str {
        match self.train_envs.len() {
            0 => &self.env,
            n => &self.train_envs[i % n],
        }
    }

    /// Which seed each use of this run's `seed` gets.
    pub fn seeds(&self) -> crate::Seeds {
        crate::Seeds::of(self.seed)
    }

    /// The env the run's evaluation drives: a race's policy alone on the same track
    /// ([`agvrl_envs::lone_car_id`]).
    pub fn eval_env_id(&self) -> &str {
        agvrl_envs::lone_car_id(&self.env, &self.env_config)
    }

    /// Env settings for evaluation episodes: the built-in map, held-out seeds.
    pub fn eval_env_config(&self) -> EnvConfig {
        // Laps on a map-file or generated circuit are timed from the start line, as races are.
        let on_circuit = self.env_config.track.is_some() || self.eval_env_id() == agvrl_envs::registry::CIRCUIT_ENV;
        let spawn = match self.env_config.spawn {
            agvrl_envs::SpawnMode::Random if on_circuit => agvrl_envs::SpawnMode::Line,
            s => s,
        };
        EnvConfig {
            max_steps: self.eval_max_steps.unwrap_or(self.env_config.max_steps),
            spawn,
            layout_seed: None,
            new_layout_each_episode: false,
            held_out: true,
            safety_filter: agvrl_envs::task::SafetyFilterConfig {
                advisory: false,
                ..self.env_config.safety_filter
            },
            ..self.env_config.clone()
        }
    }

    /// Env settings for driving a car (agvrl-drive, Python's `Policy.settings()`): the env's
    /// own map unless the settings name a layout, and a filter that acts (advising is for
    /// training only).
    pub fn drive_env_config(&self) -> EnvConfig {
        let mut cfg = self.env_config.clone();
        if cfg.layout_seed.is_none() {
            cfg.new_layout_each_episode = false;
        }
        cfg.safety_filter.advisory = false;
        cfg
    }
}
