//! agvrl-rl integration tests (one binary).

mod config;
mod files;
mod image_encoder;
mod learning;
mod reach;
mod resume;
mod seeding;
