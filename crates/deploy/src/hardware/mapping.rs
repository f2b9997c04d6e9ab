//! Conversions between ROS 2 messages and agvrl's plain readings, both ways: the car's side
//! (messages in, `SensorFrame` parts out, `Control` to a drive command) and the sim-backed
//! robot's side (readings to messages, a drive command back to `Control`).

use super::config::{CameraMapping, DriveMapping, InvalidRay, ScanMapping};
use super::msg;
use agvrl_envs::api::Control;
use agvrl_sim::msg::{CameraFrame, Geodetic, GpsReading, ImuReading, LaserScan};
use agvrl_sim::sensors::CameraConfig;

/// Resample a `sensor_msgs/LaserScan` to the policy's rays (see [`ScanMapping`]). A ray with
/// no valid reading follows `m.invalid`; with `InvalidRay::Stop` it is NaN, which the watchdog
/// refuses, so NaN never reaches the policy.
pub fn scan_to_rays(scan: &msg::LaserScan, m: &ScanMapping) -> LaserScan {
    let n = m.n_rays.max(1);
    let (inc_out, half) = if n == 1 {
        (0.0, 0.5 * (m.angle_max_rad - m.angle_min_rad))
    } else {
        let inc = (m.angle_max_rad - m.angle_min_rad) / (n - 1) as f32;
        (inc, 0.5 * inc)
    };
    let centre = 0.5 * (m.angle_min_rad + m.angle_max_rad);
    let n_src = scan.ranges.len();
    let valid = |r: f32| -> Option<f32> {
        if r.is_nan() {
            None
        } else if r == f32::INFINITY {
            Some(m.range_max_m)
        } else if r == f32::NEG_INFINITY {
            Some(m.range_min_m)
        } else {
            Some(r.clamp(m.range_min_m, m.range_max_m))
        }
    };
    let src_inc = scan.angle_increment;
    let usable = n_src > 0 && src_inc.is_finite() && scan.angle_min.is_finite() && (src_inc != 0.0 || n_src == 1);
    let mut ranges = Vec::with_capacity(n);
    for j in 0..n {
        let a = if n == 1 {
            centre
        } else {
            m.angle_min_rad + j as f32 * inc_out
        };
        let mut best: Option<f32> = None;
        if usable {
            for i in bin_indices(a, half, scan.angle_min, src_inc, n_src) {
                if let Some(r) = valid(scan.ranges[i]) {
                    best = Some(best.map_or(r, |b| b.min(r)));
                }
            }
        }
        ranges.push(best.unwrap_or(match m.invalid {
            InvalidRay::Stop => f32::NAN,
            InvalidRay::RangeMax => m.range_max_m,
            InvalidRay::RangeMin => m.range_min_m,
        }));
    }
    let hit = ranges.iter().map(|r| *r < m.range_max_m).collect();
    LaserScan {
        angle_min: if n == 1 { centre } else { m.angle_min_rad },
        angle_increment: inc_out,
        range_min: m.range_min_m,
        range_max: m.range_max_m,
        ranges,
        hit,
        ..LaserScan::default()
    }
}

/// Indices of the source rays within `half` of bearing `a` (1e-4 of a spacing of slack, so
/// equal grids map one to one), or the nearest ray when none falls inside; empty outside the
/// scan.
fn bin_indices(a: f32, half: f32, angle_min: f32, inc: f32, n_src: usize) -> std::ops::Range<usize> {
    if inc == 0.0 {
        return if (a - angle_min).abs() <= half + 1e-6 {
            0..1
        } else {
            0..0
        };
    }
    let x0 = (a - half - angle_min) / inc;
    let x1 = (a + half - angle_min) / inc;
    let (x0, x1) = if x0 <= x1 { (x0, x1) } else { (x1, x0) };
    let lo = (x0 - 1e-4).ceil().max(0.0);
    let hi = (x1 + 1e-4).floor().min(n_src as f32 - 1.0);
    if lo <= hi {
        return lo as usize..hi as usize + 1;
    }
    let k = ((a - angle_min) / inc).round();
    if k >= 0.0 && k < n_src as f32 && (angle_min + k * inc - a).abs() <= 0.5 * inc.abs() + 1e-6 {
        k as usize..k as usize + 1
    } else {
        0..0
    }
}

