//! Racing: laps, lap times and progress along the centre line, under [`RacingRules`]: the
//! paper's on the oval (R_racing = 5 T^2 - 2 delta^2, -50 and the end when r_m < 0.8 m), rules a
//! 2.2 m track admits on map-file and generated tracks (contact ends the episode, progress along
//! the centre line pays).

use super::reward::{self, RacingPay, RacingReward};
use super::{CommonConfig, Intervention, Outcome, SafetyFilter, ScanHistory, Task, min_static_range_m, terminate};
use crate::api::{BoxSpace, Control, EnvError, MapInfo, RacingInfo, SensorFrame, SensorNeeds};
use serde::{Deserialize, Serialize};

/// The racing rules as run configs set them (`[env_config.racing]`): each unset key takes the
/// track's default ([`RacingRules::oval`] on the oval, [`RacingRules::map_track`] on map-file and
/// generated tracks).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RacingRulesSetting {
    /// See [`RacingRules::end_below_m`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub end_below_m: Option<f32>,
    /// See [`RacingRules::reward`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reward: Option<RacingReward>,
    /// See [`RacingRules::progress_per_m`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub progress_per_m: Option<f64>,
    /// See [`RacingRules::steering_weight`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub steering_weight: Option<f64>,
    /// See [`RacingRules::crash_penalty`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub crash_penalty: Option<f64>,
    /// See [`RacingRules::stall_after_s`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stall_after_s: Option<f64>,
    /// See [`RacingRules::time_limit_laps`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub time_limit_laps: Option<f64>,
}

/// The racing rules in force: when an episode ends and how a step is paid.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct RacingRules {
    /// The episode ends (and `crash_penalty` is charged) when the nearest wall return of the
    /// LiDAR falls below this, metres. 0: only contact ends it, the car's body touching a wall,
    /// as F1TENTH counts a crash.
    pub end_below_m: f32,
    /// The reward form.
    pub reward: RacingReward,
    /// Reward per metre along the centre line (the `progress` form).
    pub progress_per_m: f64,
    /// Charge per rad^2 of steering (the `progress` form; the paper's is 2).
    pub steering_weight: f64,
    /// Charged once when the episode ends by a crash (<= 0).
    pub crash_penalty: f64,
    /// The episode ends, truncated, when the car has gained no ground along the centre line
    /// (beyond its best so far, by [`STALL_GAIN_M`]) for this long, seconds. 0: never. The clock
    /// stands still while the safety filter brakes or reverses the car: its recovery from a dead
    /// end is not a stall.
    pub stall_after_s: f64,
    /// The episode ends, truncated, after this many laps' time at the car's top speed (a time
    /// limit that scales with the track, for episodes on circuits of any length). 0: none (the
    /// env's `max_steps` still applies).
    pub time_limit_laps: f64,
}

/// Ground a car must gain on its best progress to count as advancing, metres.
pub const STALL_GAIN_M: f64 = 0.25;

impl RacingRules {
    /// What a step pays under these rules.
    pub fn pay(&self) -> RacingPay {
        RacingPay {
            reward: self.reward,
            progress_per_m: self.progress_per_m,
            steering_weight: self.steering_weight,
            end_below_m: self.end_below_m,
            crash_penalty: self.crash_penalty,
        }
    }

    /// The paper's rules, the oval's default: AutoVRL's 0.8 m proximity end, 5 T^2 - 2 delta^2,
    /// -50 on the end, no stall limit.
    pub fn oval() -> Self {
        Self {
            end_below_m: 0.8,
            reward: RacingReward::Paper,
            progress_per_m: 0.0,
            steering_weight: 2.0,
            crash_penalty: reward::PENALTY,
            stall_after_s: 0.0,
            time_limit_laps: 0.0,
        }
    }

    /// The default on map-file and generated tracks (2.2 m wide F1TENTH circuits leave a 0.8 m
    /// limit a band 0.6 m wide): contact ends the episode, progress pays, a car that gains no
    /// ground for 5 s ends its episode.
    pub fn map_track() -> Self {
        Self {
            end_below_m: 0.0,
            reward: RacingReward::Progress,
            progress_per_m: 1.0,
            steering_weight: 0.05,
            crash_penalty: -10.0,
            stall_after_s: 5.0,
            time_limit_laps: 0.0,
        }
    }

