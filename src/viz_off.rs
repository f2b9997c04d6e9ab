//! Stand-in for `viz.rs` when agvrl is built without the `rerun` feature: asking for a
//! recording is an error that says how to get one.

use crate::episode::StepView;
use anyhow::{Result, bail};
use std::path::PathBuf;

pub use crate::sink::{BagView, Sink, sink_of};

/// Never constructed without the feature.
pub struct Recorder {
    _private: (),
}

impl Recorder {
    pub fn new(_sink: Sink, _name: &str, _camera: Option<&agvrl_sim::sensors::CameraConfig>) -> Result<Self> {
        bail!("this agvrl was built without rerun; rebuild with the default features (cargo build --release)")
    }

    pub fn step(&mut self, _v: &StepView<'_>) -> Result<()> {
        Ok(())
    }

    pub fn race_step(
        &mut self,
        _sim: &agvrl_sim::Sim,
        _scans: &[Option<&agvrl_sim::msg::LaserScan>],
        _race: usize,
        _step: u64,
    ) -> Result<()> {
        Ok(())
    }

    pub fn finish(self) -> Result<Option<PathBuf>> {
        Ok(None)
    }
}

/// Whether recordings can be made.
pub const ENABLED: bool = false;

pub fn bag(_sink: Sink, _dir: &std::path::Path) -> Result<(Option<PathBuf>, BagView)> {
    bail!("this agvrl was built without rerun; rebuild with the default features (cargo build --release)")
}
