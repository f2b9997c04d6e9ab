use std::path::PathBuf;
use thiserror::Error;

/// Everything that can go wrong in the simulator, with the file and the problem named.
#[derive(Debug, Error)]
pub enum SimError {
    /// A file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// A URDF file is malformed or uses something we do not support.
    #[error("{path}: bad URDF: {msg}")]
    Urdf {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        msg: String,
    },
    /// A TOML file (scene, vehicle) is malformed.
    #[error("{path}: {msg}")]
    Toml {
        /// The file.
        path: PathBuf,
        /// What is wrong (from the TOML parser, with line and column).
        msg: String,
    },
    /// A mesh could not be loaded.
    #[error("{path}: bad mesh: {msg}")]
    Mesh {
        /// The mesh file.
        path: PathBuf,
        /// What is wrong.
        msg: String,
    },
    /// A vehicle or scene description is inconsistent (missing joint, unknown model, ...).
    #[error("{context}: {msg}")]
    Invalid {
        /// Where (file or component).
        context: String,
        /// What is wrong.
        msg: String,
    },
    /// The simulation produced NaN or infinity.
    #[error("simulation state is not finite: {0}")]
    NotFinite(String),
}

/// A setting outside the values it may take. Every settings table's `validate` returns it, so a
/// caller can tell a bad setting from a failed read and knows which table to point at.
#[derive(Clone, Debug, PartialEq, Eq, Error)]
#[error("{message}")]
pub struct InvalidSetting {
    /// The settings table: `lidar`, `camera`, `safety_filter`, `safe_reward`,
    /// `observation.explored`, `car config`.
    pub table: &'static str,
    /// What is wrong, naming the key and the value.
    pub message: String,
}

impl InvalidSetting {
    /// A bad setting of `table`.
    pub fn new(table: &'static str, message: impl Into<String>) -> Self {
        Self {
            table,
            message: message.into(),
        }
    }
}
