//! How a policy's action becomes the vehicle's control (throttle and steering): a choice of
//! the task, not of the simulator, so a hardware vehicle gets the same mapping.

use agvrl_sim::Control;
use serde::{Deserialize, Serialize};

/// How an action `a in [-1, 1]^2` becomes throttle and steering.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ActionMapping {
    /// The paper and AutoVRL: T = clamp(a0, 0, 1), delta = clamp(a1, -delta_max, delta_max) with
    /// a1 read as radians (half of a0's range coasts, most of a1's saturates).
    Paper,
    /// T = (a0 + 1) / 2, delta = a1 * delta_max: every part of the action range does something.
    #[default]
    Scaled,
    /// T = clamp(a0, 0, 1), delta = a1 * delta_max: the lower half of a0 asks for a standstill,
    /// so with a braking drive a car can stop and stay stopped under exploration noise.
    ScaledStop,
    /// T = a0 for a0 >= 0, else a0 * REVERSE_THROTTLE_MAX (reverse, slower than forward, like
    /// XTENTH-CAR's ESC), delta = a1 * delta_max: a car that can back out of a dead end. The
    /// safety filter checks a reverse path against the points the car saw on its way in.
    ScaledReverse,
}

/// The largest reverse throttle of [`ActionMapping::ScaledReverse`].
pub const REVERSE_THROTTLE_MAX: f64 = 0.5;

impl ActionMapping {
    /// Map a (finite) action to a control. Non-finite inputs give a safe zero control.
    pub fn control(self, a0: f64, a1: f64, delta_max_rad: f64) -> Control {
        if !a0.is_finite() || !a1.is_finite() {
            return Control::default();
        }
        match self {
            ActionMapping::Paper => Control {
                throttle: a0.clamp(0.0, 1.0),
                steering_rad: a1.clamp(-delta_max_rad, delta_max_rad),
            },
            ActionMapping::Scaled => Control {
                throttle: ((a0.clamp(-1.0, 1.0) + 1.0) / 2.0),
                steering_rad: a1.clamp(-1.0, 1.0) * delta_max_rad,
            },
            ActionMapping::ScaledStop => Control {
                throttle: a0.clamp(0.0, 1.0),
                steering_rad: a1.clamp(-1.0, 1.0) * delta_max_rad,
            },
            ActionMapping::ScaledReverse => {
                let a0 = a0.clamp(-1.0, 1.0);
                Control {
                    throttle: if a0 < 0.0 { a0 * REVERSE_THROTTLE_MAX } else { a0 },
                    steering_rad: a1.clamp(-1.0, 1.0) * delta_max_rad,
                }
            }
        }
    }

    /// The action whose control is `c` (the inverse of [`ActionMapping::control`] on the
    /// controls it can produce; others are clamped into the action box first): what a policy
    /// would have had to propose to get the control a safety filter sent instead of its own.
    pub fn action(self, c: Control, delta_max_rad: f64) -> [f64; 2] {
        let steer = if delta_max_rad > 0.0 {
            (c.steering_rad / delta_max_rad).clamp(-1.0, 1.0)
        } else {
            0.0
        };
        match self {
            ActionMapping::Paper => [
                c.throttle.clamp(0.0, 1.0),
                c.steering_rad.clamp(-delta_max_rad, delta_max_rad),
            ],
            ActionMapping::Scaled => [2.0 * c.throttle.clamp(0.0, 1.0) - 1.0, steer],
            ActionMapping::ScaledStop => [c.throttle.clamp(0.0, 1.0), steer],
            ActionMapping::ScaledReverse => {
                let t = c.throttle.clamp(-REVERSE_THROTTLE_MAX, 1.0);
                [if t < 0.0 { t / REVERSE_THROTTLE_MAX } else { t }, steer]
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paper_mapping_clips_like_autovrl() {
        let c = ActionMapping::Paper.control(-0.5, 0.9, 0.36);
        assert_eq!(
            c,
            Control {
                throttle: 0.0,
                steering_rad: 0.36
            }
        );
        let c = ActionMapping::Paper.control(0.25, -0.1, 0.36);
        assert_eq!(
            c,
            Control {
                throttle: 0.25,
                steering_rad: -0.1
            }
        );
    }

    #[test]
    fn reverse_mapping_reverses_slower_than_it_drives() {
        let m = ActionMapping::ScaledReverse;
        assert_eq!(
            m.control(-1.0, 1.0, 0.36),
            Control {
                throttle: -REVERSE_THROTTLE_MAX,
                steering_rad: 0.36
            }
        );
        assert_eq!(m.control(0.8, 0.0, 0.36).throttle, 0.8);
        assert_eq!(m.control(-0.4, 0.0, 0.36).throttle, -0.4 * REVERSE_THROTTLE_MAX);
        assert_eq!(m.control(5.0, 0.0, 0.36).throttle, 1.0);
        assert_eq!(m.control(f64::NAN, 0.0, 0.36), Control::default());
    }

    #[test]
    fn action_of_a_control_maps_back_to_that_control() {
        let limit = 0.36;
        for m in [
            ActionMapping::Paper,
            ActionMapping::Scaled,
            ActionMapping::ScaledStop,
            ActionMapping::ScaledReverse,
        ] {
            let lowest = if m == ActionMapping::ScaledReverse {
                -REVERSE_THROTTLE_MAX
            } else {
                0.0
            };
            for t in [lowest, -0.125, 0.0, 0.25, 1.0] {
                for s in [-limit, -0.09, 0.0, 0.27, limit] {
                    let c = Control {
                        throttle: t.max(lowest),
                        steering_rad: s,
                    };
                    let [a0, a1] = m.action(c, limit);
                    assert!((-1.0..=1.0).contains(&a0) && (-1.0..=1.0).contains(&a1), "{m:?} {c:?}");
                    let back = m.control(a0, a1, limit);
                    assert!(
                        (back.throttle - c.throttle).abs() < 1e-12
                            && (back.steering_rad - c.steering_rad).abs() < 1e-12,
                        "{m:?}: {c:?} -> [{a0}, {a1}] -> {back:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn scaled_mapping_uses_the_whole_range() {
        let c = ActionMapping::Scaled.control(-1.0, -1.0, 0.36);
        assert_eq!(
            c,
            Control {
                throttle: 0.0,
                steering_rad: -0.36
            }
        );
        let c = ActionMapping::Scaled.control(0.0, 0.5, 0.36);
        assert_eq!(
            c,
            Control {
                throttle: 0.5,
                steering_rad: 0.18
            }
        );
        assert_eq!(ActionMapping::Scaled.control(f64::NAN, 0.0, 0.36), Control::default());
        let stop = ActionMapping::ScaledStop;
        assert_eq!(
            stop.control(-0.3, -1.0, 0.36),
            Control {
                throttle: 0.0,
                steering_rad: -0.36
            }
        );
        assert_eq!(
            stop.control(0.5, 0.5, 0.36),
            Control {
                throttle: 0.5,
                steering_rad: 0.18
            }
        );
    }
}
