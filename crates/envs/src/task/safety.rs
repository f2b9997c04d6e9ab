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

use crate::api::{Control, SensorFrame};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;

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
    /// Rear-axle pose in the odometry frame: x, y, heading.
    pose: [f64; 3],
    last_stamp_s: Option<f64>,
    /// Obstacle points in the odometry frame, one per `CELL_M` cell, with the time the cell
    /// was last seen occupied (a wall seen in 45 scans is remembered once).
    memory: CellMemory,
    /// Points near the car in its current frame, seen within `memory_s` (rebuilt every
    /// control; for the reverse lengths alone, all of them).
    near: Vec<[f32; 2]>,
    /// Older remembered points near the car (only reverse paths are checked against them).
    near_old: Vec<[f32; 2]>,
    /// `near` and `near_old` bucketed by place, for the path checks (`near_old`'s only once a
    /// reverse path is checked this control: most controls check none).
    near_grid: PointGrid,
    near_old_grid: PointGrid,
    /// The reach of `near_old` while it is still to be gathered.
    old_pending: Option<f32>,
    last: Intervention,
    /// Distance driven over the last control period by odometry, metres.
    last_ds: f32,
    /// Consecutive controls braked by the filter at a standstill.
    stuck: u32,
    /// Consecutive controls at a standstill with no forward arc free for `backout_m`.
    parked: u32,
    /// Whether controls may reverse (else only `memory_s` of points is kept).
    reverses: bool,
    /// A back-out under way: distance still to reverse (m) and its steering (rad).
    backout: Option<(f32, f64)>,
    /// How far the car may reverse: the distance it drove forward (less what it reversed since),
    /// at most `MAX_BACKABLE_M`. Reversing retraces ground the car has driven over; at a spawn
    /// nothing behind it is known.
    backable_m: f32,
}

/// Half the angle the frame's scan covers (pi without a scan).
fn whole_scan_half_rad(frame: &SensorFrame) -> f32 {
    frame.scan.as_ref().map_or(std::f32::consts::PI, |s| {
        let end = s.angle_min + s.angle_increment * s.ranges.len().saturating_sub(1) as f32;
        s.angle_min.abs().max(end.abs())
    })
}

/// The most a car reverses along the way it came, metres (about what it drove in
/// `reverse_memory_s` at low speed; farther back, odometry drifts).
const MAX_BACKABLE_M: f32 = 3.0;

/// Below this speed a braked car counts as stopped, m/s.
const STILL_MPS: f32 = 0.05;
/// Controls braked at a standstill before the filter backs out.
const STUCK_CONTROLS: u32 = 3;
/// A back-out shorter than this is not worth starting, metres.
const MIN_BACKOUT_M: f32 = 0.15;

/// Scan points farther than this from the LiDAR are not remembered, metres: within the memory's
/// time the car cannot reach them without scanning them again.
const REMEMBER_WITHIN_M: f32 = 3.0;
/// Spacing of the poses checked along a path, metres.
const PATH_STEP_M: f32 = 0.04;
/// Remembered points are merged into cells this wide, metres (a point moves by at most half a
/// diagonal, under 3.6 cm: inside the margins).
const CELL_M: f64 = 0.05;

