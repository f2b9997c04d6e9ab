//! GPS: the base link's pose, with an optional geodetic fix around a configured origin.

use crate::msg::{Geodetic, GpsReading};
use rapier3d::prelude::*;
use serde::{Deserialize, Serialize};

/// GPS settings.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct GpsConfig {
    /// Geodetic coordinates of the world origin; when set, readings carry latitude/longitude.
    pub origin: Option<Geodetic>,
}

const EARTH_RADIUS_M: f64 = 6_378_137.0;

/// Read the GPS at base pose `pose_w`.
pub fn read(cfg: &GpsConfig, pose_w: &Pose) -> GpsReading {
    let t = pose_w.translation.as_dvec3();
    let q = pose_w.rotation.as_dquat();
    let (yaw, pitch, roll) = q.to_euler(glam_euler());
    let geodetic = cfg.origin.map(|o| {
        // Flat-earth (local tangent plane) approximation: x east, y north.
        let lat0 = o.latitude_deg.to_radians();
        Geodetic {
            latitude_deg: o.latitude_deg + (t.y / EARTH_RADIUS_M).to_degrees(),
            longitude_deg: o.longitude_deg + (t.x / (EARTH_RADIUS_M * lat0.cos())).to_degrees(),
            altitude_m: o.altitude_m + t.z,
        }
    });
    GpsReading {
        position_m: t.to_array(),
        orientation_xyzw: q.to_array(),
        rpy_rad: [roll, pitch, yaw],
        geodetic,
    }
}

fn glam_euler() -> rapier3d::glamx::EulerRot {
    rapier3d::glamx::EulerRot::ZYX
}
