//! A LiDAR safety filter between the policy and the drive: before a control goes out, the car's
//! path under it (the Ackermann arc of its steering, long enough to react and brake to a stop)
//! is checked against the obstacle points of the last second of scans. An unsafe control is
//! replaced by the nearest steering whose path is clear, or by braking on the clearest arc.
//! Only the scan, the IMU's speed and yaw rate, and the car's geometry enter, so the same filter
//! runs in simulation and on the car.
//!
//! A car without reverse that stops facing a wall stays there (its turning circle is wider than
//! the gap). With `backout_m > 0` the filter then reverses out of the dead end: on the steering
//! lock that turns the nose towards the side with more free path ahead, checked against the
//! points of the last `reverse_memory_s` seconds (the LiDAR does not see behind the car, but the
//! car drove in through what lies behind it, and saw the sides on the way).
//!
//! This file holds the settings and the decision (which control goes out); the parts it
//! composes live beside it: `memory.rs` (odometry, the remembered obstacle points, and how far
//! an arc stays clear of them), `arcs.rs` (poses along a steering's arc and the body's check at
//! each) and `backout.rs` (when, on which lock and how far the car reverses out of a dead end).

mod arcs;
mod backout;
mod memory;

use crate::api::{Control, SensorFrame};
use backout::{BackOut, STILL_MPS};
pub(crate) use memory::ObstacleMemory;
use serde::{Deserialize, Serialize};

/// Settings of the safety filter. The geometry defaults are XTENTH-CAR's, measured from the
/// rear axle (x forward, y left).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SafetyFilterConfig {
    /// Filter the policy's controls (off: they pass unchanged).
    pub enabled: bool,
    /// Advise only: the filter runs and reports its correction (`Info::corrected_action`),
    /// but the policy's control goes out (a training setting: the policy meets the outcome of
    /// its own controls, and a learner can imitate the advice on the states the policy
    /// reaches).
    pub advisory: bool,
    /// Smallest distance from the LiDAR to an obstacle point inside its field of view that the
    /// predicted path may reach, metres (the search task ends an episode under 0.6 m).
    pub clearance_m: f32,
    /// Margin around the body's footprint, metres.
    pub body_margin_m: f32,
    /// Deceleration when the filter brakes, m/s^2 (0 in an env config: the drive's
    /// `brake_mps2`).
    pub decel_mps2: f32,
    /// Time before a brake takes effect (one control period of latency, and the next), s.
    pub reaction_s: f32,
    /// Free path demanded beyond the stopping point when the control drives, metres.
    pub lookahead_m: f32,
    /// How long obstacle points are remembered (by odometry from the IMU), s.
    pub memory_s: f32,
    /// Steering angles tried, evenly spaced over the steering range.
    pub n_steering: usize,
    /// Wheelbase, metres.
    pub wheelbase_m: f32,
    /// LiDAR position ahead of the rear axle, metres.
    pub lidar_x_m: f32,
    /// Front of the body ahead of the rear axle, metres.
    pub front_m: f32,
    /// Back of the body behind the rear axle, metres.
    pub rear_m: f32,
    /// Half the body's width, wheels included, metres.
    pub half_width_m: f32,
    /// How far to reverse out of a dead end, metres (0: never reverse; the car waits braked).
    pub backout_m: f32,
    /// Throttle while reversing, in (0, 1].
    pub backout_throttle: f32,
    /// Also back out a car that stopped itself in a dead end: standing still under a zero or
    /// forward throttle, with no forward arc free for `backout_m` (else the filter backs out
    /// only a car it braked, and a policy that parks in front of a wall stays there).
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub backout_parked: bool,
    /// How long obstacle points are kept for checking a reverse path (the policy's or a
    /// back-out's), s (at least `memory_s`).
    pub reverse_memory_s: f32,
    /// Smallest distance from the LiDAR to a point in its fan that a reverse path may reach,
    /// metres (backing away from the wall in front needs less than driving on).
    pub reverse_clearance_m: f32,
}

impl Default for SafetyFilterConfig {
    fn default() -> Self {
        Self {
            enabled: false,
            advisory: false,
            clearance_m: 0.75,
            body_margin_m: 0.08,
            decel_mps2: 0.0,
            reaction_s: 0.1,
            lookahead_m: 0.25,
            memory_s: 1.5,
            n_steering: 9,
            wheelbase_m: 0.33,
            lidar_x_m: 0.16,
            front_m: 0.415,
            rear_m: 0.085,
            half_width_m: 0.192,
            backout_m: 0.0,
            backout_throttle: 0.25,
            backout_parked: false,
            reverse_memory_s: 10.0,
            reverse_clearance_m: 0.65,
        }
    }
}

