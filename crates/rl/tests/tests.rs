//! agvrl-rl integration tests (one binary).

mod issue_4_config;
mod issue_4_files;
mod issue_4_learning;
mod issue_4_seeding;
mod issue_6_cnn;
mod reach;
