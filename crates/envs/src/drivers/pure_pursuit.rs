//! Pure pursuit (Coulter 1992): steer the rear axle along the circle through the goal point, the
//! path point one lookahead distance away, and drive at the path's speed profile.

use super::{CarLimits, Driver, RacePath, measured_speed_mps};
use crate::api::{Control, MapInfo, SensorFrame};
use agvrl_sim::InvalidSetting;
use serde::{Deserialize, Serialize};

/// How far behind the last nearest point a window search looks, metres (a car never backs up
/// further in one period).
const SEARCH_BACK_M: f64 = 1.0;
/// How far ahead of the last nearest point a window search looks, metres: several periods at
/// top speed.
const SEARCH_AHEAD_M: f64 = 4.0;
/// Lookahead per metre of the rear axle's distance from the path, when that exceeds the
/// speed's lookahead: a car off the path (at the start, on the centre line, of a raceline that
/// runs near a wall) joins it at about `atan(1/5)` = 11 degrees, so it does not cross it at a
/// steep angle and overshoot towards the wall behind it. Along a raceline this holds all the
/// way; along the centre line, which keeps clear of the walls, only until the car first joins
/// it: there a longer lookahead in a tight bend cuts across its inside (berlin's hairpin round
/// a thin wall's tip).
const JOIN_LOOKAHEAD_PER_M: f64 = 5.0;

/// Settings of [`PurePursuit`] (a TOML table; unknown keys are an error). The defaults are tuned
/// for XTENTH-CAR (1.79 m/s, 0.33 m wheelbase, 0.36 rad) on the oval and the shipped map tracks
/// (`assets/tracks/bean.yaml`, `sweepers.yaml`): two laps each without touching a wall.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PurePursuitSettings {
    /// Scale of the speed profile of the path built from the map at reset, in (0, 1] (a path
    /// given to [`PurePursuit::new`] carries its own profile).
    pub speed_scale: f64,
    /// Lookahead distance at standstill, metres.
    pub lookahead_min_m: f64,
    /// Lookahead added per m/s of speed, seconds: a faster car looks further, so it steers more
    /// smoothly where it has less time to correct.
    pub lookahead_per_mps: f64,
    /// Largest lookahead distance, metres.
    pub lookahead_max_m: f64,
    /// Throttle added per m/s the measured speed falls short of the target (taken away above
    /// it), 1/(m/s); used when the frame carries an IMU.
    pub speed_gain_per_mps: f64,
    /// Room a raceline leaves between the car's side and the nearest wall, metres: at reset,
    /// on a map whose track knows its clearance, every raceline point further from the centre
    /// line than the clearance less the car's half width less this moves in to that distance
    /// ([`RacePath::fit_to`]).
    pub wall_margin_m: f64,
}

impl Default for PurePursuitSettings {
    /// Tuned on XTENTH-CAR (see the type's doc): a lookahead of 0.4 m + 0.2 s, 0.76 m at top
    /// speed (2.3 wheelbases, so a period's command delay does not make it weave). Of the
    /// lookaheads tried (0.3-0.6 m + 0.1-0.4 s), shorter ones cut the bends less (the bean's
    /// 1 m bend: 0.15 m off the centre line at 0.58 m, 0.32 m at 1.3 m) at the same lap time
    /// within 0.5 %.
    fn default() -> Self {
        Self {
            speed_scale: 1.0,
            lookahead_min_m: 0.4,
            lookahead_per_mps: 0.2,
            lookahead_max_m: 2.0,
            speed_gain_per_mps: 1.0,
            // Pure pursuit's tracking error off a raceline's bends (up to 0.11 m on F1TENTH's
            // circuits), the 0.02 m at which contact counts, and walls traced from 0.05 m map
            // pixels, which bulge between the centre-line points the clearance is measured at:
            // at 0.1 and 0.15 m XTENTH-CAR still touched a wall on some of them.
            wall_margin_m: 0.2,
        }
    }
}

