//! `make(id, config)`: every env agvrl ships, by id.

use crate::api::{Env, EnvError, Vehicle};
use crate::pendulum::Pendulum;
use crate::sim_vehicle::{Randomisation, SimCar, SimVehicle, SpawnMode};
use crate::task::racing::{RacingConfig, RacingRules, RacingRulesSetting};
use crate::task::search::SearchConfig;
use crate::task::{
    ActionMapping, CommonConfig, ObsConfig, Racing, SafeShaping, SafetyFilterConfig, Search, SearchReward,
};
use crate::task_env::TaskEnv;
use crate::wrappers::{NoiseConfig, Noisy, TimeLimit};
use agvrl_sim::{MapTrack, SceneKind, SceneSource, SimConfig, SimSettings};
use serde::{Deserialize, Serialize};

/// The task an env id poses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TaskKind {
    /// Explore a scene without colliding ([`crate::task::Search`]).
    Search,
    /// Lap the oval ([`crate::task::Racing`]).
    Racing,
    /// Gymnasium's Pendulum-v1 (no vehicle).
    Pendulum,
}

/// One env `make` knows: its id, task and scene.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EnvSpec {
    /// The id `make` takes.
    pub id: &'static str,
    /// The task.
    pub task: TaskKind,
    /// The built-in scene the vehicle drives in (None: no vehicle).
    pub scene: Option<&'static str>,
    /// The generator family and inner half size (m) of procedural layouts like the scene
    /// (`layout_seed`); None where the scene has no procedural counterpart.
    pub procedural: Option<(SceneKind, f32)>,
    /// AutoVRL's code penalises slow driving in this scene only (`search_reward = "autovrl_code"`).
    pub autovrl_slow_penalty: bool,
}

const fn search(id: &'static str, scene: &'static str, kind: SceneKind, half_m: f32) -> EnvSpec {
    EnvSpec {
        id,
        task: TaskKind::Search,
        scene: Some(scene),
        procedural: Some((kind, half_m)),
        autovrl_slow_penalty: false,
    }
}

/// The racing env on generated circuits ([`agvrl_sim::CircuitSettings`]).
pub const CIRCUIT_ENV: &str = "racing-circuit";

/// Every env agvrl ships.
pub const ENVS: [EnvSpec; 7] = [
    search("search-outdoor-20", "outdoor-20", SceneKind::Outdoor, 10.0),
    EnvSpec {
        autovrl_slow_penalty: true,
        ..search("search-outdoor-50", "outdoor-50", SceneKind::Outdoor, 25.0)
    },
    search("search-urban-20", "urban-20", SceneKind::Urban, 10.0),
    search("search-urban-50", "urban-50", SceneKind::Urban, 25.0),
    EnvSpec {
        id: "racing-oval",
        task: TaskKind::Racing,
        scene: Some("oval"),
        procedural: None,
        autovrl_slow_penalty: false,
    },
    EnvSpec {
        id: CIRCUIT_ENV,
        task: TaskKind::Racing,
        scene: Some("circuit"),
        procedural: None,
        autovrl_slow_penalty: false,
    },
    EnvSpec {
        id: "pendulum",
        task: TaskKind::Pendulum,
        scene: None,
        procedural: None,
        autovrl_slow_penalty: false,
    },
];

const ENV_ID_ARRAY: [&str; ENVS.len()] = {
    let mut ids = [""; ENVS.len()];
    let mut i = 0;
    while i < ENVS.len() {
        ids[i] = ENVS[i].id;
        i += 1;
    }
    ids
};

/// Ids `make` knows, in [`ENVS`]' order.
pub const ENV_IDS: &[&str] = &ENV_ID_ARRAY;

/// The table entry of `id`.
pub fn spec(id: &str) -> Option<&'static EnvSpec> {
    ENVS.iter().find(|s| s.id == id)
}

