//! The back-out: a car that stops facing a wall cannot turn out of the dead end (its turning
//! circle is wider than the gap), so with `backout_m > 0` the filter reverses it out. This file
//! holds when a back-out starts (a few controls at a standstill, braked or parked), on which
//! lock and how far the car reverses, and when the back-out ends.

use super::SafetyFilterConfig;
use super::memory::ObstacleMemory;
use crate::api::Control;

/// Below this speed a braked car counts as stopped, m/s.
pub(super) const STILL_MPS: f32 = 0.05;
/// Controls braked at a standstill before the filter backs out.
const STUCK_CONTROLS: u32 = 3;
/// A back-out shorter than this is not worth starting, metres.
const MIN_BACKOUT_M: f32 = 0.15;

/// The back-out's state: the standstills counted towards one, and one under way.
#[derive(Clone, Debug, Default)]
pub(super) struct BackOut {
    /// Consecutive controls braked by the filter at a standstill.
    pub(super) stuck: u32,
    /// Consecutive controls at a standstill with no forward arc free for `backout_m`.
    parked: u32,
    /// A back-out under way: distance still to reverse (m) and its steering (rad).
    under_way: Option<(f32, f64)>,
}

impl BackOut {
    /// Forget the counts and a back-out under way (a new episode).
    pub(super) fn reset(&mut self) {
        self.stuck = 0;
        self.parked = 0;
        self.under_way = None;
    }

    /// A car standing still under a forward or zero throttle (`backout_parked`): after
    /// `STUCK_CONTROLS` such controls in a row with no forward arc free for `backout_m`, the
    /// back-out's first control. A car moving at `speed` starts the count again.
    pub(super) fn back_out_if_parked(
        &mut self,
        cfg: &SafetyFilterConfig,
        memory: &mut ObstacleMemory,
        speed: f32,
        delta: f64,
        steering_limit_rad: f64,
        fan_half_rad: f32,
    ) -> Option<Control> {
        if speed.abs() >= STILL_MPS {
            self.parked = 0;
            return None;
        }
        let want = cfg.backout_m;
        let trapped = std::iter::once(delta)
            .chain(cfg.steerings_nearest(delta, steering_limit_rad))
            .all(|d| memory.free_length(cfg, d as f32, want, fan_half_rad) < want);
        self.parked = if trapped { self.parked + 1 } else { 0 };
        if self.parked < STUCK_CONTROLS {
            return None;
        }
        let c = self.start_backing_out(cfg, memory, steering_limit_rad, fan_half_rad)?;
        self.parked = 0;
        Some(c)
    }

    /// A control the filter brakes at `speed`, no arc being clear: after `STUCK_CONTROLS` of
    /// them in a row at a standstill (and with `backout_m > 0`), the back-out's first control.
    pub(super) fn back_out_if_stuck(
        &mut self,
        cfg: &SafetyFilterConfig,
        memory: &mut ObstacleMemory,
        speed: f32,
        steering_limit_rad: f64,
        fan_half_rad: f32,
    ) -> Option<Control> {
        self.stuck = if speed.abs() < STILL_MPS { self.stuck + 1 } else { 0 };
        if cfg.backout_m > 0.0
            && self.stuck >= STUCK_CONTROLS
            && let Some(c) = self.start_backing_out(cfg, memory, steering_limit_rad, fan_half_rad)
        {
            self.stuck = 0;
            return Some(c);
        }
        None
    }

    /// Begin reversing out of a dead end: the nose should swing towards the open side (the
    /// one whose nearest point ahead of the LiDAR is farther), so the car reverses on the
    /// opposite lock (else straight, else the other lock), as far as `backout_m` or the longest
    /// clear reverse path.
    fn start_backing_out(
        &mut self,
        cfg: &SafetyFilterConfig,
        memory: &mut ObstacleMemory,
        limit_rad: f64,
        fan_half_rad: f32,
    ) -> Option<Control> {
        memory.grid_old_points(cfg);
        let (mut left, mut right) = (f32::INFINITY, f32::INFINITY);
        for &[x, y] in &memory.near {
            let lx = x - cfg.lidar_x_m;
            if lx > 0.0 {
                let d2 = lx * lx + y * y;
                if y > 0.0 {
                    left = left.min(d2);
                } else {
                    right = right.min(d2);
                }
            }
        }
        let towards = if left >= right { 1.0 } else { -1.0 };
        let want = cfg.backout_m;
        let mut best: Option<(f32, f64)> = None;
        for d in [-towards * limit_rad, 0.0, towards * limit_rad] {
            let f = memory.reverse_free_length(cfg, d as f32, want, fan_half_rad);
            if f >= want {
                best = Some((f, d));
                break;
            }
            if best.is_none_or(|b| f > b.0) {
                best = Some((f, d));
            }
        }
        let (len, d) = best.filter(|b| b.0 >= MIN_BACKOUT_M)?;
        self.under_way = Some((len, d));
        Some(Control {
            throttle: -(cfg.backout_throttle as f64),
            steering_rad: d,
        })
    }

