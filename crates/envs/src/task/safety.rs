//! A LiDAR safety filter between the policy and the drive: before a control goes out, the car's
//! path under it (the Ackermann arc of its steering, long enough to react and brake to a stop)
//! is checked against the obstacle points of the last second of scans. An unsafe control is
//! replaced by the nearest steering whose path is clear, or by braking on the clearest arc.
//! Only the scan, the IMU's speed and yaw rate, and the car's geometry enter, so the same filter
//! runs in simulation and on the car.

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
}

impl Default for SafetyFilterConfig {
    fn default() -> Self {
        Self {
            enabled: false,
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
        }
    }
}

impl SafetyFilterConfig {
    /// Check the settings.
    pub fn validate(&self) -> Result<(), String> {
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
        ];
        for (name, v) in lengths {
            if !(v.is_finite() && v >= 0.0) {
                return Err(format!("safety_filter.{name} must be finite and >= 0, got {v}"));
            }
        }
        for (name, v) in [
            ("wheelbase_m", self.wheelbase_m),
            ("front_m", self.front_m),
            ("half_width_m", self.half_width_m),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("safety_filter.{name} must be finite and > 0, got {v}"));
            }
        }
        if self.n_steering < 2 {
            return Err(format!(
                "safety_filter.n_steering must be >= 2, got {}",
                self.n_steering
            ));
        }
        if !(self.decel_mps2.is_finite() && self.decel_mps2 > 0.0) {
            return Err(
                "safety_filter needs a braking drive: set brake_mps2 (or safety_filter.decel_mps2) > 0; \
                 a coasting car cannot stop where the filter plans"
                    .into(),
            );
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
    memory: HashMap<(i32, i32), f64>,
    /// Points near the car in its current frame (rebuilt every control).
    near: Vec<[f32; 2]>,
    last: Intervention,
}

/// Scan points farther than this from the LiDAR are not remembered, metres: within the memory's
/// time the car cannot reach them without scanning them again.
const REMEMBER_WITHIN_M: f32 = 3.0;
/// Spacing of the poses checked along a path, metres.
const PATH_STEP_M: f32 = 0.04;
/// Remembered points are merged into cells this wide, metres (a point moves by at most half a
/// diagonal, under 3.6 cm: inside the margins).
const CELL_M: f64 = 0.05;