/// Settings of the vehicle envs (ignored by `pendulum`). Loadable from TOML; unknown keys are
/// an error.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EnvConfig {
    /// The simulator's settings (vehicle, dynamics, substeps, brake, LiDAR, GPS, camera,
    /// subjects), at the top level of the env TOML; the env id picks the scene.
    #[serde(flatten)]
    pub sim: SimSettings,
    /// Observation composition.
    pub observation: ObsConfig,
    /// Action mapping.
    pub action_mapping: ActionMapping,
    /// R_search form.
    pub search_reward: SearchReward,
    /// Constants of the `safe` search reward (ignored by the other forms).
    pub safe_reward: SafeShaping,
    /// Search: r_m (reward and "too close" termination) is the minimum range within half
    /// this of straight ahead, degrees; 0 (the default): every ray. 90 keeps AutoVRL's r_m
    /// with a wider LiDAR, whose side rays then only feed the observation.
    pub clearance_fov_deg: f32,
    /// The LiDAR safety filter between the policy's action and the drive (off by default; needs
    /// `brake_mps2 > 0`, whose deceleration it plans with unless it sets its own).
    pub safety_filter: SafetyFilterConfig,
    /// Where episodes start.
    pub spawn: SpawnMode,
    /// Sensor noise and latency.
    pub noise: NoiseConfig,
    /// Per-episode domain randomisation.
    pub randomisation: Randomisation,
    /// Time limit, control steps (truncation).
    pub max_steps: u64,
    /// Drive on a seeded procedural layout of the env's kind and size (same object families
    /// and densities) instead of its built-in map: layout randomisation for training. `None`
    /// (the default) is the built-in map.
    pub layout_seed: Option<u64>,
    /// With `layout_seed`: draw a new procedural layout at every reset, from the episode seed,
    /// instead of keeping one layout for the env's life.
    pub new_layout_each_episode: bool,
    /// Draw episode seeds and procedural layouts from the evaluation half of the seed space
    /// (see `heldout`): evaluation sets it, training never does, so the two never share an
    /// episode or a layout.
    pub held_out: bool,
    /// Race on a track from a ROS map file instead of the env's own (racing envs): the map
    /// YAML's path, or the track loaded from it, as run configs and policy files carry it.
    pub track: Option<TrackSetting>,
    /// The circuit generator's settings (`racing-circuit`); unset, its defaults.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub circuit: Option<agvrl_sim::CircuitSettings>,
    /// Race settings of the multi-car envs ([`MULTI_ENV_IDS`]); unset, their defaults.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub race: Option<crate::race_env::RaceSettings>,
    /// Racing rules (racing envs): the end rule, the reward, the stall and time limits. Unset
    /// keys take the track's defaults: the paper's on the oval ([`RacingRules::oval`]),
    /// [`RacingRules::map_track`] on map-file and generated tracks.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub racing: Option<RacingRulesSetting>,
}

/// `EnvConfig::track`: a map YAML's path, or the track loaded from it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged, expecting = "a map YAML's path, or a loaded track table")]
pub enum TrackSetting {
    /// The map YAML (relative paths from the working directory).
    Path(std::path::PathBuf),
    /// The loaded track: walls and centre line.
    Loaded(Box<MapTrack>),
}

impl TrackSetting {
    /// The track, loading it when this is a path.
    pub fn load(&self) -> Result<MapTrack, EnvError> {
        match self {
            // A file that will not load is a bad setting, as a bad value would be.
            Self::Path(p) => MapTrack::load(p).map_err(|e| EnvError::Config(format!("track: {e}"))),
            Self::Loaded(t) => Ok((**t).clone()),
        }
    }
}

impl Default for EnvConfig {
    fn default() -> Self {
        Self {
            sim: SimSettings::default(),
            observation: ObsConfig::default(),
            action_mapping: ActionMapping::Scaled,
            search_reward: SearchReward::AutovrlCode,
            safe_reward: SafeShaping::default(),
            clearance_fov_deg: 0.0,
            safety_filter: SafetyFilterConfig::default(),
            spawn: SpawnMode::Random,
            noise: NoiseConfig::default(),
            randomisation: Randomisation::default(),
            max_steps: 1000,
            layout_seed: None,
            new_layout_each_episode: false,
            held_out: false,
            track: None,
            circuit: None,
            race: None,
            racing: None,
        }
    }
}

impl EnvConfig {
    /// The `paper` preset: AutoVRL's observation (100 raw ranges), its action mapping and
    /// fixed spawn, no noise, no randomisation.
    pub fn paper() -> Self {
        Self {
            observation: ObsConfig::paper(),
            action_mapping: ActionMapping::Paper,
            spawn: SpawnMode::Fixed,
            ..Self::default()
        }
    }

    /// The `sim2real` preset: the default with sensor noise, latency and randomisation on.
    pub fn sim2real() -> Self {
        Self {
            noise: NoiseConfig::sim2real(),
            randomisation: Randomisation::sim2real(),
            ..Self::default()
        }
    }

    /// These settings with the `sim2real` preset's sensor noise, latency and randomisation.
    pub fn with_sim2real_noise(mut self) -> Self {
        let s2r = Self::sim2real();
        self.noise = s2r.noise;
        self.randomisation = s2r.randomisation;
        self
    }