impl SafetyFilterConfig {
    /// The filter on a drive that brakes at `brake_mps2`: `decel_mps2 = 0` takes the drive's rate.
    pub fn on_drive(mut self, brake_mps2: f64) -> Self {
        if self.decel_mps2 == 0.0 {
            self.decel_mps2 = brake_mps2 as f32;
        }
        self
    }

    /// Check the settings.
    pub fn validate(&self) -> Result<(), agvrl_sim::InvalidSetting> {
        if !self.enabled {
            return Ok(());
        }
        let lengths = [
            ("clearance_m", self.clearance_m),
            ("body_margin_m", self.body_margin_m),
            ("reaction_s", self.reaction_s),
            ("lookahead_m", self.lookahead_m),
            ("memory_s", self.memory_s),
            ("lidar_x_m", self.lidar_x_m),
            ("rear_m", self.rear_m),
            ("backout_m", self.backout_m),
            ("reverse_clearance_m", self.reverse_clearance_m),
            ("reverse_memory_s", self.reverse_memory_s),
        ];
        for (name, v) in lengths {
            if !(v.is_finite() && v >= 0.0) {
                return Err(agvrl_sim::InvalidSetting::new(
                    "safety_filter",
                    format!("safety_filter.{name} must be finite and >= 0, got {v}"),
                ));
            }
        }
        for (name, v) in [
            ("wheelbase_m", self.wheelbase_m),
            ("front_m", self.front_m),
            ("half_width_m", self.half_width_m),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(agvrl_sim::InvalidSetting::new(
                    "safety_filter",
                    format!("safety_filter.{name} must be finite and > 0, got {v}"),
                ));
            }
        }
        if self.backout_m > 0.0 && !(self.backout_throttle > 0.0 && self.backout_throttle <= 1.0) {
            return Err(agvrl_sim::InvalidSetting::new(
                "safety_filter",
                format!(
                    "safety_filter.backout_throttle must be in (0, 1], got {}",
                    self.backout_throttle
                ),
            ));
        }
        if self.backout_parked && self.backout_m == 0.0 {
            return Err(agvrl_sim::InvalidSetting::new(
                "safety_filter",
                "safety_filter.backout_parked needs backout_m > 0 (how far to back out)",
            ));
        }
        if self.n_steering < 2 {
            return Err(agvrl_sim::InvalidSetting::new(
                "safety_filter",
                format!("safety_filter.n_steering must be >= 2, got {}", self.n_steering),
            ));
        }
        if !(self.decel_mps2.is_finite() && self.decel_mps2 > 0.0) {
            return Err(agvrl_sim::InvalidSetting::new(
                "safety_filter",
                "safety_filter needs a braking drive: set brake_mps2 (or safety_filter.decel_mps2) > 0; \
                 a coasting car cannot stop where the filter plans",
            ));
        }
        Ok(())
    }
}

impl SafetyFilterConfig {
    /// Path length a control needs clear: the distance to react and brake to a stop, plus
    /// `lookahead_m` when it drives.
    fn path_needed(&self, speed: f32, drives: bool) -> f32 {
        let stop = self.stop_distance(speed);
        if drives { stop + self.lookahead_m } else { stop }
    }

    /// Distance to react and brake to a stop from `speed` along the way it drives (0 when it
    /// moves the other way), metres.
    fn stop_distance(&self, speed: f32) -> f32 {
        let v = speed.max(0.0);
        v * self.reaction_s + v * v / (2.0 * self.decel_mps2.max(1e-3))
    }

    /// The `n_steering` angles over the steering range, nearest to `delta` first.
    fn steerings_nearest(&self, delta: f64, limit_rad: f64) -> Vec<f64> {
        let n = self.n_steering;
        let mut candidates: Vec<f64> = (0..n)
            .map(|k| -limit_rad + 2.0 * limit_rad * k as f64 / (n - 1) as f64)
            .collect();
        candidates.sort_by(|a, b| (a - delta).abs().total_cmp(&(b - delta).abs()));
        candidates
    }

    /// How far from the rear axle a point may be that any path the filter checks at `speed`
    /// can reach, metres.
    fn reach(&self, speed: f32) -> f32 {
        (self.path_needed(speed, true) + 1.0).max(self.backout_m + self.rear_m)
            + self.front_m
            + self.clearance_m
            + self.half_width_m
    }

