//! `agvrl probe`: what does the car see here?

use agvrl_envs::registry::scene_of;
use agvrl_sim::{PlanarPose, SceneSource, Sim, SimConfig};
use anyhow::{Context, Result, bail};
use clap::Args;

#[derive(Args)]
pub struct ProbeArgs {
    /// Environment id (a vehicle env: search-* or racing-oval).
    #[arg(long)]
    env: String,
    /// Vehicle pose as x,y,yaw (metres, metres, radians).
    #[arg(long, allow_hyphen_values = true)]
    pose: String,
}

pub fn probe(a: ProbeArgs) -> Result<()> {
    let Some(scene) = scene_of(&a.env) else {
        bail!(
            "'{}' is not a vehicle env; vehicle envs: search-outdoor-20, search-outdoor-50, search-urban-20, search-urban-50, racing-oval",
            a.env
        )
    };
    let p: Vec<f32> = a
        .pose
        .split(',')
        .map(|s| s.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .with_context(|| format!("--pose '{}': expected x,y,yaw numbers", a.pose))?;
    let [x, y, yaw] = p[..] else {
        bail!("--pose '{}': expected three numbers x,y,yaw", a.pose)
    };
    if !(x.is_finite() && y.is_finite() && yaw.is_finite()) {
        bail!("--pose must be finite");
    }
    let mut sim = Sim::new(SimConfig {
        scene: SceneSource::Builtin(scene.into()),
        ..SimConfig::default()
    })?;
    sim.reset(PlanarPose {
        x_m: x,
        y_m: y,
        yaw_rad: yaw,
    })?;
    let scan = sim.lidar_scan();
    let out = serde_json::json!({
        "env": a.env,
        "pose": {"x_m": x, "y_m": y, "yaw_rad": yaw},
        "free": sim.free_at(x, y, 0.3),
        "scan": scan,
        "gps": sim.gps(),
        "imu": sim.imu(),
    });
    println!("{}", serde_json::to_string_pretty(&out)?);
    Ok(())
}