    /// Load a track given by path, so that this config carries the track itself (a policy
    /// trained with it then drives it without the files).
    pub fn embed_track(&mut self) -> Result<(), EnvError> {
        if let Some(t @ TrackSetting::Path(_)) = &self.track {
            self.track = Some(TrackSetting::Loaded(Box::new(t.load()?)));
        }
        Ok(())
    }

    /// ` on NAME` for a map-file track (titles of plots and recordings), else nothing.
    pub fn track_suffix(&self) -> String {
        match &self.track {
            Some(TrackSetting::Loaded(t)) => format!(" on {}", t.name),
            Some(TrackSetting::Path(p)) => format!(" on {}", p.display()),
            None => String::new(),
        }
    }

    /// A named preset: `default`, `paper` or `sim2real`.
    pub fn preset(name: &str) -> Result<Self, EnvError> {
        match name {
            "default" => Ok(Self::default()),
            "paper" => Ok(Self::paper()),
            "sim2real" => Ok(Self::sim2real()),
            other => Err(EnvError::Config(format!(
                "unknown preset '{other}'; presets: default, paper, sim2real"
            ))),
        }
    }
}

/// The built-in scene behind a vehicle env id.
pub fn scene_of(id: &str) -> Option<&'static str> {
    spec(id).and_then(|s| s.scene)
}

fn unknown(id: &str) -> EnvError {
    if MULTI_ENV_IDS.contains(&id) {
        return EnvError::Config(format!(
            "{id} races several cars: build it with make_multi (Python: agvrl.make_multi)"
        ));
    }
    EnvError::UnknownId {
        id: id.to_string(),
        valid: ENV_IDS.iter().map(|s| s.to_string()).collect(),
    }
}

/// The vehicle of env `id` (no task), for tools that drive a vehicle directly: what the
/// [`Vehicle`](crate::Vehicle) seam promises, and nothing of the simulator behind it.
pub fn make_vehicle(id: &str, cfg: &EnvConfig) -> Result<Box<dyn crate::Vehicle>, EnvError> {
    Ok(Box::new(make_sim_car(id, cfg)?))
}

/// The simulated car of env `id` (no task), for the code that looks behind the seam at the
/// simulator ([`SimCar::sim`]: viewers, plots, the planner, Python's render, the sim-backed
/// ROS 2 robot). Everything else takes [`make_vehicle`].
pub fn make_sim_car(id: &str, cfg: &EnvConfig) -> Result<SimCar, EnvError> {
    let spec = spec(id).filter(|s| s.scene.is_some()).ok_or_else(|| unknown(id))?;
    let sim = sim_config(spec, cfg)?;
    // racing-circuit draws a new circuit every episode unless a layout_seed pins one.
    let redraw = cfg.new_layout_each_episode || (spec.id == CIRCUIT_ENV && cfg.layout_seed.is_none());
    let v = SimVehicle::new(sim, cfg.spawn, cfg.randomisation)?.with_new_layout_each_episode(redraw);
    Ok(if cfg.noise.is_off() {
        SimCar::Exact(Box::new(v))
    } else {
        SimCar::Noisy(Box::new(Noisy::new(v, cfg.noise)))
    })
}

/// The simulator's config for env `spec` with `cfg`: the scene (built-in, procedural or a
/// map-file track) and the settings.
fn sim_config(spec: &EnvSpec, cfg: &EnvConfig) -> Result<SimConfig, EnvError> {
    let id = spec.id;
    let scene = spec.scene.unwrap_or_default();
    if cfg.track.is_some() && spec.task != TaskKind::Racing {
        return Err(EnvError::Config(format!(
            "track is a racing setting; {id} is not a racing env"
        )));
    }
    if cfg.circuit.is_some() && id != CIRCUIT_ENV {
        return Err(EnvError::Config(format!(
            "circuit sets the generated circuits of {CIRCUIT_ENV}; {id} does not draw circuits"
        )));
    }
    let source = match (&cfg.track, cfg.layout_seed) {
        (Some(_), _) if id == CIRCUIT_ENV => {
            return Err(EnvError::Config(format!(
                "{CIRCUIT_ENV} races on generated circuits: a map-file track is racing-oval's `track`"
            )));
        }
        (None, seed) if id == CIRCUIT_ENV => {
            let settings = cfg.circuit.unwrap_or_default();
            settings.validate()?;
            SceneSource::Circuit {
                seed: crate::heldout::split(seed.unwrap_or(0), cfg.held_out),
                settings,
            }
        }
        (Some(_), Some(_)) => {
            return Err(EnvError::Config(
                "a map-file track has no procedural layouts: leave layout_seed unset".into(),
            ));
        }
        (Some(t), None) => SceneSource::Map(Box::new(t.load()?)),
        (None, None) => SceneSource::Builtin(scene.into()),
        (None, Some(seed)) => {
            let (kind, half_m) = spec.procedural.unwrap_or((SceneKind::Track, 0.0));
            SceneSource::Procedural {
                kind,
                seed: crate::heldout::split(seed, cfg.held_out),
                half_m,
            }
        }
    };
    if cfg.max_steps == 0 {
        return Err(EnvError::Config("max_steps must be at least 1".into()));
    }
    if cfg.new_layout_each_episode && cfg.layout_seed.is_none() && id != CIRCUIT_ENV {
        return Err(EnvError::Config(
            "new_layout_each_episode needs layout_seed (a procedural map to redraw)".into(),
        ));
    }
    Ok(SimConfig {
        scene: source,
        settings: cfg.sim.clone(),
    })
}

