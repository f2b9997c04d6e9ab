//! Where a recording goes, and what a bag drawn into one held: the same with or without the
//! `rerun` feature.

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

/// What `agvrl view --bag` put into the recording.
#[derive(Debug, Default)]
pub struct BagView {
    /// Scans, poses, images, ticks drawn.
    pub scans: u64,
    pub poses: u64,
    pub images: u64,
    pub ticks: u64,
    /// Messages of topics with nothing to draw (the raw MCAP in rerun shows what it knows).
    pub skipped: u64,
    /// Where the bag stopped being readable, if it did.
    pub damage: Option<String>,
}
