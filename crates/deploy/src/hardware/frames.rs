//! ROS 2 messages to the `SensorFrame` a task reads: the newest message of each subscribed
//! topic, mapped as the car's TOML says. The ROS 2 vehicle (live) and the bag replay share it,
//! so a replayed car log gives the frames the car gave.

use super::config::{Ros2Config, Topics};
use super::mapping::{self, scan_to_rays};
use super::msg;
use agvrl_envs::api::{Control, SensorFrame};
use agvrl_sim::msg::CameraFrame;
use agvrl_sim::sensors::CameraConfig;

/// Which topics feed the frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Subscribed {
    /// LaserScan.
    pub scan: bool,
    /// Imu.
    pub imu: bool,
    /// Odometry.
    pub odom: bool,
    /// NavSatFix.
    pub navsat: bool,
    /// The depth Image.
    pub image: bool,
}

impl Subscribed {
    /// The topics of `t` that are named (an empty name is not subscribed), and the image when
    /// the policy sees one.
    pub fn of_topics(t: &Topics, camera: bool) -> Self {
        Self {
            scan: !t.scan.is_empty(),
            imu: !t.imu.is_empty(),
            odom: !t.odom.is_empty(),
            navsat: !t.navsat.is_empty(),
            image: camera && !t.image.is_empty(),
        }
    }

    /// The sensors a simulated frame carries, as the topics a car would publish them on.
    pub fn of_frame(f: &SensorFrame) -> Self {
        Self {
            scan: f.scan.is_some(),
            imu: f.imu.is_some(),
            odom: f.imu.is_some() && f.gps.is_some(),
            navsat: f.gps.as_ref().is_some_and(|g| g.geodetic.is_some()),
            image: f.image.is_some(),
        }
    }
}

/// Whether a message stamped as `new` replaces the held one (`held`): only a newer stamp does,
/// so a duplicate, or a message overtaken on the wire (reordered, or a sensor clock stepped
/// back), is never taken for news; it is counted in `count`.
fn newer(count: &mut u64, held: Option<&msg::Header>, new: &msg::Header) -> bool {
    let newer = held.is_none_or(|h| new.stamp.as_secs() > h.stamp.as_secs());
    *count += u64::from(!newer);
    newer
}

/// The newest message of each topic, and the frame they make.
pub struct FrameBuilder {
    cfg: Ros2Config,
    camera: Option<CameraConfig>,
    on: Subscribed,
    scan: Option<msg::LaserScan>,
    imu: Option<msg::Imu>,
    odom: Option<msg::Odometry>,
    navsat: Option<msg::NavSatFix>,
    /// The newest image that decoded, as the policy camera's frame.
    image: Option<(msg::Header, CameraFrame)>,
    /// Why the newest image that could not be used was refused.
    image_error: Option<String>,
    /// Images refused so far.
    bad_images: u64,
    /// Messages not newer than the one held (see [`newer`]).
    not_newer: u64,
}

impl FrameBuilder {
    /// Frames from the topics of `cfg` (an empty name is not subscribed), and a depth image
    /// cut to `camera` when the policy sees one.
    pub fn new(cfg: Ros2Config, camera: Option<CameraConfig>) -> Self {
        let on = Subscribed::of_topics(&cfg.topics, camera.is_some());
        Self {
            cfg,
            camera,
            on,
            scan: None,
            imu: None,
            odom: None,
            navsat: None,
            image: None,
            image_error: None,
            bad_images: 0,
            not_newer: 0,
        }
    }

    /// The topics that feed the frame.
    pub fn subscribed(&self) -> Subscribed {
        self.on
    }

    /// The car's settings.
    pub fn cfg(&self) -> &Ros2Config {
        &self.cfg
    }

    /// The policy camera images are cut to.
    pub fn camera(&self) -> Option<&CameraConfig> {
        self.camera.as_ref()
    }

    /// A LaserScan arrived.
    pub fn scan(&mut self, m: msg::LaserScan) {
        if newer(&mut self.not_newer, self.scan.as_ref().map(|h| &h.header), &m.header) {
            self.scan = Some(m);
        }
    }

    /// An Imu arrived.
    pub fn imu(&mut self, m: msg::Imu) {
        if newer(&mut self.not_newer, self.imu.as_ref().map(|h| &h.header), &m.header) {
            self.imu = Some(m);
        }
    }

    /// An Odometry arrived.
    pub fn odom(&mut self, m: msg::Odometry) {
        if newer(&mut self.not_newer, self.odom.as_ref().map(|h| &h.header), &m.header) {
            self.odom = Some(m);
        }
    }

