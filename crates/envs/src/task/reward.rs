//! The paper's rewards (section 6) and AutoVRL's code forms of them: the one home of reward
//! arithmetic. T = throttle in [0, 1], delta = steering in rad, d = r_m = minimum LiDAR range.

use crate::api::RewardTerms;
use serde::{Deserialize, Serialize};

/// Which R_search.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SearchReward {
    /// AutoVRL's code (produced the paper's results): 0.005 d^2 + 5 T^2 - 2 delta^2, then +2 if
    /// 2.0 < d < 2.5, then -50 if d < 1.0 (all additive).
    #[default]
    AutovrlCode,
    /// The paper's cases: -50 if d < 1.0, else 2.0 if 2.0 < d < 2.5, else
    /// 0.005 d^2 + 5 T^2 - 2 delta^2.
    PaperCases,
}

/// Penalty of a collision, and of AutoVRL's outdoor-50 crawl.
pub const PENALTY: f64 = -50.0;

/// R_search for one step. `slow_penalty`: AutoVRL's outdoor-50 adds -50 when T < 0.1.
pub fn search(form: SearchReward, d: f64, t: f64, delta: f64, slow_penalty: bool) -> RewardTerms {
    let mut r = RewardTerms::default();
    let band = d > 2.0 && d < 2.5;
    match form {
        SearchReward::AutovrlCode => {
            r.clearance = 0.005 * d * d;
            r.throttle = 5.0 * t * t;
            r.steering = -2.0 * delta * delta;
            if band {
                r.band = 2.0;
            }
            if d < 1.0 {
                r.collision = PENALTY;
            }
        }
        SearchReward::PaperCases => {
            if d < 1.0 {
                r.collision = PENALTY;
            } else if band {
                r.band = 2.0;
            } else {
                r.clearance = 0.005 * d * d;
                r.throttle = 5.0 * t * t;
                r.steering = -2.0 * delta * delta;
            }
        }
    }
    if slow_penalty && t < 0.1 {
        r.slow = PENALTY;
    }
    r
}

/// R_racing: 5 T^2 - 2 delta^2, or -50 (and the episode ends) when `d < 0.8`.
pub fn racing(d: f64, t: f64, delta: f64) -> RewardTerms {
    if d < 0.8 {
        RewardTerms {
            collision: PENALTY,
            ..RewardTerms::default()
        }
    } else {
        RewardTerms {
            throttle: 5.0 * t * t,
            steering: -2.0 * delta * delta,
            ..RewardTerms::default()
        }
    }
}

impl RewardTerms {
    /// Sum of the terms.
    pub fn total(&self) -> f64 {
        self.throttle + self.steering + self.clearance + self.band + self.collision + self.slow
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn autovrl_code_form_by_hand() {
        // d = 2.2 (band), T = 0.5, delta = 0.1: 0.005*4.84 + 1.25 - 0.02 + 2 = 3.2542
        let r = search(SearchReward::AutovrlCode, 2.2, 0.5, 0.1, false).total();
        assert!((r - 3.2542).abs() < 1e-12, "{r}");
        // d = 0.7 (terminal too), T = 1, delta = -0.36: 0.00245 + 5 - 0.2592 - 50 = -45.25675
        let r = search(SearchReward::AutovrlCode, 0.7, 1.0, -0.36, false).total();
        assert!((r + 45.25675).abs() < 1e-12, "{r}");
        // d = 5, T = 0.05 with outdoor-50's crawl penalty: 0.125 + 0.0125 - 0 - 50
        let r = search(SearchReward::AutovrlCode, 5.0, 0.05, 0.0, true).total();
        assert!((r + 49.8625).abs() < 1e-12, "{r}");
    }

    #[test]
    fn paper_case_form_by_hand() {
        assert_eq!(search(SearchReward::PaperCases, 2.2, 0.5, 0.1, false).total(), 2.0);
        assert_eq!(search(SearchReward::PaperCases, 0.7, 1.0, 0.3, false).total(), -50.0);
        let r = search(SearchReward::PaperCases, 3.0, 0.5, 0.1, false).total();
        assert!((r - (0.045 + 1.25 - 0.02)).abs() < 1e-12, "{r}");
    }

    #[test]
    fn racing_by_hand() {
        let r = racing(1.2, 0.8, 0.2).total();
        assert!((r - (3.2 - 0.08)).abs() < 1e-12, "{r}");
        assert_eq!(racing(0.79, 1.0, 0.0).total(), -50.0);
    }
}