impl SafetyFilter {
    /// A filter with empty memory (`cfg` validated) for a car whose controls may reverse
    /// (`reverses`: its old points are kept for reverse paths) or not.
    pub fn new(cfg: SafetyFilterConfig, reverses: bool) -> Self {
        Self {
            reverses: reverses || cfg.backout_m > 0.0,
            cfg,
            pose: [0.0; 3],
            last_stamp_s: None,
            memory: CellMemory::default(),
            near: Vec::new(),
            near_old: Vec::new(),
            near_grid: PointGrid::default(),
            near_old_grid: PointGrid::default(),
            old_pending: None,
            last: Intervention::None,
            last_ds: 0.0,
            stuck: 0,
            parked: 0,
            backout: None,
            backable_m: 0.0,
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
        self.pose = [0.0; 3];
        self.last_stamp_s = None;
        self.memory.clear();
        self.last = Intervention::None;
        self.last_ds = 0.0;
        self.stuck = 0;
        self.parked = 0;
        self.backout = None;
        self.backable_m = 0.0;
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
        let speed = self.observe(frame);
        self.collect_near(self.reach(speed), true);
        if let Some(c) = self.keep_backing_out(speed, fan_half_rad) {
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
            if speed.abs() >= STILL_MPS {
                self.parked = 0;
            } else if let Some(c) = self.back_out_if_parked(delta, steering_limit_rad, fan_half_rad) {
                self.last = Intervention::Reversed;
                return c;
            }
        }
        let need = self.path_needed(speed, drives);
        if self.free_length(delta as f32, need, fan_half_rad) >= need {
            self.stuck = 0;
            return proposed;
        }
        let candidates = self.steerings_nearest(delta, steering_limit_rad);
        for &d in &candidates {
            if self.free_length(d as f32, need, fan_half_rad) >= need {
                self.stuck = 0;
                self.last = Intervention::Steered;
                return Control {
                    throttle: proposed.throttle,
                    steering_rad: d,
                };
            }
        }
        // Nothing clear: brake, on the arc that stays free longest (the policy's on a tie).
        let horizon = self.path_needed(speed, true) + 1.0;
        let mut best = (delta, self.free_length(delta as f32, horizon, fan_half_rad));
        for &d in &candidates {
            let f = self.free_length(d as f32, horizon, fan_half_rad);
            if f > best.1 + 1e-4 {
                best = (d, f);
            }
        }
        self.stuck = if speed.abs() < STILL_MPS { self.stuck + 1 } else { 0 };
        if self.cfg.backout_m > 0.0
            && self.stuck >= STUCK_CONTROLS
            && let Some(c) = self.start_backing_out(steering_limit_rad, fan_half_rad)
        {
            self.stuck = 0;
            self.last = Intervention::Reversed;
            return c;
        }
        self.last = Intervention::Braked;
        Control {
            throttle: 0.0,
            steering_rad: best.0,
        }
    }

    /// A car standing still under a forward or zero throttle (`backout_parked`): after
    /// `STUCK_CONTROLS` such controls in a row with no forward arc free for `backout_m`, the
    /// back-out's first control.
    fn back_out_if_parked(&mut self, delta: f64, steering_limit_rad: f64, fan_half_rad: f32) -> Option<Control> {
        let want = self.cfg.backout_m;
        let trapped = std::iter::once(delta)
            .chain(self.steerings_nearest(delta, steering_limit_rad))
            .all(|d| self.free_length(d as f32, want, fan_half_rad) < want);
        self.parked = if trapped { self.parked + 1 } else { 0 };
        if self.parked < STUCK_CONTROLS {
            return None;
        }
        let c = self.start_backing_out(steering_limit_rad, fan_half_rad)?;
        self.parked = 0;
        Some(c)
    }

    /// A reverse control: while the car still rolls forward the drive only brakes, so it is
    /// judged as braking (its throttle kept); otherwise its reverse arc (reacting, braking and
    /// `lookahead_m`) must be clear of every remembered point, else the nearest clear steering
    /// reverses, else the car brakes.
    fn filter_reverse(&mut self, speed: f32, proposed: Control, limit_rad: f64, fan_half_rad: f32) -> Control {
        self.grid_old_points();
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
        self.stuck = 0;
        let need = self.stop_distance(-speed) + self.cfg.lookahead_m;
        let delta = proposed.steering_rad.clamp(-limit_rad, limit_rad);
        if self.reverse_free_length(delta as f32, need, fan_half_rad) >= need {
            return proposed;
        }
        let candidates = self.steerings_nearest(delta, limit_rad);
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
        let fan_half_rad = fan_half_rad.unwrap_or_else(|| whole_scan_half_rad(frame));
        self.observe(frame);
        // Only reverse paths are checked here, against old and recent points alike.
        self.collect_near(self.reverse_reach(max_m), false);
        self.grid_old_points();
        out.extend(
            deltas
                .iter()
                .map(|&d| self.reverse_free_length(d, max_m, fan_half_rad) / max_m),
        );
    }

    /// Begin reversing out of a dead end: the nose should swing towards the open side (the
    /// one whose nearest point ahead of the LiDAR is farther), so the car reverses on the
    /// opposite lock (else straight, else the other lock), as far as `backout_m` or the longest
    /// clear reverse path.
    fn start_backing_out(&mut self, limit_rad: f64, fan_half_rad: f32) -> Option<Control> {
        self.grid_old_points();
        let (mut left, mut right) = (f32::INFINITY, f32::INFINITY);
        for &[x, y] in &self.near {
            let lx = x - self.cfg.lidar_x_m;
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
        let want = self.cfg.backout_m;
        let mut best: Option<(f32, f64)> = None;
        for d in [-towards * limit_rad, 0.0, towards * limit_rad] {
            let f = self.reverse_free_length(d as f32, want, fan_half_rad);
            if f >= want {
                best = Some((f, d));
                break;
            }
            if best.is_none_or(|b| f > b.0) {
                best = Some((f, d));
            }
        }
        let (len, d) = best.filter(|b| b.0 >= MIN_BACKOUT_M)?;
        self.backout = Some((len, d));
        Some(Control {
            throttle: -(self.cfg.backout_throttle as f64),
            steering_rad: d,
        })
    }

    /// The next control of a back-out under way, or `None` when there is none or it is over
    /// (done, or its path is no longer clear: then the car stops and the filter decides anew).
    fn keep_backing_out(&mut self, speed: f32, fan_half_rad: f32) -> Option<Control> {
        let (left, d) = self.backout?;
        self.grid_old_points();
        let left = left - self.last_ds;
        if left <= self.stop_distance(-speed) || self.reverse_free_length(d as f32, left, fan_half_rad) < left {
            self.backout = None;
            return None;
        }
        self.backout = Some((left, d));
        Some(Control {
            throttle: -(self.cfg.backout_throttle as f64),
            steering_rad: d,
        })
    }

    /// Path length a control needs clear: the distance to react and brake to a stop, plus
    /// `lookahead_m` when it drives.
    fn path_needed(&self, speed: f32, drives: bool) -> f32 {
        let stop = self.stop_distance(speed);
        if drives { stop + self.cfg.lookahead_m } else { stop }
    }

    /// Distance to react and brake to a stop from `speed` along the way it drives (0 when it
    /// moves the other way), metres.
    fn stop_distance(&self, speed: f32) -> f32 {
        let v = speed.max(0.0);
        v * self.cfg.reaction_s + v * v / (2.0 * self.cfg.decel_mps2.max(1e-3))
    }

    /// The `n_steering` angles over the steering range, nearest to `delta` first.
    fn steerings_nearest(&self, delta: f64, limit_rad: f64) -> Vec<f64> {
        let n = self.cfg.n_steering;
        let mut candidates: Vec<f64> = (0..n)
            .map(|k| -limit_rad + 2.0 * limit_rad * k as f64 / (n - 1) as f64)
            .collect();
        candidates.sort_by(|a, b| (a - delta).abs().total_cmp(&(b - delta).abs()));
        candidates
    }

    /// Advance odometry to the frame and remember its near scan points; returns forward speed.
    fn observe(&mut self, frame: &SensorFrame) -> f32 {
        let (v, w) = frame
            .imu
            .as_ref()
            .map(|i| (i.lin_vel_b[0], i.ang_vel_b[2]))
            .unwrap_or((0.0, 0.0));
        if let Some(t0) = self.last_stamp_s {
            let dt = (frame.stamp_s - t0).clamp(0.0, 0.5);
            // Midpoint heading: exact enough for one control period on an arc.
            let th = self.pose[2] + 0.5 * w * dt;
            self.last_ds = (v * dt).abs() as f32;
            self.backable_m = (self.backable_m + (v * dt) as f32).clamp(0.0, MAX_BACKABLE_M);
            self.pose[0] += v * dt * th.cos();
            self.pose[1] += v * dt * th.sin();
            self.pose[2] += w * dt;
        }
        self.last_stamp_s = Some(frame.stamp_s);
        let keep_s = if self.reverses {
            self.cfg.reverse_memory_s.max(self.cfg.memory_s)
        } else {
            self.cfg.memory_s
        };
        self.memory.forget_before(frame.stamp_s - keep_s as f64);
        if let Some(scan) = &frame.scan {
            let (s, c) = self.pose[2].sin_cos();
            for (i, &r) in scan.ranges.iter().enumerate() {
                let hit = scan.hit_at(i);
                if !hit || !r.is_finite() || r > REMEMBER_WITHIN_M {
                    continue;
                }
                let b = scan.bearing(i);
                let (px, py) = ((self.cfg.lidar_x_m + r * b.cos()) as f64, (r * b.sin()) as f64);
                let wx = self.pose[0] + c * px - s * py;
                let wy = self.pose[1] + s * px + c * py;
                let cell = ((wx / CELL_M).floor() as i32, (wy / CELL_M).floor() as i32);
                self.memory.insert(cell, frame.stamp_s);
            }
        }
        v as f32
    }

    /// How far from the rear axle a point may be that any path the filter checks at `speed`
    /// can reach, metres.
    fn reach(&self, speed: f32) -> f32 {
        (self.path_needed(speed, true) + 1.0).max(self.cfg.backout_m + self.cfg.rear_m)
            + self.cfg.front_m
            + self.cfg.clearance_m
            + self.cfg.half_width_m
    }

    /// As [`Self::reach`] for reverse paths of up to `limit_m` alone: a pose on one is within
    /// `limit_m` of the rear axle, and the box of points that can fail its check
    /// ([`Self::pose_box`]) within a square around it of half-side the farthest its body or
    /// LiDAR clearance reaches.
    fn reverse_reach(&self, limit_m: f32) -> f32 {
        let cfg = &self.cfg;
        let m = cfg.body_margin_m;
        let body = (cfg.front_m.max(cfg.rear_m) + m).hypot(cfg.half_width_m + m);
        let lidar = cfg.lidar_x_m.abs() + cfg.reverse_clearance_m;
        // The box's 1 mm pad, and as much again for rounding.
        limit_m + std::f32::consts::SQRT_2 * (body.max(lidar) + 2e-3)
    }

    /// Remembered points within `reach` metres of the rear axle, in the car's frame: those seen
    /// within `memory_s` in `near` and older ones in `near_old` (gathered once a reverse path is
    /// checked: most controls check none), or all in `near` if not `split_old`.
    fn collect_near(&mut self, reach: f32, split_old: bool) {
        let recent_after = self.recent_after();
        let mut near = std::mem::take(&mut self.near);
        near.clear();
        self.push_points(reach, |seen| !split_old || seen >= recent_after, &mut near);
        self.near = near;
        self.near_grid.rebuild(&self.near);
        self.near_old.clear();
        if split_old {
            self.old_pending = Some(reach);
        } else {
            self.near_old_grid.rebuild(&[]);
            self.old_pending = None;
        }
    }

    /// Points seen before this are old (only reverse paths are checked against them).
    fn recent_after(&self) -> f64 {
        self.last_stamp_s.unwrap_or(0.0) - self.cfg.memory_s as f64
    }

    /// Push to `out` the remembered points within `reach` metres of the rear axle, in the car's
    /// frame, whose time last seen passes `keep`.
    fn push_points(&self, reach: f32, keep: impl Fn(f64) -> bool, out: &mut Vec<[f32; 2]>) {
        let (s, c) = self.pose[2].sin_cos();
        let (s, c) = (s as f32, c as f32);
        for cells in self.memory.around(self.pose[0], self.pose[1], reach as f64) {
            for &((i, j), seen) in cells {
                if !(self.memory.remembers(seen) && keep(seen)) {
                    continue;
                }
                // Relative to the car in f64, then f32: odometry may run far from its origin.
                let dx = ((i as f64 + 0.5) * CELL_M - self.pose[0]) as f32;
                let dy = ((j as f64 + 0.5) * CELL_M - self.pose[1]) as f32;
                let p = [c * dx + s * dy, -s * dx + c * dy];
                if p[0] * p[0] + p[1] * p[1] <= reach * reach {
                    out.push(p);
                }
            }
        }
    }

    /// Gather and bucket `near_old` for the reverse path checks of this control.
    fn grid_old_points(&mut self) {
        if let Some(reach) = self.old_pending.take() {
            let recent_after = self.recent_after();
            let mut old = std::mem::take(&mut self.near_old);
            self.push_points(reach, |seen| seen < recent_after, &mut old);
            self.near_old = old;
            self.near_old_grid.rebuild(&self.near_old);
        }
    }

    /// A box (min, max corners, in the car's frame) holding every point that can fail the check
    /// of `pose` ([`Self::points_clear`]): the body's rectangle with margin, and the LiDAR's
    /// sector of radius `clearance_m` over its fan (a disk for a fan of 90 degrees or more),
    /// widened by 1 mm for rounding.
    fn pose_box(&self, pose: Pose, fan: Fan) -> ([f32; 2], [f32; 2]) {
        use std::f32::consts::FRAC_PI_2;
        let cfg = &self.cfg;
        let m = cfg.body_margin_m;
        let Pose { x, y, sin: s, cos: c } = pose;
        let (mut lo, mut hi) = ([f32::MAX; 2], [f32::MIN; 2]);
        let mut add = |px: f32, py: f32| {
            lo = [lo[0].min(px), lo[1].min(py)];
            hi = [hi[0].max(px), hi[1].max(py)];
        };
        for bx in [-cfg.rear_m - m, cfg.front_m + m] {
            for by in [-cfg.half_width_m - m, cfg.half_width_m + m] {
                add(x + c * bx - s * by, y + s * bx + c * by);
            }
        }
        let (ax, ay) = (x + c * cfg.lidar_x_m, y + s * cfg.lidar_x_m);
        let r = fan.clearance_m;
        if fan.half_rad >= FRAC_PI_2 {
            add(ax - r, ay - r);
            add(ax + r, ay + r);
        } else {
            add(ax, ay);
            // The arc's ends, at headings th -+ fan.
            let (sf, cf) = (fan.sin, fan.cos);
            add(ax + r * (c * cf + s * sf), ay + r * (s * cf - c * sf));
            add(ax + r * (c * cf - s * sf), ay + r * (s * cf + c * sf));
            // The circle's extremes along the axes that lie within the fan (an axis within
            // the fan makes an angle of at most the fan with the heading; the slack only
            // widens the box).
            for (ex, ey) in [(1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0)] {
                if ex * c + ey * s >= cf - 1e-4 {
                    add(ax + r * ex, ay + r * ey);
                }
            }
        }
        let pad = 1e-3;
        ([lo[0] - pad, lo[1] - pad], [hi[0] + pad, hi[1] + pad])
    }

    /// How far the car reverses along the arc of steering `delta` before its body (with
    /// margin) touches any remembered point or the LiDAR comes within `reverse_clearance_m`
    /// of one in its fan, metres (up to `limit`, and never beyond the way the car came).
    fn reverse_free_length(&self, delta: f32, limit: f32, fan_half_rad: f32) -> f32 {
        debug_assert!(
            self.old_pending.is_none(),
            "near_old is bucketed before a reverse check"
        );
        let fan = Fan::new(fan_half_rad, self.cfg.reverse_clearance_m);
        self.walk_arc(delta, limit.min(self.backable_m), -1.0, |pose| {
            let (lo, hi) = self.pose_box(pose, fan);
            [&self.near_grid, &self.near_old_grid]
                .iter()
                .all(|g| self.points_clear(g.within(lo, hi), pose, fan))
        })
    }

    /// How far along the arc of steering `delta` the car drives before its body (with margin)
    /// touches a point or the LiDAR comes within `clearance_m` of a point in its fan, metres
    /// (checked up to `limit`; `limit` itself when the path is clear).
    fn free_length(&self, delta: f32, limit: f32, fan_half_rad: f32) -> f32 {
        let fan = Fan::new(fan_half_rad, self.cfg.clearance_m);
        self.walk_arc(delta, limit, 1.0, |pose| {
            let (lo, hi) = self.pose_box(pose, fan);
            self.points_clear(self.near_grid.within(lo, hi), pose, fan)
        })
    }

    /// Poses every `PATH_STEP_M` along the arc of steering `delta`, forward (`sign` 1) or in
    /// reverse (-1), up to `limit`: the distance before the first pose `clear` rejects, or
    /// `limit`.
    fn walk_arc(&self, delta: f32, limit: f32, sign: f32, clear: impl Fn(Pose) -> bool) -> f32 {
        let k = delta.tan() / self.cfg.wheelbase_m;
        let n = (limit / PATH_STEP_M).ceil().max(1.0) as usize;
        for i in 1..=n {
            let s = (i as f32 * PATH_STEP_M).min(limit);
            if !clear(arc_pose(k, sign * s)) {
                return (s - PATH_STEP_M).max(0.0);
            }
        }
        limit
    }

    /// Whether the body (with margin) at `pose` touches none of `points` and the LiDAR keeps
    /// `fan.clearance_m` from those in its fan.
    fn points_clear<'a>(&self, points: impl IntoIterator<Item = &'a [f32; 2]>, pose: Pose, fan: Fan) -> bool {
        let cfg = &self.cfg;
        let Pose { x, y, sin: s, cos: c } = pose;
        let m = cfg.body_margin_m;
        let tan_fan = fan.tan;
        let c2 = fan.clearance_m * fan.clearance_m;
        for &[px, py] in points {
            let (dx, dy) = (px - x, py - y);
            let bx = c * dx + s * dy;
            let by = -s * dx + c * dy;
            if bx >= -cfg.rear_m - m && bx <= cfg.front_m + m && by.abs() <= cfg.half_width_m + m {
                return false;
            }
            let lx = bx - cfg.lidar_x_m;
            if lx * lx + by * by < c2 && (by.abs() <= lx * tan_fan || tan_fan.is_infinite()) {
                return false;
            }
        }
        true
    }
}

/// A remembered cell and the time it was last seen occupied.
type SeenCell = ((i32, i32), f64);

/// The filter's remembered cells, bucketed by place: the points a path could reach are found
/// without visiting all of `reverse_memory_s` of scans along the way the car came, and old cells
/// are dropped in a sweep now and then rather than every control.
#[derive(Clone, Debug)]
struct CellMemory {
    /// Each remembered cell's slot in its chunk.
    slot: HashMap<(i32, i32), u32>,
    /// The cells of each chunk (`CHUNK` cells a side), with the time each was last seen.
    chunks: HashMap<(i32, i32), Vec<SeenCell>>,
    /// Cells last seen before this are forgotten: skipped, and dropped by the next sweep.
    forget_before: f64,
    /// `forget_before` at the last sweep.
    swept_at: f64,
}

impl Default for CellMemory {
    fn default() -> Self {
        Self {
            slot: HashMap::new(),
            chunks: HashMap::new(),
            forget_before: f64::NEG_INFINITY,
            swept_at: f64::NEG_INFINITY,
        }
    }
}

impl CellMemory {
    /// Chunk side, cells.
    const CHUNK: i32 = 32;
    /// Seconds of forgetting between sweeps.
    const SWEEP_S: f64 = 1.0;