    /// As [`Self::reach`] for reverse paths of up to `limit_m` alone: a pose on one is within
    /// `limit_m` of the rear axle, and the box of points that can fail its check
    /// ([`Self::pose_box`]) within a square around it of half-side the farthest its body or
    /// LiDAR clearance reaches.
    fn reverse_reach(&self, limit_m: f32) -> f32 {
        let cfg = self;
        let m = cfg.body_margin_m;
        let body = (cfg.front_m.max(cfg.rear_m) + m).hypot(cfg.half_width_m + m);
        let lidar = cfg.lidar_x_m.abs() + cfg.reverse_clearance_m;
        // The box's 1 mm pad, and as much again for rounding.
        limit_m + std::f32::consts::SQRT_2 * (body.max(lidar) + 2e-3)
    }
}

/// Whether (and how) the filter changed the last control.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Intervention {
    /// The policy's control went out unchanged.
    #[default]
    None,
    /// Another steering angle, the throttle kept.
    Steered,
    /// Zero throttle (the drive brakes), on the clearest arc.
    Braked,
    /// Reversing out of a dead end (`backout_m`).
    Reversed,
}

/// The filter and its memory of obstacle points.
#[derive(Clone, Debug)]
pub struct SafetyFilter {
    cfg: SafetyFilterConfig,
    /// Odometry and the obstacle points remembered along the way.
    memory: ObstacleMemory,
    /// The back-out's state (`backout_m`).
    backout: BackOut,
    last: Intervention,
}

/// Half the angle the frame's scan covers (pi without a scan).
fn whole_scan_half_rad(frame: &SensorFrame) -> f32 {
    frame.scan.as_ref().map_or(std::f32::consts::PI, |s| {
        let end = s.angle_min + s.angle_increment * s.ranges.len().saturating_sub(1) as f32;
        s.angle_min.abs().max(end.abs())
    })
}

impl SafetyFilter {
    /// A filter with empty memory (`cfg` validated) for a car whose controls may reverse
    /// (`reverses`: its old points are kept for reverse paths) or not.
    pub fn new(cfg: SafetyFilterConfig, reverses: bool) -> Self {
        Self {
            memory: ObstacleMemory::new(reverses || cfg.backout_m > 0.0),
            cfg,
            backout: BackOut::default(),
            last: Intervention::None,
        }
    }

    /// Whether the filter acts.
    pub fn enabled(&self) -> bool {
        self.cfg.enabled
    }

    /// What the last call of [`SafetyFilter::filter`] did.
    pub fn last_intervention(&self) -> Intervention {
        self.last
    }

    /// Forget everything (a new episode).
    pub fn reset(&mut self) {
        self.memory.reset();
        self.last = Intervention::None;
        self.backout.reset();
    }

    /// [`SafetyFilter::filter`], and what goes out: the filtered control, or with `advisory`
    /// the proposed one; second, the filter's control when it changed the proposed one.
    pub fn apply(
        &mut self,
        frame: &SensorFrame,
        proposed: Control,
        steering_limit_rad: f64,
        fan_half_rad: Option<f32>,
    ) -> (Control, Option<Control>) {
        let c = self.filter(frame, proposed, steering_limit_rad, fan_half_rad);
        let correction = (self.last != Intervention::None).then_some(c);
        (if self.cfg.advisory { proposed } else { c }, correction)
    }

    /// Take in a frame (odometry and scan points) and return the control to send instead of
    /// `proposed`. `steering_limit_rad` bounds the steering; `fan_half_rad` is the half-angle of
    /// the LiDAR rays whose range may not fall under `clearance_m` (`None`: the whole scan).
    pub fn filter(
        &mut self,
        frame: &SensorFrame,
        proposed: Control,
        steering_limit_rad: f64,
        fan_half_rad: Option<f32>,
    ) -> Control {
        self.last = Intervention::None;
        if !self.cfg.enabled {
            return proposed;
        }
        let fan_half_rad = fan_half_rad.unwrap_or_else(|| whole_scan_half_rad(frame));
        let speed = self.memory.observe(&self.cfg, frame);
        self.memory.collect_near(&self.cfg, self.cfg.reach(speed), true);
        let Self {
            cfg, memory, backout, ..
        } = self;
        if let Some(c) = backout.keep_backing_out(cfg, memory, speed, fan_half_rad) {
            self.last = Intervention::Reversed;
            return c;
        }
        let c = if proposed.throttle < 0.0 {
            self.filter_reverse(speed, proposed, steering_limit_rad, fan_half_rad)
        } else {
            self.filter_forward(speed, proposed, steering_limit_rad, fan_half_rad)
        };
        // A policy already braking on the clearest arc (zero throttle, or reverse while still
        // rolling forward) sends what the filter would: nothing was corrected.
        let clamped = proposed.steering_rad.clamp(-steering_limit_rad, steering_limit_rad);
        if self.last == Intervention::Braked && c.throttle == proposed.throttle && c.steering_rad == clamped {
            self.last = Intervention::None;
        }
        c
    }

