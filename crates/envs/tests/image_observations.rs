//! Camera frames and image observations: a configured camera fills the sensor frame, the
//! camera-only observation and its depth noise, camera channels stacked after the LiDAR vector.

use super::*;
use agvrl_envs::task::{ImageChannels, ImageObs, ObsConfig};

#[test]
fn a_configured_camera_fills_the_sensor_frame() {
    let camera = Some(agvrl_sim::sensors::CameraConfig {
        width: 32,
        height: 24,
        ..Default::default()
    });
    let cfg = EnvConfig {
        sim: agvrl_sim::SimSettings {
            camera,
            ..Default::default()
        },
        spawn: SpawnMode::Fixed,
        ..EnvConfig::default()
    };
    let mut v = make_vehicle("racing-oval", &cfg).unwrap();
    let f = v.reset(0).unwrap();
    let img = f.image.expect("camera frame");
    assert_eq!(
        (img.width, img.height, img.rgb.len(), img.depth_m.len()),
        (32, 24, 32 * 24 * 3, 32 * 24)
    );
    let mut plain = make_vehicle("racing-oval", &EnvConfig::default()).unwrap();
    assert!(plain.reset(0).unwrap().image.is_none());
}

/// configs/racing-camera.toml's env settings.
fn camera_only() -> EnvConfig {
    let run: toml::Table = toml::from_str(include_str!("../../../configs/racing-camera.toml")).unwrap();
    run["env_config"].clone().try_into().unwrap()
}

/// Without the LiDAR the observation is speed, yaw rate, steering, throttle and the depth
/// image; under sim2real the depth gets noise growing with distance, holes and the minimum
/// range, and a pixel without a reading reads 0.
#[test]
fn a_camera_only_observation_and_its_depth_noise() {
    let cfg = EnvConfig {
        spawn: SpawnMode::Fixed,
        ..camera_only()
    };
    let mut env = make("racing-oval", &cfg).unwrap();
    let (obs, _) = env.reset(Some(0)).unwrap();
    assert_eq!(obs.len(), 4 + 64 * 48);
    assert_eq!(env.observation_space().dim(), obs.len());
    let image = &obs[4..];
    assert!(image.iter().all(|v| (0.0..=1.0).contains(v)));
    let clean_frame = make_vehicle("racing-oval", &cfg).unwrap().reset(0).unwrap();
    let depth = clean_frame.image.unwrap().depth_m;
    assert!(depth.iter().all(|z| z.is_finite()));
    let noisy_cfg = EnvConfig {
        noise: EnvConfig::sim2real().noise,
        ..cfg.clone()
    };
    let frame = make_vehicle("racing-oval", &noisy_cfg).unwrap().reset(0).unwrap();
    let noisy = frame.image.unwrap().depth_m;
    let holes = noisy.iter().filter(|z| z.is_nan()).count();
    // The ground just in front of the car lies within the camera's 0.3 m minimum range.
    let pairs = || depth.iter().zip(&noisy);
    assert!(pairs().filter(|(z, _)| **z < 0.299).all(|(_, n)| n.is_nan()));
    // 2 % holes elsewhere.
    let beyond = pairs().filter(|(z, _)| **z > 0.4).count();
    let far_holes = pairs().filter(|(z, n)| **z > 0.4 && n.is_nan()).count();
    let expected = 0.02 * beyond as f64;
    assert!(
        (far_holes as f64 - expected).abs() < 4.0 * expected.sqrt() + 2.0,
        "{far_holes} holes among {beyond} pixels"
    );
    let err = |near: bool| {
        let d: Vec<f64> = depth
            .iter()
            .zip(&noisy)
            .filter(|(z, n)| !n.is_nan() && (**z < 2.0) == near && **z < 8.0)
            .map(|(z, n)| ((n - z) / (z * z)) as f64)
            .collect();
        (d.iter().map(|v| v * v).sum::<f64>() / d.len() as f64).sqrt()
    };
    // The error over z^2 has the same spread near and far: 0.0033 / m.
    for near in [true, false] {
        assert!((err(near) - 0.0033).abs() < 0.001, "near {near}: {}", err(near));
    }
    let mut noisy_env = make("racing-oval", &noisy_cfg).unwrap();
    let (obs, _) = noisy_env.reset(Some(0)).unwrap();
    let zeros = obs[4..].iter().filter(|v| **v == 0.0).count();
    let too_near = depth.iter().filter(|z| **z < 0.299).count();
    assert!(
        too_near > 0 && zeros > too_near && holes > too_near,
        "{zeros} {too_near} {holes}"
    );
    let rgb = EnvConfig {
        observation: agvrl_envs::task::ObsConfig {
            image: agvrl_envs::task::ImageObs {
                channels: agvrl_envs::task::ImageChannels::Rgb,
                ..cfg.observation.image
            },
            ..cfg.observation
        },
        ..cfg
    };
    let e = make("racing-oval", &rgb).err().unwrap().to_string();
    assert!(e.contains("depth_only"), "{e}");
    // Search subjects are found by segmentation, which a depth camera leaves out.
    let mut search = camera_only();
    search.sim.subjects = 3;
    let e = make("search-outdoor-20", &search).err().unwrap().to_string();
    assert!(e.contains("segmentation") && e.contains("depth_only"), "{e}");
    search.sim.subjects = 0;
    assert!(make("search-outdoor-20", &search).is_ok());
}

fn cfg(channels: ImageChannels, camera: bool) -> EnvConfig {
    EnvConfig {
        sim: agvrl_sim::SimSettings {
            camera: camera.then(|| agvrl_sim::sensors::CameraConfig {
                width: 64,
                height: 48,
                ..Default::default()
            }),
            ..Default::default()
        },
        observation: ObsConfig {
            image: ImageObs {
                channels,
                width: 16,
                height: 12,
                depth_max_m: 12.0,
            },
            ..ObsConfig::default()
        },
        max_steps: 40,
        ..EnvConfig::default()
    }
}

#[test]
fn camera_channels_are_stacked_after_the_lidar_vector() {
    for (ch, n) in [
        (ImageChannels::Depth, 1),
        (ImageChannels::Rgb, 3),
        (ImageChannels::DepthRgb, 4),
    ] {
        let mut env = make("racing-oval", &cfg(ch, true)).unwrap();
        assert_eq!(env.observation_space().dim(), 104 + n * 16 * 12);
        check_env(env.as_mut(), 60).unwrap();
        let (obs, _) = env.reset(Some(1)).unwrap();
        let img = &obs[104..];
        assert!(img.iter().all(|v| (0.0..=1.0).contains(v)));
        assert!(
            img.iter().any(|v| *v > 0.0) && img.iter().any(|v| *v < 1.0),
            "{ch:?}: the image carries information"
        );
    }
    // Depth in the bottom row (the track just ahead) is nearer than in the middle row.
    let mut env = make("racing-oval", &cfg(ImageChannels::Depth, true)).unwrap();
    let (obs, _) = env.reset(Some(1)).unwrap();
    let img = &obs[104..];
    assert!(
        img[11 * 16 + 8] < img[6 * 16 + 8],
        "bottom {} middle {}",
        img[11 * 16 + 8],
        img[6 * 16 + 8]
    );
}

#[test]
fn image_observations_without_a_camera_are_refused() {
    let mut env = make("racing-oval", &cfg(ImageChannels::Depth, false)).unwrap();
    let e = env.reset(Some(0)).err().unwrap().to_string();
    assert!(e.contains("camera"), "{e}");
}
