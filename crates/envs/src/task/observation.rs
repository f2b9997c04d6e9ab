//! How a frame becomes the observation vector: LiDAR ranges (scaled), speed, yaw rate, the
//! applied steering and throttle, the explored-ground memory, free lengths along steering arcs,
//! and camera channels, as `ObsConfig` composes them.

use super::explored::{ExploredMemory, ExploredObs};
use crate::api::{BoxSpace, SensorFrame, SensorNeeds};
use agvrl_sim::msg::LaserScan;
use serde::{Deserialize, Serialize};

/// How LiDAR ranges enter the observation.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RangeScale {
    /// Metres, as AutoVRL.
    Raw,
    /// Divided by the LiDAR's range_max, in [0, 1].
    #[default]
    Normalised,
    /// Not in the observation (a camera-driven policy); the task may still read the scan for
    /// its reward and termination.
    Off,
}

/// Composition of the observation vector: the LiDAR ranges, then the enabled extras in this
/// order (speed / 2 m/s, yaw rate / 2 rad/s, steering / limit, throttle, the explored-ground
/// fractions, the arcs' free lengths, the reverse arcs' free lengths, camera channels).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ObsConfig {
    /// How ranges are scaled.
    pub ranges: RangeScale,
    /// Forward speed from the IMU's velocity estimate.
    pub speed: bool,
    /// Yaw rate from the gyroscope.
    pub yaw_rate: bool,
    /// The steering angle in force.
    pub steering: bool,
    /// The throttle in force.
    pub throttle: bool,
    /// The unexplored fraction of the ground around the car, by sector and ring (search only;
    /// needs the GPS / pose fix).
    pub explored: ExploredObs,
    /// Free lengths along steering arcs, from the LiDAR (left out of the settings when off, so
    /// a policy file written without them reads the same).
    #[serde(skip_serializing_if = "ArcObs::is_empty")]
    pub arcs: ArcObs,
    /// Free lengths along reverse arcs, from the points the LiDAR saw in the last seconds
    /// (search only; left out of the settings when off).
    #[serde(skip_serializing_if = "RearObs::is_empty")]
    pub rear: RearObs,
    /// The scans of a few steps before, pooled (left out of the settings when off).
    #[serde(skip_serializing_if = "PastScans::is_empty")]
    pub past_scans: PastScans,
    /// Camera channels appended after everything else (needs the vehicle camera).
    pub image: ImageObs,
}

/// Free path lengths along arcs (`[env_config.observation.arcs]`): for `n` steering angles
/// evenly from full left to full right, how far the car could drive along that arc before a
/// LiDAR return comes within `half_width_m` of its path, over `max_m` (1: free that far). The
/// ranges hold the same distances; these are the form a stopping decision reads. The arcs start
/// at the LiDAR and bend with curvature tan(steering) / `wheelbase_m` (the bicycle model with
/// its rear axle taken at the LiDAR: an approximation, the same on the car as in training).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ArcObs {
    /// Arcs (0: off); one arc is straight ahead.
    pub n: usize,
    /// A return this close to the arc's centre line blocks it, metres (half the car's width
    /// and a margin).
    pub half_width_m: f32,
    /// Wheelbase of the bicycle model, metres.
    pub wheelbase_m: f32,
    /// The length that reads 1, metres.
    pub max_m: f32,
    /// 0: a return within `half_width_m` of the centre line blocks the arc. Positive: the arc
    /// is free until a return would come this close inside `too_close_fov_deg` ahead of the car
    /// driving along it, the search task's `too_close` termination (0.6 m over 90 degrees);
    /// `half_width_m` is then unused. A return beside the car that the turn never brings into
    /// that cone blocks nothing.
    #[serde(skip_serializing_if = "is_zero")]
    pub too_close_m: f32,
    /// The cone of `too_close_m`, degrees, centred ahead.
    #[serde(skip_serializing_if = "is_ninety")]
    pub too_close_fov_deg: f32,
}

fn is_zero(v: &f32) -> bool {
    *v == 0.0
}

fn is_ninety(v: &f32) -> bool {
    *v == 90.0
}

/// The step along an arc at which `too_close_m` arcs check the cone, metres.
const TOO_CLOSE_STEP_M: f32 = 0.05;

impl Default for ArcObs {
    /// Off; XTENTH-CAR's geometry (0.33 m wheelbase, 0.30 m wide) with 0.1 m of margin.
    fn default() -> Self {
        Self {
            n: 0,
            half_width_m: 0.25,
            wheelbase_m: 0.33,
            max_m: 4.0,
            too_close_m: 0.0,
            too_close_fov_deg: 90.0,
        }
    }
}

