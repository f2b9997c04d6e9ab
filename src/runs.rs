//! Files the CLI writes: through a temporary file and a rename, so a crash never leaves a
//! half-written one. Run directories themselves are agvrl-run's (`RunDir`).

use anyhow::Result;
use std::path::Path;

/// Write `bytes` to `path` through a temporary file in the same directory, fsync and a rename
/// (agvrl-rl's, which policy files and checkpoints use too).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    Ok(agvrl_rl::write_atomic(path, bytes)?)
}
