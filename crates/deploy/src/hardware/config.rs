//! The car's TOML (`agvrl-drive --vehicle ros2 --config car.toml`): topics, QoS, the scan to
//! observation mapping and the command scaling. Unknown keys are an error.

use crate::DeployError;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Everything the ROS 2 vehicle and the sim-backed robot need to agree on.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Ros2Config {
    /// DDS domain (`ROS_DOMAIN_ID`), 0..=232.
    pub domain_id: u16,
    /// Node name (the robot appends `_sim`).
    pub node_name: String,
    /// `reset` waits this long for a full sensor set and a subscriber on the drive topic, s.
    pub startup_timeout_s: f64,
    /// Lockstep only (no `--realtime`): how long `sense` waits for the next sensor set, s.
    pub fresh_timeout_s: f64,
    /// Topic names.
    pub topics: Topics,
    /// Quality of service.
    pub qos: Qos,
    /// LaserScan to observation rays.
    pub scan: ScanMapping,
    /// Depth image to the policy's camera frame.
    pub camera: CameraMapping,
    /// Control to AckermannDrive.
    pub drive: DriveMapping,
}

impl Default for Ros2Config {
    fn default() -> Self {
        Self {
            domain_id: 0,
            node_name: "agvrl_drive".into(),
            startup_timeout_s: 10.0,
            fresh_timeout_s: 0.5,
            topics: Topics::default(),
            qos: Qos::default(),
            scan: ScanMapping::default(),
            camera: CameraMapping::default(),
            drive: DriveMapping::default(),
        }
    }
}

/// Topic names; an empty name is not subscribed (`scan` and `drive` are required).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Topics {
    /// `sensor_msgs/LaserScan`.
    pub scan: String,
    /// `sensor_msgs/Imu` (gyroscope, accelerometer, orientation).
    pub imu: String,
    /// `nav_msgs/Odometry` (pose; body-frame twist gives the speed).
    pub odom: String,
    /// `sensor_msgs/NavSatFix`.
    pub navsat: String,
    /// `sensor_msgs/Image` depth (32FC1 metres or 16UC1 millimetres), subscribed only when the
    /// policy's observation takes a camera image. The default is the ZED ROS 2 wrapper's.
    pub image: String,
    /// `ackermann_msgs/AckermannDriveStamped`, published.
    pub drive: String,
    /// `header.frame_id` of the published commands.
    pub frame_id: String,
}

impl Default for Topics {
    fn default() -> Self {
        Self {
            scan: "/scan".into(),
            imu: "/imu".into(),
            odom: "/odom".into(),
            navsat: String::new(),
            image: "/zed/zed_node/depth/depth_registered".into(),
            drive: "/drive".into(),
            frame_id: "base_link".into(),
        }
    }
}

impl Topics {
    /// These topics under namespace `ns` (`car0`: `/scan` becomes `/car0/scan`), and the
    /// commands' frame under the same prefix (`car0/base_link`), as one car of several is
    /// named; an empty `ns` changes nothing, an unnamed (empty) topic stays unnamed.
    pub fn namespaced(&self, ns: &str) -> Topics {
        let ns = ns.trim_matches('/');
        if ns.is_empty() {
            return self.clone();
        }
        let t = |name: &str| match name {
            "" => String::new(),
            n => format!("/{ns}/{}", n.trim_start_matches('/')),
        };
        Topics {
            scan: t(&self.scan),
            imu: t(&self.imu),
            odom: t(&self.odom),
            navsat: t(&self.navsat),
            image: t(&self.image),
            drive: t(&self.drive),
            frame_id: format!("{ns}/{}", self.frame_id),
        }
    }
}

/// DDS reliability.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Reliability {
    /// Samples may be lost (ROS 2 "sensor data"); a best-effort reader matches any writer.
    BestEffort,
    /// Lost samples are resent; a reliable reader matches only reliable writers.
    Reliable,
}

/// QoS of one direction.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TopicQos {
    /// Reliability.
    pub reliability: Reliability,
    /// History depth (keep last), >= 1.
    pub depth: usize,
}

/// QoS of the sensor topics and of the drive topic.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Qos {
    /// Sensor subscriptions (and the robot's sensor publishers).
    pub sensors: TopicQos,
    /// The drive command.
    pub drive: TopicQos,
}