impl PurePursuitSettings {
    /// An error naming the first setting out of range.
    pub fn validate(&self) -> Result<(), InvalidSetting> {
        let bad = |msg: String| Err(InvalidSetting::new("pure_pursuit", msg));
        if !(self.speed_scale.is_finite() && self.speed_scale > 0.0 && self.speed_scale <= 1.0) {
            return bad(format!(
                "pure_pursuit.speed_scale must be in (0, 1], got {}",
                self.speed_scale
            ));
        }
        for (name, v) in [
            ("lookahead_min_m", self.lookahead_min_m),
            ("lookahead_max_m", self.lookahead_max_m),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return bad(format!("pure_pursuit.{name} must be finite and > 0, got {v}"));
            }
        }
        for (name, v) in [
            ("lookahead_per_mps", self.lookahead_per_mps),
            ("speed_gain_per_mps", self.speed_gain_per_mps),
            ("wall_margin_m", self.wall_margin_m),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return bad(format!("pure_pursuit.{name} must be finite and >= 0, got {v}"));
            }
        }
        if self.lookahead_max_m < self.lookahead_min_m {
            return bad(format!(
                "pure_pursuit.lookahead_max_m ({}) must be >= lookahead_min_m ({})",
                self.lookahead_max_m, self.lookahead_min_m
            ));
        }
        Ok(())
    }

    /// Lookahead distance at `speed_mps`, metres.
    pub fn lookahead_m(&self, speed_mps: f64) -> f64 {
        (self.lookahead_min_m + self.lookahead_per_mps * speed_mps.max(0.0)).min(self.lookahead_max_m)
    }
}

/// Pure pursuit along a [`RacePath`] from the car's pose (`frame.gps`) and speed (`frame.imu`).
///
/// Steering: the rear axle's circle through the goal point, the first path point ahead of the
/// nearest one at the lookahead distance `Ld` from the rear axle, `delta = atan(2 L sin(alpha)
/// / Ld)` (`alpha`: the goal's bearing from the heading), clamped to the steering limit. On a
/// circular path the car's circle is the path itself, so a kinematic car holds the path's
/// radius exactly.
///
/// Speed: the lowest profile speed between the nearest point and the goal point. Pure pursuit
/// starts turning when the goal point enters a bend, about `Ld` before the path does, so the
/// car must be at the bend's speed by then; the profile's backward pass already brakes for it.
#[derive(Clone, Debug)]
pub struct PurePursuit {
    settings: PurePursuitSettings,
    limits: CarLimits,
    /// Whether the path is built from each episode's map (none was given to `new`).
    from_map: bool,
    /// The raceline given to `new`, before any fit.
    raceline: Option<RacePath>,
    /// The track the path was last fitted to, and how many raceline points the fit moved.
    fitted: Option<(crate::api::Track, usize)>,
    path: Option<RacePath>,
    /// Index of the path point nearest the rear axle at the last control.
    nearest_idx: Option<usize>,
    /// Whether the car has joined the centre line since the last reset (see
    /// [`JOIN_LOOKAHEAD_PER_M`]); a raceline is never joined for good.
    joined: bool,
}

impl PurePursuit {
    /// A pursuer with `settings` for the car of `limits`, along `path`, or, when None, along the
    /// centre line of the track each episode's map carries (built at [`Driver::reset`]; without
    /// a track it stands still).
    pub fn new(
        settings: PurePursuitSettings,
        limits: CarLimits,
        path: Option<RacePath>,
    ) -> Result<Self, InvalidSetting> {
        settings.validate()?;
        limits.validate()?;
        Ok(Self {
            settings,
            limits,
            from_map: path.is_none(),
            raceline: path.clone(),
            fitted: None,
            path,
            nearest_idx: None,
            joined: false,
        })
    }

    /// The path it follows (None before a reset found a track, when none was given).
    pub fn path(&self) -> Option<&RacePath> {
        self.path.as_ref()
    }

    /// The settings.
    pub fn settings(&self) -> &PurePursuitSettings {
        &self.settings
    }
}

