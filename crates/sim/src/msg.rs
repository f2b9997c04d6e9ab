//! Plain sensor readings, shaped like their ROS 2 messages. No rapier or glam types cross this
//! boundary, so agvrl-envs and hardware drivers can build them without the physics engine.

use serde::{Deserialize, Serialize};

/// A GPS / pose fix (like `nav_msgs/Odometry` pose plus `sensor_msgs/NavSatFix`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct GpsReading {
    /// Position of the base link in the world frame, metres (x east/forward, y left, z up).
    pub position_m: [f64; 3],
    /// Orientation of the base link in the world frame as a unit quaternion (x, y, z, w).
    pub orientation_xyzw: [f64; 4],
    /// Roll, pitch, yaw of the base link, radians (ZYX Euler angles).
    pub rpy_rad: [f64; 3],
    /// Geodetic fix (latitude deg, longitude deg, altitude m) when a geodetic origin is configured.
    pub geodetic: Option<Geodetic>,
}

/// Latitude, longitude and altitude (WGS84, flat-earth approximation around the origin).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Geodetic {
    /// Latitude, degrees north.
    pub latitude_deg: f64,
    /// Longitude, degrees east.
    pub longitude_deg: f64,
    /// Altitude above the ellipsoid, metres.
    pub altitude_m: f64,
}

/// An IMU sample (like `sensor_msgs/Imu` plus velocities a state estimator would give).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ImuReading {
    /// Orientation of the body in the world frame, unit quaternion (x, y, z, w).
    pub orientation_xyzw: [f64; 4],
    /// Linear velocity in the world frame, m/s.
    pub lin_vel_w: [f64; 3],
    /// Linear velocity in the body frame, m/s.
    pub lin_vel_b: [f64; 3],
    /// Angular velocity in the world frame, rad/s.
    pub ang_vel_w: [f64; 3],
    /// Angular velocity in the body frame, rad/s (what a gyroscope reads).
    pub ang_vel_b: [f64; 3],
    /// Specific force in the body frame, m/s^2 (what an accelerometer reads: +9.81 on z at rest).
    pub lin_acc_b: [f64; 3],
    /// Angular acceleration in the body frame, rad/s^2 (finite difference over the sample time).
    pub ang_acc_b: [f64; 3],
}

/// A planar LiDAR scan in the `sensor_msgs/LaserScan` convention: ray `i` points at
/// `angle_min + i * angle_increment` radians, counter-clockwise from the sensor's x axis.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LaserScan {
    /// Bearing of the first ray, radians.
    pub angle_min: f32,
    /// Angle between consecutive rays, radians.
    pub angle_increment: f32,
    /// Smallest range the sensor reports, metres.
    pub range_min: f32,
    /// Largest range the sensor reports, metres; misses read exactly this.
    pub range_max: f32,
    /// Range per ray, metres, in [range_min, range_max].
    pub ranges: Vec<f32>,
    /// Whether ray `i` hit something within range (false: `ranges[i] == range_max`).
    pub hit: Vec<bool>,
    /// World-frame end point of each ray (hit point, or the point at range_max), metres.
    pub points_w: Vec<[f32; 3]>,
    /// Scene object id hit by each ray (`None` for misses and for the ground).
    pub object_id: Vec<Option<u32>>,
    /// World-frame origin of the rays, metres.
    pub origin_w: [f32; 3],
    /// The other car each ray hit (`None`: the scene or nothing); empty when the world holds
    /// one car.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub car: Vec<Option<u32>>,
}

impl LaserScan {
    /// Smallest range among the rays that hit no other car, metres: the clearance to the
    /// static scene (`range_max` for an empty scan).
    pub fn min_static_range(&self) -> f32 {
        self.ranges
            .iter()
            .enumerate()
            .filter(|(i, _)| self.car.get(*i).is_none_or(|c| c.is_none()))
            .map(|(_, r)| *r)
            .fold(self.range_max, f32::min)
    }

    /// Smallest range in the scan, metres (`range_max` for an empty scan).
    pub fn min_range(&self) -> f32 {
        self.ranges.iter().copied().fold(self.range_max, f32::min)
    }

    /// Smallest range among the rays within `half_width_rad` of straight ahead, metres
    /// (`range_max` when none is).
    pub fn min_range_within(&self, half_width_rad: f32) -> f32 {
        self.ranges
            .iter()
            .enumerate()
            .filter(|(i, _)| self.bearing(*i).abs() <= half_width_rad + 1e-6)
            .map(|(_, r)| *r)
            .fold(self.range_max, f32::min)
    }

    /// Direction of ray `i` in the sensor frame, rad (positive left).
    pub fn bearing(&self, i: usize) -> f32 {
        self.angle_min + self.angle_increment * i as f32
    }

