//! Tasks turn a `SensorFrame` into observation, reward and termination: the same code in
//! simulation and on the car. This file holds the `Task` trait and the settings both LiDAR
//! tasks share; `observation.rs` composes observations, `termination.rs` ends episodes,
//! `action.rs` maps actions to controls, `reward.rs` holds every reward.

mod action;
pub mod explored;
mod observation;
pub mod racing;
pub mod reward;
pub mod safety;
pub mod search;
mod termination;

use crate::api::{BoxSpace, Control, MapInfo, RewardTerms, SensorFrame, SensorNeeds, TerminationCause};
pub use action::ActionMapping;
pub use explored::{ExploredMemory, ExploredObs};
pub use observation::{ArcObs, ImageChannels, ImageObs, ObsConfig, PastScans, RangeScale, RearObs, ScanHistory};
use serde::{Deserialize, Serialize};
pub use termination::{common_termination, min_range_ahead_m, min_range_m, min_static_range_m, terminate};

pub use racing::{Racing, RacingRules, RacingRulesSetting};
pub use reward::{RacingPay, RacingReward};
pub use reward::{SafeShaping, SearchReward};
pub use safety::{Intervention, SafetyFilter, SafetyFilterConfig};
pub use search::{CoverageGrid, Search};

/// What a task concluded about one step.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Outcome {
    /// Reward parts (sum = reward).
    pub terms: RewardTerms,
    /// Why the episode ended, if it did.
    pub termination: Option<TerminationCause>,
    /// The episode ends without a terminal state (the racing task's stall limit): the env
    /// reports it truncated.
    pub truncate: bool,
    /// Racing metrics.
    pub racing: Option<crate::api::RacingInfo>,
    /// Search metrics.
    pub search: Option<crate::api::SearchInfo>,
}

/// A task.
pub trait Task: Send {
    /// Sensors needed every frame.
    fn needs(&self) -> SensorNeeds;
    /// Observation space.
    fn observation_space(&self) -> BoxSpace;
    /// Map a (finite, in-range) action to a control, given the frame the action was chosen
    /// from (a safety filter may change the control).
    fn control(&mut self, action: &[f32], steering_limit_rad: f64, frame: &SensorFrame) -> Control;
    /// What the safety filter did to the last control.
    fn intervention(&self) -> Intervention {
        Intervention::None
    }
    /// When the safety filter changed (or, advising, would have changed) the last control:
    /// the action that maps to the filter's control, what the policy should have proposed.
    fn corrected_action(&self) -> Option<Vec<f32>> {
        None
    }
    /// The control `action` asks for before any safety filter, where the task can say (what a
    /// race's passer starts from).
    fn proposed(&self, _action: &[f32], _steering_limit_rad: f64) -> Option<Control> {
        None
    }
    /// The action that maps to `control`, where the task can say (advice from outside the
    /// task, e.g. a race's passing advice, is reported as an action).
    fn action_of(&self, _control: Control, _steering_limit_rad: f64) -> Option<Vec<f32>> {
        None
    }
    /// Start an episode from its first frame.
    fn reset(&mut self, frame: &SensorFrame, map: Option<&MapInfo>);
    /// The observation of a frame, once `reset` or `evaluate` has taken it in (the memories
    /// it reads include that frame): the env and the drive loop both call them in that order.
    fn observe(&self, frame: &SensorFrame) -> Vec<f32>;
    /// Reward and termination after a step.
    fn evaluate(&mut self, frame: &SensorFrame, map: Option<&MapInfo>) -> Outcome;
}

impl<T: Task + ?Sized> Task for Box<T> {
    fn needs(&self) -> SensorNeeds {
        (**self).needs()
    }
    fn observation_space(&self) -> BoxSpace {
        (**self).observation_space()
    }
    fn control(&mut self, action: &[f32], steering_limit_rad: f64, frame: &SensorFrame) -> Control {
        (**self).control(action, steering_limit_rad, frame)
    }
    fn intervention(&self) -> Intervention {
        (**self).intervention()
    }
    fn corrected_action(&self) -> Option<Vec<f32>> {
        (**self).corrected_action()
    }
    fn action_of(&self, control: Control, steering_limit_rad: f64) -> Option<Vec<f32>> {
        (**self).action_of(control, steering_limit_rad)
    }
    fn proposed(&self, action: &[f32], steering_limit_rad: f64) -> Option<Control> {
        (**self).proposed(action, steering_limit_rad)
    }
    fn reset(&mut self, frame: &SensorFrame, map: Option<&MapInfo>) {
        (**self).reset(frame, map)
    }
    fn observe(&self, frame: &SensorFrame) -> Vec<f32> {
        (**self).observe(frame)
    }
    fn evaluate(&mut self, frame: &SensorFrame, map: Option<&MapInfo>) -> Outcome {
        (**self).evaluate(frame, map)
    }
}

/// Settings both LiDAR tasks share.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CommonConfig {
    /// Observation composition.
    pub observation: ObsConfig,
    /// Action -> control mapping.
    pub action_mapping: ActionMapping,
    /// Number of LiDAR rays (must match the vehicle's LiDAR).
    pub n_rays: usize,
    /// LiDAR range_max, metres.
    pub range_max_m: f32,
    /// The LiDAR safety filter between action and drive (off by default).
    pub safety_filter: SafetyFilterConfig,
}

impl Default for CommonConfig {
    fn default() -> Self {
        Self {
            observation: ObsConfig::default(),
            action_mapping: ActionMapping::Scaled,
            n_rays: 100,
            range_max_m: 12.0,
            safety_filter: SafetyFilterConfig::default(),
        }
    }
}

impl CommonConfig {
    /// Sensors the observation (and the safety filter's odometry) needs.
    pub fn needs(&self) -> SensorNeeds {
        let mut n = self.observation.needs();
        n.imu |= self.safety_filter.enabled;
        n
    }

    /// The observation space.
    pub fn space(&self) -> BoxSpace {
        self.observation.space(self.n_rays, self.range_max_m)
    }

    /// Map an action to a control.
    pub fn control(&self, action: &[f32], steering_limit_rad: f64) -> Control {
        map_control(self.action_mapping, action, steering_limit_rad)
    }

    /// The action that maps to `control` ([`ActionMapping::action`]).
    pub fn action_of(&self, control: Control, steering_limit_rad: f64) -> Vec<f32> {
        let [a0, a1] = self.action_mapping.action(control, steering_limit_rad);
        vec![a0 as f32, a1 as f32]
    }
}

pub(crate) fn map_control(mapping: ActionMapping, action: &[f32], limit: f64) -> Control {
    let a0 = action.first().copied().unwrap_or(0.0) as f64;
    let a1 = action.get(1).copied().unwrap_or(0.0) as f64;
    mapping.control(a0, a1, limit)
}
