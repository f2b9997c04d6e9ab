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
}

impl LaserScan {
    /// Smallest range in the scan, metres (`range_max` for an empty scan).
    pub fn min_range(&self) -> f32 {
        self.ranges.iter().copied().fold(self.range_max, f32::min)
    }
}