    fn chunk_of(cell: (i32, i32)) -> (i32, i32) {
        (cell.0.div_euclid(Self::CHUNK), cell.1.div_euclid(Self::CHUNK))
    }

    fn clear(&mut self) {
        self.slot.clear();
        self.chunks.clear();
        self.forget_before = f64::NEG_INFINITY;
        self.swept_at = f64::NEG_INFINITY;
    }

    /// Remember `cell` as seen at `t_s` (not before the last [`Self::forget_before`]).
    fn insert(&mut self, cell: (i32, i32), t_s: f64) {
        let chunk = self.chunks.entry(Self::chunk_of(cell)).or_default();
        match self.slot.get(&cell) {
            Some(&k) => chunk[k as usize].1 = t_s,
            None => {
                self.slot.insert(cell, chunk.len() as u32);
                chunk.push((cell, t_s));
            }
        }
    }

    /// Forget the cells last seen before `t_s`. A time earlier than the last one first drops
    /// what the last one forgot, so a forgotten cell stays forgotten.
    fn forget_before(&mut self, t_s: f64) {
        if t_s < self.forget_before || t_s - self.swept_at >= Self::SWEEP_S {
            self.sweep();
        }
        self.forget_before = t_s;
    }

    /// Drop the forgotten cells.
    fn sweep(&mut self) {
        let after = self.forget_before;
        let slot = &mut self.slot;
        self.chunks.retain(|_, cells| {
            let before = cells.len();
            cells.retain(|&(cell, t)| {
                let keep = t >= after;
                if !keep {
                    slot.remove(&cell);
                }
                keep
            });
            if cells.len() < before {
                for (k, &(cell, _)) in cells.iter().enumerate() {
                    slot.insert(cell, k as u32);
                }
            }
            !cells.is_empty()
        });
        self.swept_at = after;
    }

