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
    /// agvrl's shaped form for collision-free exploration: 0.5 T^2, minus 0.1 (delta / 0.36)^2,
    /// plus 0.5 (`new_cell`) per newly covered 0.5 m cell, minus (1 - d) / 0.4 when d < 1.0 (0 at 1 m, 1 at
    /// the 0.6 m termination), and -20 once on a collision. AutoVRL's forms charge -50 on every
    /// step under 1 m but only once for ending the episode, so a car that came within 1 m of
    /// an obstacle scores best by crashing at once; here recovering always costs less than a
    /// collision, and driving over new ground beats circling.
    Safe,
}

impl SearchReward {
    /// The penalty charged once when an episode ends by a collision.
    pub fn collision_penalty(self, safe: &SafeShaping) -> f64 {
        match self {
            Self::AutovrlCode | Self::PaperCases => PENALTY,
            Self::Safe => safe.collision,
        }
    }
}

/// The constants of the `safe` form's penalties (the defaults are the form as documented on
/// [`SearchReward::Safe`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SafeShaping {
    /// The graded proximity penalty starts under this range, metres...
    pub near_m: f64,
    /// ...and grows linearly to this per step at 0.6 m, AutoVRL's termination range.
    pub near_weight: f64,
    /// Charged once on a collision (<= 0).
    pub collision: f64,
    /// When > 0, the proximity penalty is scaled by forward speed / this (capped at 1), m/s: a
    /// car standing still near an obstacle pays nothing, so stopping where it cannot turn
    /// (there is no reverse) beats crashing. 0 (the default): not scaled.
    pub near_speed_mps: f64,
    /// Charged every step the safety filter changed the policy's control (<= 0): the policy
    /// learns to propose safe controls and to keep out of places where the filter must brake
    /// (a car braked in a dead end has no reverse and stays there). 0 (the default): free.
    pub filter: f64,
    /// Paid per newly covered 0.5 m cell (>= 0).
    pub new_cell: f64,
    /// Charged every step once no new cell has been covered for `stale_after_s` (<= 0): a car
    /// parked in a pocket it has swept keeps paying until it reaches new ground, where
    /// standing still is otherwise free. 0 (the default): free.
    pub stale: f64,
    /// How long a car may go without a new cell before `stale` is charged, seconds (> 0).
    pub stale_after_s: f64,
}

impl Default for SafeShaping {
    fn default() -> Self {
        Self {
            near_m: 1.0,
            near_weight: 1.0,
            collision: -20.0,
            near_speed_mps: 0.0,
            filter: 0.0,
            new_cell: 0.5,
            stale: 0.0,
            stale_after_s: 3.0,
        }
    }
}

impl SafeShaping {
    /// Why these constants cannot shape a reward, if they cannot.
    pub fn validate(&self) -> Result<(), agvrl_sim::InvalidSetting> {
        if !(self.near_m.is_finite() && self.near_m > SAFE_FULL_M) {
            return Err(agvrl_sim::InvalidSetting::new(
                "safe_reward",
                format!("safe_reward.near_m must be above {SAFE_FULL_M} m, got {}", self.near_m),
            ));
        }
        if !(self.near_weight.is_finite() && self.near_weight >= 0.0) {
            return Err(agvrl_sim::InvalidSetting::new(
                "safe_reward",
                format!("safe_reward.near_weight must be >= 0, got {}", self.near_weight),
            ));
        }
        if !(self.near_speed_mps.is_finite() && self.near_speed_mps >= 0.0) {
            return Err(agvrl_sim::InvalidSetting::new(
                "safe_reward",
                format!("safe_reward.near_speed_mps must be >= 0, got {}", self.near_speed_mps),
            ));
        }
        if !(self.collision.is_finite() && self.collision <= 0.0) {
            return Err(agvrl_sim::InvalidSetting::new(
                "safe_reward",
                format!("safe_reward.collision must be <= 0, got {}", self.collision),
            ));
        }
        if !(self.filter.is_finite() && self.filter <= 0.0) {
            return Err(agvrl_sim::InvalidSetting::new(
                "safe_reward",
                format!("safe_reward.filter must be <= 0, got {}", self.filter),
            ));
        }
        if !(self.stale.is_finite() && self.stale <= 0.0) {
            return Err(agvrl_sim::InvalidSetting::new(
                "safe_reward",
                format!("safe_reward.stale must be <= 0, got {}", self.stale),
            ));
        }
        if !(self.stale_after_s.is_finite() && self.stale_after_s > 0.0) {
            return Err(agvrl_sim::InvalidSetting::new(
                "safe_reward",
                format!("safe_reward.stale_after_s must be > 0, got {}", self.stale_after_s),
            ));
        }
        if !(self.new_cell.is_finite() && self.new_cell >= 0.0) {
            return Err(agvrl_sim::InvalidSetting::new(
                "safe_reward",
                format!("safe_reward.new_cell must be >= 0, got {}", self.new_cell),
            ));
        }
        Ok(())
    }
}

