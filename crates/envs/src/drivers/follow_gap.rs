//! Follow the gap (F1TENTH's reactive driver): from the LiDAR alone, steer at the deepest point
//! of the widest free gap after blanking a safety bubble around the nearest return.

use super::{CarLimits, Driver, measured_speed_mps};
use crate::api::{Control, MapInfo, SensorFrame};
use agvrl_sim::InvalidSetting;
use agvrl_sim::msg::LaserScan;
use serde::{Deserialize, Serialize};

/// Margin of the default safety bubble beyond the car's half width, metres.
const BUBBLE_MARGIN_M: f64 = 0.15;
/// Ranges within this of the gap's deepest count as equally deep, metres.
const DEPTH_TIE_M: f32 = 1e-3;

/// Settings of [`FollowTheGap`] (a TOML table; unknown keys are an error). The defaults are tuned
/// for XTENTH-CAR's LiDAR (100 rays over 90 degrees, 12 m) on the oval and the shipped map
/// tracks.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FollowTheGapSettings {
    /// Speed on a straight, m/s; None: the car's top speed.
    pub top_speed_mps: Option<f64>,
    /// Scale of that speed, in (0, 1].
    pub speed_scale: f64,
    /// Radius of the safety bubble blanked around the nearest return, metres; None: the car's
    /// half width + 0.15 m, so that a gap between bubbles is one the car fits through.
    pub bubble_radius_m: Option<f64>,
    /// Ranges are capped here, metres: beyond it every direction counts as open, so the driver
    /// aims at the middle of the open directions rather than at the single longest ray.
    pub horizon_m: f64,
    /// Width of the moving average over the ranges, rays (1: none); it smooths out single rays
    /// slipping through gaps between wall segments.
    pub smoothing_rays: usize,
    /// Share of the speed given up at full steering lock, in [0, 1): speed falls linearly with
    /// the steering angle (a margin for the driver's own weaving; the tyres' limit is applied
    /// besides, from the car's lateral acceleration).
    pub steering_slowdown: f64,
    /// Throttle added per m/s the measured speed falls short of the target (taken away above
    /// it), 1/(m/s); used when the frame carries an IMU.
    pub speed_gain_per_mps: f64,
}

impl Default for FollowTheGapSettings {
    /// Tuned on XTENTH-CAR (see the type's doc): a 3 m horizon (2.5 m laps 1-2 % slower; 4 m
    /// touched the bean's walls from every spawn tried), a 3-ray average, and a fifth of the
    /// speed given up at full lock (none laps about 2 % faster, also without contact from 20
    /// seeded spawns a track: the margin is kept for a real car's lag).
    fn default() -> Self {
        Self {
            top_speed_mps: None,
            speed_scale: 1.0,
            bubble_radius_m: None,
            horizon_m: 3.0,
            smoothing_rays: 3,
            steering_slowdown: 0.2,
            speed_gain_per_mps: 1.0,
        }
    }
}

impl FollowTheGapSettings {
    /// An error naming the first setting out of range.
    pub fn validate(&self) -> Result<(), InvalidSetting> {
        let bad = |msg: String| Err(InvalidSetting::new("follow_the_gap", msg));
        if !(self.speed_scale.is_finite() && self.speed_scale > 0.0 && self.speed_scale <= 1.0) {
            return bad(format!(
                "follow_the_gap.speed_scale must be in (0, 1], got {}",
                self.speed_scale
            ));
        }
        for (name, v) in [
            ("top_speed_mps", self.top_speed_mps),
            ("bubble_radius_m", self.bubble_radius_m),
            ("horizon_m", Some(self.horizon_m)),
        ] {
            if let Some(v) = v
                && !(v.is_finite() && v > 0.0)
            {
                return bad(format!("follow_the_gap.{name} must be finite and > 0, got {v}"));
            }
        }
        if self.smoothing_rays == 0 {
            return bad("follow_the_gap.smoothing_rays must be >= 1 (1: no smoothing), got 0".into());
        }
        if !(self.steering_slowdown.is_finite() && (0.0..1.0).contains(&self.steering_slowdown)) {
            return bad(format!(
                "follow_the_gap.steering_slowdown must be in [0, 1), got {}",
                self.steering_slowdown
            ));
        }
        if !(self.speed_gain_per_mps.is_finite() && self.speed_gain_per_mps >= 0.0) {
            return bad(format!(
                "follow_the_gap.speed_gain_per_mps must be finite and >= 0, got {}",
                self.speed_gain_per_mps
            ));
        }
        Ok(())
    }
}

