//! The passer: drives the passes of a policy-driven car in a race, in front of the safety
//! filter. It finds the car ahead, places a line beside it ([`crate::pass_advice`]), allowing
//! for where that car drifts across the track, steers the car along the line by pure pursuit
//! and holds it there until the car is past. Elsewhere the policy drives.
//!
//! The other car's place comes from the simulator ([`PasserSource::Truth`], a ceiling) or from
//! the car's own scan against the track ([`PasserSource::Scan`]): what a car that runs pure
//! pursuit has, its pose on the map, the track's centre line and widths, and its scan.

use crate::api::{Control, SensorFrame, Track};
use crate::drivers::CarLimits;
use crate::pass_advice::{Advice, Body, Pair};
use agvrl_sim::PlanarPose;
use agvrl_sim::msg::{LaserScan, Pose3};
use serde::{Deserialize, Serialize};

/// Where a passer learns the other car's place.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum PasserSource {
    /// No passer: the policy drives every step.
    #[default]
    Off,
    /// The car's scan against the track map.
    Scan,
    /// The simulator's places of both cars.
    Truth,
}

/// The lateral gap a passing line keeps between the two bodies, metres.
pub const MARGIN_M: f32 = 0.25;
/// How far behind this car's rear the other car's base must be before the line is let go,
/// metres.
pub const HOLD_M: f32 = 0.3;
/// The longest the other car's drift is carried forward, seconds.
pub const DRIFT_HORIZON_S: f32 = 1.0;
/// How far down the track the line is pursued, metres (a shorter lookahead turns hard and
/// overshoots the line).
pub const LOOKAHEAD_M: f32 = 1.5;
/// How far ahead along the track the scan looks for a car, metres.
pub const SEE_AHEAD_M: f32 = 8.0;
/// From the face of a car that the scan plane meets at its rear to its base, metres
/// (XTENTH-CAR's LiDAR stack).
pub const REAR_TO_BASE_M: f32 = 0.07;
/// The window the other car's speed and drift are fitted over, seconds.
pub const FIT_WINDOW_S: f64 = 0.5;
/// How long a car out of the scan (beside this one) is predicted on, seconds.
pub const KEEP_S: f64 = 10.0;
/// Scan points nearer a wall than this are the wall, metres.
const WALL_BAND_M: f32 = 0.05;
/// A car's scan points lie no further apart than this, metres.
const CLUSTER_GAP_M: f32 = 0.25;
/// Sightings nearer than this show only the car's side: they place it but do not time it,
/// metres.
const TIMED_FROM_M: f32 = 0.7;

/// The car a passer drives, where it is and how fast it goes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OwnCar {
    /// Its base on the map.
    pub pose: PlanarPose,
    /// Its forward speed, m/s.
    pub speed_mps: f32,
}

/// A passer on one car: it follows the car ahead in the car's scans and, while a pass is on,
/// gives the control that drives it ([`Passer::control`]).
#[derive(Clone, Debug)]
pub struct Passer {
    tracker: ScanTracker,
    body: Body,
    limits: CarLimits,
    /// The side of the pass under way (true: right of the other car).
    side: Option<bool>,
}

impl Passer {
    /// A passer on a car of `body` (both cars') driven within `limits`.
    pub fn new(body: Body, limits: CarLimits) -> Self {
        Self {
            tracker: ScanTracker::default(),
            body,
            limits,
            side: None,
        }
    }

    /// A passer on a car of `model`: its body from the model's collision shapes (a car of
    /// wheels alone: its axles), as the race env measures it.
    pub fn for_model(model: &agvrl_sim::vehicle::VehicleModel) -> Self {
        let (rear, front) = body_x_m(model);
        let half_width_m = model.body_bounds_m().map_or(0.0, |(lo, hi)| 0.5 * (hi[1] - lo[1]));
        let body = Body {
            length_m: front - rear,
            half_width_m,
        };
        Self::new(body, CarLimits::of(model, 0.0))
    }

    /// Forget the car followed and the pass under way (a new race).
    pub fn reset(&mut self) {
        self.tracker.reset();
        self.side = None;
    }

