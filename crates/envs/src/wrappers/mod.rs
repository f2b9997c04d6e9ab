//! Wrappers named by their effect.

mod time_limit;

pub use time_limit::TimeLimit;
