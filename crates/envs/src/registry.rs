//! `make(id, config)`: every env agvrl ships, by id.

use crate::api::{Env, EnvError};
use crate::pendulum::Pendulum;
use crate::wrappers::TimeLimit;

/// Ids `make` knows.
pub const ENV_IDS: &[&str] = &["pendulum"];

/// Build the env registered under `id`.
pub fn make(id: &str) -> Result<Box<dyn Env>, EnvError> {
    match id {
        "pendulum" => Ok(Box::new(TimeLimit::new(Pendulum::new(), 200))),
        _ => Err(EnvError::UnknownId { id: id.to_string(), valid: ENV_IDS.iter().map(|s| s.to_string()).collect() }),
    }
}