/// Index of the point of `path` nearest `p`: within a window around `last`, or over the whole
/// path when there is no `last` or the window's best is further than `lost_m` (the car was
/// moved); `last` becomes the answer.
fn nearest(path: &RacePath, last: &mut Option<usize>, p: [f64; 2], lost_m: f64) -> usize {
    let n = path.len();
    let windowed = last.map(|last| {
        let back = (SEARCH_BACK_M / path.spacing_m()).ceil() as usize;
        let len = ((SEARCH_BACK_M + SEARCH_AHEAD_M) / path.spacing_m()).ceil() as usize;
        path.nearest_in(p, (last + n - back.min(n)) % n, len)
    });
    let (idx, _) = match windowed {
        Some((i, d2)) if d2.sqrt() <= lost_m => (i, d2),
        _ => path.nearest_in(p, 0, n),
    };
    *last = Some(idx);
    idx
}

/// The goal point for a rear axle at `c`: walking the path from `from`, the first point at
/// `ld` from `c` (interpolated on its segment), with the index of the segment's end. When the
/// car is further than `ld` from the path, the first point past `from`.
fn goal_point(path: &RacePath, c: [f64; 2], from: usize, ld: f64) -> ([f64; 2], usize) {
    let pts = path.points();
    let n = pts.len();
    let dist = |p: [f64; 2]| (p[0] - c[0]).hypot(p[1] - c[1]);
    for k in 0..n {
        let (i, j) = ((from + k) % n, (from + k + 1) % n);
        let (a, b) = (pts[i], pts[j]);
        if dist(b) < ld {
            continue;
        }
        // |a + t (b - a) - c| = ld: the larger root is where the segment leaves the circle.
        let d = [b[0] - a[0], b[1] - a[1]];
        let f = [a[0] - c[0], a[1] - c[1]];
        let qa = d[0] * d[0] + d[1] * d[1];
        let qb = 2.0 * (f[0] * d[0] + f[1] * d[1]);
        let qc = f[0] * f[0] + f[1] * f[1] - ld * ld;
        let disc = qb * qb - 4.0 * qa * qc;
        if qa > 0.0 && disc >= 0.0 {
            let t = (-qb + disc.sqrt()) / (2.0 * qa);
            if (0.0..=1.0).contains(&t) {
                return ([a[0] + t * d[0], a[1] + t * d[1]], j);
            }
        }
        return (b, j);
    }
    // The whole path lies within ld: aim at the point after the nearest.
    let j = (from + 1) % n;
    (pts[j], j)
}

impl Driver for PurePursuit {
    fn reset(&mut self, frame: &SensorFrame, map: Option<&MapInfo>) {
        self.nearest_idx = None;
        self.joined = false;
        if self.from_map {
            // The settings and limits were validated in `new`, so a track's path builds unless
            // the track is degenerate; then the car stands still.
            self.path = map
                .and_then(|m| m.track.as_ref())
                .and_then(|t| RacePath::from_track(t, &self.limits, self.settings.speed_scale).ok());
        } else if let (Some(raceline), Some(track)) = (self.raceline.as_ref(), map.and_then(|m| m.track.as_ref())) {
            // Fit the raceline to the car on this track, once per track (a generated circuit
            // changes every episode). A fit that fails (a degenerate result) keeps the raceline.
            if self.fitted.as_ref().is_none_or(|(t, _)| t != track) {
                let (path, moved) = raceline
                    .fit_to(track, &self.limits, self.settings.wall_margin_m)
                    .unwrap_or_else(|_| (raceline.clone(), 0));
                self.path = Some(path);
                self.fitted = Some((track.clone(), moved));
            }
        }
        if let (Some(path), Some(gps)) = (self.path.as_ref(), frame.gps.as_ref()) {
            let c = rear_axle(&self.limits, gps);
            nearest(path, &mut self.nearest_idx, c, self.settings.lookahead_max_m);
        }
    }

    /// How many points of the raceline given to `new` the last fit to a map's track moved (see
    /// [`PurePursuitSettings::wall_margin_m`]); None before a fit, or without a raceline.
    fn raceline_points_moved(&self) -> Option<usize> {
        self.fitted.as_ref().map(|(_, n)| *n)
    }

