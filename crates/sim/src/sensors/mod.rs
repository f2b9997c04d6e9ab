//! Sensors. Each has a config struct and returns a plain reading from `crate::msg`.

pub mod camera;
pub mod fast_ray;
pub mod gps;
pub mod imu;
pub mod lidar;

pub use camera::{Camera, CameraConfig};
pub use gps::GpsConfig;
pub use lidar::{Lidar, LidarConfig};
