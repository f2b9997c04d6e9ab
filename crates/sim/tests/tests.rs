//! agvrl-sim integration tests, one binary with a module per topic: physics against closed forms,
//! sensors, determinism, scenes, errors, camera images, map tracks, several cars, generated
//! circuits, the F1TENTH car. The helpers here (scratch rooms, a simulator per dynamics mode) serve
//! several topics; each topic module starts with `use super::*;`.

mod camera_images;
mod circuits;
mod dynamics;
mod errors;
mod f1tenth;
mod lidar_properties;
mod map_tracks;
mod scene_files;
mod sensor_readings;
mod several_cars;

use agvrl_sim::assets::AssetSource;
use agvrl_sim::*;
use rapier3d::prelude::*;
use std::path::PathBuf;

/// A pose the simulator gives as rapier's, for the tests' geometry.
fn rp(p: &agvrl_sim::msg::Pose3) -> Pose {
    Pose::from_parts(
        Vector::from_array(p.position_m),
        Rotation::from_array(p.orientation_xyzw),
    )
}

/// A rapier pose as the simulator takes it.
fn mp(p: &Pose) -> agvrl_sim::msg::Pose3 {
    agvrl_sim::msg::Pose3 {
        position_m: p.translation.to_array(),
        orientation_xyzw: p.rotation.to_array(),
    }
}

const MODES: [DynamicsMode; 2] = [DynamicsMode::Raycast, DynamicsMode::Multibody];

/// A scratch directory, removed with everything in it when the guard drops.
fn tmpdir(name: &str) -> tempfile::TempDir {
    tempfile::Builder::new()
        .prefix(&format!("agvrl-sim-test-{name}-"))
        .tempdir()
        .unwrap()
}

/// A scene file in a scratch directory; the file lives as long as the guard (a `Sim` reads it
/// once, when it is built).
struct Room {
    path: PathBuf,
    _dir: tempfile::TempDir,
}

impl Room {
    fn src(&self) -> SceneSource {
        SceneSource::File(self.path.clone())
    }
}

/// A square room with walls only (inner faces at +-half), written to a temp file.
fn room(half: f32, name: &str) -> Room {
    walled_room(half, 0.5, name)
}

/// As [`room`], with walls `thickness` metres thick.
fn walled_room(half: f32, thickness: f32, name: &str) -> Room {
    let d = tmpdir(name);
    let p = d.path().join("room.toml");
    std::fs::write(
        &p,
        format!(
            "name = \"room\"\nkind = \"outdoor\"\n[ground]\nsize_m = [{s}, {s}]\nfriction = 1.0\ncolor = [0.5, 0.5, 0.5]\n\
             [boundary]\ninner_half_m = {half}\nthickness_m = {thickness}\nheight_m = 1.0\ncolor = [0.6, 0.6, 0.6]\n\
             [spawn]\nx_m = 0.0\ny_m = 0.0\nyaw_deg = 0.0\n",
            s = 2.0 * half + 2.0
        ),
    )
    .unwrap();
    Room { path: p, _dir: d }
}

fn sim(scene: SceneSource, mode: DynamicsMode) -> Sim {
    Sim::new(SimConfig {
        scene,
        settings: SimSettings {
            dynamics: mode,
            ..Default::default()
        },
    })
    .unwrap()
}

fn run(s: &mut Sim, c: Control, steps: usize) {
    for _ in 0..steps {
        s.step(c).unwrap();
    }
}