impl Default for Qos {
    fn default() -> Self {
        Self {
            sensors: TopicQos {
                reliability: Reliability::BestEffort,
                depth: 1,
            },
            drive: TopicQos {
                reliability: Reliability::Reliable,
                depth: 1,
            },
        }
    }
}

/// What a resampled ray with no valid reading (all NaN, or outside the scan) becomes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum InvalidRay {
    /// NaN: the watchdog stops the car on that tick.
    Stop,
    /// No return (free space).
    RangeMax,
    /// An obstacle at range_min.
    RangeMin,
}

/// LaserScan to the policy's rays: the window `[angle_min_rad, angle_max_rad]` is split into
/// `n_rays` evenly spaced bearings (as the simulator's LiDAR); each takes the smallest valid
/// range among the scan's rays within half a spacing of it (the nearest ray when the scan is
/// coarser). +inf (no return) reads `range_max_m`, -inf (too close) `range_min_m`, NaN is
/// skipped; finite ranges are clipped to `[range_min_m, range_max_m]`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ScanMapping {
    /// First bearing, rad (REP 103: counter-clockwise from x forward).
    pub angle_min_rad: f32,
    /// Last bearing, rad.
    pub angle_max_rad: f32,
    /// Rays the policy sees (the env's `lidar.n_rays`).
    pub n_rays: usize,
    /// Clip below, metres.
    pub range_min_m: f32,
    /// Clip above and no-return value, metres (the env's `lidar.range_max_m`).
    pub range_max_m: f32,
    /// A ray with no valid reading.
    pub invalid: InvalidRay,
}

impl Default for ScanMapping {
    /// The default env's LiDAR: 100 rays over 90 degrees centred ahead, 0.05-12 m.
    fn default() -> Self {
        Self {
            angle_min_rad: -std::f32::consts::FRAC_PI_4,
            angle_max_rad: std::f32::consts::FRAC_PI_4,
            n_rays: 100,
            range_min_m: 0.05,
            range_max_m: 12.0,
            invalid: InvalidRay::Stop,
        }
    }
}

impl ScanMapping {
    /// The rays of `lidar` (a policy's own LiDAR), other settings as `self`.
    pub fn with_rays_of(self, lidar: &agvrl_sim::sensors::LidarConfig) -> Self {
        let (a0, inc) = lidar.angles();
        Self {
            angle_min_rad: a0,
            angle_max_rad: a0 + inc * (lidar.n_rays.max(1) - 1) as f32,
            n_rays: lidar.n_rays,
            range_max_m: lidar.range_max_m,
            ..self
        }
    }
}

/// A depth image to the policy's camera frame: the centre window with the policy camera's
/// vertical field of view and aspect ratio (square pixels), resized by nearest pixel to its
/// size. A pixel without a reading (NaN, 0 in 16UC1, -inf: nearer than the camera's minimum
/// range) reads NaN, as the simulated camera's holes; +inf (farther than its maximum) stays.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CameraMapping {
    /// The car camera's vertical field of view, degrees.
    pub vertical_fov_deg: f32,
    /// How much older than the other sensors an image may be, seconds: its stamp plus this
    /// counts toward the frame's oldest stamp. A 15 Hz camera's frame period (67 ms) plus 33 ms
    /// of its latency; lockstep waits for a newer image anyway.
    pub max_lag_s: f64,
}

impl Default for CameraMapping {
    /// A ZED 2 (70 degrees vertically) at 15 Hz.
    fn default() -> Self {
        Self {
            vertical_fov_deg: 70.0,
            max_lag_s: 0.1,
        }
    }
}

/// Control to `AckermannDrive`: speed = throttle * `max_speed_mps`, steering_angle = steering.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DriveMapping {
    /// Speed commanded at full throttle, m/s. Unset (the default): the trained vehicle's top
    /// speed, so a car that follows the command drives as fast as the policy learned to.
    pub max_speed_mps: Option<f32>,
    /// Steering limit of the virtual centre wheel, rad (the trained vehicle's).
    pub steering_limit_rad: f64,
}

impl Default for DriveMapping {
    /// xtenth_car: 0.36 rad steering; full throttle at the trained vehicle's top speed.
    fn default() -> Self {
        Self {
            max_speed_mps: None,
            steering_limit_rad: 0.36,
        }
    }
}

/// xtenth_car's top speed, m/s: full throttle for a mapping not yet given a vehicle.
pub const XTENTH_TOP_SPEED_MPS: f32 = 1.79;

