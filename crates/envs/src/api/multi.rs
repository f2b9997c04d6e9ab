use super::env::{EnvError, Step};
use super::space::BoxSpace;

/// A multi-agent environment with Gymnasium semantics per agent (PettingZoo's parallel API):
/// every agent acts at once, each gets its own observation, reward, termination, truncation
/// and info. An agent whose episode ended drops out: its later actions are ignored and its
/// entries are `None` until the next reset. The episode (a race) is over when every agent is
/// done. `reset(Some(seed))` reseeds; the same seed and actions give bit-identical steps.
pub trait MultiEnv: Send {
    /// Number of agents (fixed for the env's life).
    fn n_agents(&self) -> usize;
    /// Each agent's observation space (the same for every agent).
    fn observation_space(&self) -> BoxSpace;
    /// Each agent's action space (the same for every agent).
    fn action_space(&self) -> BoxSpace;
    /// Start a new episode: one observation per agent.
    fn reset(&mut self, seed: Option<u64>) -> Result<Vec<Vec<f32>>, EnvError>;
    /// One action per agent (agents already done may pass anything of the right length).
    fn step(&mut self, actions: &[Vec<f32>]) -> Result<MultiStep, EnvError>;
    /// Control period, seconds.
    fn dt_s(&self) -> f64;
}

/// The result of one [`MultiEnv::step`].
#[derive(Clone, Debug, PartialEq)]
pub struct MultiStep {
    /// Per agent: its step, or `None` when its episode ended before this step.
    pub agents: Vec<Option<Step>>,
    /// On the step the race ends (every agent done): its results.
    pub summary: Option<RaceSummary>,
}

impl MultiStep {
    /// Whether every agent is done.
    pub fn over(&self) -> bool {
        self.summary.is_some()
    }
}

/// The results of a race, by car index.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RaceSummary {
    /// Car indices in finishing order: running cars by distance raced, then crashed cars by
    /// distance raced.
    pub order: Vec<usize>,
    /// Laps completed (start line crossings after the start).
    pub laps: Vec<u32>,
    /// Fastest lap, seconds.
    pub best_lap_s: Vec<Option<f64>>,
    /// Every completed lap's time, seconds, in order.
    pub lap_times_s: Vec<Vec<f64>>,
    /// Distance raced from the start line, metres.
    pub distance_m: Vec<f64>,
    /// Ground covered along the centre line from the car's own start, metres (what crashes per
    /// kilometre divide by).
    pub covered_m: Vec<f64>,
    /// Place on the grid, 1 = pole (or ahead of everyone at a start behind).
    pub start_place: Vec<usize>,
    /// Encounters begun as the car behind (see [`crate::race_figures`]).
    pub encounters: Vec<u32>,
    /// Passes made (see [`crate::race_figures`]).
    pub passes: Vec<u32>,
    /// Contacts with other cars begun.
    pub contacts: Vec<u32>,
    /// Of those, caused by the car's front.
    pub at_fault: Vec<u32>,
    /// Time lost to contacts, seconds (see `RaceCarInfo::time_lost_s`).
    pub time_lost_s: Vec<f64>,
    /// Whether the car crashed into a wall.
    pub crashed: Vec<bool>,
}

impl RaceSummary {
    /// Car `i`'s at-fault incidents: contacts its front caused, and its own crash.
    pub fn at_fault_incidents(&self, i: usize) -> u32 {
        self.at_fault[i] + u32::from(self.crashed[i])
    }
}
