//! When an episode ends: too close (LiDAR), contact, flipped, out of the map.

use crate::api::{MapInfo, RewardTerms, SensorFrame, TerminationCause};

/// The minimum LiDAR range of a frame, metres (infinite without a scan).
pub fn min_range_m(frame: &SensorFrame) -> f64 {
    frame
        .scan
        .as_ref()
        .map(|s| s.min_range())
        .unwrap_or(f32::INFINITY)
        .min(1e6) as f64
}

/// The minimum range to the static scene, metres: rays that met another car are left out (a
/// world of several cars; one car's scans, simulated or real, name no car).
pub fn min_static_range_m(frame: &SensorFrame) -> f64 {
    frame
        .scan
        .as_ref()
        .map(|s| s.min_static_range())
        .unwrap_or(f32::INFINITY)
        .min(1e6) as f64
}

/// The minimum range among the rays within `fov_deg / 2` of straight ahead, metres (the whole
/// scan when `fov_deg` is 0; infinite without a scan).
pub fn min_range_ahead_m(frame: &SensorFrame, fov_deg: f32) -> f64 {
    if fov_deg <= 0.0 {
        return min_range_m(frame);
    }
    frame
        .scan
        .as_ref()
        .map(|s| s.min_range_within(0.5 * fov_deg.to_radians()))
        .unwrap_or(f32::INFINITY)
        .min(1e6) as f64
}

/// Termination by `common_termination`, charging `penalty` once as the collision term.
pub fn terminate(
    terms: &mut RewardTerms,
    frame: &SensorFrame,
    map: Option<&MapInfo>,
    r_m: f64,
    threshold_m: f32,
    penalty: f64,
) -> Option<TerminationCause> {
    let t = common_termination(frame, map, r_m, threshold_m);
    if t.is_some() && terms.collision == 0.0 {
        terms.collision = penalty;
    }
    t
}

/// Termination shared by the tasks: too close (`r_m`, the task's minimum range, below
/// `threshold_m`), real contact, flipped, or out of the map. Returns the first that applies, in
/// that order.
pub fn common_termination(
    frame: &SensorFrame,
    map: Option<&MapInfo>,
    r_m: f64,
    threshold_m: f32,
) -> Option<TerminationCause> {
    if frame.scan.is_some() && (r_m as f32) < threshold_m {
        return Some(TerminationCause::TooClose);
    }
    if frame.contact == Some(true) {
        return Some(TerminationCause::Contact);
    }
    if let Some(imu) = &frame.imu {
        let [x, y, _, _] = imu.orientation_xyzw;
        // World z of the body's z axis: 1 - 2 (x^2 + y^2).
        if 1.0 - 2.0 * (x * x + y * y) < 0.5 {
            return Some(TerminationCause::Flipped);
        }
    }
    if let (Some(m), Some(g)) = (map, &frame.gps) {
        let [px, py, _] = g.position_m;
        if px.abs() as f32 > m.half_extent_m[0] + 0.5 || py.abs() as f32 > m.half_extent_m[1] + 0.5 {
            return Some(TerminationCause::OutOfBounds);
        }
    }
    None
}