    /// The chunks holding every remembered cell whose centre lies within `reach` metres of
    /// (`x`, `y`) in the odometry frame (and cells farther off; forgotten ones too: see
    /// [`Self::remembers`]).
    fn around(&self, x: f64, y: f64, reach: f64) -> impl Iterator<Item = &[SeenCell]> + '_ {
        // A cell's chunk is that of its centre; a cell's width of slack for rounding.
        let side = Self::CHUNK as f64 * CELL_M;
        let r = reach + CELL_M;
        let range = move |v: f64| (((v - r) / side).floor() as i32)..=(((v + r) / side).floor() as i32);
        range(x)
            .flat_map(move |ci| range(y).map(move |cj| (ci, cj)))
            .filter_map(|chunk| self.chunks.get(&chunk).map(Vec::as_slice))
    }

    /// Whether a cell last seen at `seen_s` is still remembered.
    fn remembers(&self, seen_s: f64) -> bool {
        seen_s >= self.forget_before
    }

    /// Every remembered cell and when it was last seen.
    #[cfg(test)]
    fn cells(&self) -> impl Iterator<Item = SeenCell> + '_ {
        let after = self.forget_before;
        self.chunks
            .values()
            .flatten()
            .copied()
            .filter(move |&(_, t)| t >= after)
    }
}