/// Follow the gap on the LiDAR scan (no pose, no map). Each control:
/// 1. the ranges, unreadable ones (NaN) taken as blocked and misses as `range_max`, are
///    averaged over `smoothing_rays` and capped at `horizon_m`;
/// 2. every ray within the bubble's angle around the nearest return (`atan(bubble / r)` each
///    side) is set to 0, when that return is nearer than the horizon;
/// 3. the widest run of non-zero rays is the gap;
/// 4. the aim is the middle of the longest run of the gap's deepest rays (at the horizon, the
///    middle of the open directions);
/// 5. steering is the aim's bearing, clamped to the steering limit; speed is the top speed
///    times `speed_scale`, less `steering_slowdown` of it at full lock, and at most what the
///    car's lateral acceleration allows on the circle that steering drives.
///
/// Without a scan, or with every ray blocked, it stops with straight wheels.
#[derive(Clone, Debug)]
pub struct FollowTheGap {
    settings: FollowTheGapSettings,
    limits: CarLimits,
    /// Working ranges (reused between controls).
    ranges: Vec<f32>,
}

impl FollowTheGap {
    /// A gap follower with `settings` for the car of `limits`.
    pub fn new(settings: FollowTheGapSettings, limits: CarLimits) -> Result<Self, InvalidSetting> {
        settings.validate()?;
        limits.validate()?;
        Ok(Self {
            settings,
            limits,
            ranges: Vec::new(),
        })
    }

    /// The settings.
    pub fn settings(&self) -> &FollowTheGapSettings {
        &self.settings
    }

    /// Radius of the safety bubble, metres.
    pub fn bubble_radius_m(&self) -> f64 {
        self.settings
            .bubble_radius_m
            .unwrap_or(self.limits.half_width_m + BUBBLE_MARGIN_M)
    }

    /// Bearing of the aim point in the scan, rad (positive left), and its range, metres; None
    /// when every ray is blocked.
    pub fn aim(&mut self, scan: &LaserScan) -> Option<(f64, f64)> {
        let n = scan.ranges.len();
        if n == 0 {
            return None;
        }
        let horizon = self.settings.horizon_m as f32;
        let clean = |r: f32| {
            if r.is_nan() {
                0.0
            } else if r == f32::INFINITY {
                scan.range_max
            } else {
                r.max(0.0)
            }
        };
        // 1. Smooth (a centred moving average, shorter at the ends) and cap.
        let half = self.settings.smoothing_rays / 2;
        self.ranges.clear();
        self.ranges.extend((0..n).map(|i| {
            let (lo, hi) = (i.saturating_sub(half), (i + half).min(n - 1));
            let sum: f32 = scan.ranges[lo..=hi].iter().map(|&r| clean(r)).sum();
            (sum / (hi - lo + 1) as f32).min(horizon)
        }));
        // 2. The bubble around the nearest return.
        let (nearest, r0) =
            self.ranges.iter().copied().enumerate().fold(
                (0, f32::INFINITY),
                |best, (i, r)| if r < best.1 { (i, r) } else { best },
            );
        // Nothing within the horizon is no obstacle: no bubble.
        if r0 < horizon {
            let half_angle = (self.bubble_radius_m() as f32).atan2(r0);
            let b0 = scan.bearing(nearest);
            for (i, r) in self.ranges.iter_mut().enumerate() {
                if (scan.bearing(i) - b0).abs() <= half_angle {
                    *r = 0.0;
                }
            }
        }
        // 3. The widest run of free rays (the first of equals).
        let mut gap: Option<(usize, usize)> = None;
        let mut start = None;
        for i in 0..=n {
            let free = i < n && self.ranges[i] > 0.0;
            match (free, start) {
                (true, None) => start = Some(i),
                (false, Some(s)) => {
                    if gap.is_none_or(|(a, b)| i - s > b - a) {
                        gap = Some((s, i));
                    }
                    start = None;
                }
                _ => {}
            }
        }
        let (a, b) = gap?;
        // 4. The middle of the longest run of the gap's deepest rays.
        let deepest = self.ranges[a..b].iter().copied().fold(0.0f32, f32::max);
        let mut best: Option<(usize, usize)> = None;
        let mut start = None;
        for i in a..=b {
            let deep = i < b && self.ranges[i] >= deepest - DEPTH_TIE_M;
            match (deep, start) {
                (true, None) => start = Some(i),
                (false, Some(s)) => {
                    if best.is_none_or(|(x, y)| i - s > y - x) {
                        best = Some((s, i));
                    }
                    start = None;
                }
                _ => {}
            }
        }
        let (s, e) = best?;
        let bearing = 0.5 * (scan.bearing(s) + scan.bearing(e - 1)) as f64;
        Some((bearing, deepest as f64))
    }
}