/// Where the `safe` form's proximity penalty reaches its full weight, metres.
const SAFE_FULL_M: f64 = 0.6;

/// Penalty of a collision, and of AutoVRL's outdoor-50 crawl.
pub const PENALTY: f64 = -50.0;

/// R_search for one step. `slow_penalty`: AutoVRL's outdoor-50 adds -50 when T < 0.1;
/// `new_cells`: coverage cells first reached this step (used by `Safe` only).
pub fn search(
    form: SearchReward,
    safe: &SafeShaping,
    d: f64,
    t: f64,
    delta: f64,
    slow_penalty: bool,
    new_cells: usize,
) -> RewardTerms {
    let mut r = RewardTerms::default();
    let band = d > 2.0 && d < 2.5;
    match form {
        SearchReward::Safe => {
            r.throttle = 0.5 * t * t;
            r.steering = -0.1 * (delta / 0.36).powi(2);
            r.coverage = safe.new_cell * new_cells as f64;
            if d < safe.near_m {
                r.proximity = -safe.near_weight * ((safe.near_m - d) / (safe.near_m - SAFE_FULL_M)).min(1.0);
            }
        }
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
    // The crawl penalty is AutoVRL's; the safe form must be free to slow down near obstacles.
    if slow_penalty && t < 0.1 && form != SearchReward::Safe {
        r.slow = PENALTY;
    }
    r
}

/// Scale the `safe` proximity term by forward speed (see [`SafeShaping::near_speed_mps`]).
pub fn weight_proximity_by_speed(terms: &mut RewardTerms, safe: &SafeShaping, forward_mps: f64) {
    if safe.near_speed_mps > 0.0 {
        terms.proximity *= (forward_mps / safe.near_speed_mps).clamp(0.0, 1.0);
    }
}

/// How a racing step is paid.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RacingReward {
    /// The paper's R_racing: 5 T^2 - 2 delta^2 (pays throttle, whichever way the car goes).
    Paper,
    /// `progress_per_m` per metre gained along the centre line (negative when going back),
    /// minus `steering_weight` delta^2.
    Progress,
}

/// What a racing step pays: the reward fields of the racing rules
/// ([`RacingRules::pay`](super::RacingRules::pay)).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RacingPay {
    /// The form.
    pub reward: RacingReward,
    /// Paid per metre along the centre line (`Progress`).
    pub progress_per_m: f64,
    /// Charged per rad^2 of steering (`Progress`).
    pub steering_weight: f64,
    /// Clearance below which the step pays `crash_penalty` alone (0: never).
    pub end_below_m: f32,
    /// What a crash pays.
    pub crash_penalty: f64,
}