    /// A forward (or zero-throttle) control: its arc must be clear for reacting, braking and,
    /// when it drives, `lookahead_m`; else the nearest clear steering, else brake.
    fn filter_forward(&mut self, speed: f32, proposed: Control, steering_limit_rad: f64, fan_half_rad: f32) -> Control {
        let delta = proposed.steering_rad.clamp(-steering_limit_rad, steering_limit_rad);
        let drives = proposed.throttle > 0.0;
        if self.cfg.backout_parked {
            let Self {
                cfg, memory, backout, ..
            } = self;
            if let Some(c) = backout.back_out_if_parked(cfg, memory, speed, delta, steering_limit_rad, fan_half_rad) {
                self.last = Intervention::Reversed;
                return c;
            }
        }
        let need = self.cfg.path_needed(speed, drives);
        if self.free_length(delta as f32, need, fan_half_rad) >= need {
            self.backout.stuck = 0;
            return proposed;
        }
        let candidates = self.cfg.steerings_nearest(delta, steering_limit_rad);
        for &d in &candidates {
            if self.free_length(d as f32, need, fan_half_rad) >= need {
                self.backout.stuck = 0;
                self.last = Intervention::Steered;
                return Control {
                    throttle: proposed.throttle,
                    steering_rad: d,
                };
            }
        }
        // Nothing clear: brake, on the arc that stays free longest (the policy's on a tie).
        let horizon = self.cfg.path_needed(speed, true) + 1.0;
        let mut best = (delta, self.free_length(delta as f32, horizon, fan_half_rad));
        for &d in &candidates {
            let f = self.free_length(d as f32, horizon, fan_half_rad);
            if f > best.1 + 1e-4 {
                best = (d, f);
            }
        }
        let Self {
            cfg, memory, backout, ..
        } = self;
        if let Some(c) = backout.back_out_if_stuck(cfg, memory, speed, steering_limit_rad, fan_half_rad) {
            self.last = Intervention::Reversed;
            return c;
        }
        self.last = Intervention::Braked;
        Control {
            throttle: 0.0,
            steering_rad: best.0,
        }
    }

    /// A reverse control: while the car still rolls forward the drive only brakes, so it is
    /// judged as braking (its throttle kept); otherwise its reverse arc (reacting, braking and
    /// `lookahead_m`) must be clear of every remembered point, else the nearest clear steering
    /// reverses, else the car brakes.
    fn filter_reverse(&mut self, speed: f32, proposed: Control, limit_rad: f64, fan_half_rad: f32) -> Control {
        self.memory.grid_old_points(&self.cfg);
        if speed > STILL_MPS {
            let braking = Control {
                throttle: 0.0,
                ..proposed
            };
            let c = self.filter_forward(speed, braking, limit_rad, fan_half_rad);
            return Control {
                throttle: proposed.throttle,
                ..c
            };
        }
        self.backout.stuck = 0;
        let need = self.cfg.stop_distance(-speed) + self.cfg.lookahead_m;
        let delta = proposed.steering_rad.clamp(-limit_rad, limit_rad);
        if self.reverse_free_length(delta as f32, need, fan_half_rad) >= need {
            return proposed;
        }
        let candidates = self.cfg.steerings_nearest(delta, limit_rad);
        for &d in &candidates {
            if self.reverse_free_length(d as f32, need, fan_half_rad) >= need {
                self.last = Intervention::Steered;
                return Control {
                    throttle: proposed.throttle,
                    steering_rad: d,
                };
            }
        }
        self.last = Intervention::Braked;
        Control {
            throttle: 0.0,
            steering_rad: delta,
        }
    }

    /// Take in a frame as [`SafetyFilter::filter`] does, filtering nothing, and push to `out`
    /// how far the car could reverse from here along the arc of each steering in `deltas`,
    /// over `max_m` (the reverse check of a policy's control, up to `max_m`). `fan_half_rad`
    /// as in `filter`.
    pub fn reverse_free_fractions(
        &mut self,
        frame: &SensorFrame,
        deltas: &[f32],
        max_m: f32,
        fan_half_rad: Option<f32>,
        out: &mut Vec<f32>,
    ) {
        let Self { cfg, memory, .. } = self;
        memory.reverse_free_fractions(cfg, frame, deltas, max_m, fan_half_rad, out);
    }

    /// [`ObstacleMemory::reverse_free_length`] under this filter's settings.
    fn reverse_free_length(&self, delta: f32, limit: f32, fan_half_rad: f32) -> f32 {
        self.memory.reverse_free_length(&self.cfg, delta, limit, fan_half_rad)
    }

