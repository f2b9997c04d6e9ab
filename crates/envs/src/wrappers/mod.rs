//! Wrappers named by their effect.

mod noise;
mod time_limit;

pub use noise::{NoiseConfig, Noisy};
pub use time_limit::TimeLimit;
