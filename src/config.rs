//! The run configuration (agvrl-run's `RunConfig`, shared with agvrl-drive and Python) and the
//! default job.

pub use agvrl_run::RunConfig;

/// The default job, also embedded so the binary works outside a checkout.
pub const DEFAULT_TOML: &str = include_str!("../configs/default.toml");

/// What `agvrl train --track MAP.yaml` trains without `--config`: the per-track recipe.
pub const TRACK_TOML: &str = include_str!("../configs/racing-track.toml");