    /// [`ObstacleMemory::free_length`] under this filter's settings.
    fn free_length(&self, delta: f32, limit: f32, fan_half_rad: f32) -> f32 {
        self.memory.free_length(&self.cfg, delta, limit, fan_half_rad)
    }
}

#[cfg(test)]
mod tests {
    use super::arcs::PATH_STEP_M;
    use super::memory::{CELL_M, MAX_BACKABLE_M};
    use super::*;
    use agvrl_sim::msg::{ImuReading, LaserScan};

    /// A 90 degree scan of a wall `wall_m` ahead of the LiDAR, the IMU reading `speed`.
    pub(super) fn wall_frame(wall_m: f32, stamp_s: f64, speed: f64) -> SensorFrame {
        slanted_wall_frame(wall_m, 0.0, stamp_s, speed)
    }

    /// As [`wall_frame`], the wall `x + slope y = wall_m` in the LiDAR's frame (slope > 0:
    /// nearer on the left).
    pub(super) fn slanted_wall_frame(wall_m: f32, slope: f32, stamp_s: f64, speed: f64) -> SensorFrame {
        let n = 101;
        let half = std::f32::consts::FRAC_PI_4;
        let inc = 2.0 * half / (n - 1) as f32;
        let ranges: Vec<f32> = (0..n)
            .map(|i| {
                let b = -half + inc * i as f32;
                (wall_m / (b.cos() + slope * b.sin())).min(12.0)
            })
            .collect();
        let hit = ranges.iter().map(|r| *r < 12.0).collect();
        frame_of(-half, inc, ranges, hit, stamp_s, speed)
    }

    /// A frame with a 12 m scan from `angle_min` by `inc` (`ranges`, `hit`) and the IMU
    /// reading `speed`.
    fn frame_of(angle_min: f32, inc: f32, ranges: Vec<f32>, hit: Vec<bool>, stamp_s: f64, speed: f64) -> SensorFrame {
        SensorFrame {
            stamp_s,
            scan: Some(LaserScan {
                angle_min,
                angle_increment: inc,
                range_min: 0.05,
                range_max: 12.0,
                points_w: vec![],
                object_id: vec![],
                car: vec![],
                origin_w: [0.0; 3],
                ranges,
                hit,
            }),
            imu: Some(ImuReading {
                lin_vel_b: [speed, 0.0, 0.0],
                ..ImuReading::default()
            }),
            ..SensorFrame::default()
        }
    }

    pub(super) fn on() -> SafetyFilter {
        SafetyFilter::new(
            SafetyFilterConfig {
                enabled: true,
                decel_mps2: 3.0,
                ..SafetyFilterConfig::default()
            },
            true,
        )
    }

    pub(super) const FAN: Option<f32> = Some(std::f32::consts::FRAC_PI_4);

    #[test]
    fn a_clear_path_passes_unchanged_and_a_disabled_filter_never_acts() {
        let go = Control {
            throttle: 1.0,
            steering_rad: 0.1,
        };
        let mut f = on();
        assert_eq!(f.filter(&wall_frame(5.0, 0.0, 1.5), go, 0.36, FAN), go);
        assert_eq!(f.last_intervention(), Intervention::None);
        let mut off = SafetyFilter::new(SafetyFilterConfig::default(), false);
        assert_eq!(off.filter(&wall_frame(0.7, 0.0, 1.5), go, 0.36, FAN), go);
    }

    #[test]
    fn a_wall_inside_the_stopping_distance_brakes_and_one_beyond_it_does_not() {
        // At 1.5 m/s with 3 m/s^2: 0.15 m reacting + 0.375 m braking + 0.25 m lookahead, and the
        // LiDAR must stay 0.75 m off the wall: the straight path needs ~1.53 m of range; every
        // arc within +-0.36 rad still meets a wall this wide.
        let go = Control {
            throttle: 1.0,
            steering_rad: 0.0,
        };
        let mut f = on();
        let c = f.filter(&wall_frame(1.2, 0.0, 1.5), go, 0.36, FAN);
        assert_eq!(f.last_intervention(), Intervention::Braked);
        assert_eq!(c.throttle, 0.0);
        let mut f = on();
        assert_eq!(f.filter(&wall_frame(1.7, 0.0, 1.5), go, 0.36, FAN), go);
    }

