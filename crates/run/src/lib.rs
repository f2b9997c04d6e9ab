//! What the `agvrl` command line, `agvrl-drive` and the Python wheel share above the learners.

mod error_line;

pub use error_line::error_line;