    /// Both cars' body, as the passer plans with it.
    pub fn body(&self) -> Body {
        self.body
    }

    /// The car's limits, as the passer steers and throttles with them.
    pub fn limits(&self) -> CarLimits {
        self.limits
    }

    /// The control that drives `car`'s pass of the car ahead in `scan` (taken at `now_s`)
    /// instead of `control`; None while no pass is on and the policy drives.
    pub fn control(
        &mut self,
        track: &Track,
        car: OwnCar,
        scan: Option<&LaserScan>,
        now_s: f64,
        control: Control,
        steering_limit_rad: f64,
    ) -> Option<Control> {
        let behind_m = self.body.length_m + HOLD_M;
        let (pose, speed_mps) = (car.pose, car.speed_mps);
        let Some(seen) = self.tracker.update(track, pose, speed_mps, scan, now_s, behind_m) else {
            self.side = None;
            return None;
        };
        let s = track.centreline_s(pose.x_m, pose.y_m);
        let pair = Pair {
            ahead_m: seen.ahead_m,
            offset_m: track.offset_right_m(pose.x_m, pose.y_m),
            other_offset_m: seen.offset_m,
            speed_mps,
            other_speed_mps: seen.speed_mps,
            half_width_m: track.clearance_at_m(s)?,
        };
        self.pass(track, car, (pair, seen.drift_mps), control, steering_limit_rad)
    }

    /// The control that drives `car`'s pass of the other car of `pair`, which drifts across
    /// the track at `drift_mps`, instead of `control`; None when the policy drives. A pass keeps
    /// the side it started on while the other car stays straight ahead.
    pub fn pass(
        &mut self,
        track: &Track,
        car: OwnCar,
        (mut pair, drift_mps): (Pair, f32),
        control: Control,
        steering_limit_rad: f64,
    ) -> Option<Control> {
        pair.other_offset_m = drifted_offset(&pair, drift_mps, &self.body);
        let advice = crate::pass_advice::advise_passing(&pair, &self.body, MARGIN_M, HOLD_M, self.side);
        self.side = match advice {
            Some(Advice::Line(o)) => Some(o > pair.other_offset_m),
            Some(Advice::Follow(_)) => self.side,
            None => None,
        };
        let plan = Plan {
            track,
            limits: &self.limits,
            body: &self.body,
        };
        Some(plan.apply(car, advice?, control, steering_limit_rad, LOOKAHEAD_M))
    }

    /// As [`Passer::control`], from what a drive's frame carries: the pose on the map
    /// (`frame.gps`), the forward speed (`frame.imu`) and the scan, whose rays are placed on the
    /// map from the pose and the LiDAR's mount `lidar_b` on the base where the frame does not
    /// place them (a car's scans). None also when the frame lacks one of these.
    pub fn control_on_frame(
        &mut self,
        track: &Track,
        frame: &SensorFrame,
        lidar_b: &Pose3,
        control: Control,
        steering_limit_rad: f64,
    ) -> Option<Control> {
        let gps = frame.gps.as_ref()?;
        let speed_mps = crate::drivers::measured_speed_mps(frame)? as f32;
        let pose = PlanarPose {
            x_m: gps.position_m[0] as f32,
            y_m: gps.position_m[1] as f32,
            yaw_rad: gps.rpy_rad[2] as f32,
        };
        let scan = frame.scan.as_ref().map(|s| {
            if s.points_w.len() == s.ranges.len() {
                std::borrow::Cow::Borrowed(s)
            } else {
                let mut placed = s.clone();
                placed.points_w = scan_points_w(s, pose, lidar_b);
                std::borrow::Cow::Owned(placed)
            }
        });
        let car = OwnCar { pose, speed_mps };
        self.control(track, car, scan.as_deref(), frame.stamp_s, control, steering_limit_rad)
    }
}

/// Where the car's body ends behind and ahead of its base along x, metres (a car of wheels
/// alone: its axles).
pub fn body_x_m(model: &agvrl_sim::vehicle::VehicleModel) -> (f32, f32) {
    model
        .body_bounds_m()
        .map_or((0.0, model.wheelbase_m), |(lo, hi)| (lo[0], hi[0]))
}

