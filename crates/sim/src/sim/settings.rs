//! What defines a simulation: the scene's source, the settings (vehicle, dynamics, timing,
//! sensors, drive), and the per-episode vehicle parameters.

use crate::SimError;
use crate::assets::AssetSource;
use crate::scene::{CircuitSettings, MapTrack, SceneKind};
use crate::sensors::{GpsConfig, LidarConfig};
use crate::vehicle::{DriveModel, DynamicsMode, VehicleModel};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// Where the scene comes from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SceneSource {
    /// A built-in scene id (`outdoor-20`, `outdoor-50`, `urban-20`, `urban-50`, `oval`).
    Builtin(String),
    /// A scene TOML on disk.
    File(PathBuf),
    /// A seeded random layout.
    Procedural {
        /// Generator family.
        kind: SceneKind,
        /// Layout seed.
        seed: u64,
        /// Inner half size of the map, metres (outdoor/urban).
        half_m: f32,
    },
    /// A race track loaded from a map file (see [`MapTrack::load`]).
    Map(Box<MapTrack>),
    /// A seeded race circuit (see [`MapTrack::generated`]): the settings travel, not the walls.
    Circuit {
        /// Circuit seed.
        seed: u64,
        /// What the circuit is drawn from (defaults when left out).
        #[serde(default)]
        settings: CircuitSettings,
    },
}

/// How near a car's collider must come to another collider for the physics to report a contact,
/// metres: rapier's contact prediction distance. A racing episode that ends on contact ends
/// this far from the wall.
pub fn contact_distance_m() -> f32 {
    rapier3d::prelude::IntegrationParameters::default().prediction_distance()
}

/// Everything that defines a simulation: the scene and the settings.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SimConfig {
    /// The scene.
    pub scene: SceneSource,
    /// Vehicle, dynamics, timing, sensors and drive.
    pub settings: SimSettings,
}

/// Which vehicle [`SimSettings::vehicle`] names.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum VehicleSource {
    /// A built-in vehicle (`assets/vehicles/<name>.toml`).
    Builtin(String),
    /// A vehicle TOML (and the URDF it names) on disk.
    File(PathBuf),
}

impl VehicleSource {
    /// A setting ending in `.toml` is a file; anything else a built-in name.
    pub fn of(setting: &str) -> Self {
        if setting.ends_with(".toml") {
            Self::File(PathBuf::from(setting))
        } else {
            Self::Builtin(setting.to_string())
        }
    }

    /// Load the vehicle (its TOML and URDF), without building a simulator.
    pub fn load(&self) -> Result<VehicleModel, SimError> {
        match self {
            Self::File(path) => {
                let (src, name) = AssetSource::for_file(path);
                VehicleModel::load(&src, &name)
            }
            Self::Builtin(name) => VehicleModel::builtin(&AssetSource::builtin(), name),
        }
    }
}

/// The simulator's settings besides the scene. agvrl-envs' `EnvConfig` embeds them (its env id
/// picks the scene), so an env TOML and the simulator read the same keys.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct SimSettings {
    /// A built-in vehicle name (`xtenth_car`, `racecar`) or the path of a vehicle TOML.
    pub vehicle: String,
    /// Dynamics mode.
    pub dynamics: DynamicsMode,
    /// Control period, seconds (AutoVRL: 1/30).
    pub control_period_s: f64,
    /// Physics steps per control period (the substep must be <= 1/60 s).
    pub substeps: u32,
    /// Braking deceleration of the drive when the throttle asks for less speed, m/s^2, like
    /// the car's speed-controlled ESC; 0 (the default) coasts, as AutoVRL (see `DriveModel`).
    pub brake_mps2: f64,
    /// Split steering between the front wheels by Ackermann geometry (`None`: the vehicle's
    /// own setting; `Some(false)`: AutoVRL's equal angles).
    pub ackermann: Option<bool>,
    /// LiDAR settings.
    pub lidar: LidarConfig,
    /// GPS settings.
    pub gps: GpsConfig,
    /// Human-sized subjects added to the scene (search targets), placed by `subject_seed`;
    /// finding them needs the camera.
    pub subjects: usize,
    /// Seed of the subjects' placement.
    pub subject_seed: u64,
    /// The vehicle's camera (on its camera link), when set.
    pub camera: Option<crate::sensors::CameraConfig>,
    /// Ray-cast mode: control periods in which no contact can start skip rapier's pipeline
    /// and integrate the lone chassis as rapier's solver would. The motion is the same to the
    /// bit up to the first contact; at a contact, rapier's narrow phase depends on when the
    /// pair was first seen, so the contact step itself may differ in the last bits. `false`
    /// sends every step through rapier.
    pub free_flight: bool,
}

impl Default for SceneSource {
    fn default() -> Self {
        Self::Builtin("oval".into())
    }
}

impl Default for SimSettings {
    fn default() -> Self {
        Self {
            vehicle: "xtenth_car".into(),
            dynamics: DynamicsMode::Raycast,
            control_period_s: 1.0 / 30.0,
            substeps: 4,
            brake_mps2: 0.0,
            ackermann: None,
            lidar: LidarConfig::default(),
            gps: GpsConfig::default(),
            subjects: 0,
            subject_seed: 0,
            camera: None,
            free_flight: true,
        }
    }
}

impl SimSettings {
    /// The vehicle these settings name, loaded without building a simulator (its top speed,
    /// geometry).
    pub fn vehicle_model(&self) -> Result<VehicleModel, SimError> {
        VehicleSource::of(&self.vehicle).load()
    }
}

/// A planar pose: where to put the vehicle.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PlanarPose {
    /// x, metres.
    pub x_m: f32,
    /// y, metres.
    pub y_m: f32,
    /// Heading, radians counter-clockwise from +x.
    pub yaw_rad: f32,
}

/// Vehicle parameters that may change per episode (domain randomisation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VehicleParams {
    /// Wheel-speed model.
    pub drive: DriveModel,
    /// Tyre friction coefficient.
    pub tyre_friction: f32,
    /// Factor on mass and inertia.
    pub mass_scale: f32,
    /// Constant offset added to the commanded steering angle, rad.
    pub steering_offset_rad: f64,
}