    /// Whether ray `i` returned from something: its `hit` flag, or for a scan without flags
    /// (a car's LaserScan), a range short of `range_max`.
    pub fn hit_at(&self, i: usize) -> bool {
        self.hit.get(i).copied().unwrap_or(self.ranges[i] < self.range_max)
    }
}

/// A drive command (like `ackermann_msgs/AckermannDrive`, in AutoVRL's throttle form).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Control {
    /// Throttle in [-1, 1]; negative reverses. The policies' action mappings give [0, 1]
    /// (AutoVRL's car); only a safety filter backing out of a dead end reverses.
    pub throttle: f64,
    /// Steering angle of the virtual centre front wheel, rad, positive = left.
    pub steering_rad: f64,
}

/// A camera frame (filled by the camera sensor when a vehicle carries one).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CameraFrame {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// RGB, row-major, 3 bytes per pixel.
    pub rgb: Vec<u8>,
    /// Depth along the optical axis, metres, row-major.
    pub depth_m: Vec<f32>,
    /// Scene object id + 1 per pixel (0: ground or sky).
    pub segmentation: Vec<u32>,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The yaw is where the pose's x axis points seen from above, as rapier's rotation puts
    /// it, also for a pose pitched and rolled.
    #[test]
    fn yaw_is_the_heading_of_the_x_axis_seen_from_above() {
        use rapier3d::prelude::{Rotation, Vector};
        for k in -15..=15 {
            let yaw = k as f32 * 0.2;
            for (pitch, roll) in [(0.0, 0.0), (0.5, 0.0), (-0.3, 0.7)] {
                let q =
                    Rotation::from_rotation_z(yaw) * Rotation::from_rotation_y(pitch) * Rotation::from_rotation_x(roll);
                let fwd = q * Vector::X;
                let pose = Pose3 {
                    position_m: [1.0, 2.0, 3.0],
                    orientation_xyzw: q.to_array(),
                };
                let d = pose.yaw_rad() - fwd.y.atan2(fwd.x);
                assert!(
                    d.sin().abs() < 1e-5 && d.cos() > 0.0,
                    "yaw {yaw}, pitch {pitch}: off by {d}"
                );
            }
            assert!((Pose3::from_position_yaw([0.0; 3], yaw).yaw_rad() - yaw).sin().abs() < 1e-6);
        }
    }
    use crate::sensors::LidarConfig;

    fn scan(fov_deg: f32, n: usize) -> LaserScan {
        let (angle_min, angle_increment) = LidarConfig {
            n_rays: n,
            fov_deg,
            ..LidarConfig::default()
        }
        .angles();
        // Ray i reads 1 + i metres, so the nearest ray of a window is its first.
        LaserScan {
            angle_min,
            angle_increment,
            range_max: 500.0,
            ranges: (0..n).map(|i| 1.0 + i as f32).collect(),
            ..LaserScan::default()
        }
    }

    #[test]
    fn min_range_within_a_window_sees_only_its_rays() {
        let quarter = std::f32::consts::FRAC_PI_4;
        // AutoVRL's 90 degree fan lies wholly within +-45 degrees.
        let s = scan(90.0, 100);
        assert_eq!(s.min_range_within(quarter), s.min_range());
        // Of 271 rays over 270 degrees (one per degree), +-45 degrees starts at ray 90.
        let s = scan(270.0, 271);
        assert_eq!(s.min_range(), 1.0);
        assert_eq!(s.min_range_within(quarter), 91.0);
    }
}

/// A rigid pose in the world frame (like `geometry_msgs/Pose`): where a car's base, LiDAR or
/// camera stands.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Pose3 {
    /// Position, metres.
    pub position_m: [f32; 3],
    /// Orientation as a unit quaternion (x, y, z, w).
    pub orientation_xyzw: [f32; 4],
}

impl Default for Pose3 {
    fn default() -> Self {
        Self {
            position_m: [0.0; 3],
            orientation_xyzw: [0.0, 0.0, 0.0, 1.0],
        }
    }
}

impl Pose3 {
    /// At `position_m`, turned `yaw_rad` about z (counter-clockwise seen from above).
    pub fn from_position_yaw(position_m: [f32; 3], yaw_rad: f32) -> Self {
        let (s, c) = (0.5 * yaw_rad).sin_cos();
        Self {
            position_m,
            orientation_xyzw: [0.0, 0.0, s, c],
        }
    }

    /// Heading of the pose's x axis seen from above (its projection on the ground),
    /// counter-clockwise from the world's x axis, radians in (-pi, pi].
    pub fn yaw_rad(&self) -> f32 {
        let [x, y, z, w] = self.orientation_xyzw;
        (2.0 * (x * y + w * z)).atan2(1.0 - 2.0 * (y * y + z * z))
    }

    /// Whether every number is finite.
    pub fn is_finite(&self) -> bool {
        self.position_m
            .iter()
            .chain(&self.orientation_xyzw)
            .all(|v| v.is_finite())
    }
}
