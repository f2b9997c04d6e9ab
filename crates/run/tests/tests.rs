//! agvrl-run integration tests (one binary).

mod policy_settings;
mod report;
mod run_config;