    fn control(&mut self, frame: &SensorFrame, _map: Option<&MapInfo>) -> Control {
        let (Some(path), Some(gps)) = (self.path.as_ref(), frame.gps.as_ref()) else {
            return Control::default();
        };
        let yaw = gps.rpy_rad[2];
        let c = rear_axle(&self.limits, gps);
        let i = nearest(path, &mut self.nearest_idx, c, self.settings.lookahead_max_m);
        let measured = measured_speed_mps(frame);
        let p = path.points()[i];
        let off_m = (p[0] - c[0]).hypot(p[1] - c[1]);
        let tracking_ld = self.settings.lookahead_m(measured.unwrap_or(path.speeds_mps()[i]));
        let join_ld = JOIN_LOOKAHEAD_PER_M * off_m;
        self.joined |= self.from_map && join_ld <= tracking_ld;
        let ld = if self.joined {
            tracking_ld
        } else {
            tracking_ld.max(join_ld)
        };
        let (g, j) = goal_point(path, c, i, ld);
        let (dx, dy) = (g[0] - c[0], g[1] - c[1]);
        let d = dx.hypot(dy).max(1e-6);
        let alpha = dy.atan2(dx) - yaw;
        let curvature = 2.0 * alpha.sin() / d;
        let max = self.limits.max_steering_rad;
        let steering_rad = (self.limits.wheelbase_m * curvature).atan().clamp(-max, max);
        let n = path.len();
        let span = (j + n - i) % n;
        // No faster than the grip allows on the arc it steers: off the path (out of one bend
        // into the next) that arc is tighter than the path's.
        let steered_curvature = steering_rad.tan().abs() / self.limits.wheelbase_m;
        let target = (0..=span)
            .map(|k| path.speeds_mps()[(i + k) % n])
            .fold((self.limits.lateral_accel_mps2 / steered_curvature).sqrt(), f64::min);
        let throttle = self.limits.throttle(target, measured, self.settings.speed_gain_per_mps);
        Control { throttle, steering_rad }
    }
}