/// Each ray's end point on the map of a car at `pose` whose LiDAR sits at `lidar_b` on its
/// base, in the plane of the track.
pub fn scan_points_w(scan: &LaserScan, pose: PlanarPose, lidar_b: &Pose3) -> Vec<[f32; 3]> {
    let mount_yaw = lidar_b.yaw_rad();
    let (sn, cs) = pose.yaw_rad.sin_cos();
    let [mx, my, mz] = lidar_b.position_m;
    let (ox, oy) = (pose.x_m + mx * cs - my * sn, pose.y_m + mx * sn + my * cs);
    (0..scan.ranges.len())
        .map(|k| {
            let a = pose.yaw_rad + mount_yaw + scan.angle_min + k as f32 * scan.angle_increment;
            let r = scan.ranges[k];
            [ox + r * a.cos(), oy + r * a.sin(), mz]
        })
        .collect()
}

/// What a pass is planned on: the track, and both cars' body and this car's limits.
pub struct Plan<'a> {
    /// The track.
    pub track: &'a Track,
    /// This car's limits (its wheelbase steers the line, its drive the throttle).
    pub limits: &'a CarLimits,
    /// Both cars' body.
    pub body: &'a Body,
}

impl Plan<'_> {
    /// `control` with `advice` applied: steering by pure pursuit of the advised line
    /// `lookahead_m` down the track, or the throttle capped to follow.
    pub fn apply(
        &self,
        car: OwnCar,
        advice: Advice,
        control: Control,
        steering_limit_rad: f64,
        lookahead_m: f32,
    ) -> Control {
        let (p, limit) = (car.pose, steering_limit_rad);
        match advice {
            Advice::Line(offset_m) => {
                let s = self.track.centreline_s(p.x_m, p.y_m);
                let ([cx, cy], [dx, dy]) = self.track.centreline_at(s + lookahead_m);
                let (tx, ty) = (cx + offset_m * dy, cy - offset_m * dx);
                let (sn, cs) = p.yaw_rad.sin_cos();
                let rear = self.limits.rear_axle_x_m as f32;
                let (ax, ay) = (p.x_m + rear * cs, p.y_m + rear * sn);
                let alpha = (ty - ay).atan2(tx - ax) - p.yaw_rad;
                let d = (tx - ax).hypot(ty - ay).max(1e-3);
                let curvature = 2.0 * f64::from(alpha.sin()) / f64::from(d);
                Control {
                    steering_rad: (self.limits.wheelbase_m * curvature).atan().clamp(-limit, limit),
                    ..control
                }
            }
            Advice::Follow(v) => Control {
                throttle: control
                    .throttle
                    .min(self.limits.throttle(f64::from(v), Some(f64::from(car.speed_mps)), 1.0)),
                ..control
            },
        }
    }
}

/// The other car as a passer knows it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Other {
    /// Its base ahead of this car's along the centre line, metres.
    pub ahead_m: f32,
    /// Its offset from the centre line, metres, positive on the right.
    pub offset_m: f32,
    /// Its speed along the track, m/s.
    pub speed_mps: f32,
    /// How fast its offset grows, m/s.
    pub drift_mps: f32,
}

