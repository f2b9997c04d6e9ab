//! Tasks turn a `SensorFrame` into observation, reward and termination: the same code in
//! simulation and on the car.

mod action;
pub mod racing;
pub mod reward;
pub mod search;

use crate::api::{BoxSpace, Control, MapInfo, RewardTerms, SensorFrame, SensorNeeds, TerminationCause};
pub use action::ActionMapping;
use serde::{Deserialize, Serialize};

pub use racing::Racing;
pub use reward::{SafeShaping, SearchReward};
pub use search::Search;

/// What a task concluded about one step.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Outcome {
    /// Reward parts (sum = reward).
    pub terms: RewardTerms,
    /// Why the episode ended, if it did.
    pub termination: Option<TerminationCause>,
    /// Racing metrics.
    pub racing: Option<crate::api::RacingInfo>,
    /// Search metrics.
    pub search: Option<crate::api::SearchInfo>,
}

/// A task.
pub trait Task: Send {
    /// Sensors needed every frame.
    fn needs(&self) -> SensorNeeds;
    /// Observation space.
    fn observation_space(&self) -> BoxSpace;
    /// Map a (finite, in-range) action to a control.
    fn control(&self, action: &[f32], steering_limit_rad: f64) -> Control;
    /// Start an episode from its first frame.
    fn reset(&mut self, frame: &SensorFrame, map: Option<&MapInfo>);
    /// The observation of a frame.
    fn observe(&self, frame: &SensorFrame) -> Vec<f32>;
    /// Reward and termination after a step.
    fn evaluate(&mut self, frame: &SensorFrame, map: Option<&MapInfo>) -> Outcome;
}

impl<T: Task + ?Sized> Task for Box<T> {
    fn needs(&self) -> SensorNeeds {
        (**self).needs()
    }
    fn observation_space(&self) -> BoxSpace {
        (**self).observation_space()
    }
    fn control(&self, action: &[f32], steering_limit_rad: f64) -> Control {
        (**self).control(action, steering_limit_rad)
    }
    fn reset(&mut self, frame: &SensorFrame, map: Option<&MapInfo>) {
        (**self).reset(frame, map)
    }
    fn observe(&self, frame: &SensorFrame) -> Vec<f32> {
        (**self).observe(frame)
    }
    fn evaluate(&mut self, frame: &SensorFrame, map: Option<&MapInfo>) -> Outcome {
        (**self).evaluate(frame, map)
    }
}

/// How LiDAR ranges enter the observation.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RangeScale {
    /// Metres, as AutoVRL.
    Raw,
    /// Divided by the LiDAR's range_max, in [0, 1].
    #[default]
    Normalised,
}

