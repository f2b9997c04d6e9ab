//! agvrl-sim: the simulator.
#![warn(missing_docs)]

mod error;
pub mod msg;

pub use error::SimError;