/// The task of vehicle env `id` with `cfg`, for a vehicle whose steering limit is
/// `steering_limit_rad` (the deploy loop pairs it with any `Vehicle`).
pub fn make_task(id: &str, cfg: &EnvConfig, steering_limit_rad: f64) -> Result<Box<dyn crate::task::Task>, EnvError> {
    let spec = spec(id).filter(|s| s.scene.is_some()).ok_or_else(|| unknown(id))?;
    cfg.safe_reward.validate()?;
    if !(cfg.clearance_fov_deg.is_finite() && (0.0..=360.0).contains(&cfg.clearance_fov_deg)) {
        return Err(EnvError::Config(format!(
            "clearance_fov_deg must be in [0, 360], got {}",
            cfg.clearance_fov_deg
        )));
    }
    cfg.observation.explored.validate()?;
    cfg.observation.arcs.validate()?;
    cfg.observation.rear.validate()?;
    cfg.observation.past_scans.validate()?;
    if spec.task == TaskKind::Racing && !cfg.observation.explored.is_empty() {
        return Err(EnvError::Config(format!(
            "observation.explored is a search observation; {id} is a racing env"
        )));
    }
    if spec.task == TaskKind::Racing && !cfg.observation.rear.is_empty() {
        return Err(EnvError::Config(format!(
            "observation.rear is a search observation; {id} is a racing env"
        )));
    }
    if let Some(cam) = cfg.sim.camera.as_ref().filter(|c| c.depth_only) {
        use crate::task::ImageChannels;
        if matches!(
            cfg.observation.image.channels,
            ImageChannels::Rgb | ImageChannels::DepthRgb
        ) {
            return Err(EnvError::Config(
                "observation.image takes RGB but camera.depth_only renders depth alone".into(),
            ));
        }
        if spec.task != TaskKind::Racing && cfg.sim.subjects > 0 {
            return Err(EnvError::Config(format!(
                "{id} finds its subjects by the camera's segmentation, which camera.depth_only \
                 leaves out ({}x{} depth only)",
                cam.width, cam.height
            )));
        }
    }
    let safety_filter = cfg.safety_filter.on_drive(cfg.sim.brake_mps2);
    safety_filter.validate()?;
    let rules = racing_rules(spec, cfg)?;
    let ends_below_m = match spec.task {
        TaskKind::Racing => rules.end_below_m,
        _ => SearchConfig::default().terminate_below_m,
    };
    if safety_filter.enabled && safety_filter.clearance_m <= ends_below_m {
        return Err(EnvError::Config(format!(
            "safety_filter.clearance_m = {} must exceed the {} m at which {id} ends an episode",
            safety_filter.clearance_m, ends_below_m
        )));
    }
    let common = CommonConfig {
        observation: cfg.observation,
        action_mapping: cfg.action_mapping,
        n_rays: cfg.sim.lidar.n_rays,
        range_max_m: cfg.sim.lidar.range_max_m,
        safety_filter,
    };
    Ok(if spec.task == TaskKind::Racing {
        Box::new(Racing::new(
            RacingConfig {
                common,
                rules,
                top_speed_mps: cfg.sim.vehicle_model()?.top_speed_mps() as f64,
            },
            steering_limit_rad,
        ))
    } else {
        Box::new(Search::new(
            SearchConfig {
                common,
                reward: cfg.search_reward,
                safe: cfg.safe_reward,
                clearance_fov_deg: cfg.clearance_fov_deg,
                slow_penalty: spec.autovrl_slow_penalty && cfg.search_reward == SearchReward::AutovrlCode,
                ..SearchConfig::default()
            },
            steering_limit_rad,
        ))
    })
}