impl ArcObs {
    /// Values appended.
    pub fn len(&self) -> usize {
        self.n
    }

    /// Whether it is off.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// An error for settings that cannot work.
    pub fn validate(&self) -> Result<(), agvrl_sim::InvalidSetting> {
        let positive = |v: f32| v.is_finite() && v > 0.0;
        let cone = self.too_close_m == 0.0
            || (positive(self.too_close_m) && self.too_close_fov_deg > 0.0 && self.too_close_fov_deg < 180.0);
        if self.n <= 32 && positive(self.half_width_m) && positive(self.wheelbase_m) && positive(self.max_m) && cone {
            Ok(())
        } else {
            Err(agvrl_sim::InvalidSetting::new(
                "observation.arcs",
                format!(
                    "observation.arcs needs n <= 32, positive half_width_m, wheelbase_m, max_m, and too_close_m 0 or positive with too_close_fov_deg in (0, 180); got {self:?}"
                ),
            ))
        }
    }

    /// The free length along the arc of curvature `c` (1/m, positive left) among `points`
    /// (x ahead, y left, metres, from the arc's start), at most `max_m`.
    pub fn free_length(&self, c: f32, points: impl Iterator<Item = (f32, f32)>) -> f32 {
        if self.too_close_m > 0.0 {
            return self.free_length_to_too_close(c, points);
        }
        let (w, mut free) = (self.half_width_m, self.max_m);
        if c.abs() < 1e-4 {
            for (x, y) in points {
                if x > 0.0 && y.abs() < w {
                    free = free.min(x);
                }
            }
            return free;
        }
        // The centre of the turn is (0, r); the angle about it from the start, in the direction
        // of travel, times the radius is the length driven to pass the point.
        let r = 1.0 / c;
        for (x, y) in points {
            if ((y - r).hypot(x) - r.abs()).abs() >= w {
                continue;
            }
            let turned = if r > 0.0 { x.atan2(r - y) } else { x.atan2(y - r) };
            free = free.min(turned.rem_euclid(std::f32::consts::TAU) * r.abs());
        }
        free
    }

    /// `free_length` for `too_close_m` arcs: the first pose along the arc, every
    /// `TOO_CLOSE_STEP_M`, at which a point lies within `too_close_m` and inside the cone ahead
    /// (so at most one step past the exact length; the cone's edge is widened by a step, so a
    /// return up to about a step outside it may block). Only the poses within `too_close_m` of
    /// a point are checked for it.
    fn free_length_to_too_close(&self, c: f32, points: impl Iterator<Item = (f32, f32)>) -> f32 {
        let (reach, ds) = (self.too_close_m, TOO_CLOSE_STEP_M);
        let tan_half = (0.5 * self.too_close_fov_deg).to_radians().tan();
        let n = (self.max_m / ds).floor() as usize;
        // Poses after j steps: position and heading (cos, sin), by rotating one step at a time.
        let (sd, cd) = (ds * c).sin_cos();
        let mut poses = Vec::with_capacity(n + 1);
        let (mut cs, mut sn) = (1.0_f32, 0.0_f32);
        for j in 0..=n {
            let (x, y) = if c.abs() < 1e-4 {
                (j as f32 * ds, 0.0)
            } else {
                (sn / c, (1.0 - cs) / c)
            };
            poses.push((x, y, cs, sn));
            (cs, sn) = (cs * cd - sn * sd, sn * cd + cs * sd);
        }
        let mut free = self.max_m;
        for (px, py) in points {
            // The arc lengths at which the car is within reach of the point.
            let (lo, hi) = if c.abs() < 1e-4 {
                if py.abs() >= reach {
                    continue;
                }
                (px - reach, px + reach)
            } else {
                let r = 1.0 / c;
                let rho = (py - r).hypot(px);
                let k = (rho * rho + r * r - reach * reach) / (2.0 * rho * r.abs());
                if k >= 1.0 {
                    continue;
                }
                let turned = if r > 0.0 { px.atan2(r - py) } else { px.atan2(py - r) };
                let turned = turned.rem_euclid(std::f32::consts::TAU);
                let beta = k.max(-1.0).acos();
                ((turned - beta) * r.abs(), (turned + beta) * r.abs())
            };
            let first = (lo.max(0.0) / ds).ceil() as usize;
            let last = ((hi.min(free) / ds).floor() as usize).min(n);
            for (j, &(x, y, cs, sn)) in poses.iter().enumerate().take(last + 1).skip(first) {
                let (dx, dy) = (px - x, py - y);
                let (qx, qy) = (cs * dx + sn * dy, cs * dy - sn * dx);
                // The cone's edge widened by one step, so that a pass through the cone shorter
                // than a step is not missed between two poses.
                if qx > 0.0 && qx * qx + qy * qy < reach * reach && qy.abs() <= (qx + ds) * tan_half {
                    free = free.min(j as f32 * ds);
                    break;
                }
            }
        }
        free
    }