/// Composition of the observation vector: the LiDAR ranges, then the enabled extras in this
/// order (speed / 2 m/s, yaw rate / 2 rad/s, steering / limit, throttle).
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
    /// Camera channels appended after everything else (needs the vehicle camera).
    pub image: ImageObs,
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
/// `depth_max_m`, colour / 255), ready for a CNN encoder.
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
        if depth {
            for y in 0..h {
                for x in 0..w {
                    let z = img.depth_m.get(src(x, y)).copied().unwrap_or(self.depth_max_m);
                    out.push((z / self.depth_max_m).clamp(0.0, 1.0));
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

impl Default for ObsConfig {
    /// Normalised ranges plus speed, yaw rate, steering and throttle.
    fn default() -> Self {
        Self {
            ranges: RangeScale::Normalised,
            speed: true,
            yaw_rate: true,
            steering: true,
            throttle: true,
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
            imu: self.speed || self.yaw_rate,
            gps: false,
            image: !self.image.is_empty(),
        }
    }

    /// The space for `n_rays` rays of range `range_max_m`.
    pub fn space(&self, n_rays: usize, range_max_m: f32) -> BoxSpace {
        let hi = match self.ranges {
            RangeScale::Raw => range_max_m,
            RangeScale::Normalised => 1.0,
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
        s.low.extend(std::iter::repeat_n(0.0, self.image.len()));
        s.high.extend(std::iter::repeat_n(1.0, self.image.len()));
        s
    }

    /// Build the observation (the frame's needs were checked by the env).
    pub fn observe(&self, frame: &SensorFrame, steering_limit_rad: f64) -> Vec<f32> {
        let mut out = Vec::new();
        if let Some(scan) = &frame.scan {
            out.reserve(scan.ranges.len() + self.n_extra());
            match self.ranges {
                RangeScale::Raw => out.extend(scan.ranges.iter().map(|r| r.clamp(0.0, scan.range_max))),
                RangeScale::Normalised => out.extend(scan.ranges.iter().map(|r| (r / scan.range_max).clamp(0.0, 1.0))),
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
        if !self.image.is_empty() {
            self.image.append(frame.image.as_ref(), &mut out);
        }
        out
    }
}

/// Settings both LiDAR tasks share.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CommonConfig {
    /// Observation composition.
    pub observation: ObsConfig,
    /// Action -> control mapping.
    pub action_mapping: ActionMapping,
    /// Number of LiDAR rays (must match the vehicle's LiDAR).
    pub n_rays: usize,
    /// LiDAR range_max, metres.
    pub range_max_m: f32,
}

impl Default for CommonConfig {
    fn default() -> Self {
        Self {
            observation: ObsConfig::default(),
            action_mapping: ActionMapping::Scaled,
            n_rays: 100,
            range_max_m: 12.0,
        }
    }
}

impl CommonConfig {
    /// Sensors the observation needs.
    pub fn needs(&self) -> SensorNeeds {
        self.observation.needs()
    }

    /// The observation space.
    pub fn space(&self) -> BoxSpace {
        self.observation.space(self.n_rays, self.range_max_m)
    }

    /// Map an action to a control.
    pub fn control(&self, action: &[f32], steering_limit_rad: f64) -> Control {
        map_control(self.action_mapping, action, steering_limit_rad)
    }
}

/// The minimum LiDAR range of a frame, metres (infinite without a scan).
pub fn min_range_m(frame: &SensorFrame) -> f64 {
    frame
        .scan
        .as_ref()
        .map(|s| s.min_range())
        .unwrap_or(f32::INFINITY)
        .min(1e6) as f64
}

/// The minimum range among the rays within `fov_deg / 2` of straight ahead, metres (the whole
/// scan when `fov_deg` is 0; infinite without a scan).
pub fn min_range_ahead_m(frame: &SensorFrame, fov_deg: f32) -> f64 {
    if fov_deg <= 0.0 {
        return min_range_m(frame);
    }
    frame
        .scan
        .as_ref()
        .map(|s| s.min_range_within(0.5 * fov_deg.to_radians()))
        .unwrap_or(f32::INFINITY)
        .min(1e6) as f64
}

/// Termination by `common_termination`, charging `penalty` once as the collision term.
pub fn terminate(
    terms: &mut RewardTerms,
    frame: &SensorFrame,
    map: Option<&MapInfo>,
    r_m: f64,
    threshold_m: f32,
    penalty: f64,
) -> Option<TerminationCause> {
    let t = common_termination(frame, map, r_m, threshold_m);
    if t.is_some() && terms.collision == 0.0 {
        terms.collision = penalty;
    }
    t
}

/// Termination shared by the tasks: too close (`r_m`, the task's minimum range, below
/// `threshold_m`), real contact, flipped, or out of the map. Returns the first that applies, in
/// that order.
pub fn common_termination(
    frame: &SensorFrame,
    map: Option<&MapInfo>,
    r_m: f64,
    threshold_m: f32,
) -> Option<TerminationCause> {
    if frame.scan.is_some() && (r_m as f32) < threshold_m {
        return Some(TerminationCause::TooClose);
    }
    if frame.contact == Some(true) {
        return Some(TerminationCause::Contact);
    }
    if let Some(imu) = &frame.imu {
        let [x, y, _, _] = imu.orientation_xyzw;
        // World z of the body's z axis: 1 - 2 (x^2 + y^2).
        if 1.0 - 2.0 * (x * x + y * y) < 0.5 {
            return Some(TerminationCause::Flipped);
        }
    }
    if let (Some(m), Some(g)) = (map, &frame.gps) {
        let [px, py, _] = g.position_m;
        if px.abs() as f32 > m.half_extent_m[0] + 0.5 || py.abs() as f32 > m.half_extent_m[1] + 0.5 {
            return Some(TerminationCause::OutOfBounds);
        }
    }
    None
}

pub(crate) fn map_control(mapping: ActionMapping, action: &[f32], limit: f64) -> Control {
    let a0 = action.first().copied().unwrap_or(0.0) as f64;
    let a1 = action.get(1).copied().unwrap_or(0.0) as f64;
    mapping.control(a0, a1, limit)
}
