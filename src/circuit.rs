//! `agvrl circuit`: write one generated circuit to disk as a map_server track (YAML, PNG and
//! the centre-line CSV), the files `--track` and F1TENTH's tools read.

use agvrl_sim::{CircuitSettings, MapTrack, Scene};
use anyhow::{Context, Result};
use clap::Args;
use std::path::PathBuf;

#[derive(Args)]
pub struct CircuitArgs {
    /// The circuit's seed (racing-circuit draws the same circuit for the same layout seed).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Take the seed from the held-out half, as evaluation episodes do (training never draws
    /// these circuits).
    #[arg(long)]
    pub held_out: bool,
    /// The folder to write NAME.yaml, NAME.png and NAME.csv into (created if missing).
    #[arg(long, short)]
    pub out: PathBuf,
    /// A generator setting, KEY=VALUE (`--set width_m=[1.5,2.0]`); keys as in
    /// `[env_config.circuit]`.
    #[arg(long, value_name = "KEY=VALUE")]
    pub set: Vec<String>,
    /// Also draw the circuit (walls, centre line, start) into this PNG.
    #[arg(long, value_name = "FILE.png")]
    pub plot: Option<PathBuf>,
}

/// The generator's settings under `sets` (`KEY=VALUE`, values in TOML).
pub fn settings(sets: &[String]) -> Result<CircuitSettings> {
    let mut table = toml::Table::try_from(CircuitSettings::default()).context("circuit settings")?;
    for s in sets {
        let (k, v) = s
            .split_once('=')
            .with_context(|| format!("--set {s}: expected KEY=VALUE"))?;
        let value: toml::Value = toml::from_str::<toml::Table>(&format!("v = {v}"))
            .map(|mut t| t.remove("v").unwrap_or(toml::Value::String(v.into())))
            .unwrap_or_else(|_| toml::Value::String(v.into()));
        table.insert(k.trim().to_string(), value);
    }
    let s: CircuitSettings = table.try_into().context("circuit settings")?;
    s.validate()?;
    Ok(s)
}

pub fn circuit(a: CircuitArgs) -> Result<()> {
    let settings = settings(&a.set)?;
    let seed = agvrl_envs::heldout::split(a.seed, a.held_out);
    let (track, info) = MapTrack::generated(seed, &settings)?;
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let yaml = agvrl_sim::scene::write_map(&track, &info, &a.out)?;
    println!("circuit={}", track.name);
    println!("seed={seed}");
    println!("lap_m={:.2}", info.length_m);
    println!("width_m={:.2}", info.width_m);
    println!("min_radius_m={:.2}", info.min_radius_m);
    println!(
        "direction={}",
        if info.clockwise {
            "clockwise"
        } else {
            "counterclockwise"
        }
    );
    println!("walls={}", track.walls.len());
    println!("pockets={}", info.pockets.len());
    println!("yaml={}", yaml.display());
    if let Some(p) = &a.plot {
        let scene = Scene::from_map(&track)?;
        let centre = crate::plots::Path2 {
            xy: track.centreline.iter().map(|p| (p[0], p[1])).collect(),
            collided: false,
            label: Some("centre line".into()),
        };
        crate::plots::trajectory(
            p,
            &scene,
            &[centre],
            &format!(
                "{}: {:.0} m, {:.1} m wide, tightest radius {:.1} m",
                track.name, info.length_m, info.width_m, info.min_radius_m
            ),
        )?;
        println!("plot={}", p.display());
    }
    Ok(())
}