    #[test]
    fn a_policy_already_braking_on_the_clearest_arc_is_not_corrected() {
        let go = Control {
            throttle: 1.0,
            steering_rad: 0.0,
        };
        let frame = wall_frame(1.2, 0.0, 1.5);
        let braked = on().filter(&frame, go, 0.36, FAN);
        assert_eq!(braked.throttle, 0.0);
        // Zero throttle on the filter's own arc, and reverse (the drive brakes while the car
        // still rolls forward) on it: the control goes out as proposed and counts as none.
        for throttle in [0.0, -0.5] {
            let own = Control { throttle, ..braked };
            let mut f = on();
            assert_eq!(f.apply(&frame, own, 0.36, FAN), (own, None), "throttle {throttle}");
            assert_eq!(f.last_intervention(), Intervention::None);
        }
        // Any throttle on that arc is still corrected to zero.
        let slower = Control {
            throttle: 0.3,
            ..braked
        };
        let mut f = on();
        assert_eq!(f.apply(&frame, slower, 0.36, FAN), (braked, Some(braked)));
        assert_eq!(f.last_intervention(), Intervention::Braked);
    }

    #[test]
    fn an_advisory_filter_sends_the_proposed_control_and_reports_its_correction() {
        let go = Control {
            throttle: 1.0,
            steering_rad: 0.0,
        };
        let mut acting = on();
        let (sent, correction) = acting.apply(&wall_frame(1.2, 0.0, 1.5), go, 0.36, FAN);
        assert_eq!(correction, Some(sent));
        assert_eq!(sent.throttle, 0.0);
        let mut advising = SafetyFilter::new(
            SafetyFilterConfig {
                advisory: true,
                ..acting.cfg
            },
            false,
        );
        let (sent_advising, advice) = advising.apply(&wall_frame(1.2, 0.0, 1.5), go, 0.36, FAN);
        assert_eq!(sent_advising, go);
        assert_eq!(advice, correction);
        assert_eq!(advising.last_intervention(), Intervention::Braked);
        // A clear path: nothing to correct.
        let mut clear = on();
        assert_eq!(clear.apply(&wall_frame(5.0, 0.0, 1.5), go, 0.36, FAN), (go, None));
    }

    #[test]
    fn needed_path_is_reaction_plus_braking_distance() {
        let f = on();
        let v: f32 = 2.0;
        let want = v * 0.1 + v * v / 6.0;
        assert!((f.cfg.path_needed(v, false) - want).abs() < 1e-6);
        assert!((f.cfg.path_needed(v, true) - (want + 0.25)).abs() < 1e-6);
    }

    /// A filter at rest at time `t_s` that remembers one point, seen at `seen_s`, at (x, y)
    /// from the rear axle.
    pub(super) fn remembering(x: f64, y: f64, seen_s: f64, t_s: f64) -> SafetyFilter {
        let mut f = on();
        f.memory.last_stamp_s = Some(t_s);
        f.memory.backable_m = MAX_BACKABLE_M;
        let cell = ((x / CELL_M).floor() as i32, (y / CELL_M).floor() as i32);
        f.memory.cells.insert(cell, seen_s);
        f
    }

    #[test]
    fn a_reverse_control_is_checked_against_points_seen_on_the_way_in() {
        let back = Control {
            throttle: -0.25,
            steering_rad: 0.0,
        };
        let at_rest = |t: f64| {
            let mut fr = wall_frame(12.0, t, 0.0);
            fr.scan.as_mut().unwrap().hit.fill(false);
            fr
        };
        // 0.3 m behind the rear axle, seen 5 s ago (out of sight since): reversing 0.25 m
        // (the lookahead at rest) brings the body's back (0.085 m + 0.08 m margin) onto it,
        // on every steering.
        let mut f = remembering(-0.3, 0.0, 0.0, 5.0);
        let c = f.filter(&at_rest(5.0), back, 0.36, FAN);
        assert_eq!(f.last_intervention(), Intervention::Braked);
        assert_eq!(c.throttle, 0.0);
        // Beyond reverse_memory_s it is forgotten; 0.5 m behind it is out of reach.
        let mut f = remembering(-0.3, 0.0, 0.0, 10.5);
        assert_eq!(f.filter(&at_rest(10.5), back, 0.36, FAN), back);
        let mut f = remembering(-0.5, 0.0, 0.0, 5.0);
        assert_eq!(f.filter(&at_rest(5.0), back, 0.36, FAN), back);
        // Only reverse paths use old points: one 0.5 m ahead, seen 5 s ago, lets the car drive.
        let go = Control {
            throttle: 0.5,
            steering_rad: 0.0,
        };
        let mut f = remembering(0.9, 0.0, 0.0, 5.0);
        assert_eq!(f.filter(&at_rest(5.0), go, 0.36, FAN), go);
        assert_eq!(f.last_intervention(), Intervention::None);
        // Nothing seen, but nothing driven either: a car never reverses where it has not been.
        let mut f = on();
        assert_eq!(f.filter(&at_rest(0.0), back, 0.36, FAN).throttle, 0.0);
        assert_eq!(f.last_intervention(), Intervention::Braked);
        for k in 1..=10 {
            let mut fr = at_rest(0.1 * k as f64);
            fr.imu.as_mut().unwrap().lin_vel_b[0] = 1.0;
            f.filter(&fr, go, 0.36, FAN);
        }
        assert_eq!(f.filter(&at_rest(1.1), back, 0.36, FAN), back);
        // Rolling forward, reverse only brakes: judged as braking, the wall being far.
        let mut f = on();
        assert_eq!(f.filter(&wall_frame(5.0, 0.0, 1.5), back, 0.36, FAN), back);
        assert_eq!(f.last_intervention(), Intervention::None);
    }