impl SafetyFilter {
    /// A filter with empty memory (`cfg` validated).
    pub fn new(cfg: SafetyFilterConfig) -> Self {
        Self {
            cfg,
            pose: [0.0; 3],
            last_stamp_s: None,
            memory: HashMap::new(),
            near: Vec::new(),
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
        self.pose = [0.0; 3];
        self.last_stamp_s = None;
        self.memory.clear();
        self.last = Intervention::None;
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
        let fan_half_rad = fan_half_rad.unwrap_or_else(|| {
            frame.scan.as_ref().map_or(std::f32::consts::PI, |s| {
                let end = s.angle_min + s.angle_increment * s.ranges.len().saturating_sub(1) as f32;
                s.angle_min.abs().max(end.abs())
            })
        });
        let speed = self.observe(frame);
        self.collect_near(speed);
        let delta = proposed.steering_rad.clamp(-steering_limit_rad, steering_limit_rad);
        let drives = proposed.throttle > 0.0;
        let need = self.path_needed(speed, drives);
        if self.free_length(delta as f32, need, fan_half_rad) >= need {
            return proposed;
        }
        let n = self.cfg.n_steering;
        let mut candidates: Vec<f64> = (0..n)
            .map(|k| -steering_limit_rad + 2.0 * steering_limit_rad * k as f64 / (n - 1) as f64)
            .collect();
        candidates.sort_by(|a, b| (a - delta).abs().total_cmp(&(b - delta).abs()));
        for &d in &candidates {
            if self.free_length(d as f32, need, fan_half_rad) >= need {
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
        self.last = Intervention::Braked;
        Control {
            throttle: 0.0,
            steering_rad: best.0,
        }
    }

    /// Path length a control needs clear: the distance to react and brake to a stop, plus
    /// `lookahead_m` when it drives.
    fn path_needed(&self, speed: f32, drives: bool) -> f32 {
        let v = speed.max(0.0);
        let stop = v * self.cfg.reaction_s + v * v / (2.0 * self.cfg.decel_mps2.max(1e-3));
        if drives { stop + self.cfg.lookahead_m } else { stop }
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
            self.pose[0] += v * dt * th.cos();
            self.pose[1] += v * dt * th.sin();
            self.pose[2] += w * dt;
        }
        self.last_stamp_s = Some(frame.stamp_s);
        let keep_after = frame.stamp_s - self.cfg.memory_s as f64;
        self.memory.retain(|_, t| *t >= keep_after);
        if let Some(scan) = &frame.scan {
            let (s, c) = self.pose[2].sin_cos();
            for (i, &r) in scan.ranges.iter().enumerate() {
                let hit = scan.hit.get(i).copied().unwrap_or(r < scan.range_max);
                if !hit || !r.is_finite() || r > REMEMBER_WITHIN_M {
                    continue;
                }
                let b = scan.angle_min + scan.angle_increment * i as f32;
                let (px, py) = ((self.cfg.lidar_x_m + r * b.cos()) as f64, (r * b.sin()) as f64);
                let wx = self.pose[0] + c * px - s * py;
                let wy = self.pose[1] + s * px + c * py;
                let cell = ((wx / CELL_M).floor() as i32, (wy / CELL_M).floor() as i32);
                self.memory.insert(cell, frame.stamp_s);
            }
        }
        v as f32
    }

    /// Remembered points that a path from here could reach, in the car's frame.
    fn collect_near(&mut self, speed: f32) {
        let reach =
            self.path_needed(speed, true) + 1.0 + self.cfg.front_m + self.cfg.clearance_m + self.cfg.half_width_m;
        let (s, c) = self.pose[2].sin_cos();
        let (s, c) = (s as f32, c as f32);
        self.near.clear();
        for &(i, j) in self.memory.keys() {
            // Relative to the car in f64, then f32: odometry may run far from its origin.
            let dx = ((i as f64 + 0.5) * CELL_M - self.pose[0]) as f32;
            let dy = ((j as f64 + 0.5) * CELL_M - self.pose[1]) as f32;
            let p = [c * dx + s * dy, -s * dx + c * dy];
            if p[0] * p[0] + p[1] * p[1] <= reach * reach {
                self.near.push(p);
            }
        }
    }

    /// How far along the arc of steering `delta` the car drives before its body (with margin)
    /// touches a point or the LiDAR comes within `clearance_m` of a point in its fan, metres
    /// (checked up to `limit`; `limit` itself when the path is clear).
    fn free_length(&self, delta: f32, limit: f32, fan_half_rad: f32) -> f32 {
        let k = delta.tan() / self.cfg.wheelbase_m;
        let n = (limit / PATH_STEP_M).ceil().max(1.0) as usize;
        for i in 1..=n {
            let sd = (i as f32 * PATH_STEP_M).min(limit);
            let (x, y, th) = if k.abs() < 1e-6 {
                (sd, 0.0, 0.0)
            } else {
                let th = k * sd;
                (th.sin() / k, (1.0 - th.cos()) / k, th)
            };
            if !self.pose_clear(x, y, th, fan_half_rad) {
                return (sd - PATH_STEP_M).max(0.0);
            }
        }
        limit
    }

    fn pose_clear(&self, x: f32, y: f32, th: f32, fan_half_rad: f32) -> bool {
        let cfg = &self.cfg;
        let (s, c) = th.sin_cos();
        let m = cfg.body_margin_m;
        let tan_fan = if fan_half_rad < std::f32::consts::FRAC_PI_2 {
            fan_half_rad.tan()
        } else {
            f32::INFINITY
        };
        let c2 = cfg.clearance_m * cfg.clearance_m;
        for &[px, py] in &self.near {
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

#[cfg(test)]
mod tests {
    use super::*;
    use agvrl_sim::msg::{ImuReading, LaserScan};

    /// A 90 degree scan of a wall `wall_m` ahead of the LiDAR, at rest.
    fn wall_frame(wall_m: f32, stamp_s: f64, speed: f64) -> SensorFrame {
        let n = 101;
        let half = std::f32::consts::FRAC_PI_4;
        let inc = 2.0 * half / (n - 1) as f32;
        let ranges: Vec<f32> = (0..n)
            .map(|i| (wall_m / (-half + inc * i as f32).cos()).min(12.0))
            .collect();
        let hit = ranges.iter().map(|r| *r < 12.0).collect();
        SensorFrame {
            stamp_s,
            scan: Some(LaserScan {
                angle_min: -half,
                angle_increment: inc,
                range_min: 0.05,
                range_max: 12.0,
                points_w: vec![],
                object_id: vec![],
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
        SafetyFilter::new(SafetyFilterConfig {
            enabled: true,
            decel_mps2: 3.0,
            ..SafetyFilterConfig::default()
        })
    }

    const FAN: Option<f32> = Some(std::f32::consts::FRAC_PI_4);

    #[test]
    fn a_clear_path_passes_unchanged_and_a_disabled_filter_never_acts() {
        let go = Control {
            throttle: 1.0,
            steering_rad: 0.1,
        };
        let mut f = on();
        assert_eq!(f.filter(&wall_frame(5.0, 0.0, 1.5), go, 0.36, FAN), go);
        assert_eq!(f.last_intervention(), Intervention::None);
        let mut off = SafetyFilter::new(SafetyFilterConfig::default());
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
        let mut body_only = SafetyFilter::new(SafetyFilterConfig {
            clearance_m: 0.0,
            ..on().cfg
        });
        let k = 0.36f32.tan() / 0.33;
        let r = 1.0 / k;
        body_only.near = vec![[r, r]];
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
}
