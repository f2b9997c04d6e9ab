//! Hardware vehicles. The message layouts, the car's TOML and the conversions are plain Rust
//! (always built, unit-tested); the DDS transport is behind the `ros2` feature.

pub mod config;
pub mod frames;
pub mod mapping;
pub mod msg;
#[cfg(feature = "ros2")]
pub mod ros2;
#[cfg(feature = "ros2")]
pub mod sim_robot;
pub mod wire;

pub use config::Ros2Config;
#[cfg(feature = "ros2")]
pub use ros2::Ros2Vehicle;
#[cfg(feature = "ros2")]
pub use sim_robot::{Faults, Opponent, Pace, RobotHandle, RobotStats, SimRobot};
pub use wire::WireFaults;
