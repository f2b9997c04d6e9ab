//! agvrl-envs: the reinforcement-learning contract.
#![warn(missing_docs)]

pub mod api;
pub mod pendulum;
pub mod registry;
pub mod vec_env;
pub mod wrappers;

pub use api::{BoxSpace, Env, EnvError, Info, Step};
pub use registry::{make, ENV_IDS};
pub use vec_env::{VecEnv, VecStep};
