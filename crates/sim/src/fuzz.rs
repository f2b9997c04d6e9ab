//! The body of the fuzz target on the files a user writes for the simulator (`fuzz/`,
//! cargo-fuzz on nightly), here so that the inputs it kept replay on stable
//! (`fuzz_regressions_*`).

use crate::assets::{AssetSource, embedded_files};
use crate::urdf::UrdfModel;
use crate::{Control, SceneSource, Sim, SimConfig, SimSettings};
use rapier3d::prelude::Vector;

/// A private copy of the built-in assets, where a fuzzed file replaces one of them; one per
/// input, removed when dropped, so replays leave nothing in the temp folder.
fn assets_dir() -> tempfile::TempDir {
    let dir = tempfile::Builder::new()
        .prefix("agvrl-fuzz-assets-")
        .tempdir()
        .expect("temp dir");
    for (rel, text) in embedded_files() {
        let path = dir.path().join(rel);
        std::fs::create_dir_all(path.parent().expect("a file in a folder")).expect("temp dir");
        std::fs::write(&path, text).expect("temp dir");
    }
    dir
}

/// `asset_files`: byte 0 picks the file, the rest is its text, loaded as a user's file is:
/// - 0: a scene TOML (`--set env_config.scene=...`), built into a simulator with XTENTH-CAR;
/// - 1: a vehicle TOML, or 2: the URDF XTENTH-CAR's TOML names, in a simulator on the oval;
/// - 3: an object URDF, read and its collision shapes built.
///
/// A simulator that builds is driven for a few control periods, and scanned.
pub fn asset_file(data: &[u8]) {
    let Some((&which, body)) = data.split_first() else {
        return;
    };
    let Ok(text) = std::str::from_utf8(body) else {
        return;
    };
    let assets = assets_dir();
    let dir = assets.path();
    let mut cfg = SimConfig::default();
    match which % 4 {
        0 => {
            let path = dir.join("scenes/fuzz.toml");
            std::fs::write(&path, text).expect("temp dir");
            cfg.scene = SceneSource::File(path);
        }
        1 => {
            let path = dir.join("vehicles/fuzz.toml");
            std::fs::write(&path, text).expect("temp dir");
            cfg.settings = vehicle(&path);
        }
        2 => {
            let toml = embedded_files()
                .iter()
                .find(|(p, _)| *p == "vehicles/xtenth_car.toml")
                .expect("XTENTH-CAR is built in")
                .1
                .replace("xtenth_car.urdf", "fuzz.urdf");
            std::fs::write(dir.join("vehicles/fuzz.urdf"), text).expect("temp dir");
            let path = dir.join("vehicles/fuzz-urdf.toml");
            std::fs::write(&path, toml).expect("temp dir");
            cfg.settings = vehicle(&path);
        }
        _ => {
            let src = AssetSource::Dir(dir.to_path_buf());
            if let Ok(model) = UrdfModel::parse(&src, "objects/fuzz.urdf", text) {
                let _ = model.collision_shapes(&src, Vector::new(1.0, 1.0, 1.0), |_| true);
            }
            return;
        }
    }
    drive(cfg);
}

/// Build a simulator from `cfg` (when it builds), drive it for a few control periods, and scan.
fn drive(cfg: SimConfig) {
    let Ok(mut sim) = Sim::new(cfg) else {
        return;
    };
    for throttle in [1.0, 1.0, -1.0] {
        let control = Control {
            throttle,
            steering_rad: 0.3,
        };
        if sim.step(control).is_err() {
            return;
        }
    }
    let _ = sim.lidar_scan(0);
}

fn vehicle(path: &std::path::Path) -> SimSettings {
    SimSettings {
        vehicle: path.display().to_string(),
        ..SimSettings::default()
    }
}

/// `map_file`: a map-file track as `--track` loads one. The input is
/// `[yaml length: u16 LE][YAML][CSV length: u16 LE][CSV][image]`, written as `map.yaml`,
/// `map.csv` (when its length is not 0) and both `map.pgm` and `map.png`. A track that loads is
/// built into a simulator, driven for a few control periods, and scanned.
pub fn map_file(data: &[u8]) {
    fn take<'a>(data: &mut &'a [u8]) -> Option<&'a [u8]> {
        let (len, rest) = data.split_first_chunk::<2>()?;
        let n = u16::from_le_bytes(*len) as usize;
        let (part, rest) = (rest.get(..n)?, rest.get(n..)?);
        *data = rest;
        Some(part)
    }
    let mut rest = data;
    let (Some(yaml), Some(csv)) = (take(&mut rest), take(&mut rest)) else {
        return;
    };
    // A map file names only its own files: an empty folder of its own, no copy of the assets.
    let folder = tempfile::Builder::new()
        .prefix("agvrl-fuzz-map-")
        .tempdir()
        .expect("temp dir");
    let dir = folder.path();
    std::fs::write(dir.join("map.yaml"), yaml).expect("temp dir");
    if !csv.is_empty() {
        std::fs::write(dir.join("map.csv"), csv).expect("temp dir");
    }
    for name in ["map.pgm", "map.png"] {
        std::fs::write(dir.join(name), rest).expect("temp dir");
    }
    let Ok(track) = crate::MapTrack::load(&dir.join("map.yaml")) else {
        return;
    };
    let cfg = SimConfig {
        scene: SceneSource::Map(Box::new(track)),
        ..SimConfig::default()
    };
    drive(cfg);
}