/// The ROS time of `t_s` seconds.
pub fn header(t_s: f64, frame_id: &str) -> msg::Header {
    msg::Header {
        stamp: msg::Time::from_secs(t_s),
        frame_id: frame_id.to_string(),
    }
}

/// Roll, pitch, yaw (ZYX) of a unit quaternion (x, y, z, w), rad.
pub fn rpy(q: [f64; 4]) -> [f64; 3] {
    let [x, y, z, w] = q;
    let roll = (2.0 * (w * x + y * z)).atan2(1.0 - 2.0 * (x * x + y * y));
    let pitch = (2.0 * (w * y - z * x)).clamp(-1.0, 1.0).asin();
    let yaw = (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z));
    [roll, pitch, yaw]
}

/// Rotate body-frame `v` into the world by unit quaternion `q` (x, y, z, w).
fn rotate(q: [f64; 4], v: [f64; 3]) -> [f64; 3] {
    let [x, y, z, w] = q;
    let u = [x, y, z];
    let cross = |a: [f64; 3], b: [f64; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let t = cross(u, v).map(|c| 2.0 * c);
    let ut = cross(u, t);
    [0, 1, 2].map(|i| v[i] + w * t[i] + ut[i])
}

fn xyzw(q: &msg::Quaternion) -> [f64; 4] {
    [q.x, q.y, q.z, q.w]
}

fn v3(v: &msg::Vector3) -> [f64; 3] {
    [v.x, v.y, v.z]
}

/// An IMU reading from `sensor_msgs/Imu` plus, when given, the body-frame velocity of
/// `nav_msgs/Odometry`'s twist (a bare IMU knows no velocity: it reads zero).
pub fn imu_reading(imu: &msg::Imu, odom: Option<&msg::Odometry>) -> ImuReading {
    let q = xyzw(&imu.orientation);
    let ang_vel_b = v3(&imu.angular_velocity);
    let lin_vel_b = odom.map(|o| v3(&o.twist.twist.linear)).unwrap_or_default();
    ImuReading {
        orientation_xyzw: q,
        lin_vel_w: rotate(q, lin_vel_b),
        lin_vel_b,
        ang_vel_w: rotate(q, ang_vel_b),
        ang_vel_b,
        lin_acc_b: v3(&imu.linear_acceleration),
        ang_acc_b: [0.0; 3],
    }
}

/// A pose fix from odometry and / or a NavSatFix.
pub fn gps_reading(odom: Option<&msg::Odometry>, fix: Option<&msg::NavSatFix>) -> GpsReading {
    let (position_m, q) = match odom {
        Some(o) => {
            let p = o.pose.pose.position;
            ([p.x, p.y, p.z], xyzw(&o.pose.pose.orientation))
        }
        None => ([0.0; 3], [0.0, 0.0, 0.0, 1.0]),
    };
    GpsReading {
        position_m,
        orientation_xyzw: q,
        rpy_rad: rpy(q),
        geodetic: fix.filter(|f| f.status.status >= 0).map(|f| Geodetic {
            latitude_deg: f.latitude,
            longitude_deg: f.longitude,
            altitude_m: f.altitude,
        }),
    }
}

/// The drive command for `c` (throttle and steering clipped to the car's limits first).
pub fn drive_command(c: Control, m: &DriveMapping, stamp_s: f64, frame_id: &str) -> msg::AckermannDriveStamped {
    let c = clip(c, m);
    msg::AckermannDriveStamped {
        header: header(stamp_s, frame_id),
        drive: msg::AckermannDrive {
            steering_angle: c.steering_rad as f32,
            speed: (c.throttle as f32) * m.full_throttle_mps(),
            ..msg::AckermannDrive::default()
        },
    }
}

/// `c` inside the car's limits (non-finite parts read zero).
pub fn clip(c: Control, m: &DriveMapping) -> Control {
    let f = |v: f64| if v.is_finite() { v } else { 0.0 };
    Control {
        throttle: f(c.throttle).clamp(-1.0, 1.0),
        steering_rad: f(c.steering_rad).clamp(-m.steering_limit_rad, m.steering_limit_rad),
    }
}

/// The control a drive command asks for (the inverse of [`drive_command`]; a negative speed
/// reverses).
pub fn control_of(d: &msg::AckermannDrive, m: &DriveMapping) -> Control {
    clip(
        Control {
            throttle: (d.speed / m.full_throttle_mps()) as f64,
            steering_rad: d.steering_angle as f64,
        },
        m,
    )
}

/// A simulated scan as `sensor_msgs/LaserScan`: misses (no hit) read +inf as REP 117 says.
pub fn scan_msg(s: &LaserScan, stamp_s: f64, frame_id: &str, period_s: f32) -> msg::LaserScan {
    let n = s.ranges.len();
    msg::LaserScan {
        header: header(stamp_s, frame_id),
        angle_min: s.angle_min,
        angle_max: s.angle_min + s.angle_increment * n.saturating_sub(1) as f32,
        angle_increment: s.angle_increment,
        time_increment: 0.0,
        scan_time: period_s,
        range_min: s.range_min,
        range_max: s.range_max,
        ranges: s
            .ranges
            .iter()
            .zip(s.hit.iter().chain(std::iter::repeat(&true)))
            .map(|(r, hit)| if *hit { *r } else { f32::INFINITY })
            .collect(),
        intensities: Vec::new(),
    }
}

/// A simulated IMU sample as `sensor_msgs/Imu`.
pub fn imu_msg(i: &ImuReading, stamp_s: f64, frame_id: &str) -> msg::Imu {
    let [x, y, z, w] = i.orientation_xyzw;
    let v = |a: [f64; 3]| msg::Vector3 {
        x: a[0],
        y: a[1],
        z: a[2],
    };
    msg::Imu {
        header: header(stamp_s, frame_id),
        orientation: msg::Quaternion { x, y, z, w },
        orientation_covariance: [0.0; 9],
        angular_velocity: v(i.ang_vel_b),
        angular_velocity_covariance: [0.0; 9],
        linear_acceleration: v(i.lin_acc_b),
        linear_acceleration_covariance: [0.0; 9],
    }
}

/// Simulated pose and body velocity as `nav_msgs/Odometry` (frame `odom`, child the body).
pub fn odom_msg(g: &GpsReading, i: &ImuReading, stamp_s: f64, child_frame_id: &str) -> msg::Odometry {
    let [x, y, z, w] = g.orientation_xyzw;
    let v = |a: [f64; 3]| msg::Vector3 {
        x: a[0],
        y: a[1],
        z: a[2],
    };
    msg::Odometry {
        header: header(stamp_s, "odom"),
        child_frame_id: child_frame_id.to_string(),
        pose: msg::PoseWithCovariance {
            pose: msg::Pose {
                position: msg::Point {
                    x: g.position_m[0],
                    y: g.position_m[1],
                    z: g.position_m[2],
                },
                orientation: msg::Quaternion { x, y, z, w },
            },
            covariance: msg::Covariance6::default(),
        },
        twist: msg::TwistWithCovariance {
            twist: msg::Twist {
                linear: v(i.lin_vel_b),
                angular: v(i.ang_vel_b),
            },
            covariance: msg::Covariance6::default(),
        },
    }
}

/// An Odometry message's pose as the transform from its frame to its child frame.
pub fn odom_transform(o: &msg::Odometry) -> msg::Transform {
    let p = o.pose.pose;
    msg::Transform {
        translation: msg::Vector3 {
            x: p.position.x,
            y: p.position.y,
            z: p.position.z,
        },
        rotation: p.orientation,
    }
}

/// A simulated geodetic fix as `sensor_msgs/NavSatFix`.
pub fn navsat_msg(g: &Geodetic, stamp_s: f64, frame_id: &str) -> msg::NavSatFix {
    msg::NavSatFix {
        header: header(stamp_s, frame_id),
        status: msg::NavSatStatus { status: 0, service: 1 },
        latitude: g.latitude_deg,
        longitude: g.longitude_deg,
        altitude: g.altitude_m,
        position_covariance: [0.0; 9],
        position_covariance_type: 0,
    }
}

/// A depth `sensor_msgs/Image` as the policy camera's frame (see [`CameraMapping`]): depth
/// only, `cam.width` x `cam.height`. The error says why the image cannot be used.
pub fn depth_frame(img: &msg::Image, m: &CameraMapping, cam: &CameraConfig) -> Result<CameraFrame, String> {
    let (w, h) = (img.width as usize, img.height as usize);
    let bpp = match img.encoding.as_str() {
        "32FC1" => 4,
        "16UC1" | "mono16" => 2,
        e => {
            return Err(format!(
                "encoding '{e}' is no depth image (32FC1 metres or 16UC1 millimetres)"
            ));
        }
    };
    let step = img.step as usize;
    if w == 0 || h == 0 || step < w * bpp || img.data.len() < step * (h - 1) + w * bpp {
        return Err(format!(
            "a {w}x{h} {} image with step {step} needs {} bytes and has {}",
            img.encoding,
            step * h.saturating_sub(1) + w * bpp,
            img.data.len()
        ));
    }
    let (pw, ph) = (cam.width as usize, cam.height as usize);
    let half_tan = |deg: f32| (0.5 * deg as f64).to_radians().tan();
    let ch = h as f64 * half_tan(cam.fov_deg) / half_tan(m.vertical_fov_deg);
    let cw = ch * pw as f64 / ph as f64;
    // Half a pixel of slack: equal fields of view must not fail on rounding.
    if ch > h as f64 + 0.5 || cw > w as f64 + 0.5 {
        return Err(format!(
            "a {w}x{h} image over {} degrees vertically does not cover the policy camera ({pw}x{ph} over {} \
             degrees needs a {cw:.0}x{ch:.0} window)",
            m.vertical_fov_deg, cam.fov_deg
        ));
    }
    let (x0, y0) = (0.5 * (w as f64 - cw), 0.5 * (h as f64 - ch));
    let src = |i: usize, n: usize, origin: f64, span: f64, max: usize| {
        ((origin + (i as f64 + 0.5) * span / n as f64).floor().max(0.0) as usize).min(max - 1)
    };
    let big = img.is_bigendian != 0;
    let read = |x: usize, y: usize| -> f32 {
        let o = y * step + x * bpp;
        let b = &img.data[o..o + bpp];
        let z = if bpp == 4 {
            let b = [b[0], b[1], b[2], b[3]];
            if big {
                f32::from_be_bytes(b)
            } else {
                f32::from_le_bytes(b)
            }
        } else {
            let b = [b[0], b[1]];
            let mm = if big {
                u16::from_be_bytes(b)
            } else {
                u16::from_le_bytes(b)
            };
            if mm == 0 { f32::NAN } else { mm as f32 / 1000.0 }
        };
        if z > 0.0 { z } else { f32::NAN }
    };
    let cols: Vec<usize> = (0..pw).map(|x| src(x, pw, x0, cw, w)).collect();
    let mut depth_m = Vec::with_capacity(pw * ph);
    for y in 0..ph {
        let sy = src(y, ph, y0, ch, h);
        depth_m.extend(cols.iter().map(|&sx| read(sx, sy)));
    }
    Ok(CameraFrame {
        width: cam.width,
        height: cam.height,
        depth_m,
        ..CameraFrame::default()
    })
}

/// A simulated camera frame's depth as a 32FC1 `sensor_msgs/Image` (little-endian metres).
pub fn depth_image_msg(f: &CameraFrame, stamp_s: f64, frame_id: &str) -> msg::Image {
    msg::Image {
        header: header(stamp_s, frame_id),
        height: f.height,
        width: f.width,
        encoding: "32FC1".into(),
        is_bigendian: 0,
        step: 4 * f.width,
        data: f.depth_m.iter().flat_map(|z| z.to_le_bytes()).collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scan(angle_min: f32, inc: f32, ranges: Vec<f32>) -> msg::LaserScan {
        msg::LaserScan {
            angle_min,
            angle_increment: inc,
            angle_max: angle_min + inc * (ranges.len() as f32 - 1.0),
            range_min: 0.05,
            range_max: 12.0,
            ranges,
            ..msg::LaserScan::default()
        }
    }

    #[test]
    fn equal_grids_map_one_to_one() {
        let m = ScanMapping::default();
        let (a0, inc) = (m.angle_min_rad, (m.angle_max_rad - m.angle_min_rad) / 99.0);
        let ranges: Vec<f32> = (0..100).map(|i| 1.0 + 0.05 * i as f32).collect();
        let out = scan_to_rays(&scan(a0, inc, ranges.clone()), &m);
        assert_eq!(out.ranges, ranges);
    }

    #[test]
    fn a_finer_scan_takes_the_bin_minimum_and_skips_nan() {
        let m = ScanMapping {
            angle_min_rad: -1.0,
            angle_max_rad: 1.0,
            n_rays: 3,
            ..ScanMapping::default()
        };
        // 9 rays over [-1.5, 1.5] (0.375 apart); bins are +-0.5 around -1, 0, 1.
        let mut r = vec![5.0; 9];
        r[1] = 2.0; // -1.125: first bin
        r[4] = f32::NAN; // 0: middle bin, but 3 and 5 are valid
        r[3] = 3.0;
        r[7] = f32::INFINITY; // 1.125: no return
        r[6] = 20.0; // 0.75: clipped to 12
        r[8] = f32::INFINITY; // 1.5: the last bin is 0.75, 1.125, 1.5
        let out = scan_to_rays(&scan(-1.5, 0.375, r), &m);
        assert_eq!(out.ranges, vec![2.0, 3.0, 12.0]);
    }

    #[test]
    fn a_ray_with_only_nan_follows_the_invalid_setting() {
        let mut m = ScanMapping {
            angle_min_rad: -1.0,
            angle_max_rad: 1.0,
            n_rays: 3,
            ..ScanMapping::default()
        };
        let s = scan(-1.0, 1.0, vec![4.0, f32::NAN, f32::NEG_INFINITY]);
        let out = scan_to_rays(&s, &m);
        assert!(out.ranges[1].is_nan());
        assert_eq!([out.ranges[0], out.ranges[2]], [4.0, 0.05]);
        m.invalid = InvalidRay::RangeMax;
        assert_eq!(scan_to_rays(&s, &m).ranges[1], 12.0);
    }

    #[test]
    fn a_coarser_scan_uses_the_nearest_ray_and_a_reversed_scan_works() {
        let mut m = ScanMapping {
            angle_min_rad: -0.4,
            angle_max_rad: 0.4,
            n_rays: 5,
            ..ScanMapping::default()
        };
        // Rays at -0.5, 0, 0.5; bearings -0.4, -0.2, 0, 0.2, 0.4 (bins +-0.1).
        let out = scan_to_rays(&scan(-0.5, 0.5, vec![1.0, 2.0, 3.0]), &m);
        assert_eq!(out.ranges, vec![1.0, 2.0, 2.0, 2.0, 3.0]);
        (m.angle_min_rad, m.angle_max_rad) = (-0.5, 0.5);
        // Clockwise scanner: first ray at +0.5.
        let out = scan_to_rays(&scan(0.5, -0.25, vec![1.0, 2.0, 3.0, 4.0, 5.0]), &m);
        assert_eq!(out.ranges, vec![5.0, 4.0, 3.0, 2.0, 1.0]);
    }

    fn cam(width: u32, height: u32, fov_deg: f32) -> CameraConfig {
        CameraConfig {
            width,
            height,
            fov_deg,
            ..CameraConfig::default()
        }
    }

    /// A 32FC1 image whose pixel (x, y) reads 1 + x + 1000 y metres.
    fn coded(w: u32, h: u32) -> msg::Image {
        let f = CameraFrame {
            width: w,
            height: h,
            depth_m: (0..h)
                .flat_map(|y| (0..w).map(move |x| (1 + x + 1000 * y) as f32))
                .collect(),
            ..CameraFrame::default()
        };
        depth_image_msg(&f, 1.0, "camera")
    }

    /// Column and row of the coded image a pixel came from.
    fn origin(z: f32) -> (u32, u32) {
        let k = z as u32 - 1;
        (k % 1000, k / 1000)
    }

    #[test]
    fn a_depth_image_of_the_policys_geometry_passes_through_bit_for_bit() {
        let m = CameraMapping::default();
        let img = coded(64, 48);
        let f = depth_frame(&img, &m, &cam(64, 48, 70.0)).unwrap();
        assert_eq!((f.width, f.height), (64, 48));
        let want: Vec<f32> = img
            .data
            .chunks(4)
            .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
            .collect();
        assert_eq!(f.depth_m, want);
        assert!(f.rgb.is_empty() && f.segmentation.is_empty());
    }

    #[test]
    fn a_wide_image_is_centre_cropped_to_the_policys_aspect_and_resized_by_nearest_pixel() {
        // 16:9, 128x72, same vertical field of view: the 96x72 centre window (x 16..112), each
        // policy pixel taking the source pixel under its centre (1.5 source pixels per pixel).
        let m = CameraMapping::default();
        let f = depth_frame(&coded(128, 72), &m, &cam(64, 48, 70.0)).unwrap();
        for y in 0..48u32 {
            for x in 0..64u32 {
                let (sx, sy) = origin(f.depth_m[(y * 64 + x) as usize]);
                // floor((i + 0.5) * 1.5) in integers.
                assert_eq!(sx, 16 + (2 * x + 1) * 3 / 4, "column of ({x}, {y})");
                assert_eq!(sy, (2 * y + 1) * 3 / 4, "row of ({x}, {y})");
            }
        }
        // A camera seeing 90 degrees vertically: the window is tan(35)/tan(45) = 0.700 of the
        // height, centred.
        let wide = CameraMapping {
            vertical_fov_deg: 90.0,
            ..m
        };
        let f = depth_frame(&coded(128, 72), &wide, &cam(64, 48, 70.0)).unwrap();
        let ch = 72.0 * (35f64.to_radians().tan());
        let (x0, y0) = (64.0 - ch * 4.0 / 6.0, 36.0 - ch / 2.0);
        for (y, x) in [(0u32, 0u32), (47, 63), (24, 32), (10, 50)] {
            let (sx, sy) = origin(f.depth_m[(y * 64 + x) as usize]);
            assert_eq!(sx, (x0 + (x as f64 + 0.5) * ch * 4.0 / 3.0 / 64.0).floor() as u32);
            assert_eq!(sy, (y0 + (y as f64 + 0.5) * ch / 48.0).floor() as u32);
        }
    }

    #[test]
    fn depth_without_a_reading_is_nan_and_16_bit_millimetres_decode_in_either_byte_order() {
        let m = CameraMapping::default();
        let mut img = coded(4, 3);
        for (i, z) in [f32::NAN, f32::NEG_INFINITY, f32::INFINITY, 0.0, -1.0]
            .into_iter()
            .enumerate()
        {
            img.data[4 * i..4 * i + 4].copy_from_slice(&z.to_le_bytes());
        }
        let f = depth_frame(&img, &m, &cam(4, 3, 70.0)).unwrap();
        assert!(f.depth_m[0].is_nan() && f.depth_m[1].is_nan(), "no reading, too close");
        assert_eq!(f.depth_m[2], f32::INFINITY, "farther than the camera sees");
        assert!(f.depth_m[3].is_nan() && f.depth_m[4].is_nan());
        assert_eq!(f.depth_m[5], 1002.0, "pixel (1, 1)");
        let mm: [u16; 6] = [0, 1, 1500, 65535, 300, 8000];
        for big in [false, true] {
            let img = msg::Image {
                width: 3,
                height: 2,
                encoding: "16UC1".into(),
                is_bigendian: big.into(),
                step: 8, // rows padded to 8 bytes
                data: [&mm[..3], &[7][..], &mm[3..], &[7][..]]
                    .concat()
                    .iter()
                    .flat_map(|v| if big { v.to_be_bytes() } else { v.to_le_bytes() })
                    .collect(),
                ..msg::Image::default()
            };
            let f = depth_frame(&img, &m, &cam(3, 2, 70.0)).unwrap();
            assert!(f.depth_m[0].is_nan(), "0 mm is no reading");
            assert_eq!(&f.depth_m[1..], &[0.001, 1.5, 65.535, 0.3, 8.0]);
        }
    }

    #[test]
    fn an_unusable_image_is_refused_with_the_reason() {
        let m = CameraMapping::default();
        let mut img = coded(64, 48);
        img.encoding = "rgb8".into();
        let e = depth_frame(&img, &m, &cam(64, 48, 70.0)).unwrap_err();
        assert!(e.contains("'rgb8'"), "{e}");
        let mut img = coded(64, 48);
        img.data.truncate(100);
        let e = depth_frame(&img, &m, &cam(64, 48, 70.0)).unwrap_err();
        assert!(e.contains("12288") && e.contains("100"), "{e}");
        // A 4:3 policy cannot be cut from a 1:1 image of the same vertical field of view.
        let e = depth_frame(&coded(48, 48), &m, &cam(64, 48, 70.0)).unwrap_err();
        assert!(e.contains("64x48 window"), "{e}");
        // Nor from a camera narrower than the policy's.
        let narrow = CameraMapping {
            vertical_fov_deg: 60.0,
            ..m
        };
        assert!(depth_frame(&coded(128, 72), &narrow, &cam(64, 48, 70.0)).is_err());
    }

    #[test]
    fn commands_round_trip_and_time_splits() {
        let m = DriveMapping::default();
        let c = Control {
            throttle: 0.75,
            steering_rad: -0.25,
        };
        let back = control_of(&drive_command(c, &m, 1.5, "base_link").drive, &m);
        assert!((back.throttle - 0.75).abs() < 1e-6 && (back.steering_rad + 0.25).abs() < 1e-6);
        // The safety filter's back-out reverses: a negative speed, and back.
        let rev = Control {
            throttle: -0.25,
            steering_rad: 0.36,
        };
        let cmd = drive_command(rev, &m, 1.5, "base_link").drive;
        assert!((cmd.speed + 0.25 * m.full_throttle_mps()).abs() < 1e-6);
        assert!((control_of(&cmd, &m).throttle + 0.25).abs() < 1e-6);
        let wild = Control {
            throttle: f64::NAN,
            steering_rad: 3.0,
        };
        assert_eq!(
            clip(wild, &m),
            Control {
                throttle: 0.0,
                steering_rad: 0.36
            }
        );
        let t = msg::Time::from_secs(12.25);
        assert_eq!((t.sec, t.nanosec), (12, 250_000_000));
        assert_eq!(t.as_secs(), 12.25);
    }

    #[test]
    fn rpy_of_a_yaw_quaternion() {
        let h = 0.3f64;
        let r = rpy([0.0, 0.0, (h / 2.0).sin(), (h / 2.0).cos()]);
        assert!(r[0].abs() < 1e-12 && r[1].abs() < 1e-12 && (r[2] - h).abs() < 1e-12);
        let v = rotate([0.0, 0.0, (h / 2.0).sin(), (h / 2.0).cos()], [1.0, 0.0, 0.0]);
        assert!((v[0] - h.cos()).abs() < 1e-12 && (v[1] - h.sin()).abs() < 1e-12);
    }
}
