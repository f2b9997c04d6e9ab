//! Vehicles: the data that describes them, the paper's actuation, and the two dynamics modes.

pub mod actuation;
pub(crate) mod body;
pub mod spec;

pub use actuation::{ackermann_split, ActionMapping, Control, DriveModel};
pub use body::{BodyParams, DynamicsMode};
pub use spec::{DriveSpec, SteeringSpec, VehicleModel, VehicleSpec, WheelGeom, WheelSpec};
