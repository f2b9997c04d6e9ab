//! Vehicles: the data that describes them, the paper's actuation, and the two dynamics modes.

pub mod actuation;
pub(crate) mod body;
pub mod spec;

pub use actuation::{Control, DriveModel, ackermann_split};
pub use body::{BodyParams, DynamicsMode};
pub use spec::{DriveSpec, SteeringSpec, TyreSpec, VehicleModel, VehicleSpec, WheelGeom, WheelSpec};
