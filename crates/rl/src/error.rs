//! The crate's one error type.

use agvrl_envs::EnvError;
use std::path::PathBuf;
use thiserror::Error;

/// Why training, saving or loading failed.
#[derive(Debug, Error)]
pub enum RlError {
    /// The env failed to reset or step.
    #[error("env: {0}")]
    Env(#[from] EnvError),
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// A policy or checkpoint file is truncated, corrupted or of another format/version.
    #[error("{path}: {reason}")]
    BadFile {
        /// The file.
        path: PathBuf,
        /// What is wrong with it.
        reason: String,
    },
    /// A policy or checkpoint does not fit the env it is used with.
    #[error("{what} mismatch: file has {file}, env has {env}")]
    Mismatch {
        /// Which property differs (observation space, action space, algorithm).
        what: &'static str,
        /// The file's value.
        file: String,
        /// The env's value.
        env: String,
    },
    /// A configuration value is invalid or the TOML could not be parsed.
    #[error("config: {0}")]
    Config(String),
    /// An observation or action has the wrong length.
    #[error("{what} has {got} elements, expected a multiple of {dim}")]
    Shape {
        /// Observation or action.
        what: &'static str,
        /// Elements given.
        got: usize,
        /// Elements per row.
        dim: usize,
    },
    /// Training produced a non-finite value (loss or weight).
    #[error("non-finite {0} during training")]
    NonFinite(&'static str),
    /// A bug inside agvrl-rl (a worker thread panicked); the run cannot go on.
    #[error("internal error: {0}")]
    Internal(String),
    /// Reading tensor data back from the device failed.
    #[error("tensor data: {0}")]
    Tensor(String),
}

/// Result with [`RlError`].
pub type Result<T> = std::result::Result<T, RlError>;
