//! agvrl-envs integration tests, one binary with a module per topic: the Env contract, episodes
//! and rewards, vector envs and noise, camera frames and image observations, the search task, the
//! safety filter, races and racing rules, the classical drivers. The imports and helpers here serve
//! the topic modules that start with `use super::*;`.

mod drivers;
mod env_contract;
mod episodes;
mod image_observations;
mod racing_against_others;
mod racing_rules;
mod safety_filter;
mod search_task;
mod vec_and_noise;
mod vec_env_properties;

use agvrl_envs::api::{Control, MapInfo, SensorFrame, TerminationCause};
use agvrl_envs::pendulum::{Pendulum, angle_normalize};
use agvrl_envs::task::racing::RacingConfig;
use agvrl_envs::task::{Racing, Task};
use agvrl_envs::wrappers::TimeLimit;
use agvrl_envs::*;

fn quick_cfg() -> EnvConfig {
    EnvConfig::default()
}