    /// A NavSatFix arrived.
    pub fn navsat(&mut self, m: msg::NavSatFix) {
        if newer(&mut self.not_newer, self.navsat.as_ref().map(|h| &h.header), &m.header) {
            self.navsat = Some(m);
        }
    }

    /// Messages dropped so far for a stamp no newer than the one held.
    pub fn not_newer(&self) -> u64 {
        self.not_newer
    }

    /// A depth image arrived: decoded and cut to the policy camera, or refused (counted, the
    /// reason kept).
    pub fn image(&mut self, m: &msg::Image) {
        if self.camera.is_none() || !newer(&mut self.not_newer, self.image.as_ref().map(|h| &h.0), &m.header) {
            return;
        }
        let Some(cam) = &self.camera else { return };
        match mapping::depth_frame(m, &self.cfg.camera, cam) {
            Ok(f) => self.image = Some((m.header.clone(), f)),
            Err(e) => {
                self.bad_images += 1;
                self.image_error = Some(e);
            }
        }
    }

    /// Images refused so far.
    pub fn bad_images(&self) -> u64 {
        self.bad_images
    }

    /// Why the newest refused image was refused.
    pub fn image_error(&self) -> Option<&str> {
        self.image_error.as_deref()
    }

    /// The oldest stamp of the subscribed topics, an image's `image_lag_s` later than its own
    /// (None: one has sent nothing yet).
    pub fn stamps(&self, image_lag_s: f64) -> Option<f64> {
        let s = |on: bool, h: Option<&msg::Header>| -> Option<f64> {
            if on {
                h.map(|h| h.stamp.as_secs())
            } else {
                Some(f64::INFINITY)
            }
        };
        let all = [
            s(self.on.scan, self.scan.as_ref().map(|m| &m.header))?,
            s(self.on.imu, self.imu.as_ref().map(|m| &m.header))?,
            s(self.on.odom, self.odom.as_ref().map(|m| &m.header))?,
            s(self.on.navsat, self.navsat.as_ref().map(|m| &m.header))?,
            s(self.on.image, self.image.as_ref().map(|m| &m.0))? + image_lag_s,
        ];
        Some(all.into_iter().fold(f64::INFINITY, f64::min))
    }

    /// The frame of the newest messages; its stamp is their oldest (an image `camera.max_lag_s`
    /// later than its own), `applied` the control in force.
    pub fn frame(&self, applied: Control) -> SensorFrame {
        let odom_ready = !self.on.odom || self.odom.is_some();
        SensorFrame {
            stamp_s: self.stamps(self.cfg.camera.max_lag_s).unwrap_or(f64::NEG_INFINITY),
            scan: self.scan.as_ref().map(|s| scan_to_rays(s, &self.cfg.scan)),
            imu: self
                .imu
                .as_ref()
                .filter(|_| odom_ready)
                .map(|i| mapping::imu_reading(i, self.odom.as_ref())),
            gps: (self.odom.is_some() || self.navsat.is_some())
                .then(|| mapping::gps_reading(self.odom.as_ref(), self.navsat.as_ref())),
            image: self.image.as_ref().map(|(_, f)| f.clone()),
            contact: None,
            applied,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scan_at(sec: i32, range: f32) -> msg::LaserScan {
        let mut m = msg::LaserScan {
            angle_min: -0.5,
            angle_max: 0.5,
            angle_increment: 0.5,
            range_min: 0.05,
            range_max: 12.0,
            ranges: vec![range; 3],
            ..Default::default()
        };
        m.header.stamp.sec = sec;
        m
    }

    #[test]
    fn a_copy_or_an_older_message_never_replaces_the_one_held() {
        let mut f = FrameBuilder::new(Ros2Config::default(), None);
        f.scan(scan_at(10, 2.0));
        // A copy (same stamp) and an overtaken one (older) arrive: neither is news.
        f.scan(scan_at(10, 3.0));
        f.scan(scan_at(9, 4.0));
        assert_eq!(f.not_newer(), 2);
        assert_eq!(
            f.scan.as_ref().map(|s| (s.header.stamp.sec, s.ranges[0])),
            Some((10, 2.0))
        );
        f.scan(scan_at(11, 5.0));
        assert_eq!(f.scan.as_ref().map(|s| s.header.stamp.sec), Some(11));
        assert_eq!(f.not_newer(), 2);
    }
}
