use super::space::BoxSpace;
use thiserror::Error;

/// Why an env could not reset or step.
#[derive(Debug, Error)]
pub enum EnvError {
    /// The action has the wrong length.
    #[error("action has {got} elements, the action space has {expected}")]
    ActionShape {
        /// Length of the action space.
        expected: usize,
        /// Length of the action given.
        got: usize,
    },
    /// The action holds NaN or infinity; it never reaches the physics.
    #[error("action element {index} is not finite ({value})")]
    ActionNotFinite {
        /// Index of the offending element.
        index: usize,
        /// Its value.
        value: f32,
    },
    /// `step` was called before `reset`, or after the episode ended without a reset.
    #[error("step called on an env that needs reset (call reset first, and after every episode end)")]
    NeedsReset,
    /// `make` was given an id it does not know.
    #[error("unknown env id '{id}'; valid ids: {}", valid.join(", "))]
    UnknownId {
        /// The id asked for.
        id: String,
        /// Every registered id.
        valid: Vec<String>,
    },
    /// The simulator failed (bad scene, vehicle, or a non-finite state).
    #[error(transparent)]
    Sim(#[from] agvrl_sim::SimError),
    /// A vehicle (simulated or hardware) could not deliver what the task needs.
    #[error("vehicle: {0}")]
    Vehicle(String),
    /// A configuration value is invalid.
    #[error("config: {0}")]
    Config(String),
    /// A setting outside the values it may take (a settings table's `validate`).
    #[error("config: {0}")]
    Setting(#[from] agvrl_sim::InvalidSetting),
    /// Env `env` of a vector env failed.
    #[error("env {env}: {source}")]
    InEnv {
        /// Index of the env in the vector.
        env: usize,
        /// What went wrong there.
        source: Box<EnvError>,
    },
    /// A bug or an earlier panic left agvrl's own state unusable (a poisoned lock, a lost
    /// worker result); not something a setting can fix.
    #[error("internal error: {0}")]
    Internal(&'static str),
}

impl EnvError {
    /// The error itself, without the vector env's "env i" wrapping.
    pub fn innermost(&self) -> &EnvError {
        match self {
            EnvError::InEnv { source, .. } => source.innermost(),
            e => e,
        }
    }
}

/// Named parts of the last reward, for logging (absent terms are 0).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RewardTerms {
    /// Speed term, 5 T^2.
    pub throttle: f64,
    /// Steering penalty, -2 delta^2.
    pub steering: f64,
    /// Clearance term, 0.005 r_m^2 (search only).
    pub clearance: f64,
    /// Bonus for keeping 2.0 m < r_m < 2.5 m (search only).
    pub band: f64,
    /// Collision or near-collision penalty (-50).
    pub collision: f64,
    /// Extra penalty for crawling (AutoVRL's outdoor-50 only).
    pub slow: f64,
    /// Graded penalty for driving close to an obstacle (the `safe` search reward).
    pub proximity: f64,
    /// Reward for newly covered ground (the `safe` search reward).
    pub coverage: f64,
    /// Penalty for a step whose control the safety filter changed (the `safe` search reward).
    pub filter: f64,
    /// Penalty for a step long after the last newly covered cell (the `safe` search reward).
    pub stale: f64,
    /// Progress along the centre line (racing against others).
    pub progress: f64,
    /// Penalty for touching another car with one's front, and for the closing speed of a
    /// rear-end contact one caused (racing against others).
    pub car_contact: f64,
    /// Ground gained on the other cars within the position window (racing against others).
    pub position: f64,
}

/// Racing progress, reported every step of a racing task.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RacingInfo {
    /// Completed laps since reset.
    pub laps: u32,
    /// Duration of the last completed lap, seconds.
    pub last_lap_s: Option<f64>,
    /// Fastest completed lap since reset, seconds.
    pub best_lap_s: Option<f64>,
    /// The first completed lap since reset, seconds (from the start, wherever the car started).
    pub first_lap_s: Option<f64>,
    /// Progress along the centre line, laps (fractional, grows in the racing direction).
    pub progress_laps: f64,
}

/// Search metrics, reported every step of a search task.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SearchInfo {
    /// Fraction of free 0.5 m cells that came within 2 m of the vehicle, in [0, 1].
    pub coverage: f64,
    /// Path length since reset, metres.
    pub distance_m: f64,
    /// Subjects seen by the camera so far (see `SearchConfig::found_min_pixels`).
    pub subjects_found: usize,
    /// Subjects placed in the scene.
    pub subjects_total: usize,
    /// Time from reset to each find, seconds, in the order found.
    pub find_times_s: Vec<f64>,
    /// Steps since reset whose control the safety filter changed.
    pub filter_interventions: u64,
    /// Of those, the steps it steered to another angle (throttle kept)...
    pub filter_steered: u64,
    /// ...the steps it braked...
    pub filter_braked: u64,
    /// ...and the steps it reversed out of a dead end (the back-outs' ticks).
    pub filter_reversed: u64,
    /// Back-outs begun since reset.
    pub filter_backouts: u64,
    /// r_m after this step: the smallest LiDAR range within the task's clearance fan, metres
    /// (infinite without a scan).
    pub clearance_m: f64,
}

/// Why an episode terminated.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TerminationCause {
    /// Real contact between the vehicle and something other than the ground.
    Contact,
    /// The minimum LiDAR range fell below the task's threshold.
    TooClose,
    /// The vehicle rolled over.
    Flipped,
    /// The vehicle left the map.
    OutOfBounds,
}