/// World position of the rear axle (x, y), metres, from the pose of the base link.
fn rear_axle(limits: &CarLimits, gps: &agvrl_sim::msg::GpsReading) -> [f64; 2] {
    let (s, c) = gps.rpy_rad[2].sin_cos();
    [
        gps.position_m[0] + limits.rear_axle_x_m * c,
        gps.position_m[1] + limits.rear_axle_x_m * s,
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::drivers::tests::{circle, xtenth};
    use agvrl_sim::msg::{GpsReading, ImuReading};

    const DT_S: f64 = 1.0 / 30.0;

    /// A frame of a car whose rear axle is at (x, y) heading `yaw` at `speed_mps`.
    fn frame_at(limits: &CarLimits, x: f64, y: f64, yaw: f64, speed_mps: f64) -> SensorFrame {
        let (s, c) = yaw.sin_cos();
        SensorFrame {
            gps: Some(GpsReading {
                position_m: [x - limits.rear_axle_x_m * c, y - limits.rear_axle_x_m * s, 0.0],
                rpy_rad: [0.0, 0.0, yaw],
                ..GpsReading::default()
            }),
            imu: Some(ImuReading {
                lin_vel_b: [speed_mps, 0.0, 0.0],
                ..ImuReading::default()
            }),
            ..SensorFrame::default()
        }
    }

    /// Drive a kinematic bicycle (rear-axle reference, the drive model for the speed, each
    /// period's arc in closed form) with `driver` for `seconds` from the rear-axle pose `start`;
    /// gives the rear axle's positions and speeds.
    fn drive_bicycle(
        driver: &mut PurePursuit,
        limits: &CarLimits,
        start: [f64; 3],
        seconds: f64,
    ) -> Vec<([f64; 2], f64)> {
        let [mut x, mut y, mut yaw] = start;
        let mut w = 0.0;
        let mut out = Vec::new();
        let v = |w: f64| w * limits.drive_radius_m;
        driver.reset(&frame_at(limits, x, y, yaw, 0.0), None);
        for _ in 0..(seconds / DT_S).round() as usize {
            let u = driver.control(&frame_at(limits, x, y, yaw, v(w)), None);
            let delta = u.steering_rad.clamp(-limits.max_steering_rad, limits.max_steering_rad);
            w = limits.drive.advance(w, u.throttle, DT_S);
            let ds = v(w) * DT_S;
            if delta.abs() > 1e-12 {
                let r = limits.wheelbase_m / delta.tan();
                let yaw1 = yaw + ds / r;
                x += r * (yaw1.sin() - yaw.sin());
                y -= r * (yaw1.cos() - yaw.cos());
                yaw = yaw1;
            } else {
                x += ds * yaw.cos();
                y += ds * yaw.sin();
            }
            out.push(([x, y], v(w)));
        }
        out
    }

    /// On a circle of radius R the goal point lies on the path, and the circle through the rear
    /// axle, tangent to its heading, through the goal, is the path itself when the axle is on
    /// it: pure pursuit's fixed point is radius R (not the `sqrt(R^2 - Ld^2)` of a driver that
    /// heads straight at the goal point). The path is a polygon whose chords sag inside the
    /// circle by `s^2 / (8 R)` for its spacing s; the goal point lies on a chord, so the
    /// settled radius is R within that sag (plus float rounding). Also with the base link
    /// 0.2 m ahead of the rear axle: the driver steers the axle, not the GPS point.
    #[test]
    fn pure_pursuit_tracks_a_circle_of_known_radius() {
        for (r, rear_axle_x_m) in [(2.0, 0.0), (4.0, 0.0), (2.0, -0.2)] {
            let limits = CarLimits {
                rear_axle_x_m,
                ..xtenth(0.0)
            };
            let n = (std::f64::consts::TAU * r / 0.1).round() as usize;
            let path = RacePath::new(&circle(r, n), &limits, 1.0).unwrap();
            let mut driver = PurePursuit::new(PurePursuitSettings::default(), limits, Some(path.clone())).unwrap();
            // Start 0.3 m outside the circle, 0.1 rad off its tangent (counter-clockwise).
            let run = drive_bicycle(
                &mut driver,
                &limits,
                [r + 0.3, 0.0, std::f64::consts::FRAC_PI_2 + 0.1],
                60.0,
            );
            let sag = path.spacing_m().powi(2) / (8.0 * r);
            let last_10_s = &run[run.len() - 300..];
            let (lo, hi) = last_10_s.iter().fold((f64::MAX, f64::MIN), |(lo, hi), (p, _)| {
                let rho = p[0].hypot(p[1]);
                (lo.min(rho), hi.max(rho))
            });
            assert!(
                lo >= r - sag - 1e-6 && hi <= r + 1e-6,
                "R {r}, axle at {rear_axle_x_m}: settled on radii {lo}..{hi}, expected {}..{r}",
                r - sag
            );
            // It drives at the profile's speed (the top speed, on these circles), within the
            // drive's approach to its steady state.
            let v = last_10_s.last().unwrap().1;
            assert!((v - path.speeds_mps()[0]).abs() < 0.01, "v {v}");
        }
    }

    /// Off its path and steering back hard, it asks for no more speed than the grip allows on
    /// the arc it steers, though the path's own profile allows the top speed there.
    #[test]
    fn off_the_path_it_slows_for_the_arc_it_steers() {
        let mut limits = xtenth(0.0);
        limits.lateral_accel_mps2 = 0.5;
        let path = RacePath::new(&circle(50.0, 3142), &limits, 1.0).unwrap();
        assert!(
            path.speeds_mps()
                .iter()
                .all(|&v| (v - limits.top_speed_mps).abs() < 1e-9)
        );
        let mut driver = PurePursuit::new(PurePursuitSettings::default(), limits, Some(path)).unwrap();
        // 0.3 m outside the circle, heading 0.5 rad away from it, at the top speed.
        let v = limits.top_speed_mps;
        let f = frame_at(&limits, 50.3, 0.0, std::f64::consts::FRAC_PI_2 - 0.5, v);
        driver.reset(&f, None);
        let u = driver.control(&f, None);
        let kappa = u.steering_rad.tan().abs() / limits.wheelbase_m;
        let cap = (limits.lateral_accel_mps2 / kappa).sqrt();
        assert!(cap < 0.9 * v, "the arc {kappa} 1/m allows {cap} m/s: no test");
        let want = limits.throttle(cap, Some(v), PurePursuitSettings::default().speed_gain_per_mps);
        assert!(
            (u.throttle - want).abs() < 1e-12,
            "throttle {} for {cap} m/s: {want}",
            u.throttle
        );
    }

    #[test]
    fn the_goal_point_is_on_the_path_at_the_lookahead_distance() {
        let limits = xtenth(0.0);
        let path = RacePath::new(&circle(2.0, 126), &limits, 1.0).unwrap();
        for ld in [0.5, 1.0, 1.5] {
            let (g, _) = goal_point(&path, [2.0, 0.0], 0, ld);
            assert!(((g[0] - 2.0).hypot(g[1]) - ld).abs() < 1e-9, "{g:?}");
            assert!(g[1] > 0.0, "ahead, counter-clockwise: {g:?}");
        }
        // Far from the path: the point after the nearest.
        let (g, j) = goal_point(&path, [10.0, 0.0], 0, 1.0);
        assert_eq!((g, j), (path.points()[1], 1));
    }

    #[test]
    fn without_a_pose_or_a_path_it_stands_still() {
        let limits = xtenth(0.0);
        let mut driver = PurePursuit::new(PurePursuitSettings::default(), limits, None).unwrap();
        let frame = frame_at(&limits, 0.0, 0.0, 0.0, 1.0);
        driver.reset(&frame, None);
        assert_eq!(driver.control(&frame, None), Control::default());
        let path = RacePath::new(&circle(2.0, 126), &limits, 1.0).unwrap();
        let mut driver = PurePursuit::new(PurePursuitSettings::default(), limits, Some(path)).unwrap();
        driver.reset(&SensorFrame::default(), None);
        assert_eq!(driver.control(&SensorFrame::default(), None), Control::default());
        // A frame without a fix loses nothing: the next fix drives again.
        let on_path = frame_at(&limits, 2.0, 0.0, std::f64::consts::FRAC_PI_2, 1.0);
        let u = driver.control(&on_path, None);
        assert!(u.throttle > 0.0 && u.steering_rad > 0.0, "{u:?}");
    }

    #[test]
    fn pure_pursuit_settings_defaults_and_bad_values() {
        let d: PurePursuitSettings = toml::from_str("").unwrap();
        assert_eq!(d, PurePursuitSettings::default());
        assert_eq!(
            (
                d.speed_scale,
                d.lookahead_min_m,
                d.lookahead_per_mps,
                d.lookahead_max_m,
                d.speed_gain_per_mps
            ),
            (1.0, 0.4, 0.2, 2.0, 1.0)
        );
        assert!(toml::from_str::<PurePursuitSettings>("lookahead = 1.0").is_err());
        for (s, key) in [
            (
                PurePursuitSettings {
                    speed_scale: 0.0,
                    ..d.clone()
                },
                "speed_scale",
            ),
            (
                PurePursuitSettings {
                    lookahead_min_m: -1.0,
                    ..d.clone()
                },
                "lookahead_min_m",
            ),
            (
                PurePursuitSettings {
                    lookahead_per_mps: f64::NAN,
                    ..d.clone()
                },
                "lookahead_per_mps",
            ),
            (
                PurePursuitSettings {
                    lookahead_max_m: 0.3,
                    ..d.clone()
                },
                "lookahead_max_m",
            ),
        ] {
            let e = s.validate().unwrap_err();
            assert!(e.message.contains(key), "{key}: {e}");
            assert_eq!(e.table, "pure_pursuit");
        }
        assert!((d.lookahead_m(1.79) - 0.758).abs() < 1e-9);
        assert_eq!(d.lookahead_m(10.0), 2.0);
    }
}