    /// Generated scans for the properties: two frames 0.1 s apart (the car drives between
    /// them by odometry), so the check runs on remembered points as well as the latest scan.
    mod properties {
        use super::*;
        use proptest::prelude::*;

        const RAYS: usize = 61;
        const LIMIT_RAD: f64 = 0.36;

        /// A scan over `fan` either side with `ranges[i]` (`None`: no return).
        fn scan_frame(ranges: &[Option<f32>], fan: f32, stamp_s: f64, speed: f64) -> SensorFrame {
            let inc = 2.0 * fan / (RAYS - 1) as f32;
            let hit = ranges.iter().map(Option::is_some).collect();
            frame_of(
                -fan,
                inc,
                ranges.iter().map(|r| r.unwrap_or(12.0)).collect(),
                hit,
                stamp_s,
                speed,
            )
        }

        /// The first pose along the arc of `steering_rad` (every `PATH_STEP_M` up to
        /// `need_m`) at which some remembered point is inside the body's rectangle with margin
        /// or within `clearance_m` of the LiDAR in its fan: a check over every point in the
        /// memory, without the near-point radius, the boxes or the grid.
        fn brute_force_hit(f: &SafetyFilter, steering_rad: f64, need_m: f32, fan: f32) -> Option<(f32, [f32; 2])> {
            let cfg = &f.cfg;
            let [ox, oy, oth] = f.memory.pose;
            let k = (steering_rad as f32).tan() / cfg.wheelbase_m;
            let n = (need_m / PATH_STEP_M).ceil().max(1.0) as usize;
            for i in 1..=n {
                let s = (i as f32 * PATH_STEP_M).min(need_m);
                let (x, y, th) = if k.abs() < 1e-6 {
                    (s, 0.0, 0.0)
                } else {
                    ((k * s).sin() / k, (1.0 - (k * s).cos()) / k, k * s)
                };
                for ((ci, cj), _) in f.memory.cells.cells() {
                    // The cell's centre in the car's frame, then in the pose's frame.
                    let (wx, wy) = ((ci as f64 + 0.5) * CELL_M - ox, (cj as f64 + 0.5) * CELL_M - oy);
                    let (px, py) = (
                        (oth.cos() * wx + oth.sin() * wy) as f32,
                        (-oth.sin() * wx + oth.cos() * wy) as f32,
                    );
                    let (dx, dy) = (px - x, py - y);
                    let (bx, by) = (th.cos() * dx + th.sin() * dy, -th.sin() * dx + th.cos() * dy);
                    let m = cfg.body_margin_m;
                    let in_body = (-cfg.rear_m - m..=cfg.front_m + m).contains(&bx) && by.abs() <= cfg.half_width_m + m;
                    let lx = bx - cfg.lidar_x_m;
                    let in_fan = fan >= std::f32::consts::FRAC_PI_2 || by.atan2(lx).abs() <= fan;
                    let near_lidar = lx * lx + by * by < cfg.clearance_m * cfg.clearance_m && in_fan;
                    if in_body || near_lidar {
                        return Some((s, [px, py]));
                    }
                }
            }
            None
        }

        prop_compose! {
            /// Two scans (a ray returns with probability `p`, 0.2 to 6 m), the speeds the
            /// IMU reads with them, the fan and a driving control: from open ground, where
            /// most controls pass, to clutter, where most are corrected.
            fn scene()(p in 0.01f64..0.3)(
                first in prop::collection::vec(prop::option::weighted(p, 0.2f32..6.0), RAYS),
                second in prop::collection::vec(prop::option::weighted(p, 0.2f32..6.0), RAYS),
                speeds in (0.0f64..2.5, 0.0f64..2.5),
                fan in prop_oneof![Just(std::f32::consts::FRAC_PI_4), Just(1.2f32), Just(2.3f32)],
                throttle in 0.01f64..=1.0,
                steering_rad in -LIMIT_RAD..=LIMIT_RAD,
            ) -> (Vec<Option<f32>>, Vec<Option<f32>>, (f64, f64), f32, Control) {
                (first, second, speeds, fan, Control { throttle, steering_rad })
            }
        }

