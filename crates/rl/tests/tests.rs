//! agvrl-rl integration tests (one binary).

mod cnn;
mod config;
mod files;
mod learning;
mod reach;
mod sb3_numerics;
mod seeding;