    /// `defaults` with the keys `set` gives replaced, checked.
    pub fn resolve(defaults: Self, set: &RacingRulesSetting) -> Result<Self, EnvError> {
        let r = Self {
            end_below_m: set.end_below_m.unwrap_or(defaults.end_below_m),
            reward: set.reward.unwrap_or(defaults.reward),
            progress_per_m: set.progress_per_m.unwrap_or(defaults.progress_per_m),
            steering_weight: set.steering_weight.unwrap_or(defaults.steering_weight),
            crash_penalty: set.crash_penalty.unwrap_or(defaults.crash_penalty),
            stall_after_s: set.stall_after_s.unwrap_or(defaults.stall_after_s),
            time_limit_laps: set.time_limit_laps.unwrap_or(defaults.time_limit_laps),
        };
        let bad = |m: String| Err(EnvError::Config(format!("racing.{m}")));
        if !(r.end_below_m.is_finite() && (0.0..=5.0).contains(&r.end_below_m)) {
            return bad(format!(
                "end_below_m must be in [0, 5] metres (0: contact only), got {}",
                r.end_below_m
            ));
        }
        if !(r.progress_per_m.is_finite() && r.progress_per_m >= 0.0) {
            return bad(format!("progress_per_m must be >= 0, got {}", r.progress_per_m));
        }
        if !(r.steering_weight.is_finite() && r.steering_weight >= 0.0) {
            return bad(format!("steering_weight must be >= 0, got {}", r.steering_weight));
        }
        if !(r.crash_penalty.is_finite() && r.crash_penalty <= 0.0) {
            return bad(format!("crash_penalty must be <= 0, got {}", r.crash_penalty));
        }
        if !(r.stall_after_s.is_finite() && r.stall_after_s >= 0.0) {
            return bad(format!(
                "stall_after_s must be >= 0 seconds (0: never), got {}",
                r.stall_after_s
            ));
        }
        if !(r.time_limit_laps.is_finite() && r.time_limit_laps >= 0.0) {
            return bad(format!(
                "time_limit_laps must be >= 0 (0: none), got {}",
                r.time_limit_laps
            ));
        }
        Ok(r)
    }
}

/// Racing settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RacingConfig {
    /// Shared settings.
    pub common: CommonConfig,
    /// The rules.
    pub rules: RacingRules,
    /// The car's top speed, m/s (for `time_limit_laps`).
    pub top_speed_mps: f64,
}

impl Default for RacingConfig {
    fn default() -> Self {
        Self {
            common: CommonConfig::default(),
            rules: RacingRules::oval(),
            top_speed_mps: 1.79,
        }
    }
}

/// The racing task.
pub struct Racing {
    cfg: RacingConfig,
    steering_limit: f64,
    last_s: Option<f32>,
    progress_m: f64,
    info: RacingInfo,
    lap_start_s: f64,
    /// The best progress so far and when it was last beaten by [`STALL_GAIN_M`], seconds.
    best_progress_m: f64,
    advanced_s: f64,
    started_s: f64,
    last_stamp_s: f64,
    filter: SafetyFilter,
    correction: Option<Vec<f32>>,
    past: ScanHistory,
}

impl Racing {
    /// A racing task.
    pub fn new(cfg: RacingConfig, steering_limit_rad: f64) -> Self {
        Self {
            cfg,
            steering_limit: steering_limit_rad,
            last_s: None,
            progress_m: 0.0,
            info: RacingInfo::default(),
            lap_start_s: 0.0,
            best_progress_m: 0.0,
            advanced_s: 0.0,
            started_s: 0.0,
            last_stamp_s: 0.0,
            filter: SafetyFilter::new(
                cfg.common.safety_filter,
                cfg.common.action_mapping == crate::task::ActionMapping::ScaledReverse,
            ),
            correction: None,
            past: ScanHistory::new(cfg.common.observation.past_scans),
        }
    }
}

impl Task for Racing {
    fn needs(&self) -> SensorNeeds {
        self.cfg.common.needs()
    }

    fn observation_space(&self) -> BoxSpace {
        self.cfg.common.space()
    }

    fn control(&mut self, action: &[f32], steering_limit_rad: f64, frame: &SensorFrame) -> Control {
        let proposed = self.cfg.common.control(action, steering_limit_rad);
        let (c, correction) = self.filter.apply(frame, proposed, steering_limit_rad, None);
        self.correction = correction.map(|k| self.cfg.common.action_of(k, steering_limit_rad));
        c
    }