    fn append(&self, scan: Option<&LaserScan>, steering_limit_rad: f64, out: &mut Vec<f32>) {
        let Some(s) = scan else {
            out.extend(std::iter::repeat_n(0.0, self.n));
            return;
        };
        let points: Vec<(f32, f32)> = s
            .ranges
            .iter()
            .enumerate()
            .filter(|&(k, &r)| r.is_finite() && s.hit_at(k))
            .map(|(k, &r)| {
                let (sa, ca) = s.bearing(k).sin_cos();
                (r * ca, r * sa)
            })
            .collect();
        for k in 0..self.n {
            let steer = match self.n {
                1 => 0.0,
                n => steering_limit_rad as f32 * (1.0 - 2.0 * k as f32 / (n - 1) as f32),
            };
            let c = steer.tan() / self.wheelbase_m;
            out.push(self.free_length(c, points.iter().copied()) / self.max_m);
        }
    }
}

/// Which camera channels enter the observation.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ImageChannels {
    /// No image.
    #[default]
    None,
    /// Depth only.
    Depth,
    /// RGB only.
    Rgb,
    /// Depth, then RGB.
    DepthRgb,
}

/// The camera part of the observation: the frame resampled (nearest pixel) to `width` x
/// `height`, flattened channel-major (`[C, H, W]`, depth first), every value in [0, 1] (depth /
/// `depth_max_m`, a pixel without a depth reading 0; colour / 255), ready for a CNN encoder.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ImageObs {
    /// Channels.
    pub channels: ImageChannels,
    /// Width after resampling, pixels.
    pub width: u32,
    /// Height after resampling, pixels.
    pub height: u32,
    /// Depth that maps to 1, metres (farther reads 1).
    pub depth_max_m: f32,
}

impl Default for ImageObs {
    fn default() -> Self {
        Self {
            channels: ImageChannels::None,
            width: 64,
            height: 48,
            depth_max_m: 12.0,
        }
    }
}

impl ImageObs {
    fn n_channels(&self) -> usize {
        match self.channels {
            ImageChannels::None => 0,
            ImageChannels::Depth => 1,
            ImageChannels::Rgb => 3,
            ImageChannels::DepthRgb => 4,
        }
    }

    /// Number of values appended.
    pub fn len(&self) -> usize {
        self.n_channels() * self.width as usize * self.height as usize
    }

    /// Whether no image enters the observation.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    fn append(&self, img: Option<&agvrl_sim::msg::CameraFrame>, out: &mut Vec<f32>) {
        let n = self.len();
        let Some(img) = img.filter(|i| i.width > 0 && i.height > 0) else {
            out.extend(std::iter::repeat_n(0.0, n));
            return;
        };
        let (w, h) = (self.width as usize, self.height as usize);
        let (sw, sh) = (img.width as usize, img.height as usize);
        let src = |x: usize, y: usize| ((y * sh + sh / 2) / h).min(sh - 1) * sw + ((x * sw + sw / 2) / w).min(sw - 1);
        let depth = matches!(self.channels, ImageChannels::Depth | ImageChannels::DepthRgb);
        let rgb = matches!(self.channels, ImageChannels::Rgb | ImageChannels::DepthRgb);
        // No reading (NaN: a hole, or nearer than the camera's minimum range) reads 0, as in a
        // 16-bit depth image.
        let scaled = |z: f32| {
            if z.is_nan() {
                0.0
            } else {
                (z / self.depth_max_m).clamp(0.0, 1.0)
            }
        };
        if depth && (sw, sh) == (w, h) && img.depth_m.len() == w * h {
            // A camera rendered at the observation's size: no resampling.
            out.extend(img.depth_m.iter().map(|z| scaled(*z)));
        } else if depth {
            for y in 0..h {
                for x in 0..w {
                    out.push(scaled(img.depth_m.get(src(x, y)).copied().unwrap_or(self.depth_max_m)));
                }
            }
        }
        if rgb {
            for c in 0..3 {
                for y in 0..h {
                    for x in 0..w {
                        out.push(img.rgb.get(3 * src(x, y) + c).copied().unwrap_or(0) as f32 / 255.0);
                    }
                }
            }
        }
    }
}

