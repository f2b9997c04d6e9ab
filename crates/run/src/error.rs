//! The crate's one error type.

use std::path::PathBuf;
use thiserror::Error;

/// Why a run configuration, a run directory or a policy's settings could not be used.
#[derive(Debug, Error)]
pub enum RunError {
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// A run TOML or a setting is invalid; the message names the file (or `--set`) and the key.
    #[error("{0}")]
    Config(String),
    /// A run directory cannot be created or published.
    #[error("{0}")]
    RunDir(String),
    /// A policy file could not be read.
    #[error(transparent)]
    Policy(#[from] agvrl_rl::RlError),
}

/// Results of this crate.
pub type Result<T> = std::result::Result<T, RunError>;
