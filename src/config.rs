//! The run configuration (agvrl-rl's `RunConfig`, shared with agvrl-drive) and the default job.

pub use agvrl_rl::RunConfig;

/// The default job, also embedded so the binary works outside a checkout.
pub const DEFAULT_TOML: &str = include_str!("../configs/default.toml");
