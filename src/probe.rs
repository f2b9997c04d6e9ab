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
    /// Also write the vehicle camera's RGB view at that pose to this PNG file.
    #[arg(long)]
    image: Option<std::path::PathBuf>,
    /// Camera image size as WIDTHxHEIGHT.
    #[arg(long, default_value = "400x300")]
    image_size: String,
}

/// Write an RGB8 image as PNG (through a temporary file and a rename).
pub fn write_png(path: &std::path::Path, width: u32, height: u32, rgb: &[u8]) -> Result<()> {
    let mut bytes = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut bytes, width, height);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut w = enc.write_header()?;
        w.write_image_data(rgb)?;
    }
    Ok(agvrl_run::write_atomic(path, &bytes)?)
}

/// Read an RGB8 PNG back: (width, height, pixels).
#[cfg(test)]
pub fn read_png(path: &std::path::Path) -> Result<(u32, u32, Vec<u8>)> {
    let dec = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path)?));
    let mut r = dec.read_info()?;
    let mut buf = vec![0; r.output_buffer_size().unwrap_or(0)];
    let info = r.next_frame(&mut buf)?;
    buf.truncate(info.buffer_size());
    Ok((info.width, info.height, buf))
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
    let camera = match &a.image {
        Some(_) => {
            let (w, h) = a
                .image_size
                .split_once('x')
                .and_then(|(w, h)| Some((w.parse::<u32>().ok()?, h.parse::<u32>().ok()?)))
                .with_context(|| format!("--image-size '{}': expected WIDTHxHEIGHT", a.image_size))?;
            Some(agvrl_sim::sensors::CameraConfig {
                width: w,
                height: h,
                ..Default::default()
            })
        }
        None => None,
    };
    let mut sim = Sim::new(SimConfig {
        scene: SceneSource::Builtin(scene.into()),
        settings: agvrl_sim::SimSettings {
            camera,
            ..Default::default()
        },
    })?;
    sim.reset(PlanarPose {
        x_m: x,
        y_m: y,
        yaw_rad: yaw,
    })?;
    let scan = sim.lidar_scan(0);
    let out = serde_json::json!({
        "env": a.env,
        "pose": {"x_m": x, "y_m": y, "yaw_rad": yaw},
        "free": sim.free_at(x, y, 0.3),
        "scan": scan,
        "gps": sim.car(0).gps(),
        "imu": sim.car(0).imu(),
    });
    println!("{}", serde_json::to_string_pretty(&out)?);
    if let (Some(path), Some(f)) = (&a.image, sim.car(0).camera_frame()) {
        write_png(path, f.frame.width, f.frame.height, &f.frame.rgb)?;
        eprintln!("wrote {}", path.display());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    #[test]
    fn png_round_trip_keeps_every_pixel() {
        let (w, h) = (7u32, 5u32);
        let rgb: Vec<u8> = (0..w * h * 3).map(|i| (i * 37 % 251) as u8).collect();
        let p = std::env::temp_dir().join(format!("agvrl-png-{}.png", std::process::id()));
        super::write_png(&p, w, h, &rgb).unwrap();
        let back = super::read_png(&p);
        let _ = std::fs::remove_file(&p);
        assert_eq!(back.unwrap(), (w, h, rgb));
    }
}