impl Driver for FollowTheGap {
    fn reset(&mut self, _frame: &SensorFrame, _map: Option<&MapInfo>) {}

    fn control(&mut self, frame: &SensorFrame, _map: Option<&MapInfo>) -> Control {
        let Some(scan) = frame.scan.as_ref() else {
            return Control::default();
        };
        let Some((bearing, _)) = self.aim(scan) else {
            return Control::default();
        };
        let max = self.limits.max_steering_rad;
        let steering_rad = bearing.clamp(-max, max);
        let top = self.settings.top_speed_mps.unwrap_or(self.limits.top_speed_mps);
        let curvature = steering_rad.abs().tan() / self.limits.wheelbase_m;
        let target =
            (top * self.settings.speed_scale * (1.0 - self.settings.steering_slowdown * steering_rad.abs() / max))
                .min((self.limits.lateral_accel_mps2 / curvature).sqrt());
        let throttle = self
            .limits
            .throttle(target, measured_speed_mps(frame), self.settings.speed_gain_per_mps);
        Control { throttle, steering_rad }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::drivers::tests::xtenth;

    /// XTENTH-CAR's scan (100 rays over 90 degrees, 12 m) of the segments `walls` ((x0, y0),
    /// (x1, y1) in the sensor frame, metres) and the discs `discs` ((x, y), radius).
    fn scan_of(walls: &[[f32; 4]], discs: &[[f32; 3]]) -> LaserScan {
        let (angle_min, angle_increment) = agvrl_sim::sensors::LidarConfig::default().angles();
        let range_max = 12.0f32;
        let ranges = (0..100)
            .map(|i| {
                let th = angle_min + angle_increment * i as f32;
                let (dx, dy) = (th.cos(), th.sin());
                let mut r = range_max;
                for w in walls {
                    // Ray t (dx, dy) meets a + u (b - a).
                    let (ex, ey) = (w[2] - w[0], w[3] - w[1]);
                    let den = dx * ey - dy * ex;
                    if den.abs() < 1e-9 {
                        continue;
                    }
                    let t = (w[0] * ey - w[1] * ex) / den;
                    let u = (w[0] * dy - w[1] * dx) / den;
                    if t > 0.0 && (0.0..=1.0).contains(&u) {
                        r = r.min(t);
                    }
                }
                for d in discs {
                    let b = d[0] * dx + d[1] * dy;
                    let c = d[0] * d[0] + d[1] * d[1] - d[2] * d[2];
                    let disc = b * b - c;
                    if disc >= 0.0 && b - disc.sqrt() > 0.0 {
                        r = r.min(b - disc.sqrt());
                    }
                }
                r
            })
            .collect();
        LaserScan {
            angle_min,
            angle_increment,
            range_min: 0.05,
            range_max,
            ranges,
            ..LaserScan::default()
        }
    }

    fn steer(scan: LaserScan) -> Control {
        let mut d = FollowTheGap::new(FollowTheGapSettings::default(), xtenth(0.0)).unwrap();
        let frame = SensorFrame {
            scan: Some(scan),
            ..SensorFrame::default()
        };
        d.reset(&frame, None);
        d.control(&frame, None)
    }

    /// Walls 1 m either side, running ahead out of range.
    const CORRIDOR: [[f32; 4]; 2] = [[0.0, 1.0, 30.0, 1.0], [0.0, -1.0, 30.0, -1.0]];

    #[test]
    fn an_empty_corridor_steers_straight() {
        let u = steer(scan_of(&CORRIDOR, &[]));
        // The open directions are symmetric about the axis; the bubble on one wall does not
        // reach them. Half a ray of asymmetry at most.
        let half_ray = 0.5 * (90.0f64 / 99.0).to_radians();
        assert!(u.steering_rad.abs() <= half_ray + 1e-6, "{u:?}");
        // Straight: full speed.
        assert!((u.throttle - 1.0).abs() < 0.05, "{u:?}");
        // And an empty world too.
        let u = steer(scan_of(&[], &[]));
        assert!(u.steering_rad.abs() <= (90.0f64 / 99.0).to_radians(), "{u:?}");
    }

    #[test]
    fn an_obstacle_ahead_slightly_left_steers_right() {
        for y in [0.1, 0.25] {
            let u = steer(scan_of(&CORRIDOR, &[[2.0, y, 0.2]]));
            assert!(u.steering_rad < -0.1, "obstacle at y {y}: {u:?}");
            // Mirrored: steers left.
            let v = steer(scan_of(&CORRIDOR, &[[2.0, -y, 0.2]]));
            assert!(v.steering_rad > 0.1, "obstacle at y {}: {v:?}", -y);
        }
    }

    #[test]
    fn a_gap_on_the_left_only_steers_left() {
        // The corridor turns left: a wall across it 1.5 m ahead, open past y = 1 on the left.
        let walls = [[0.0, -1.0, 2.5, -1.0], [1.5, -1.0, 1.5, 1.0], [0.0, 1.0, 0.5, 1.0]];
        let u = steer(scan_of(&walls, &[]));
        assert!(u.steering_rad > 0.2, "{u:?}");
        // Steering hard, it slows.
        assert!(u.throttle < 0.95, "{u:?}");
    }

    /// A thin post straight ahead in the corridor: without the bubble the aim would be the middle
    /// of the open directions beside it, a ray passing 0.14 m from the post's face, closer than
    /// the car's half width (0.19 m); the bubble blanks the directions within 0.34 m of it.
    #[test]
    fn the_bubble_keeps_the_aim_a_half_width_clear_of_a_post_ahead() {
        let (px, py, pr) = (1.0f64, 0.0f64, 0.05f64);
        let scan = scan_of(&CORRIDOR, &[[px as f32, py as f32, pr as f32]]);
        let limits = xtenth(0.0);
        let mut d = FollowTheGap::new(FollowTheGapSettings::default(), limits).unwrap();
        let (bearing, _) = d.aim(&scan).unwrap();
        let clearance = (px * bearing.sin() - py * bearing.cos()).abs() - pr;
        assert!(
            clearance >= limits.half_width_m,
            "aim {bearing:.3} rad passes {clearance:.3} m from the post"
        );
    }

    #[test]
    fn a_blocked_or_missing_scan_stops_the_car() {
        let mut blocked = scan_of(&[], &[]);
        blocked.ranges.iter_mut().for_each(|r| *r = f32::NAN);
        assert_eq!(steer(blocked), Control::default());
        let mut d = FollowTheGap::new(FollowTheGapSettings::default(), xtenth(0.0)).unwrap();
        assert_eq!(d.control(&SensorFrame::default(), None), Control::default());
    }

    #[test]
    fn follow_the_gap_settings_defaults_and_bad_values() {
        let d: FollowTheGapSettings = toml::from_str("").unwrap();
        assert_eq!(d, FollowTheGapSettings::default());
        assert_eq!(
            (
                d.top_speed_mps,
                d.speed_scale,
                d.bubble_radius_m,
                d.horizon_m,
                d.smoothing_rays
            ),
            (None, 1.0, None, 3.0, 3)
        );
        let g = FollowTheGap::new(d.clone(), xtenth(0.0)).unwrap();
        assert!((g.bubble_radius_m() - (0.192 + 0.15)).abs() < 1e-6);
        assert!(toml::from_str::<FollowTheGapSettings>("bubble_m = 1.0").is_err());
        for (s, key) in [
            (
                FollowTheGapSettings {
                    speed_scale: 2.0,
                    ..d.clone()
                },
                "speed_scale",
            ),
            (
                FollowTheGapSettings {
                    top_speed_mps: Some(0.0),
                    ..d.clone()
                },
                "top_speed_mps",
            ),
            (
                FollowTheGapSettings {
                    horizon_m: f64::NAN,
                    ..d.clone()
                },
                "horizon_m",
            ),
            (
                FollowTheGapSettings {
                    smoothing_rays: 0,
                    ..d.clone()
                },
                "smoothing_rays",
            ),
            (
                FollowTheGapSettings {
                    steering_slowdown: 1.0,
                    ..d.clone()
                },
                "steering_slowdown",
            ),
        ] {
            let e = s.validate().unwrap_err();
            assert!(e.message.contains(key), "{key}: {e}");
            assert_eq!(e.table, "follow_the_gap");
        }
    }
}