/// The racing rules env `spec` runs under with `cfg`: the track's defaults (the paper's on the
/// oval, [`RacingRules::map_track`] on a map-file or generated track) under the keys
/// `cfg.racing` sets.
pub fn racing_rules(spec: &EnvSpec, cfg: &EnvConfig) -> Result<RacingRules, EnvError> {
    if spec.task != TaskKind::Racing {
        if cfg.racing.is_some() {
            return Err(EnvError::Config(format!(
                "racing is a racing setting; {} is not a racing env",
                spec.id
            )));
        }
        return Ok(RacingRules::oval());
    }
    let defaults = if cfg.track.is_some() || spec.id == CIRCUIT_ENV {
        RacingRules::map_track()
    } else {
        RacingRules::oval()
    };
    RacingRules::resolve(defaults, &cfg.racing.unwrap_or_default())
}

/// The multi-agent envs [`make_multi`] builds: `racing-duel`, cars racing on the oval, on
/// `track`, or on generated circuits (`layout_seed` or `circuit`; two cars unless `race.cars`
/// says otherwise).
pub const MULTI_ENV_IDS: &[&str] = &["racing-duel"];

/// The single-car env a policy of env `id` with `cfg` drives alone: a race's is `racing-oval`
/// (on the same track), or `racing-circuit` for races on generated circuits; any other env its
/// own.
pub fn lone_car_id<'a>(id: &'a str, cfg: &EnvConfig) -> &'a str {
    match id {
        _ if !MULTI_ENV_IDS.contains(&id) => id,
        _ if cfg.layout_seed.is_some() || cfg.circuit.is_some() => CIRCUIT_ENV,
        _ => "racing-oval",
    }
}

/// Build the multi-agent env `id` with `cfg`: one racing task per car (the single-car task's
/// observation, actions and safety filter), race rewards from `cfg.race`. Sensor noise is a
/// single-car setting.
pub fn make_multi(id: &str, cfg: &EnvConfig) -> Result<Box<dyn crate::api::MultiEnv>, EnvError> {
    Ok(Box::new(make_race(id, cfg)?))
}

/// [`make_multi`]'s race, typed: viewers and plots reach its simulator.
pub fn make_race(id: &str, cfg: &EnvConfig) -> Result<crate::race_env::RaceEnv, EnvError> {
    if !MULTI_ENV_IDS.contains(&id) {
        return Err(EnvError::UnknownId {
            id: id.to_string(),
            valid: MULTI_ENV_IDS.iter().map(|s| s.to_string()).collect(),
        });
    }
    let settings = cfg.race.unwrap_or_default();
    settings.validate()?;
    if !cfg.noise.is_off() {
        return Err(EnvError::Config(format!(
            "{id}: sensor noise and latency are single-car settings; leave noise off"
        )));
    }
    if cfg.max_steps == 0 {
        return Err(EnvError::Config("max_steps must be at least 1".into()));
    }
    // `layout_seed` or `circuit` race on racing-circuit's generated circuits: the circuit of
    // layout_seed, or a new one every race (unset, or with new_layout_each_episode).
    let on_circuits = cfg.layout_seed.is_some() || cfg.circuit.is_some();
    let racing_id = if on_circuits { CIRCUIT_ENV } else { "racing-oval" };
    let racing = spec(racing_id).ok_or(EnvError::Internal("the racing envs are registered"))?;
    let sim = sim_config(racing, cfg)?;
    let limit = cfg.sim.vehicle_model()?.spec.steering.max_rad;
    let tasks = (0..settings.cars)
        .map(|_| make_task(racing.id, cfg, limit))
        .collect::<Result<Vec<_>, _>>()?;
    let end_below_m = racing_rules(racing, cfg)?.end_below_m;
    let redraw = on_circuits && (cfg.layout_seed.is_none() || cfg.new_layout_each_episode);
    Ok(crate::race_env::RaceEnv::new(
        sim,
        tasks,
        settings,
        cfg.randomisation,
        cfg.max_steps,
        cfg.held_out,
        end_below_m,
    )?
    .with_new_layout_each_race(redraw))
}

/// Build the env registered under `id` with `cfg` (`EnvConfig::default()` for the standard
/// setup), wrapped in its time limit.
pub fn make(id: &str, cfg: &EnvConfig) -> Result<Box<dyn Env>, EnvError> {
    if spec(id).is_some_and(|s| s.task == TaskKind::Pendulum) {
        return Ok(Box::new(TimeLimit::new(Pendulum::new(), 200)));
    }
    let vehicle = make_sim_car(id, cfg)?;
    let task = make_task(id, cfg, vehicle.steering_limit_rad())?;
    Ok(Box::new(TimeLimit::new(
        TaskEnv::new(vehicle, task).with_held_out(cfg.held_out),
        cfg.max_steps,
    )))
}
