//! Racing on the oval (the paper's R_racing = 5 T^2 - 2 delta^2, -50 and the end when r_m <
//! 0.8 m). Reports laps, lap times and progress along the centre line.

use super::reward;
use super::{CommonConfig, Intervention, Outcome, SafetyFilter, Task, min_static_range_m, terminate};
use crate::api::{BoxSpace, Control, MapInfo, RacingInfo, SensorFrame, SensorNeeds};
use serde::{Deserialize, Serialize};

/// Racing settings.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RacingConfig {
    /// Shared settings.
    #[serde(flatten)]
    pub common: CommonConfig,
    /// The episode ends when the minimum range falls below this, metres (the paper: 0.8).
    pub terminate_below_m: f32,
}

impl Default for RacingConfig {
    fn default() -> Self {
        Self {
            common: CommonConfig::default(),
            terminate_below_m: 0.8,
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
    filter: SafetyFilter,
    correction: Option<Vec<f32>>,
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
            filter: SafetyFilter::new(
                cfg.common.safety_filter,
                cfg.common.action_mapping == crate::task::ActionMapping::ScaledReverse,
            ),
            correction: None,
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

    fn reset(&mut self, frame: &SensorFrame, map: Option<&MapInfo>) {
        self.filter.reset();
        self.correction = None;
        self.info = RacingInfo::default();
        self.progress_m = 0.0;
        self.lap_start_s = frame.stamp_s;
        self.last_s = match (map.and_then(|m| m.track.as_ref()), &frame.gps) {
            (Some(t), Some(g)) => Some(t.centreline_s(g.position_m[0] as f32, g.position_m[1] as f32)),
            _ => None,
        };
    }

    fn observe(&self, frame: &SensorFrame) -> Vec<f32> {
        self.cfg
            .common
            .observation
            .observe(frame, self.steering_limit, None, None)
    }

    fn evaluate(&mut self, frame: &SensorFrame, map: Option<&MapInfo>) -> Outcome {
        // Another car close by ends nothing (self-play would learn never to close in): only
        // the walls count.
        let d = min_static_range_m(frame);
        let c = frame.applied;
        let mut terms = reward::racing(d, c.throttle, c.steering_rad);
        let termination = terminate(&mut terms, frame, map, d, self.cfg.terminate_below_m, reward::PENALTY);
        let mut racing = None;
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
                while self.progress_m >= (self.info.laps as f64 + 1.0) * lap {
                    self.info.laps += 1;
                    let lap_s = frame.stamp_s - self.lap_start_s;
                    self.info.last_lap_s = Some(lap_s);
                    self.info.best_lap_s = Some(self.info.best_lap_s.map_or(lap_s, |b| b.min(lap_s)));
                    self.lap_start_s = frame.stamp_s;
                }
            }
            self.last_s = Some(s);
            self.info.progress_laps = self.progress_m / lap;
            racing = Some(self.info.clone());
        }
        Outcome {
            terms,
            termination,
            racing,
            search: None,
        }
    }
}