    /// The next control of a back-out under way, or `None` when there is none or it is over
    /// (done, or its path is no longer clear: then the car stops and the filter decides anew).
    pub(super) fn keep_backing_out(
        &mut self,
        cfg: &SafetyFilterConfig,
        memory: &mut ObstacleMemory,
        speed: f32,
        fan_half_rad: f32,
    ) -> Option<Control> {
        let (left, d) = self.under_way?;
        memory.grid_old_points(cfg);
        let left = left - memory.last_ds;
        if left <= cfg.stop_distance(-speed) || memory.reverse_free_length(cfg, d as f32, left, fan_half_rad) < left {
            self.under_way = None;
            return None;
        }
        self.under_way = Some((left, d));
        Some(Control {
            throttle: -(cfg.backout_throttle as f64),
            steering_rad: d,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::task::safety::memory::MAX_BACKABLE_M;
    use crate::task::safety::tests::{FAN, on, slanted_wall_frame, wall_frame};
    use crate::task::safety::{Intervention, SafetyFilter};

    /// A filter that backs out 0.6 m (`backout_parked` as given) and may reverse as far as it
    /// ever does.
    fn backing_out(backout_parked: bool) -> SafetyFilter {
        let mut f = SafetyFilter::new(
            SafetyFilterConfig {
                backout_m: 0.6,
                backout_parked,
                ..on().cfg
            },
            true,
        );
        f.memory.backable_m = MAX_BACKABLE_M;
        f
    }

    #[test]
    fn a_car_stuck_at_a_wall_backs_out_turning_its_nose_to_the_open_side() {
        let mut f = backing_out(false);
        let go = Control {
            throttle: 1.0,
            steering_rad: 0.0,
        };
        // A wall 0.8 m ahead, nearer on the left: every arc is blocked within the lookahead.
        let dt = 0.1;
        for k in 0..STUCK_CONTROLS - 1 {
            let c = f.filter(&slanted_wall_frame(0.8, 0.3, k as f64 * dt, 0.0), go, 0.36, FAN);
            assert_eq!((f.last_intervention(), c.throttle), (Intervention::Braked, 0.0));
        }
        let mut t = (STUCK_CONTROLS - 1) as f64 * dt;
        let c = f.filter(&slanted_wall_frame(0.8, 0.3, t, 0.0), go, 0.36, FAN);
        assert_eq!(f.last_intervention(), Intervention::Reversed);
        // Reversing on left lock swings the nose right, to the open side.
        assert_eq!(
            c,
            Control {
                throttle: -0.25,
                steering_rad: 0.36
            }
        );
        // At 0.5 m/s back (5 cm a control) it reverses until what is left of 0.6 m is its
        // stopping distance (0.05 m reacting + 0.042 m braking), then the policy drives again.
        let mut reversing = 1;
        loop {
            t += dt;
            f.filter(&slanted_wall_frame(0.8, 0.3, t, -0.5), go, 0.36, FAN);
            if f.last_intervention() != Intervention::Reversed {
                break;
            }
            reversing += 1;
            assert!(reversing < 30, "never stops reversing");
        }
        let want = 1 + ((0.6 - 0.05 - 0.25 / 6.0) / 0.05f64).floor() as i32;
        assert!(
            (reversing - want).abs() <= 1,
            "{reversing} controls reversing, want {want}"
        );
        // Without backout_m the car waits.
        let mut f = on();
        for k in 0..10 {
            f.filter(&slanted_wall_frame(0.8, 0.3, k as f64 * dt, 0.0), go, 0.36, FAN);
            assert_eq!(f.last_intervention(), Intervention::Braked);
        }
    }

    #[test]
    fn a_car_that_parked_itself_in_a_dead_end_backs_out_only_with_backout_parked() {
        let wait = Control {
            throttle: 0.0,
            steering_rad: 0.1,
        };
        let dt = 0.1;
        // At rest 1.0 m from a wall: braking needs no path, so the zero throttle is no
        // correction, but no forward arc is free for 0.6 m.
        let mut f = backing_out(true);
        for k in 0..STUCK_CONTROLS - 1 {
            let c = f.filter(&slanted_wall_frame(1.0, 0.3, k as f64 * dt, 0.0), wait, 0.36, FAN);
            assert_eq!((f.last_intervention(), c), (Intervention::None, wait));
        }
        let t = (STUCK_CONTROLS - 1) as f64 * dt;
        let c = f.filter(&slanted_wall_frame(1.0, 0.3, t, 0.0), wait, 0.36, FAN);
        assert_eq!(f.last_intervention(), Intervention::Reversed);
        assert_eq!(c.throttle, -0.25);
        // Without the setting the car waits there for good.
        let mut f = backing_out(false);
        for k in 0..10 {
            assert_eq!(
                f.filter(&slanted_wall_frame(1.0, 0.3, k as f64 * dt, 0.0), wait, 0.36, FAN),
                wait
            );
            assert_eq!(f.last_intervention(), Intervention::None);
        }
        // With room to drive on (the wall 3 m off), a car that waits is left waiting.
        let mut f = backing_out(true);
        for k in 0..10 {
            assert_eq!(f.filter(&wall_frame(3.0, k as f64 * dt, 0.0), wait, 0.36, FAN), wait);
            assert_eq!(f.last_intervention(), Intervention::None);
        }
        // The setting needs a back-out length.
        let bad = SafetyFilterConfig {
            backout_parked: true,
            backout_m: 0.0,
            decel_mps2: 3.0,
            ..on().cfg
        };
        assert!(bad.validate().unwrap_err().to_string().contains("backout_parked"));
    }
}