/// The nearest car ahead in `scan`, as (its base ahead of this car's along the centre line,
/// its offset, the along-track distances and offsets of its points); None when none shows.
///
/// Scan points inside the walls and up to [`SEE_AHEAD_M`] ahead, in runs of neighbouring rays,
/// are a car when a run holds two points or more and does not touch the scan's edge (where the
/// car may go on out of sight).
pub fn detect(track: &Track, pose: PlanarPose, scan: &LaserScan) -> Option<(f32, f32)> {
    let lap = track.lap_length_m();
    let s0 = track.centreline_s(pose.x_m, pose.y_m);
    // (ray, along, offset, point)
    let mut pts: Vec<(usize, f32, f32, [f32; 3])> = Vec::new();
    for k in 0..scan.ranges.len() {
        let Some(&w) = scan.points_w.get(k) else { break };
        // Beyond this range no point lies within SEE_AHEAD_M along the track: tracks are
        // narrower than 4 m.
        if !scan.hit_at(k) || scan.ranges[k] > SEE_AHEAD_M + 2.0 {
            continue;
        }
        let (s, off) = track.place_near_m(w[0], w[1], s0, SEE_AHEAD_M + 4.0);
        let Some(half) = track.clearance_at_m(s) else { continue };
        if off.abs() > half - WALL_BAND_M {
            continue;
        }
        let d = wrap(s - s0, lap);
        if d > 0.0 && d <= SEE_AHEAD_M {
            pts.push((k, d, off, w));
        }
    }
    let mut best: Option<(f32, f32)> = None;
    let mut start = 0;
    while start < pts.len() {
        let mut end = start + 1;
        while end < pts.len() {
            let (a, b) = (pts[end - 1].3, pts[end].3);
            if pts[end].0 - pts[end - 1].0 > 2 || (a[0] - b[0]).hypot(a[1] - b[1]) > CLUSTER_GAP_M {
                break;
            }
            end += 1;
        }
        let run = &pts[start..end];
        let at_edge = run[0].0 == 0 || run[run.len() - 1].0 + 1 >= scan.ranges.len();
        if run.len() >= 2 && !at_edge {
            let nearest = run.iter().map(|q| q.1).fold(f32::MAX, f32::min);
            let offset = run.iter().map(|q| q.2).sum::<f32>() / run.len() as f32;
            let base = nearest + REAR_TO_BASE_M;
            if best.is_none_or(|b| base < b.0) {
                best = Some((base, offset));
            }
        }
        start = end;
    }
    best
}

/// Follows the car ahead through this car's scans: its place along the track, unwrapped, its
/// offset, and its speed and drift fitted over the last [`FIT_WINDOW_S`] of sightings. Out of
/// the scan (beside this car) its place is predicted at that speed.
#[derive(Clone, Debug, Default)]
pub struct ScanTracker {
    /// This car's centre-line place: (as the track gives it, unwrapped).
    own: Option<(f32, f64)>,
    /// (unwrapped place, offset, speed, drift, last seen, last updated)
    other: Option<(f64, f32, f32, f32, f64, f64)>,
    /// Timed sightings: (time, unwrapped place, offset).
    sightings: Vec<(f64, f64, f32)>,
}

impl ScanTracker {
    /// Forget everything (a new race).
    pub fn reset(&mut self) {
        *self = Self::default();
    }

    /// Take in a scan at `now_s`, this car at `pose` running at `speed_mps`, and say where
    /// the other car is; None when no car is followed, or it is more than `behind_m` behind.
    pub fn update(
        &mut self,
        track: &Track,
        pose: PlanarPose,
        speed_mps: f32,
        scan: Option<&LaserScan>,
        now_s: f64,
        behind_m: f32,
    ) -> Option<Other> {
        let lap = track.lap_length_m();
        let s = track.centreline_s(pose.x_m, pose.y_m);
        let own = match self.own {
            Some((prev, at)) => at + f64::from(wrap(s - prev, lap)),
            None => f64::from(s),
        };
        self.own = Some((s, own));
        match scan.and_then(|scan| detect(track, pose, scan)) {
            Some((ahead, offset)) => {
                let at = own + f64::from(ahead);
                if ahead > TIMED_FROM_M {
                    self.sightings.push((now_s, at, offset));
                }
                self.sightings.retain(|h| now_s - h.0 <= FIT_WINDOW_S);
                let (speed, drift) = match fit(&self.sightings) {
                    Some((speed, drift)) => (speed.clamp(0.0, 3.0) as f32, drift.clamp(-1.5, 1.5) as f32),
                    // Not yet timed: taken at this car's speed, so no pass is planned yet.
                    None => self.other.map_or((speed_mps, 0.0), |o| (o.2, o.3)),
                };
                self.other = Some((at, offset, speed, drift, now_s, now_s));
            }
            None => {
                let (at, offset, speed, drift, seen, last) = self.other?;
                if now_s - seen > KEEP_S {
                    self.other = None;
                    return None;
                }
                let at = at + f64::from(speed) * (now_s - last);
                self.other = Some((at, offset, speed, drift, seen, now_s));
            }
        }
        let (at, offset, speed, drift, _, _) = self.other?;
        let ahead = (at - own) as f32;
        if ahead < -behind_m || ahead > SEE_AHEAD_M {
            self.other = None;
            return None;
        }
        Some(Other {
            ahead_m: ahead,
            offset_m: offset,
            speed_mps: speed,
            drift_mps: drift,
        })
    }
}

