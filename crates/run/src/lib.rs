//! agvrl-run: what the `agvrl` command line, `agvrl-drive` and the Python wheel share above the
//! learners: the run TOML ([`RunConfig`]), run directories ([`Run`], [`RunDir`], [`files`]),
//! what a `--policy` or `--run` argument means ([`PolicySettings`]), what an evaluation or a race found
//! ([`RunReport`], [`EvalReport`], [`RaceReport`]), and how an error reads ([`error_line`]).

#![warn(missing_docs)]

mod config;
mod dir;
mod error;
mod error_line;
#[doc(hidden)]
pub mod fuzz;
mod race_report;
mod report;
mod seeds;
mod settings;
pub mod stats;

pub use config::RunConfig;
pub use dir::{Run, RunDir, files, stamp, write_atomic};
pub use error::{Result, RunError};
pub use error_line::error_line;
pub use race_report::{CarFigures, RaceReport, WIDTH_BANDS, WidthBand, width_band};
pub use report::{EvalReport, FilterReport, RacingReport, RunReport, SearchReport, SubjectsReport};
pub use seeds::Seeds;
pub use settings::{PolicySettings, SettingsSource};

/// `--track MAP.yaml` as the `--set` it stands for (train, eval, view, agvrl-drive).
pub fn track_set(path: &std::path::Path) -> String {
    format!("env_config.track={}", toml::Value::String(path.display().to_string()))
}
