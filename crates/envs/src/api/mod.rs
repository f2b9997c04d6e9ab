//! The contract: `Env`, spaces, `Step`, `Info`, and the `Vehicle` seam. Invariant: this module
//! sees agvrl-sim only through `agvrl_sim::msg` (plain readings) and its error type.

mod env;
mod multi;
mod space;
mod track;
mod vehicle;

pub use env::*;
pub use multi::{MultiEnv, MultiStep, RaceSummary};
pub use space::BoxSpace;
pub use track::{OvalTrack, PathTrack, Track};
pub use vehicle::*;
