//! agvrl-run integration tests (one binary).

mod policy_settings;
mod run_config;