/// A `max_speed_mps` further than this fraction from the trained top speed is warned about.
pub const SPEED_TOLERANCE: f32 = 0.1;

impl DriveMapping {
    /// Speed commanded at full throttle, m/s.
    pub fn full_throttle_mps(&self) -> f32 {
        self.max_speed_mps.unwrap_or(XTENTH_TOP_SPEED_MPS)
    }

    /// Take the trained vehicle's top speed for full throttle unless the car's TOML set one;
    /// returns a warning when the set one differs from it by more than `SPEED_TOLERANCE`.
    pub fn for_trained_top_speed(&mut self, top_speed_mps: f32) -> Option<String> {
        match self.max_speed_mps {
            None => {
                self.max_speed_mps = Some(top_speed_mps);
                None
            }
            Some(v) if (v / top_speed_mps - 1.0).abs() > SPEED_TOLERANCE => Some(format!(
                "drive.max_speed_mps = {v} m/s, but the policy was trained on a car whose top speed is \
                 {top_speed_mps:.2} m/s: full throttle will drive {:.1}x as fast as in training",
                v / top_speed_mps
            )),
            Some(_) => None,
        }
    }
}

impl Ros2Config {
    /// Read and check a TOML file.
    pub fn load(path: &Path) -> Result<Self, DeployError> {
        let text = std::fs::read_to_string(path).map_err(|source| DeployError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_toml(&text).map_err(|e| DeployError::Config(format!("{}: {e}", path.display())))
    }

    /// Parse and check TOML text; the error is one line.
    pub fn from_toml(text: &str) -> Result<Self, String> {
        let c: Self = toml::from_str(text).map_err(|e| e.message().trim().replace('\n', " "))?;
        c.validate().map_err(|e| e.message)?;
        Ok(c)
    }

    /// Check the values, naming the first bad one.
    pub fn validate(&self) -> Result<(), agvrl_sim::InvalidSetting> {
        let s = &self.scan;
        let c = &self.camera;
        let checks: [(bool, &str); 12] = [
            (self.domain_id <= 232, "domain_id must be in 0..=232"),
            (
                self.startup_timeout_s > 0.0 && self.fresh_timeout_s > 0.0,
                "startup_timeout_s and fresh_timeout_s must be positive",
            ),
            (
                !self.topics.scan.is_empty() && !self.topics.drive.is_empty(),
                "topics.scan and topics.drive are required",
            ),
            (
                s.n_rays >= 1 && s.n_rays <= 100_000,
                "scan.n_rays must be in 1..=100000",
            ),
            (
                s.angle_min_rad.is_finite() && s.angle_max_rad.is_finite() && s.angle_min_rad <= s.angle_max_rad,
                "scan.angle_min_rad must be finite and <= scan.angle_max_rad",
            ),
            (
                s.n_rays == 1 || s.angle_min_rad < s.angle_max_rad,
                "scan window is empty: angle_min_rad == angle_max_rad needs n_rays = 1",
            ),
            (
                s.range_min_m >= 0.0 && s.range_min_m < s.range_max_m && s.range_max_m.is_finite(),
                "scan ranges must satisfy 0 <= range_min_m < range_max_m < inf",
            ),
            (
                c.vertical_fov_deg > 0.0 && c.vertical_fov_deg < 179.0,
                "camera.vertical_fov_deg must be in (0, 179)",
            ),
            ((0.0..=1.0).contains(&c.max_lag_s), "camera.max_lag_s must be in [0, 1]"),
            (
                self.qos.sensors.depth >= 1 && self.qos.drive.depth >= 1,
                "qos depth must be at least 1",
            ),
            (
                self.drive.max_speed_mps.is_none_or(|v| v > 0.0 && v.is_finite()),
                "drive.max_speed_mps must be positive",
            ),
            (
                self.drive.steering_limit_rad > 0.0 && self.drive.steering_limit_rad.is_finite(),
                "drive.steering_limit_rad must be positive",
            ),
        ];
        match checks.iter().find(|(ok, _)| !ok) {
            Some((_, why)) => Err(agvrl_sim::InvalidSetting::new("car config", *why)),
            None => Ok(()),
        }
    }

    /// Error unless the scan mapping gives the rays the env's task was trained on: as many,
    /// as far, over the same field of view.
    pub fn check_lidar(&self, lidar: &agvrl_sim::sensors::LidarConfig) -> Result<(), DeployError> {
        let s = &self.scan;
        let (a0, inc) = lidar.angles();
        let span = inc * (lidar.n_rays.max(1) - 1) as f32;
        let same_window = (s.angle_min_rad - a0).abs() < 1e-3 && (s.angle_max_rad - (a0 + span)).abs() < 1e-3;
        if s.n_rays != lidar.n_rays || s.range_max_m != lidar.range_max_m || !same_window {
            return Err(DeployError::Config(format!(
                "scan mapping gives {} rays from {:.4} to {:.4} rad up to {} m; the policy's task expects {} rays \
                 from {a0:.4} to {:.4} rad up to {} m",
                s.n_rays,
                s.angle_min_rad,
                s.angle_max_rad,
                s.range_max_m,
                lidar.n_rays,
                a0 + span,
                lidar.range_max_m
            )));
        }
        Ok(())
    }
}

impl Ros2Config {
    /// Error unless the car's camera sees at least the policy camera's vertical field of view
    /// (a narrower one cannot be cropped to it; the width is checked per image).
    pub fn check_camera(&self, cam: &agvrl_sim::sensors::CameraConfig) -> Result<(), DeployError> {
        if self.camera.vertical_fov_deg + 0.05 < cam.fov_deg {
            return Err(DeployError::Config(format!(
                "camera.vertical_fov_deg = {}, but the policy's camera sees {} degrees vertically: a narrower \
                 camera cannot be cropped to it",
                self.camera.vertical_fov_deg, cam.fov_deg
            )));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use agvrl_sim::sensors::LidarConfig;

    #[test]
    fn the_scan_window_must_match_the_policys_lidar() {
        let cfg = Ros2Config::default();
        cfg.check_lidar(&LidarConfig::default())
            .expect("the default mapping is the default LiDAR");
        let wide = LidarConfig {
            fov_deg: 270.0,
            ..LidarConfig::default()
        };
        let e = cfg.check_lidar(&wide).unwrap_err().to_string();
        assert!(e.contains("2.3562"), "names the expected window: {e}");
        let mut c = cfg.clone();
        c.scan.angle_min_rad = -135f32.to_radians();
        c.scan.angle_max_rad = 135f32.to_radians();
        c.check_lidar(&wide)
            .expect("a 270 degree window for a 270 degree LiDAR");
        let more = LidarConfig {
            n_rays: 101,
            ..LidarConfig::default()
        };
        assert!(cfg.check_lidar(&more).is_err());
    }

    #[test]
    fn full_throttle_comes_from_the_trained_vehicle_unless_set() {
        let mut m = DriveMapping::default();
        assert_eq!(m.for_trained_top_speed(1.5), None);
        assert_eq!(m.full_throttle_mps(), 1.5);
        let mut m = DriveMapping {
            max_speed_mps: Some(1.6),
            ..DriveMapping::default()
        };
        assert_eq!(m.for_trained_top_speed(1.5), None, "within 10 %");
        assert_eq!(m.full_throttle_mps(), 1.6, "an explicit value is kept");
        let mut m = DriveMapping {
            max_speed_mps: Some(4.0),
            ..DriveMapping::default()
        };
        let w = m.for_trained_top_speed(1.79).expect("2.2x is warned about");
        assert!(w.contains("2.2x"), "{w}");
        assert!(Ros2Config::from_toml("[drive]\nmax_speed_mps = -1.0\n").is_err());
        // The fallback is xtenth_car's model top speed.
        let top = agvrl_envs::EnvConfig::default()
            .sim
            .vehicle_model()
            .unwrap()
            .top_speed_mps();
        assert!((top - XTENTH_TOP_SPEED_MPS).abs() < 0.01, "{top}");
    }

    #[test]
    fn a_namespace_prefixes_every_named_topic_and_the_command_frame() {
        let t = Topics::default().namespaced("/car1/");
        assert_eq!(t.scan, "/car1/scan");
        assert_eq!(t.drive, "/car1/drive");
        assert_eq!(t.image, "/car1/zed/zed_node/depth/depth_registered");
        assert_eq!(t.navsat, "", "an unnamed topic stays unnamed");
        assert_eq!(t.frame_id, "car1/base_link");
        assert_eq!(Topics::default().namespaced(""), Topics::default());
    }
}
