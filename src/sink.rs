//! Where a recording goes: the same choice with or without the `rerun` feature.

use std::path::{Path, PathBuf};

/// Where a recording goes.
pub enum Sink {
    /// An .rrd file (written to a temp name, renamed on `finish`).
    File(PathBuf),
    /// A rerun viewer spawned from `rerun` on PATH.
    Viewer,
}

/// `--rerun FILE` / `--spawn-viewer` as a sink.
pub fn sink_of(file: Option<&Path>, spawn: bool) -> Option<Sink> {
    match (file, spawn) {
        (Some(f), _) => Some(Sink::File(f.to_path_buf())),
        (None, true) => Some(Sink::Viewer),
        (None, false) => None,
    }
}
