//! The learners' settings (a run TOML's `[ppo]` and `[sac]` tables; the run TOML itself is
//! agvrl-run's `RunConfig`).

mod ppo;
mod sac;

pub use ppo::PpoConfig;
pub use sac::{EntCoef, SacConfig};