/// Free reverse lengths (`[env_config.observation.rear]`): for `n` steering angles evenly from
/// full left to full right (one: straight), how far the car could reverse along that arc, over
/// `max_m`. The LiDAR does not see behind the car, so the lengths come from the safety filter's
/// memory of scan points (by odometry, the last `reverse_memory_s`) and its reverse check: the
/// body with its margin keeps off every remembered point, and the car never reverses farther
/// than it drove forward (0 at a spawn). The same memory and check on the car as in training.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RearObs {
    /// Reverse arcs (0: off).
    pub n: usize,
    /// Longest length looked at, metres (at most the 3 m the filter ever reverses).
    pub max_m: f32,
}

impl Default for RearObs {
    fn default() -> Self {
        Self { n: 0, max_m: 1.5 }
    }
}

impl RearObs {
    /// Values appended.
    pub fn len(&self) -> usize {
        self.n
    }

    /// Whether it is off.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// The steering angles of the arcs, full left (positive) to full right.
    pub fn steerings(&self, steering_limit_rad: f64) -> Vec<f32> {
        match self.n {
            0 => vec![],
            1 => vec![0.0],
            n => (0..n)
                .map(|k| (steering_limit_rad * (1.0 - 2.0 * k as f64 / (n - 1) as f64)) as f32)
                .collect(),
        }
    }

    /// An error for settings that cannot work.
    pub fn validate(&self) -> Result<(), agvrl_sim::InvalidSetting> {
        if self.n <= 9 && self.max_m.is_finite() && self.max_m > 0.0 && self.max_m <= 3.0 {
            Ok(())
        } else {
            Err(agvrl_sim::InvalidSetting::new(
                "observation.rear",
                format!("observation.rear needs n <= 9 and max_m in (0, 3]; got {self:?}"),
            ))
        }
    }
}

/// The scans of earlier steps (`[env_config.observation.past_scans]`): those `every`, 2 x
/// `every`, ... `n` x `every` control steps before the current one, each pooled to its nearest
/// return over `pool` neighbouring rays and divided by range_max, in the car's frame of their
/// time. Memory for a driver that has lost sight of a wall it is turning round. At an episode's
/// start every past scan is the first one.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PastScans {
    /// Past scans (0: off).
    pub n: usize,
    /// Control steps between them.
    pub every: usize,
    /// Neighbouring rays pooled into one value (the last group may hold fewer).
    pub pool: usize,
}

impl Default for PastScans {
    fn default() -> Self {
        Self {
            n: 0,
            every: 5,
            pool: 4,
        }
    }
}

impl PastScans {
    /// Values appended for a LiDAR of `n_rays` rays.
    pub fn len(&self, n_rays: usize) -> usize {
        self.n * n_rays.div_ceil(self.pool.max(1))
    }

    /// Whether it is off.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// An error for settings that cannot work.
    pub fn validate(&self) -> Result<(), agvrl_sim::InvalidSetting> {
        if self.n <= 8 && (1..=100).contains(&self.every) && self.pool >= 1 {
            Ok(())
        } else {
            Err(agvrl_sim::InvalidSetting::new(
                "observation.past_scans",
                format!("observation.past_scans needs n <= 8, every in [1, 100] and pool >= 1; got {self:?}"),
            ))
        }
    }

    fn pooled(&self, scan: Option<&LaserScan>) -> Vec<f32> {
        let Some(scan) = scan else { return vec![] };
        scan.ranges
            .chunks(self.pool.max(1))
            .map(|c| (c.iter().fold(f32::INFINITY, |m, r| m.min(*r)) / scan.range_max).clamp(0.0, 1.0))
            .collect()
    }
}

/// The pooled scans [`PastScans`] reads, oldest first, as a task keeps them.
#[derive(Clone, Debug, Default)]
pub struct ScanHistory {
    cfg: PastScans,
    scans: std::collections::VecDeque<Vec<f32>>,
}

impl ScanHistory {
    /// An empty history for `cfg`.
    pub fn new(cfg: PastScans) -> Self {
        Self {
            cfg,
            scans: Default::default(),
        }
    }

