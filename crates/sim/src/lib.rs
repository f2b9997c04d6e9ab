//! agvrl-sim: the simulator. rapier3d physics, URDF vehicles and objects, the paper's Ackermann
//! actuation, GPS / IMU / LiDAR / camera (RGB, depth, segmentation), the five AutoVRL scenes,
//! and race tracks from map files or generated from a seed (`MapTrack::generated`).
//!
//! ```text
//! Control{throttle, steering} -> DriveModel (w) + ackermann_split (left, right)
//!   -> vehicle body (raycast | multibody) x substeps -> rapier World
//!   -> sensors: gps::read, ImuState, Lidar::scan -> msg::{GpsReading, ImuReading, LaserScan}
//! ```
//!
//! Invariants: z up, gravity -9.81 m/s^2, SI units; readings leaving this crate are the plain
//! structs of `msg` (no rapier types); the vehicle never appears in its own LiDAR scan; the
//! world is built once and `Sim::reset` only moves the vehicle; the same actions from the same
//! reset give a bit-identical trajectory. No reward, policy or rendering lives here.
#![warn(missing_docs)]

pub mod assets;
mod error;
pub mod fs;
#[doc(hidden)]
pub mod fuzz;
pub mod msg;
pub mod scene;
pub mod sensors;
mod sim;
pub mod urdf;
pub mod vehicle;
pub mod world;

pub use error::{InvalidSetting, SimError};
pub use fs::write_atomic;
pub use scene::{CircuitInfo, CircuitSettings, MapTrack, SCENE_IDS, Scene, SceneKind};
pub use sim::{
    CarContact, CarView, MAX_CARS, PlanarPose, SceneSource, Sim, SimConfig, SimSettings, VehicleParams, VehicleSource,
    contact_distance_m,
};
pub use vehicle::{Control, DriveModel, DynamicsMode};
