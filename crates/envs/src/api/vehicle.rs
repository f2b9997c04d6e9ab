use super::env::EnvError;
use super::track::Track;
pub use agvrl_sim::msg::Control;
use agvrl_sim::msg::{CameraFrame, GpsReading, ImuReading, LaserScan};

/// Everything a vehicle's sensors delivered for one control tick. Sensors a real car may lack
/// are optional; a task says which it needs.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SensorFrame {
    /// Time of the frame, seconds (simulated time, or the car's clock).
    pub stamp_s: f64,
    /// The LiDAR scan.
    pub scan: Option<LaserScan>,
    /// The IMU sample.
    pub imu: Option<ImuReading>,
    /// The GPS / pose fix.
    pub gps: Option<GpsReading>,
    /// A camera frame.
    pub image: Option<CameraFrame>,
    /// Whether the vehicle touches something other than the ground (simulation; a bumper).
    pub contact: Option<bool>,
    /// The command in force during the last period (after limits), as the vehicle applied it.
    pub applied: Control,
}

/// Which sensors a task needs in every frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SensorNeeds {
    /// LiDAR.
    pub scan: bool,
    /// IMU.
    pub imu: bool,
    /// GPS.
    pub gps: bool,
    /// Camera.
    pub image: bool,
}

impl SensorNeeds {
    /// An error naming the first needed sensor missing from `frame`.
    pub fn check(&self, frame: &SensorFrame) -> Result<(), EnvError> {
        let missing = [
            (self.scan && frame.scan.is_none(), "LiDAR scan"),
            (self.imu && frame.imu.is_none(), "IMU"),
            (self.gps && frame.gps.is_none(), "GPS"),
            (self.image && frame.image.is_none(), "camera image"),
        ];
        match missing.iter().find(|(m, _)| *m) {
            Some((_, what)) => Err(EnvError::Vehicle(format!(
                "the task needs a {what} and the vehicle delivered none"
            ))),
            None => Ok(()),
        }
    }
}

/// What a simulated vehicle knows about its map (a real car knows nothing of it).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MapInfo {
    /// Half extents of the drivable area around the origin, metres (leaving it ends episodes).
    pub half_extent_m: [f32; 2],
    /// Race track geometry, when the map is a track.
    pub track: Option<Track>,
    /// Centres of the free cells of a `cell_m` grid (coverage), metres.
    pub free_cells: Vec<[f32; 2]>,
    /// Cell size of `free_cells`, metres.
    pub cell_m: f32,
    /// Scene object ids of the search subjects (segmentation shows id + 1).
    pub subjects: Vec<u32>,
}

/// The sensor/actuator seam shared by the simulator and a real car. Time belongs to the
/// vehicle: `actuate` lasts one control period (the simulator advances physics, a real car
/// waits for the next tick), so `TaskEnv` never asks which one it drives.
pub trait Vehicle: Send {
    /// Start an episode: the simulator spawns (seeded) and re-draws randomised parameters; a real
    /// car stops and reports its sensors.
    fn reset(&mut self, seed: u64) -> Result<SensorFrame, EnvError>;
    /// Apply `control` for one control period.
    fn actuate(&mut self, control: Control) -> Result<(), EnvError>;
    /// The latest sensor frame.
    fn sense(&mut self) -> Result<SensorFrame, EnvError>;
    /// Control period, seconds.
    fn control_period_s(&self) -> f64;
    /// Steering limit of the virtual centre wheel, rad.
    fn steering_limit_rad(&self) -> f64;
    /// The map of the current episode, when the vehicle is simulated (a real car has none).
    /// Asked for at reset rather than given when the task is built, because the simulator
    /// redraws procedural layouts at reset.
    fn map(&self) -> Option<&MapInfo> {
        None
    }
}

impl<V: Vehicle + ?Sized> Vehicle for Box<V> {
    fn reset(&mut self, seed: u64) -> Result<SensorFrame, EnvError> {
        (**self).reset(seed)
    }
    fn actuate(&mut self, control: Control) -> Result<(), EnvError> {
        (**self).actuate(control)
    }
    fn sense(&mut self) -> Result<SensorFrame, EnvError> {
        (**self).sense()
    }
    fn control_period_s(&self) -> f64 {
        (**self).control_period_s()
    }
    fn steering_limit_rad(&self) -> f64 {
        (**self).steering_limit_rad()
    }
    fn map(&self) -> Option<&MapInfo> {
        (**self).map()
    }
}
