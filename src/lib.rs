//! The agvrl application layer, shared by the `agvrl` CLI and the Python package: run
//! configurations, training into run directories, evaluation, plots and recordings.

pub mod bench;
pub mod circuit;
pub mod cli;
pub mod config;
// Without rerun, nothing reads what only recordings use.
#[cfg_attr(not(feature = "rerun"), allow(dead_code))]
pub mod episode;
pub mod eval;
pub mod eval_bag;
pub mod planner;
pub mod plots;
pub mod policy_file;
pub mod probe;
pub mod race;
pub mod racer;
#[cfg_attr(not(feature = "rerun"), allow(dead_code))]
pub mod selfplay;
pub mod sink;
pub mod train;
#[cfg_attr(not(feature = "rerun"), allow(dead_code))]
pub mod view;
#[cfg_attr(not(feature = "rerun"), path = "viz_off.rs")]
pub mod viz;