    /// Start an episode: every past scan is this frame's.
    pub fn reset(&mut self, frame: &SensorFrame) {
        self.scans.clear();
        if self.cfg.is_empty() {
            return;
        }
        let now = self.cfg.pooled(frame.scan.as_ref());
        self.scans
            .extend(std::iter::repeat_n(now, self.cfg.n * self.cfg.every + 1));
    }

    /// Take in the frame of a step.
    pub fn push(&mut self, frame: &SensorFrame) {
        if self.cfg.is_empty() {
            return;
        }
        if self.scans.len() > self.cfg.n * self.cfg.every {
            self.scans.pop_front();
        }
        self.scans.push_back(self.cfg.pooled(frame.scan.as_ref()));
    }

    fn append(&self, width: usize, out: &mut Vec<f32>) {
        let last = self.scans.len().wrapping_sub(1);
        for k in 1..=self.cfg.n {
            match self.scans.get(last.wrapping_sub(k * self.cfg.every)) {
                Some(s) if s.len() * self.cfg.n == width => out.extend(s),
                _ => out.extend(std::iter::repeat_n(1.0, width / self.cfg.n)),
            }
        }
    }
}

impl Default for ObsConfig {
    /// Normalised ranges plus speed, yaw rate, steering and throttle.
    fn default() -> Self {
        Self {
            ranges: RangeScale::Normalised,
            speed: true,
            yaw_rate: true,
            steering: true,
            throttle: true,
            explored: ExploredObs::default(),
            arcs: ArcObs::default(),
            rear: RearObs::default(),
            past_scans: PastScans::default(),
            image: ImageObs::default(),
        }
    }
}

impl ObsConfig {
    /// AutoVRL's observation: the raw LiDAR ranges only.
    pub fn paper() -> Self {
        Self {
            ranges: RangeScale::Raw,
            speed: false,
            yaw_rate: false,
            steering: false,
            throttle: false,
            explored: ExploredObs::default(),
            arcs: ArcObs::default(),
            rear: RearObs::default(),
            past_scans: PastScans::default(),
            image: ImageObs::default(),
        }
    }

    fn n_extra(&self) -> usize {
        [self.speed, self.yaw_rate, self.steering, self.throttle]
            .iter()
            .filter(|b| **b)
            .count()
    }

    /// Needs of this composition.
    pub fn needs(&self) -> SensorNeeds {
        SensorNeeds {
            scan: true,
            imu: self.speed || self.yaw_rate || !self.rear.is_empty(),
            gps: !self.explored.is_empty(),
            image: !self.image.is_empty(),
        }
    }

    /// The space for `n_rays` rays of range `range_max_m`.
    pub fn space(&self, n_rays: usize, range_max_m: f32) -> BoxSpace {
        let (n_rays, hi) = match self.ranges {
            RangeScale::Raw => (n_rays, range_max_m),
            RangeScale::Normalised => (n_rays, 1.0),
            RangeScale::Off => (0, 1.0),
        };
        let mut s = BoxSpace::uniform(n_rays, 0.0, hi);
        for (on, lo, hi) in [
            (self.speed, -5.0, 5.0),
            (self.yaw_rate, -5.0, 5.0),
            (self.steering, -1.0, 1.0),
            (self.throttle, 0.0, 1.0),
        ] {
            if on {
                s.low.push(lo);
                s.high.push(hi);
            }
        }
        let n01 = self.explored.len() + self.arcs.len() + self.rear.len() + self.image.len();
        let n01 = n01 + self.past_scans.len(n_rays);
        s.low.extend(std::iter::repeat_n(0.0, n01));
        s.high.extend(std::iter::repeat_n(1.0, n01));
        s
    }

    /// The observation's parts in order, each with its name and width, for `n_rays` rays.
    pub fn layout(&self, n_rays: usize) -> Vec<(&'static str, usize)> {
        let rays = if self.ranges == RangeScale::Off { 0 } else { n_rays };
        let mut parts = vec![("ranges", rays)];
        for (on, name) in [
            (self.speed, "speed"),
            (self.yaw_rate, "yaw_rate"),
            (self.steering, "steering"),
            (self.throttle, "throttle"),
        ] {
            parts.push((name, on as usize));
        }
        parts.extend(self.explored.layout());
        parts.push(("arcs", self.arcs.len()));
        parts.push(("rear", self.rear.len()));
        parts.push(("past_scans", self.past_scans.len(n_rays)));
        parts.push(("image", self.image.len()));
        parts.retain(|p| p.1 > 0);
        parts
    }

