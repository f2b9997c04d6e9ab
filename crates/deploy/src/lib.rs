//! agvrl-deploy: run a trained policy on any `Vehicle` at a fixed rate, with a watchdog.
//!
//! ```text
//! every period: Vehicle::sense -> SensorFrame --watchdog--> Task::observe -> Policy::act
//!   -> Task::control -> Vehicle::actuate            (stale / non-finite / failed: safe stop)
//! ```
//!
//! Invariants: the policy sees only fresh, finite sensor data; a stale frame (older than
//! `max_age_periods` control periods), a NaN or infinite reading, or a failed inference makes the
//! loop command a safe stop (zero throttle, straight steering) on that tick, and it resumes by
//! itself once data is fresh; every such event is logged. A policy whose spaces do not match the
//! task refuses to start. No training code and no rerun are linked.

#![warn(missing_docs)]

pub mod bag;
pub mod hardware;
pub mod record;
pub mod replay;
pub mod run_loop;
pub mod stats;

pub use run_loop::{DeployError, DriveConfig, DriveLoop, DrivePasser, Event, Tick};