    fn intervention(&self) -> Intervention {
        self.filter.last_intervention()
    }

    fn corrected_action(&self) -> Option<Vec<f32>> {
        self.correction.clone()
    }

    fn action_of(&self, control: Control, steering_limit_rad: f64) -> Option<Vec<f32>> {
        Some(self.cfg.common.action_of(control, steering_limit_rad))
    }

    fn proposed(&self, action: &[f32], steering_limit_rad: f64) -> Option<Control> {
        Some(self.cfg.common.control(action, steering_limit_rad))
    }

    fn reset(&mut self, frame: &SensorFrame, map: Option<&MapInfo>) {
        self.filter.reset();
        self.correction = None;
        self.past.reset(frame);
        self.info = RacingInfo::default();
        self.progress_m = 0.0;
        self.lap_start_s = frame.stamp_s;
        self.best_progress_m = 0.0;
        self.advanced_s = frame.stamp_s;
        self.started_s = frame.stamp_s;
        self.last_stamp_s = frame.stamp_s;
        self.last_s = match (map.and_then(|m| m.track.as_ref()), &frame.gps) {
            (Some(t), Some(g)) => Some(t.centreline_s(g.position_m[0] as f32, g.position_m[1] as f32)),
            _ => None,
        };
    }

    fn observe(&self, frame: &SensorFrame) -> Vec<f32> {
        self.cfg
            .common
            .observation
            .observe(frame, self.steering_limit, None, None, Some(&self.past))
    }

    fn evaluate(&mut self, frame: &SensorFrame, map: Option<&MapInfo>) -> Outcome {
        self.past.push(frame);
        // Another car close by ends nothing (self-play would learn never to close in): only
        // the walls count.
        let d = min_static_range_m(frame);
        let c = frame.applied;
        let rules = &self.cfg.rules;
        let mut terms = reward::racing(&rules.pay(), d, c.throttle, c.steering_rad, 0.0);
        let termination = terminate(&mut terms, frame, map, d, rules.end_below_m, rules.crash_penalty);
        let mut racing = None;
        let mut truncate = false;
        if let (Some(t), Some(g)) = (map.and_then(|m| m.track.as_ref()), &frame.gps) {
            let lap = t.lap_length_m() as f64;
            let s = t.centreline_s(g.position_m[0] as f32, g.position_m[1] as f32);
            if let Some(prev) = self.last_s {
                // Wrap the step into (-lap/2, lap/2]: crossing the start line is continuous.
                let mut ds = (s - prev) as f64;
                if ds > lap / 2.0 {
                    ds -= lap;
                } else if ds < -lap / 2.0 {
                    ds += lap;
                }
                self.progress_m += ds;
                if termination.is_none() {
                    terms.progress = reward::racing(&rules.pay(), d, c.throttle, c.steering_rad, ds).progress;
                }
                while self.progress_m >= (self.info.laps as f64 + 1.0) * lap {
                    self.info.laps += 1;
                    let lap_s = frame.stamp_s - self.lap_start_s;
                    self.info.last_lap_s = Some(lap_s);
                    self.info.first_lap_s.get_or_insert(lap_s);
                    self.info.best_lap_s = Some(self.info.best_lap_s.map_or(lap_s, |b| b.min(lap_s)));
                    self.lap_start_s = frame.stamp_s;
                }
            }
            self.last_s = Some(s);
            if self.progress_m >= self.best_progress_m + STALL_GAIN_M {
                self.best_progress_m = self.progress_m;
                self.advanced_s = frame.stamp_s;
            } else if !self.cfg.common.safety_filter.advisory
                && matches!(
                    self.filter.last_intervention(),
                    Intervention::Braked | Intervention::Reversed
                )
            {
                self.advanced_s += frame.stamp_s - self.last_stamp_s;
            }
            let elapsed_s = frame.stamp_s - self.started_s;
            truncate = (rules.stall_after_s > 0.0 && frame.stamp_s - self.advanced_s > rules.stall_after_s)
                || (rules.time_limit_laps > 0.0
                    && elapsed_s >= rules.time_limit_laps * lap / self.cfg.top_speed_mps.max(1e-3));
            self.info.progress_laps = self.progress_m / lap;
            racing = Some(self.info.clone());
        }
        self.last_stamp_s = frame.stamp_s;
        Outcome {
            terms,
            termination,
            truncate: truncate && termination.is_none(),
            racing,
            search: None,
        }
    }
}