/// The slopes of place and offset against time, over at least 0.15 s of sightings.
fn fit(h: &[(f64, f64, f32)]) -> Option<(f64, f64)> {
    let span = h.last()?.0 - h.first()?.0;
    if span < 0.15 {
        return None;
    }
    let n = h.len() as f64;
    let mt = h.iter().map(|x| x.0).sum::<f64>() / n;
    let ms = h.iter().map(|x| x.1).sum::<f64>() / n;
    let mo = h.iter().map(|x| f64::from(x.2)).sum::<f64>() / n;
    let var = h.iter().map(|x| (x.0 - mt).powi(2)).sum::<f64>().max(1e-9);
    let speed = h.iter().map(|x| (x.0 - mt) * (x.1 - ms)).sum::<f64>() / var;
    let drift = h.iter().map(|x| (x.0 - mt) * (f64::from(x.2) - mo)).sum::<f64>() / var;
    Some((speed, drift))
}

/// Where the other car will stand across the track by the time this car is 0.5 m clear of it
/// (at most [`DRIFT_HORIZON_S`] ahead), when it drifts towards this car's side; where it is
/// otherwise. Kept inside the walls.
pub fn drifted_offset(p: &crate::pass_advice::Pair, drift_mps: f32, body: &crate::pass_advice::Body) -> f32 {
    let closing = (p.speed_mps - p.other_speed_mps).max(0.05);
    let t = ((p.ahead_m + body.length_m + 0.5) / closing).clamp(0.0, DRIFT_HORIZON_S);
    let towards = drift_mps * (p.offset_m - p.other_offset_m) > 0.0;
    if !towards {
        return p.other_offset_m;
    }
    let limit = (p.half_width_m - body.half_width_m).max(0.0);
    (p.other_offset_m + drift_mps * t).clamp(-limit, limit)
}

/// An along-track difference on a lap of `lap` metres, wrapped into [-lap/2, lap/2).
fn wrap(d: f32, lap: f32) -> f32 {
    let d = d.rem_euclid(lap);
    if d >= 0.5 * lap { d - lap } else { d }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pass_advice::{Body, Pair};

    const BODY: Body = Body {
        length_m: 0.6,
        half_width_m: 0.13,
    };

    /// 1 m behind, closing at 0.5 m/s: clear of the other car in 4.2 s, so its drift is carried
    /// the full second, and only when it heads towards this car's side; never into a wall.
    #[test]
    fn only_a_drift_towards_the_car_moves_the_other_cars_place() {
        let p = Pair {
            ahead_m: 1.0,
            offset_m: -0.4,
            other_offset_m: 0.0,
            speed_mps: 1.8,
            other_speed_mps: 1.3,
            half_width_m: 1.0,
        };
        assert!((drifted_offset(&p, -0.3, &BODY) + 0.3).abs() < 1e-6);
        assert_eq!(drifted_offset(&p, 0.3, &BODY), 0.0);
        assert!((drifted_offset(&p, -1.5, &BODY) + 0.87).abs() < 1e-6);
        // Nearly clear: 0.1 s to go.
        let late = Pair { ahead_m: -1.05, ..p };
        assert!((drifted_offset(&late, -0.3, &BODY) + 0.03).abs() < 1e-5);
    }

    /// Differences along the lap wrap to the nearer way round.
    #[test]
    fn along_track_differences_wrap_to_half_a_lap() {
        assert_eq!(wrap(1.0, 10.0), 1.0);
        assert_eq!(wrap(9.0, 10.0), -1.0);
        assert_eq!(wrap(-9.5, 10.0), 0.5);
        assert_eq!(wrap(5.0, 10.0), -5.0);
    }
}
