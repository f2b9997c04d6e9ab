//! How a frame becomes the observation vector: LiDAR ranges (scaled), speed, yaw rate, the
//! applied steering and throttle, the explored-ground memory, and camera channels, as
//! `ObsConfig` composes them.

use super::explored::{ExploredMemory, ExploredObs};
use crate::api::{BoxSpace, SensorFrame, SensorNeeds};
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
/// fractions, camera channels).
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
        let n01 = self.explored.len() + self.image.len();
        s.low.extend(std::iter::repeat_n(0.0, n01));
        s.high.extend(std::iter::repeat_n(1.0, n01));
        s
    }

    /// Build the observation (the frame's needs were checked by the env); `explored` is the
    /// task's memory when `self.explored` is on.
    pub fn observe(&self, frame: &SensorFrame, steering_limit_rad: f64, explored: Option<&ExploredMemory>) -> Vec<f32> {
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
        if !self.image.is_empty() {
            self.image.append(frame.image.as_ref(), &mut out);
        }
        out
    }
}