/// Points bucketed into square cells (a CSR layout rebuilt every control), so that checking a
/// pose visits the points in the cells around it instead of every remembered point: a wall seen
/// for 1.5 s is hundreds of points, and a control checks tens of poses.
#[derive(Clone, Debug, Default)]
struct PointGrid {
    /// The points, cell after cell (row-major: x index, then y index).
    points: Vec<[f32; 2]>,
    /// Cell `c` holds `points[starts[c]..starts[c + 1]]`.
    starts: Vec<u32>,
    /// Workspaces of `rebuild`: each input point's cell, and each cell's next free slot.
    cell_of_point: Vec<u32>,
    cursor: Vec<u32>,
    min: [f32; 2],
    cell_m: f32,
    /// 1 / `cell_m`.
    per_m: f32,
    dims: [usize; 2],
}

impl PointGrid {
    /// Cell side, metres (at least: a grid is kept under `MAX_CELLS` cells).
    const CELL_M: f32 = 0.25;
    const MAX_CELLS: usize = 1 << 14;

    fn rebuild(&mut self, pts: &[[f32; 2]]) {
        self.points.clear();
        self.starts.clear();
        self.dims = [0, 0];
        if pts.is_empty() {
            return;
        }
        let (mut lo, mut hi) = ([f32::MAX; 2], [f32::MIN; 2]);
        for p in pts {
            for a in 0..2 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
        let extent = (hi[0] - lo[0]).max(hi[1] - lo[1]);
        self.cell_m = Self::CELL_M.max(extent / (Self::MAX_CELLS as f32).sqrt());
        self.per_m = 1.0 / self.cell_m;
        self.min = lo;
        self.dims = [0, 1].map(|a| ((hi[a] - lo[a]) / self.cell_m) as usize + 1);
        let n = self.dims[0] * self.dims[1];
        self.starts.resize(n + 1, 0);
        self.cell_of_point.clear();
        for p in pts {
            let c = self.cell_of(p);
            self.cell_of_point.push(c as u32);
            self.starts[c + 1] += 1;
        }
        for c in 0..n {
            self.starts[c + 1] += self.starts[c];
        }
        self.points.resize(pts.len(), [0.0; 2]);
        self.cursor.clear();
        self.cursor.extend_from_slice(&self.starts[..n]);
        for (p, c) in pts.iter().zip(&self.cell_of_point) {
            let slot = &mut self.cursor[*c as usize];
            self.points[*slot as usize] = *p;
            *slot += 1;
        }
    }

    /// The cell index of coordinate `v` along axis `a`, clamped to the grid (monotonic in `v`,
    /// so a range of coordinates maps to a range of cells; `as` saturates below 0 to 0).
    fn index(&self, v: f32, a: usize) -> usize {
        (((v - self.min[a]) * self.per_m) as usize).min(self.dims[a] - 1)
    }

    fn cell_of(&self, p: &[f32; 2]) -> usize {
        self.index(p[0], 0) * self.dims[1] + self.index(p[1], 1)
    }

    /// Every point in the cells that meet the box from `lo` to `hi` (so every point in it, and
    /// some more).
    fn within(&self, lo: [f32; 2], hi: [f32; 2]) -> impl Iterator<Item = &[f32; 2]> {
        let span = |a: usize| {
            let (lo, hi) = (lo[a], hi[a]);
            let max = self.min[a] + self.dims[a] as f32 * self.cell_m;
            if self.dims[a] == 0 || hi < self.min[a] || lo > max {
                return (1, 0);
            }
            (self.index(lo, a), self.index(hi, a))
        };
        let (i0, i1) = span(0);
        let (j0, j1) = span(1);
        let empty = j0 > j1;
        (i0..=i1).flat_map(move |i| {
            let row = i * self.dims[1];
            let (s, e) = if empty {
                (0, 0)
            } else {
                (self.starts[row + j0] as usize, self.starts[row + j1 + 1] as usize)
            };
            self.points[s..e].iter()
        })
    }
}

/// A rear-axle pose in the car's frame: position, and its heading's sine and cosine.
#[derive(Clone, Copy, Debug)]
struct Pose {
    x: f32,
    y: f32,
    sin: f32,
    cos: f32,
}

impl Pose {
    #[cfg(test)]
    fn new(x: f32, y: f32, th: f32) -> Self {
        let (sin, cos) = th.sin_cos();
        Self { x, y, sin, cos }
    }
}

/// The LiDAR's clearance in a check: `clearance_m` within `half_rad` of its heading (the
/// sine, cosine and tangent of `half_rad` computed once per path, not per pose).
#[derive(Clone, Copy, Debug)]
struct Fan {
    half_rad: f32,
    clearance_m: f32,
    sin: f32,
    cos: f32,
    /// Infinite for a fan of 90 degrees or more.
    tan: f32,
}

impl Fan {
    fn new(half_rad: f32, clearance_m: f32) -> Self {
        let (sin, cos) = half_rad.sin_cos();
        let tan = if half_rad < std::f32::consts::FRAC_PI_2 {
            half_rad.tan()
        } else {
            f32::INFINITY
        };
        Self {
            half_rad,
            clearance_m,
            sin,
            cos,
            tan,
        }
    }
}

/// The rear axle's pose after driving `s` metres (negative: reversing) on an arc of curvature
/// `k`, from the origin heading along x.
fn arc_pose(k: f32, s: f32) -> Pose {
    if k.abs() < 1e-6 {
        Pose {
            x: s,
            y: 0.0,
            sin: 0.0,
            cos: 1.0,
        }
    } else {
        let (sin, cos) = (k * s).sin_cos();
        Pose {
            x: sin / k,
            y: (1.0 - cos) / k,
            sin,
            cos,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use agvrl_sim::msg::{ImuReading, LaserScan};

    /// A 90 degree scan of a wall `wall_m` ahead of the LiDAR, the IMU reading `speed`.
    fn wall_frame(wall_m: f32, stamp_s: f64, speed: f64) -> SensorFrame {
        slanted_wall_frame(wall_m, 0.0, stamp_s, speed)
    }

    /// As [`wall_frame`], the wall `x + slope y = wall_m` in the LiDAR's frame (slope > 0:
    /// nearer on the left).
    fn slanted_wall_frame(wall_m: f32, slope: f32, stamp_s: f64, speed: f64) -> SensorFrame {
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

    fn on() -> SafetyFilter {
        SafetyFilter::new(
            SafetyFilterConfig {
                enabled: true,
                decel_mps2: 3.0,
                ..SafetyFilterConfig::default()
            },
            true,
        )
    }

    const FAN: Option<f32> = Some(std::f32::consts::FRAC_PI_4);

    /// The grid only skips points that cannot fail a pose's check: for clusters of points
    /// (walls, a corner), poses anywhere around them at any heading, both clearances and four
    /// fans, a check over the grid's points in the pose's box agrees with one over every point.
    #[test]
    fn a_pose_check_over_the_grid_agrees_with_one_over_every_point() {
        let f = on();
        let mut x = 0.123f64;
        let mut next = || {
            x = (x * 3.99 * (1.0 - x)).clamp(1e-6, 1.0 - 1e-6);
            x as f32
        };
        let mut grid = PointGrid::default();
        let (mut checks, mut blocked) = (0, 0);
        for _ in 0..40 {
            // A few walls of 5 cm points, some far off the rest.
            let mut pts = Vec::new();
            for _ in 0..(1 + (next() * 5.0) as usize) {
                let (x0, y0, a) = (8.0 * next() - 4.0, 8.0 * next() - 4.0, 6.3 * next());
                for k in 0..(next() * 80.0) as usize {
                    let t = 0.05 * k as f32;
                    pts.push([x0 + t * a.cos(), y0 + t * a.sin()]);
                }
            }
            grid.rebuild(&pts);
            assert_eq!(grid.points.len(), pts.len());
            for _ in 0..200 {
                let (px, py, th) = (10.0 * next() - 5.0, 10.0 * next() - 5.0, 6.3 * next() - 3.15);
                for clearance in [f.cfg.clearance_m, f.cfg.reverse_clearance_m] {
                    for fan in [std::f32::consts::FRAC_PI_4, 1.2, 1.8, std::f32::consts::PI] {
                        let (pose, fan) = (Pose::new(px, py, th), Fan::new(fan, clearance));
                        let all = f.points_clear(&pts, pose, fan);
                        let (lo, hi) = f.pose_box(pose, fan);
                        let near = grid.within(lo, hi);
                        assert_eq!(f.points_clear(near, pose, fan), all, "pose {px} {py} {th}");
                        checks += 1;
                        blocked += usize::from(!all);
                    }
                }
            }
        }
        // Both outcomes are exercised.
        assert!(
            blocked > checks / 20 && blocked < checks - checks / 20,
            "{blocked} of {checks} blocked"
        );
        grid.rebuild(&[]);
        assert_eq!(grid.within([-1.0; 2], [1.0; 2]).count(), 0);
    }

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
        assert!((f.path_needed(v, false) - want).abs() < 1e-6);
        assert!((f.path_needed(v, true) - (want + 0.25)).abs() < 1e-6);
    }

    #[test]
    fn an_arc_is_free_until_the_body_meets_a_point_on_it() {
        // A point on the rear axle's arc at full left lock (radius r = L / tan 0.36), a quarter
        // turn ahead. Seen from the car, a point an angle a ahead on that circle sits at
        // (r sin a, r (1 - cos a)): the body's front edge (0.415 m + 0.08 m margin) reaches it
        // at sin a = 0.495 / r, while it is still within the body's half width.
        let fan = std::f32::consts::FRAC_PI_4;
        let mut body_only = SafetyFilter::new(
            SafetyFilterConfig {
                clearance_m: 0.0,
                ..on().cfg
            },
            true,
        );
        let k = 0.36f32.tan() / 0.33;
        let r = 1.0 / k;
        body_only.near = vec![[r, r]];
        body_only.near_grid.rebuild(&body_only.near);
        let free = body_only.free_length(0.36, 3.0, fan);
        let quarter = std::f32::consts::FRAC_PI_2 * r;
        let want = quarter - r * (0.495 / r).asin();
        assert!(
            free <= want && free > want - PATH_STEP_M - 1e-4,
            "free {free}, want {want}"
        );
        // The LiDAR's clearance stops the path earlier; the straight path passes the point by.
        let mut f = on();
        f.near = body_only.near.clone();
        f.near_grid.rebuild(&f.near);
        assert!(f.free_length(0.36, 3.0, fan) < free);
        assert_eq!(f.free_length(0.0, 3.0, fan), 3.0);
    }

    #[test]
    fn remembered_points_follow_the_odometry() {
        // One ray straight ahead sees a point 2 m off the LiDAR; after 1 s at 1 m/s (ten frames
        // with no hits) the point sits 1 m closer in the car's frame.
        let only_centre = |fr: &mut SensorFrame, hit_centre: bool| {
            let s = fr.scan.as_mut().unwrap();
            for (i, (r, h)) in s.ranges.iter_mut().zip(s.hit.iter_mut()).enumerate() {
                *h = hit_centre && i == 50;
                if !*h {
                    *r = 12.0;
                }
            }
        };
        let go = Control {
            throttle: 0.5,
            steering_rad: 0.0,
        };
        let mut f = on();
        let mut first = wall_frame(2.0, 0.0, 1.0);
        only_centre(&mut first, true);
        f.filter(&first, go, 0.36, FAN);
        for k in 1..=10 {
            let mut later = wall_frame(12.0, 0.1 * k as f64, 1.0);
            only_centre(&mut later, false);
            f.filter(&later, go, 0.36, FAN);
        }
        assert_eq!(f.near.len(), 1);
        let [x, y] = f.near[0];
        assert!((x - 1.16).abs() < 0.04 && y.abs() < 0.04, "({x}, {y})");
        // Forgotten after memory_s.
        let mut much_later = wall_frame(12.0, 3.0, 0.0);
        only_centre(&mut much_later, false);
        f.filter(&much_later, go, 0.36, FAN);
        assert!(f.near.is_empty());
    }

    /// A filter at rest at time `t_s` that remembers one point, seen at `seen_s`, at (x, y)
    /// from the rear axle.
    fn remembering(x: f64, y: f64, seen_s: f64, t_s: f64) -> SafetyFilter {
        let mut f = on();
        f.last_stamp_s = Some(t_s);
        f.backable_m = MAX_BACKABLE_M;
        let cell = ((x / CELL_M).floor() as i32, (y / CELL_M).floor() as i32);
        f.memory.insert(cell, seen_s);
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

    #[test]
    fn reverse_lengths_end_at_points_seen_behind_and_at_the_way_the_car_came() {
        let at_rest = |t: f64| {
            let mut fr = wall_frame(12.0, t, 0.0);
            fr.scan.as_mut().unwrap().hit.fill(false);
            fr
        };
        let lengths = |f: &mut SafetyFilter, fr: &SensorFrame| {
            let mut out = vec![];
            f.reverse_free_fractions(fr, &[0.36, 0.0, -0.36], 1.5, FAN, &mut out);
            out
        };
        // At a spawn nothing behind is known: no reverse arc is free.
        let mut f = on();
        assert_eq!(lengths(&mut f, &at_rest(0.0)), [0.0; 3]);
        // After 1 m forward with nothing seen, each arc is free for the 1 m driven.
        for k in 1..=10 {
            let mut fr = at_rest(0.1 * k as f64);
            fr.imu.as_mut().unwrap().lin_vel_b[0] = 1.0;
            lengths(&mut f, &fr);
        }
        for l in lengths(&mut f, &at_rest(1.1)) {
            assert!((l - 1.0 / 1.5).abs() < 1e-4, "{l}");
        }
        // A point seen 5 s ago 0.6 m behind the rear axle (its cell's centre 0.575 m): straight
        // back, the body's back (0.085 m) and margin (0.08 m) reach it after 0.41 m, so the
        // last clear pose is 0.40 m back.
        let mut f = remembering(-0.6, 0.0, 0.0, 5.0);
        let l = lengths(&mut f, &at_rest(5.0));
        assert!((l[1] - 0.40 / 1.5).abs() < 1e-4, "{l:?}");
        // Beyond reverse_memory_s it is forgotten.
        let mut f = remembering(-0.6, 0.0, 0.0, 10.5);
        assert_eq!(lengths(&mut f, &at_rest(10.5))[1], 1.0);
    }

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
        f.backable_m = MAX_BACKABLE_M;
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
            let [ox, oy, oth] = f.pose;
            let k = (steering_rad as f32).tan() / cfg.wheelbase_m;
            let n = (need_m / PATH_STEP_M).ceil().max(1.0) as usize;
            for i in 1..=n {
                let s = (i as f32 * PATH_STEP_M).min(need_m);
                let (x, y, th) = if k.abs() < 1e-6 {
                    (s, 0.0, 0.0)
                } else {
                    ((k * s).sin() / k, (1.0 - (k * s).cos()) / k, k * s)
                };
                for ((ci, cj), _) in f.memory.cells() {
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
                f.backable_m = MAX_BACKABLE_M;
                let second = scan_frame(&second, fan, 0.1, speeds.1);
                let mut every = f.clone();
                out.clear();
                f.reverse_free_fractions(&second, &deltas, 1.5, Some(fan), &mut out);
                every.observe(&second);
                every.collect_near(100.0, false);
                every.grid_old_points();
                prop_assert_eq!(every.near.len(), every.memory.cells().count());
                let all: Vec<f32> = deltas.iter().map(|&d| every.reverse_free_length(d, 1.5, fan) / 1.5).collect();
                prop_assert_eq!(out, all);
            }

            /// Forgetting in sweeps keeps what forgetting at every call keeps, stamps running
            /// backwards included.
            #[test]
            fn the_memory_keeps_what_forgetting_every_control_keeps(
                ops in prop::collection::vec(
                    prop_oneof![
                        ((-40i32..40, -40i32..40), 0.0f64..30.0).prop_map(|(c, t)| (Some(c), t)),
                        (0.0f64..30.0).prop_map(|t| (None, t)),
                    ],
                    1..300,
                ),
            ) {
                let mut memory = CellMemory::default();
                let mut model = HashMap::new();
                // A cell is seen at or after the last time forgetting was called with.
                let mut floor = 0.0;
                for (cell, t) in ops {
                    match cell {
                        Some(c) => {
                            memory.insert(c, floor + t);
                            model.insert(c, floor + t);
                        }
                        None => {
                            memory.forget_before(t);
                            model.retain(|_, seen| *seen >= t);
                            floor = t;
                        }
                    }
                    let mut kept: Vec<_> = memory.cells().collect();
                    kept.sort_by_key(|c| c.0);
                    let mut want: Vec<_> = model.iter().map(|(&c, &t)| (c, t)).collect();
                    want.sort_by_key(|c| c.0);
                    prop_assert_eq!(kept, want);
                }
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