        fn run(
            first: &[Option<f32>],
            second: &[Option<f32>],
            speeds: (f64, f64),
            fan: f32,
            proposed: Control,
        ) -> (SafetyFilter, Control) {
            let mut f = on();
            f.filter(&scan_frame(first, fan, 0.0, speeds.0), proposed, LIMIT_RAD, Some(fan));
            let c = f.filter(&scan_frame(second, fan, 0.1, speeds.1), proposed, LIMIT_RAD, Some(fan));
            (f, c)
        }

        /// Whatever the filter sends that drives forward (the policy's control, or its steering
        /// instead) has a path clear of every remembered point for the distance to react, brake
        /// and look ahead; and the scenes make both arms happen (a property of driving controls
        /// that no scene drives would hold without checking anything).
        #[test]
        fn a_driving_control_the_filter_sends_has_a_clear_path() {
            let config = ProptestConfig {
                cases: 400,
                ..ProptestConfig::default()
            };
            let (driving, held) = (std::cell::Cell::new(0u32), std::cell::Cell::new(0u32));
            let outcome = proptest::test_runner::TestRunner::new(config).run(
                &scene(),
                |(first, second, speeds, fan, proposed)| {
                    let (f, c) = run(&first, &second, speeds, fan, proposed);
                    if c.throttle <= 0.0 {
                        held.set(held.get() + 1);
                        return Ok(());
                    }
                    driving.set(driving.get() + 1);
                    let v = speeds.1 as f32;
                    let need = v * f.cfg.reaction_s + v * v / (2.0 * f.cfg.decel_mps2) + f.cfg.lookahead_m;
                    let hit = brute_force_hit(&f, c.steering_rad, need, fan);
                    prop_assert!(hit.is_none(), "sent {c:?} ({:?}); blocked at {hit:?}", f.last);
                    Ok(())
                },
            );
            if let Err(e) = outcome {
                panic!("{e}");
            }
            let (driving, held) = (driving.get(), held.get());
            eprintln!("driving={driving} held={held}");
            assert!(
                driving >= 40 && held >= 40,
                "{driving} scenes drove, {held} held of 400"
            );
        }

        proptest! {
            #![proptest_config(ProptestConfig { cases: 400, max_global_rejects: 4000, ..ProptestConfig::default() })]

            /// The reverse lengths look only at the points near enough to matter: they equal
            /// the lengths over every remembered point.
            #[test]
            fn reverse_lengths_over_the_near_points_equal_those_over_every_point(
                (first, second, speeds, fan, _) in scene(),
            ) {
                let deltas = [LIMIT_RAD as f32, 0.0, -LIMIT_RAD as f32];
                let mut f = on();
                let mut out = vec![];
                f.reverse_free_fractions(&scan_frame(&first, fan, 0.0, speeds.0), &deltas, 1.5, Some(fan), &mut out);
                f.memory.backable_m = MAX_BACKABLE_M;
                let second = scan_frame(&second, fan, 0.1, speeds.1);
                let mut every = f.clone();
                out.clear();
                f.reverse_free_fractions(&second, &deltas, 1.5, Some(fan), &mut out);
                every.memory.observe(&every.cfg, &second);
                every.memory.collect_near(&every.cfg, 100.0, false);
                every.memory.grid_old_points(&every.cfg);
                prop_assert_eq!(every.memory.near.len(), every.memory.cells.cells().count());
                let all: Vec<f32> = deltas.iter().map(|&d| every.reverse_free_length(d, 1.5, fan) / 1.5).collect();
                prop_assert_eq!(out, all);
            }

            /// From one state, a control the filter passes still passes with fewer points.
            #[test]
            fn removing_points_never_turns_a_passed_control_into_an_intervention(
                (first, second, speeds, fan, proposed) in scene(),
                keep in prop::collection::vec(any::<bool>(), 2 * RAYS),
            ) {
                let (f, c) = run(&first, &second, speeds, fan, proposed);
                prop_assume!(f.last == Intervention::None);
                let thin = |scan: &[Option<f32>], keep: &[bool]| -> Vec<Option<f32>> {
                    scan.iter().zip(keep).map(|(r, k)| r.filter(|_| *k)).collect()
                };
                let (g, d) = run(&thin(&first, &keep[..RAYS]), &thin(&second, &keep[RAYS..]), speeds, fan, proposed);
                prop_assert_eq!(g.last, Intervention::None);
                prop_assert_eq!(d, c);
            }
        }
    }
}
