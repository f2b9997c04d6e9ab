//! The bodies of the fuzz targets (`fuzz/`, cargo-fuzz on nightly), here so that the inputs
//! they found replay on stable in the tests (`fuzz_regressions_replay_without_panic`).

use crate::hardware::config::Ros2Config;
use crate::hardware::frames::FrameBuilder;
use crate::hardware::msg;
use agvrl_envs::api::Control;
use std::path::Path;

/// `bag_reader`: MCAP bytes through the bag reader, and every message it yields through the
/// decoder of its type.
pub fn read_and_decode(data: &[u8]) {
    if let Ok((msgs, _)) = super::read_mcap(data, Path::new("fuzz.mcap")) {
        for m in &msgs {
            let _ = crate::record::decode_json(m);
        }
    }
}

/// `ros2_messages`: byte 0 picks LaserScan, Imu, Odometry, NavSatFix or Image; the rest is the
/// message's CDR bytes with their encapsulation header, decoded and fed to a live car's
/// [`FrameBuilder`] (the scan mapping, the depth camera cut) whose frame is then built.
pub fn ros2_message(data: &[u8]) {
    let Some((&which, body)) = data.split_first() else {
        return;
    };
    let camera = agvrl_sim::sensors::CameraConfig {
        width: 64,
        height: 48,
        fov_deg: 70.0,
        depth_only: true,
        ..Default::default()
    };
    let mut f = FrameBuilder::new(Ros2Config::default(), Some(camera));
    let fed = match which % 5 {
        0 => super::decode::<msg::LaserScan>(body).map(|m| f.scan(m)),
        1 => super::decode::<msg::Imu>(body).map(|m| f.imu(m)),
        2 => super::decode::<msg::Odometry>(body).map(|m| f.odom(m)),
        3 => super::decode::<msg::NavSatFix>(body).map(|m| f.navsat(m)),
        _ => super::decode::<msg::Image>(body).map(|m| f.image(&m)),
    };
    if fed.is_ok() {
        let _ = f.frame(Control::default());
    }
}