    /// The indices of this observation's inputs that `before` (on the same LiDAR) lacks, or why
    /// a network that read `before` cannot read this one: each part of `before` must be here,
    /// as wide and in the same order.
    pub fn inputs_added_since(&self, before: &ObsConfig, n_rays: usize) -> Result<Vec<usize>, String> {
        let (old, new) = (before.layout(n_rays), self.layout(n_rays));
        let mut added = vec![];
        let (mut at, mut k) = (0, 0);
        for &(name, width) in &new {
            match old.get(k) {
                Some(&(o, w)) if o == name && w == width => k += 1,
                Some(&(o, w)) if o == name => {
                    return Err(format!("observation part {name} is {width} wide, it was {w}"));
                }
                Some(&(o, _)) if old[k..].iter().any(|p| p.0 == name) => {
                    return Err(format!("observation part {o} is gone or moved"));
                }
                _ => added.extend(at..at + width),
            }
            at += width;
        }
        match old.get(k) {
            Some((name, _)) => Err(format!("observation part {name} is gone")),
            None => Ok(added),
        }
    }

    /// Build the observation (the frame's needs were checked by the env); `explored` is the
    /// task's memory when `self.explored` is on, `rear` its reverse lengths (over `max_m`) when
    /// `self.rear` is, `past` its scan history when `self.past_scans` is.
    pub fn observe(
        &self,
        frame: &SensorFrame,
        steering_limit_rad: f64,
        explored: Option<&ExploredMemory>,
        rear: Option<&[f32]>,
        past: Option<&ScanHistory>,
    ) -> Vec<f32> {
        let mut out = Vec::new();
        if let Some(scan) = &frame.scan {
            out.reserve(scan.ranges.len() + self.n_extra());
            match self.ranges {
                RangeScale::Raw => out.extend(scan.ranges.iter().map(|r| r.clamp(0.0, scan.range_max))),
                RangeScale::Normalised => out.extend(scan.ranges.iter().map(|r| (r / scan.range_max).clamp(0.0, 1.0))),
                RangeScale::Off => {}
            }
        }
        let imu = frame.imu.as_ref();
        if self.speed {
            out.push((imu.map(|i| i.lin_vel_b[0]).unwrap_or(0.0) / 2.0).clamp(-5.0, 5.0) as f32);
        }
        if self.yaw_rate {
            out.push((imu.map(|i| i.ang_vel_b[2]).unwrap_or(0.0) / 2.0).clamp(-5.0, 5.0) as f32);
        }
        if self.steering {
            out.push((frame.applied.steering_rad / steering_limit_rad).clamp(-1.0, 1.0) as f32);
        }
        if self.throttle {
            out.push(frame.applied.throttle.clamp(0.0, 1.0) as f32);
        }
        if !self.explored.is_empty() {
            match explored {
                Some(m) => m.append(frame, &mut out),
                None => out.extend(std::iter::repeat_n(0.0, self.explored.len())),
            }
        }
        if !self.arcs.is_empty() {
            self.arcs.append(frame.scan.as_ref(), steering_limit_rad, &mut out);
        }
        if !self.rear.is_empty() {
            match rear.filter(|r| r.len() == self.rear.len()) {
                Some(r) => out.extend(r),
                None => out.extend(std::iter::repeat_n(0.0, self.rear.len())),
            }
        }
        if !self.past_scans.is_empty() {
            let n_rays = frame.scan.as_ref().map_or(0, |s| s.ranges.len());
            let width = self.past_scans.len(n_rays);
            match past {
                Some(h) => h.append(width, &mut out),
                None => out.extend(std::iter::repeat_n(1.0, width)),
            }
        }
        if !self.image.is_empty() {
            self.image.append(frame.image.as_ref(), &mut out);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f32::consts::PI;

    fn arcs(n: usize) -> ArcObs {
        ArcObs { n, ..ArcObs::default() }
    }

    /// Straight ahead the free length is the nearest return within the half width; on a turn
    /// of radius R, a return on the arc a quarter turn on is blocked at pi R / 2 (closed form).
    #[test]
    fn an_arc_is_free_up_to_the_first_return_within_its_half_width() {
        let a = arcs(1);
        let pts = [(3.0, 0.1), (2.0, 0.3), (-1.0, 0.0), (5.0, 0.0)];
        assert_eq!(
            a.free_length(0.0, pts.into_iter()),
            3.0,
            "(2, 0.3) passes 0.05 m wide of the car's half width"
        );
        assert_eq!(a.free_length(0.0, [(9.0, 0.0)].into_iter()), a.max_m, "beyond max_m");
        for r in [2.0_f32, -2.0] {
            // A quarter turn left (right) about (0, r) puts the car at (|r|, r).
            let on = (r.abs(), r);
            let s = a.free_length(1.0 / r, [on].into_iter());
            assert!((s - PI * r.abs() / 2.0).abs() < 1e-5, "radius {r}: {s}");
            // The same point mirrored is off the arc (the other side), and a point 0.2 m
            // inside the circle still blocks it, 0.3 m inside does not.
            assert_eq!(a.free_length(1.0 / r, [(r.abs(), -r)].into_iter()), a.max_m);
            let inside = |d: f32| (r.abs() - d, r);
            assert!(a.free_length(1.0 / r, [inside(0.2)].into_iter()) < a.max_m);
            assert_eq!(a.free_length(1.0 / r, [inside(0.3)].into_iter()), a.max_m);
        }
    }

    /// With `too_close_m`, an arc ends where the task would terminate: straight ahead, a return
    /// at (x, y) enters the 0.6 m cone at x - sqrt(0.36 - y^2), but only when |y| < 0.6 / sqrt 2
    /// (closed form); one beside the car never enters it; on a turn of radius R a return on the
    /// arc a quarter turn on is reached when the chord to it is 0.6 m, at R (pi / 2 - 2 asin(0.3
    /// / R)). The sampled length is at most one step past each.
    #[test]
    fn too_close_arcs_end_where_the_termination_cone_would_reach_a_return() {
        let a = ArcObs {
            n: 1,
            too_close_m: 0.6,
            ..ArcObs::default()
        };
        a.validate().unwrap();
        let near = |got: f32, want: f32| (0.0..=TOO_CLOSE_STEP_M + 1e-4).contains(&(got - want));
        for (x, y) in [(3.0_f32, 0.2_f32), (2.0, -0.4), (1.0, 0.0)] {
            let want = x - (0.36 - y * y).sqrt();
            let got = a.free_length(0.0, [(x, y)].into_iter());
            assert!(near(got, want), "({x}, {y}): {got} against {want}");
        }
        // Passes 0.45 m wide: r_m never falls under 0.6 m (a 0.5 m band blocks it).
        assert_eq!(a.free_length(0.0, [(3.0, 0.45)].into_iter()), a.max_m);
        // 0.36 m from the car, 74 degrees to the left: out of the cone, and driving on leaves it so.
        assert_eq!(a.free_length(0.0, [(0.1, 0.35)].into_iter()), a.max_m);
        for r in [2.0_f32, -2.0] {
            let want = r.abs() * (PI / 2.0 - 2.0 * (0.3 / r.abs()).asin());
            let got = a.free_length(1.0 / r, [(r.abs(), r)].into_iter());
            assert!(near(got, want), "radius {r}: {got} against {want}");
            assert_eq!(
                a.free_length(1.0 / r, [(r.abs(), -r)].into_iter()),
                a.max_m,
                "the other side"
            );
        }
        let bad = ArcObs {
            too_close_fov_deg: 180.0,
            ..a
        };
        assert!(bad.validate().is_err());
    }

    /// In the observation: one value per arc, full left first, each in [0, 1], the space's
    /// length; a wall 2 m ahead blocks the straight arc at 2 m and the full-lock arcs later or not
    /// at all; rays without a return block nothing.
    #[test]
    fn arcs_enter_the_observation_left_to_right() {
        let cfg = ObsConfig {
            arcs: arcs(5),
            ..ObsConfig::default()
        };
        cfg.arcs.validate().unwrap();
        let n_rays = 271;
        let inc = 1.5 * PI / (n_rays - 1) as f32;
        let angle = |k: usize| -0.75 * PI + inc * k as f32;
        // A wall across the way at x = 2 m, seen by the rays pointing ahead.
        let ranges: Vec<f32> = (0..n_rays)
            .map(|k| match angle(k).cos() {
                c if c > 0.05 => (2.0 / c).min(12.0),
                _ => 12.0,
            })
            .collect();
        let frame = SensorFrame {
            scan: Some(LaserScan {
                angle_min: angle(0),
                angle_increment: inc,
                range_max: 12.0,
                hit: ranges.iter().map(|&r| r < 12.0).collect(),
                ranges,
                ..LaserScan::default()
            }),
            ..SensorFrame::default()
        };
        let obs = cfg.observe(&frame, 0.36, None, None, None);
        assert_eq!(obs.len(), cfg.space(n_rays, 12.0).dim());
        let tail = &obs[obs.len() - 5..];
        assert!(tail.iter().all(|v| (0.0..=1.0).contains(v)), "{tail:?}");
        assert!((tail[2] - 2.0 / 4.0).abs() < 0.01, "straight ahead: {tail:?}");
        assert!(
            tail[0] > tail[2] && tail[4] > tail[2] && (tail[0] - tail[4]).abs() < 1e-3,
            "{tail:?}"
        );
        let mut open = frame.clone();
        if let Some(s) = open.scan.as_mut() {
            s.hit.iter_mut().for_each(|h| *h = false);
        }
        let obs = cfg.observe(&open, 0.36, None, None, None);
        assert!(obs[obs.len() - 5..].iter().all(|v| *v == 1.0));
        assert!(
            ArcObs {
                n: 40,
                ..ArcObs::default()
            }
            .validate()
            .is_err()
        );
    }
    #[test]
    fn past_scans_are_the_pooled_scans_every_steps_back_and_the_first_at_the_start() {
        let past = PastScans {
            n: 2,
            every: 3,
            pool: 4,
        };
        past.validate().unwrap();
        let cfg = ObsConfig {
            speed: false,
            yaw_rate: false,
            steering: false,
            throttle: false,
            past_scans: past,
            ..ObsConfig::default()
        };
        // Step t's scan: 10 rays, ray k at (t + k) % 10 + 1 metres of range_max 20.
        let frame = |t: usize| SensorFrame {
            scan: Some(LaserScan {
                range_max: 20.0,
                ranges: (0..10).map(|k| ((t + k) % 10 + 1) as f32).collect(),
                ..LaserScan::default()
            }),
            ..SensorFrame::default()
        };
        // Nearest return of each group of 4 rays (the last group holds 2), over range_max.
        let pooled = |t: usize| -> Vec<f32> {
            let r: Vec<f32> = (0..10).map(|k| ((t + k) % 10 + 1) as f32).collect();
            r.chunks(4)
                .map(|c| c.iter().cloned().fold(f32::MAX, f32::min) / 20.0)
                .collect()
        };
        assert_eq!(past.len(10), 6);
        assert_eq!(cfg.layout(10), vec![("ranges", 10), ("past_scans", 6)]);
        assert_eq!(cfg.space(10, 20.0).dim(), 16);
        let mut history = ScanHistory::new(past);
        history.reset(&frame(0));
        let obs = cfg.observe(&frame(0), 0.36, None, None, Some(&history));
        assert_eq!(obs[10..], [pooled(0), pooled(0)].concat());
        for t in 1..=8 {
            history.push(&frame(t));
            let obs = cfg.observe(&frame(t), 0.36, None, None, Some(&history));
            assert_eq!(obs.len(), 16);
            let back = |k: usize| pooled(t.saturating_sub(k));
            assert_eq!(obs[10..], [back(3), back(6)].concat(), "step {t}");
        }
        assert!(PastScans { every: 0, ..past }.validate().is_err());
        let before = ObsConfig {
            past_scans: PastScans::default(),
            ..cfg
        };
        assert_eq!(cfg.inputs_added_since(&before, 10), Ok((10..16).collect()));
    }

    #[test]
    fn inputs_added_since_finds_new_parts_and_refuses_lost_or_resized_ones() {
        let before = ObsConfig {
            explored: ExploredObs {
                sectors: 8,
                ..ExploredObs::default()
            },
            arcs: arcs(9),
            ..ObsConfig::default()
        };
        let rings = before.explored.len();
        let after = ObsConfig {
            explored: ExploredObs {
                stale_s: 10.0,
                ..before.explored
            },
            rear: RearObs { n: 3, max_m: 1.5 },
            ..before
        };
        let wait = 100 + 4 + rings;
        assert_eq!(
            after.inputs_added_since(&before, 100),
            Ok(vec![wait, wait + 10, wait + 11, wait + 12])
        );
        assert_eq!(after.space(100, 12.0).dim(), wait + 13);
        assert_eq!(before.inputs_added_since(&before, 100), Ok(vec![]));
        let no_arcs = ObsConfig {
            arcs: ArcObs::default(),
            ..after
        };
        assert!(no_arcs.inputs_added_since(&before, 100).unwrap_err().contains("arcs"));
        let wider = ObsConfig { arcs: arcs(5), ..after };
        assert!(wider.inputs_added_since(&before, 100).unwrap_err().contains("wide"));
        let no_speed = ObsConfig { speed: false, ..after };
        assert!(no_speed.inputs_added_since(&before, 100).unwrap_err().contains("speed"));
    }
}