/// Summary of a finished episode (set on the step that ends it).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EpisodeSummary {
    /// Sum of rewards.
    pub ret: f64,
    /// Number of steps.
    pub len: u64,
}

/// Typed step information (Gymnasium's `info`, without a string map).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Info {
    /// Parts of this step's reward.
    pub reward_terms: RewardTerms,
    /// Why the episode terminated, on a terminating step.
    pub termination: Option<TerminationCause>,
    /// Racing metrics (racing tasks).
    pub racing: Option<RacingInfo>,
    /// Search metrics (search tasks).
    pub search: Option<SearchInfo>,
    /// The last observation of an episode that a vector env auto-reset; `Step::obs` is then the
    /// first observation of the next episode.
    pub final_obs: Option<Vec<f32>>,
    /// On a step whose control a safety filter changed, the action that maps to the control
    /// sent instead (in the action space): what a learner can teach the policy to propose.
    pub corrected_action: Option<Vec<f32>>,
    /// Return and length of the episode that ended on this step (set by `TimeLimit`/`VecEnv`
    /// bookkeeping when the episode ends).
    pub episode: Option<EpisodeSummary>,
    /// A car's standing in a race against others.
    pub race: Option<RaceCarInfo>,
    /// What a learner's critic may read beside `Step::obs` (or the reset's observation) that
    /// the car does not sense: in a race with `race.critic_sees_opponents`, the other cars'
    /// state ([`Env::critic_obs_dim`] values). Never an input of a policy.
    pub critic_obs: Option<Vec<f32>>,
    /// `critic_obs` of `final_obs`, where a vector env auto-reset.
    pub final_critic_obs: Option<Vec<f32>>,
}

/// One car's standing in a race against others, reported every step.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RaceCarInfo {
    /// Position in the race, 1 = leading (by distance along the centre line from the start
    /// line; a crashed car ranks behind every running one).
    pub position: usize,
    /// Distance raced from the start line, metres (negative on the grid behind it).
    pub distance_m: f64,
    /// Contacts with other cars begun since the start.
    pub contacts: u32,
    /// Of those, the ones this car's front caused.
    pub at_fault: u32,
    /// Encounters begun since the start as the car behind (see [`crate::race_figures`]).
    pub encounters: u32,
    /// Passes made since the start (see [`crate::race_figures`]).
    pub passes: u32,
    /// Time lost to contacts: the integral of 1 - v / v_before over the two seconds after
    /// each contact began, v_before the speed just before it, seconds.
    pub time_lost_s: f64,
    /// Whether the car has crashed (it then stands where it stopped).
    pub crashed: bool,
}

/// The result of one `Env::step`.
#[derive(Clone, Debug, PartialEq)]
pub struct Step {
    /// Observation after the action.
    pub obs: Vec<f32>,
    /// Reward for the transition.
    pub reward: f64,
    /// The task ended (collision, goal): do not bootstrap.
    pub terminated: bool,
    /// The episode was cut (time limit): bootstrap from the final observation.
    pub truncated: bool,
    /// Extra information.
    pub info: Info,
}

impl Step {
    /// Whether the episode is over (terminated or truncated).
    pub fn done(&self) -> bool {
        self.terminated || self.truncated
    }
}

/// A reinforcement-learning environment with Gymnasium semantics.
///
/// Actions are flat `f32` vectors normalised to `[-1, 1]` for the vehicle tasks (check
/// `action_space`). `reset(Some(seed))` reseeds the env's RNG; `reset(None)` continues the
/// current random stream. The same seed and the same actions give bit-identical observations.
pub trait Env: Send {
    /// Shape and bounds of observations.
    fn observation_space(&self) -> BoxSpace;
    /// Shape and bounds of actions.
    fn action_space(&self) -> BoxSpace;
    /// Start a new episode.
    fn reset(&mut self, seed: Option<u64>) -> Result<(Vec<f32>, Info), EnvError>;
    /// Apply one action. Errors on a wrong-length or non-finite action.
    fn step(&mut self, action: &[f32]) -> Result<Step, EnvError>;
    /// Control period, seconds (for converting steps to time).
    fn dt_s(&self) -> f64;
    /// Length of `Info::critic_obs` on every reset and step (0: the env gives none).
    fn critic_obs_dim(&self) -> usize {
        0
    }
}

impl<E: Env + ?Sized> Env for Box<E> {
    fn observation_space(&self) -> BoxSpace {
        (**self).observation_space()
    }
    fn action_space(&self) -> BoxSpace {
        (**self).action_space()
    }
    fn reset(&mut self, seed: Option<u64>) -> Result<(Vec<f32>, Info), EnvError> {
        (**self).reset(seed)
    }
    fn step(&mut self, action: &[f32]) -> Result<Step, EnvError> {
        (**self).step(action)
    }
    fn dt_s(&self) -> f64 {
        (**self).dt_s()
    }
    fn critic_obs_dim(&self) -> usize {
        (**self).critic_obs_dim()
    }
}

/// Reject actions of the wrong length or with NaN/inf, the check every env runs first.
pub fn validate_action(space: &BoxSpace, action: &[f32]) -> Result<(), EnvError> {
    if action.len() != space.dim() {
        return Err(EnvError::ActionShape {
            expected: space.dim(),
            got: action.len(),
        });
    }
    if let Some((index, &value)) = action.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(EnvError::ActionNotFinite { index, value });
    }
    Ok(())
}