/// A racing step under `rules`: the paper's R_racing (5 T^2 - 2 delta^2), or `progress_per_m` per
/// metre `ds_m` gained along the centre line minus `steering_weight` delta^2; only the crash
/// penalty once `d` is under a positive `end_below_m` (the task ends the episode there).
pub fn racing(rules: &RacingPay, d: f64, t: f64, delta: f64, ds_m: f64) -> RewardTerms {
    if d < rules.end_below_m as f64 {
        return RewardTerms {
            collision: rules.crash_penalty,
            ..RewardTerms::default()
        };
    }
    match rules.reward {
        RacingReward::Paper => RewardTerms {
            throttle: 5.0 * t * t,
            steering: -2.0 * delta * delta,
            ..RewardTerms::default()
        },
        RacingReward::Progress => RewardTerms {
            progress: rules.progress_per_m * ds_m,
            steering: -rules.steering_weight * delta * delta,
            ..RewardTerms::default()
        },
    }
}

impl RewardTerms {
    /// Sum of the terms.
    pub fn total(&self) -> f64 {
        self.throttle
            + self.steering
            + self.clearance
            + self.band
            + self.collision
            + self.slow
            + self.proximity
            + self.coverage
            + self.filter
            + self.stale
            + self.progress
            + self.car_contact
            + self.position
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn autovrl_code_form_by_hand() {
        // d = 2.2 (band), T = 0.5, delta = 0.1: 0.005*4.84 + 1.25 - 0.02 + 2 = 3.2542
        let r = search(
            SearchReward::AutovrlCode,
            &SafeShaping::default(),
            2.2,
            0.5,
            0.1,
            false,
            0,
        )
        .total();
        assert!((r - 3.2542).abs() < 1e-12, "{r}");
        // d = 0.7 (terminal too), T = 1, delta = -0.36: 0.00245 + 5 - 0.2592 - 50 = -45.25675
        let r = search(
            SearchReward::AutovrlCode,
            &SafeShaping::default(),
            0.7,
            1.0,
            -0.36,
            false,
            0,
        )
        .total();
        assert!((r + 45.25675).abs() < 1e-12, "{r}");
        // d = 5, T = 0.05 with outdoor-50's crawl penalty: 0.125 + 0.0125 - 0 - 50
        let r = search(
            SearchReward::AutovrlCode,
            &SafeShaping::default(),
            5.0,
            0.05,
            0.0,
            true,
            0,
        )
        .total();
        assert!((r + 49.8625).abs() < 1e-12, "{r}");
    }

    #[test]
    fn paper_case_form_by_hand() {
        assert_eq!(
            search(
                SearchReward::PaperCases,
                &SafeShaping::default(),
                2.2,
                0.5,
                0.1,
                false,
                0
            )
            .total(),
            2.0
        );
        assert_eq!(
            search(
                SearchReward::PaperCases,
                &SafeShaping::default(),
                0.7,
                1.0,
                0.3,
                false,
                0
            )
            .total(),
            -50.0
        );
        let r = search(
            SearchReward::PaperCases,
            &SafeShaping::default(),
            3.0,
            0.5,
            0.1,
            false,
            0,
        )
        .total();
        assert!((r - (0.045 + 1.25 - 0.02)).abs() < 1e-12, "{r}");
    }

    #[test]
    fn safe_form_by_hand() {
        // d = 0.8, T = 1, delta = 0.18, 2 new cells: 0.5 - 0.025 + 1.0 - 0.5 = 0.975
        let r = search(SearchReward::Safe, &SafeShaping::default(), 0.8, 1.0, 0.18, false, 2);
        assert!((r.total() - 0.975).abs() < 1e-12, "{r:?}");
        assert_eq!(r.collision, 0.0);
        // Far from everything: no proximity term; at 0.5 m the term saturates at -1.
        assert_eq!(
            search(SearchReward::Safe, &SafeShaping::default(), 3.0, 0.0, 0.0, true, 0).total(),
            0.0
        );
        assert_eq!(
            search(SearchReward::Safe, &SafeShaping::default(), 0.5, 0.0, 0.0, false, 0).proximity,
            -1.0
        );
        // Ten steps of the worst proximity cost less than the collision.
        let worst = search(SearchReward::Safe, &SafeShaping::default(), 0.0, 0.0, 0.0, false, 0).proximity;
        assert!(10.0 * worst > SearchReward::Safe.collision_penalty(&SafeShaping::default()));
    }

    #[test]
    fn safe_form_with_a_wider_band_and_a_heavier_collision() {
        let wide = SafeShaping {
            near_m: 1.6,
            near_weight: 2.0,
            collision: -100.0,
            near_speed_mps: 0.0,
            filter: 0.0,
            new_cell: 2.0,
            stale: 0.0,
            stale_after_s: 3.0,
        };
        assert_eq!(search(SearchReward::Safe, &wide, 3.0, 0.0, 0.0, false, 3).coverage, 6.0);
        // Halfway between 1.6 m and 0.6 m: half of the weight.
        let r = search(SearchReward::Safe, &wide, 1.1, 0.0, 0.0, false, 0);
        assert!((r.proximity + 1.0).abs() < 1e-12, "{r:?}");
        assert_eq!(
            search(SearchReward::Safe, &wide, 0.3, 0.0, 0.0, false, 0).proximity,
            -2.0
        );
        assert_eq!(SearchReward::Safe.collision_penalty(&wide), -100.0);
        assert_eq!(SearchReward::AutovrlCode.collision_penalty(&wide), PENALTY);
        // Speed-weighted: nothing at a standstill, half at half the reference speed.
        let moving = SafeShaping {
            near_speed_mps: 1.5,
            ..wide
        };
        for (v, expect) in [(0.0, 0.0), (-0.2, 0.0), (0.75, -1.0), (3.0, -2.0)] {
            let mut r = search(SearchReward::Safe, &moving, 0.3, 0.0, 0.0, false, 0);
            weight_proximity_by_speed(&mut r, &moving, v);
            assert_eq!(r.proximity, expect, "v = {v}");
        }
        let e = SafeShaping { near_m: 0.5, ..wide }.validate().unwrap_err();
        assert_eq!(e.table, "safe_reward");
        assert!(e.message.contains("near_m"), "{e}");
        assert!(
            SafeShaping { collision: 1.0, ..wide }
                .validate()
                .unwrap_err()
                .message
                .contains("collision")
        );
        assert!(
            SafeShaping { filter: 0.5, ..wide }
                .validate()
                .unwrap_err()
                .message
                .contains("filter")
        );
        assert!(
            SafeShaping { new_cell: -0.1, ..wide }
                .validate()
                .unwrap_err()
                .message
                .contains("new_cell")
        );
        for bad in [
            SafeShaping { stale: 0.1, ..wide },
            SafeShaping {
                stale_after_s: 0.0,
                ..wide
            },
            SafeShaping {
                stale_after_s: f64::NAN,
                ..wide
            },
        ] {
            assert!(bad.validate().unwrap_err().message.contains("stale"), "{bad:?}");
        }
    }

    #[test]
    fn racing_by_hand() {
        use crate::task::racing::RacingRules;
        let paper = RacingRules::oval().pay();
        let r = racing(&paper, 1.2, 0.8, 0.2, 0.3).total();
        assert!((r - (3.2 - 0.08)).abs() < 1e-12, "{r}");
        assert_eq!(racing(&paper, 0.79, 1.0, 0.0, 0.3).total(), -50.0);
        // Progress: 2 per metre over 0.06 m, 0.05 per rad^2 at 0.2 rad; nothing for throttle,
        // and going back costs what going forward pays. Contact-only rules charge nothing near
        // a wall.
        let progress = RacingRules {
            progress_per_m: 2.0,
            ..RacingRules::map_track()
        }
        .pay();
        let r = racing(&progress, 0.05, 1.0, 0.2, 0.06);
        assert!((r.total() - (0.12 - 0.002)).abs() < 1e-12, "{r:?}");
        assert_eq!(r.throttle, 0.0);
        assert_eq!(racing(&progress, 0.05, 1.0, 0.0, -0.06).total(), -0.12);
    }
}
