//! The ROS 2 `Vehicle` over DDS (ros2-client / RustDDS, no ROS install): subscribes the
//! car's LaserScan, Imu, Odometry and NavSatFix topics (and a depth Image for a policy that
//! sees one), publishes AckermannDriveStamped.
//!
//! Two ways to keep time. Real time (`lockstep = false`, for a car): `sense` returns the newest
//! messages at once and the drive loop holds the rate with the wall clock. Lockstep (for the
//! sim-backed robot): the robot advances one control period per command it receives, and
//! `sense` after an `actuate` waits (up to `fresh_timeout_s`) for the sensor set that command
//! produced, so both sides' clocks move one period per tick, as fast as DDS allows.
//!
//! The frame's `stamp_s` is the oldest header stamp among the subscribed topics, so a topic
//! that stops makes the whole frame stale and the watchdog stops the car. An image counts with
//! its stamp plus `camera.max_lag_s` (a 15 Hz camera is older than the 30 Hz tick); the
//! lockstep wait takes no such allowance.

use super::config::{Reliability, Ros2Config, TopicQos};
use super::frames::FrameBuilder;
use super::mapping;
use super::msg;
use crate::DeployError;
use crate::record::{DriveBag, Sensor};
use agvrl_envs::api::{Control, EnvError, SensorFrame, Vehicle};
use agvrl_sim::sensors::CameraConfig;
use ros2_client::dds::rustdds::Topic;
use ros2_client::dds::rustdds::mio1::{Events, Interest, Poll, Token};
use ros2_client::qos::{Durability, History, WhenFull};
use ros2_client::{Context, ContextOptions, MessageTypeName, Name, Node, NodeName, NodeOptions, QosProfile};
use serde::de::DeserializeOwned;
use std::sync::Arc;
use std::time::{Duration, Instant};

pub use ros2_client::{Publisher, Subscription};

/// ROS type names of the topics.
pub(crate) const SCAN_TYPE: (&str, &str) = ("sensor_msgs", "LaserScan");
pub(crate) const IMU_TYPE: (&str, &str) = ("sensor_msgs", "Imu");
pub(crate) const ODOM_TYPE: (&str, &str) = ("nav_msgs", "Odometry");
pub(crate) const NAVSAT_TYPE: (&str, &str) = ("sensor_msgs", "NavSatFix");
pub(crate) const IMAGE_TYPE: (&str, &str) = ("sensor_msgs", "Image");
pub(crate) const DRIVE_TYPE: (&str, &str) = ("ackermann_msgs", "AckermannDriveStamped");
pub(crate) const TF_TYPE: (&str, &str) = ("tf2_msgs", "TFMessage");

fn dds_err(what: &str, e: impl std::fmt::Display) -> DeployError {
    DeployError::Vehicle(format!("DDS {what}: {e}"))
}

/// The QoS profile of `q` (volatile, keep last `depth`).
pub(crate) fn qos(q: TopicQos) -> QosProfile {
    let p = QosProfile::subscription_default()
        .durability(Durability::Volatile)
        .history(History::KeepLast { depth: q.depth });
    match q.reliability {
        Reliability::BestEffort => p.reliability_best_effort(),
        Reliability::Reliable => p.reliability_reliable(WhenFull::DEFAULT),
    }
}

/// A node on `cfg.domain_id`. RustDDS also announces itself to the localhost discovery ports,
/// so two processes on one host find each other without multicast (a container's `lo`).
pub(crate) fn node(cfg: &Ros2Config, name: &str) -> Result<Node, DeployError> {
    node_in_context(cfg, name).map(|(_, n)| n)
}

/// A node on `cfg.domain_id`, with its context (for discovery queries).
fn node_in_context(cfg: &Ros2Config, name: &str) -> Result<(Context, Node), DeployError> {
    let ctx =
        Context::with_options(ContextOptions::new().domain_id(cfg.domain_id)).map_err(|e| dds_err("participant", e))?;
    let name = NodeName::new("/", name).map_err(|e| DeployError::Config(format!("node name '{name}': {e:?}")))?;
    let node = ctx
        .new_node(
            name,
            NodeOptions::new().enable_rosout(false).start_parameter_services(false),
        )
        .map_err(|e| dds_err("node", format!("{e:?}")))?;
    Ok((ctx, node))
}

/// The DDS type name of ROS type `ty`.
fn dds_type(ty: (&str, &str)) -> String {
    format!("{}::msg::dds_::{}_", ty.0, ty.1)
}

/// A reader that discovery found on a topic.
#[derive(Clone, Debug, PartialEq)]
struct FoundReader {
    dds_type: String,
    reliable: bool,
    /// The first QoS policy our drive writer cannot satisfy for this reader (DDS's
    /// requested/offered rules: durability, reliability, deadline, data representation, ...).
    incompatible: Option<ros2_client::dds::rustdds::qos::QosPolicyId>,
}

/// The topic `name` of ROS type `ty`.
pub(crate) fn topic(node: &Node, name: &str, ty: (&str, &str), q: &QosProfile) -> Result<Topic, DeployError> {
    let n = Name::parse(name).map_err(|e| DeployError::Config(format!("topic name '{name}': {e:?}")))?;
    node.create_topic(&n, MessageTypeName::new(ty.0, ty.1), q)
        .map_err(|e| dds_err(name, e))
}

/// A subscription to `name` (None for an empty name).
pub(crate) fn subscribe<M: DeserializeOwned + 'static>(
    node: &mut Node,
    name: &str,
    ty: (&str, &str),
    q: TopicQos,
) -> Result<Option<Subscription<M>>, DeployError> {
    if name.is_empty() {
        return Ok(None);
    }
    let q = qos(q);
    let t = topic(node, name, ty, &q)?;
    node.create_subscription(&t, Some(q))
        .map(Some)
        .map_err(|e| dds_err(name, e))
}

/// A publisher on `name`.
pub(crate) fn publisher<M: serde::Serialize>(
    node: &mut Node,
    name: &str,
    ty: (&str, &str),
    q: TopicQos,
) -> Result<Publisher<M>, DeployError> {
    let q = qos(q);
    let t = topic(node, name, ty, &q)?;
    node.create_publisher(&t, Some(q)).map_err(|e| dds_err(name, e))
}

/// A latched publisher on `name` (reliable, transient local, keep last 1), as `/tf_static`
/// is: a reader that joins later still gets the last message.
pub(crate) fn latched_publisher<M: serde::Serialize>(
    node: &mut Node,
    name: &str,
    ty: (&str, &str),
) -> Result<Publisher<M>, DeployError> {
    let q = QosProfile::subscription_default()
        .durability(Durability::TransientLocal)
        .history(History::KeepLast { depth: 1 })
        .reliability_reliable(WhenFull::DEFAULT);
    let t = topic(node, name, ty, &q)?;
    node.create_publisher(&t, Some(q)).map_err(|e| dds_err(name, e))
}

/// Take every waiting sample of `sub`, showing each to `seen`; keep the newest in `latest`.
/// Samples that fail to decode are counted, not fatal (one bad message must not stop the loop).
pub(crate) fn drain<M: DeserializeOwned + 'static>(
    sub: &Option<Subscription<M>>,
    latest: &mut Option<M>,
    bad: &mut u64,
    mut seen: impl FnMut(&M),
) {
    let Some(s) = sub else { return };
    loop {
        match s.take() {
            Ok(Some((m, _))) => {
                seen(&m);
                *latest = Some(m);
            }
            Ok(None) => break,
            Err(_) => *bad += 1,
        }
    }
}

impl Drop for Ros2Vehicle {
    /// In lockstep the robot steps only on a command, and DDS sends from a thread of its own:
    /// leaving right after the last `actuate` can take that command down unsent, and the robot
    /// waits for it forever. Stay until the set it produced arrives (up to `fresh_timeout_s`).
    fn drop(&mut self) {
        if self.lockstep && self.awaiting {
            // That set belongs to no tick: it stays out of the bag.
            self.bag = None;
            self.wait_newer(self.last_stamp_s, Duration::from_secs_f64(self.cfg.fresh_timeout_s));
        }
    }
}

/// A car (or the sim-backed robot) over ROS 2.
pub struct Ros2Vehicle {
    cfg: Ros2Config,
    lockstep: bool,
    ctx: Context,
    /// Kept alive: it owns the subscriptions and the publisher.
    _node: Node,
    scan: Option<Subscription<msg::LaserScan>>,
    imu: Option<Subscription<msg::Imu>>,
    odom: Option<Subscription<msg::Odometry>>,
    navsat: Option<Subscription<msg::NavSatFix>>,
    image: Option<Subscription<msg::Image>>,
    drive: Publisher<msg::AckermannDriveStamped>,
    poll: Poll,
    events: Events,
    /// The newest messages, and the frame they make.
    frames: FrameBuilder,
    bad_messages: u64,
    /// Commands the drive writer would have blocked on (see `actuate`).
    blocked_commands: u64,
    last_stamp_s: f64,
    awaiting: bool,
    applied: Control,
    /// Every message received also goes here.
    bag: Option<Arc<DriveBag>>,
}

impl Ros2Vehicle {
    /// Join domain `cfg.domain_id` and create the subscriptions and the drive publisher; with
    /// `camera` (the policy's), subscribe the depth image too.
    pub fn new(cfg: Ros2Config, lockstep: bool, camera: Option<CameraConfig>) -> Result<Self, DeployError> {
        cfg.validate().map_err(|e| DeployError::Config(e.message))?;
        if let Some(c) = &camera {
            if cfg.topics.image.is_empty() {
                return Err(DeployError::Config(
                    "the policy sees a camera image: topics.image must name the depth image topic".into(),
                ));
            }
            cfg.check_camera(c)?;
        }
        let (ctx, mut node) = node_in_context(&cfg, &cfg.node_name)?;
        let (t, q) = (&cfg.topics, cfg.qos.sensors);
        let mut scan = subscribe(&mut node, &t.scan, SCAN_TYPE, q)?;
        let mut imu = subscribe(&mut node, &t.imu, IMU_TYPE, q)?;
        let mut odom = subscribe(&mut node, &t.odom, ODOM_TYPE, q)?;
        let mut navsat = subscribe(&mut node, &t.navsat, NAVSAT_TYPE, q)?;
        let image_topic = if camera.is_some() { t.image.as_str() } else { "" };
        let mut image = subscribe(&mut node, image_topic, IMAGE_TYPE, q)?;
        let drive = publisher(&mut node, &t.drive, DRIVE_TYPE, cfg.qos.drive)?;
        let poll = Poll::new().map_err(|e| dds_err("poll", e))?;
        let reg = poll.registry();
        let io = |e: std::io::Error| dds_err("poll", e);
        if let Some(s) = scan.as_mut() {
            reg.register(s, Token(0), Interest::READABLE).map_err(io)?;
        }
        if let Some(s) = imu.as_mut() {
            reg.register(s, Token(1), Interest::READABLE).map_err(io)?;
        }
        if let Some(s) = odom.as_mut() {
            reg.register(s, Token(2), Interest::READABLE).map_err(io)?;
        }
        if let Some(s) = navsat.as_mut() {
            reg.register(s, Token(3), Interest::READABLE).map_err(io)?;
        }
        if let Some(s) = image.as_mut() {
            reg.register(s, Token(4), Interest::READABLE).map_err(io)?;
        }
        let frames = FrameBuilder::new(cfg.clone(), camera);
        Ok(Self {
            cfg,
            lockstep,
            ctx,
            _node: node,
            scan,
            imu,
            odom,
            navsat,
            image,
            frames,
            drive,
            poll,
            events: Events::with_capacity(16),
            bad_messages: 0,
            blocked_commands: 0,
            last_stamp_s: f64::NEG_INFINITY,
            awaiting: false,
            applied: Control::default(),
            bag: None,
        })
    }

    /// Record every message received from now on into `bag`, at its receive time.
    pub fn record_into(&mut self, bag: Arc<DriveBag>) {
        self.bag = Some(bag);
    }

    /// Messages that failed to decode so far (images that could not be used included).
    pub fn bad_messages(&self) -> u64 {
        self.bad_messages + self.frames.bad_images()
    }

    /// Commands not sent because the drive topic's writer would have blocked.
    pub fn blocked_commands(&self) -> u64 {
        self.blocked_commands
    }

    /// Sensor messages dropped so far for a stamp no newer than the one held (copies, messages
    /// overtaken on the wire, a clock stepped back).
    pub fn not_newer(&self) -> u64 {
        self.frames.not_newer()
    }

    /// Readers of the drive topic that discovery has found so far.
    fn drive_readers(&self) -> Vec<FoundReader> {
        let dds_name = format!("rt/{}", self.cfg.topics.drive.trim_start_matches('/'));
        let offered: ros2_client::ros2::QosPolicies = qos(self.cfg.qos.drive).into();
        self.ctx
            .domain_participant()
            .discovered_readers()
            .iter()
            .map(|r| &r.subscription_topic_data)
            .filter(|d| *d.topic_name() == dds_name)
            .map(|d| FoundReader {
                dds_type: d.type_name().clone(),
                reliable: matches!(
                    d.qos().reliability(),
                    Some(ros2_client::dds::rustdds::policy::Reliability::Reliable { .. })
                ),
                incompatible: offered.compliance_failure_wrt(&d.qos()),
            })
            .collect()
    }

    /// Whether `r` can read our commands: the same type and a QoS our writer satisfies.
    fn can_read(&self, r: &FoundReader) -> bool {
        r.dds_type == dds_type(DRIVE_TYPE) && r.incompatible.is_none()
    }

    fn drain(&mut self) {
        let b = &mut self.bad_messages;
        let bag = self.bag.as_deref();
        let f = &mut self.frames;
        let (mut scan, mut imu, mut odom, mut navsat, mut img) = (None, None, None, None, None);
        drain(&self.scan, &mut scan, b, |m| {
            bag.map_or((), |r| r.received(Sensor::Scan, m))
        });
        drain(&self.imu, &mut imu, b, |m| {
            bag.map_or((), |r| r.received(Sensor::Imu, m))
        });
        drain(&self.odom, &mut odom, b, |m| bag.map_or((), |r| r.received_odom(m)));
        drain(&self.navsat, &mut navsat, b, |m| {
            bag.map_or((), |r| r.received(Sensor::NavSat, m))
        });
        drain(&self.image, &mut img, b, |m| {
            bag.map_or((), |r| r.received(Sensor::Image, m))
        });
        if let Some(m) = scan {
            f.scan(m);
        }
        if let Some(m) = imu {
            f.imu(m);
        }
        if let Some(m) = odom {
            f.odom(m);
        }
        if let Some(m) = navsat {
            f.navsat(m);
        }
        // Only the newest image of a drain is decoded (a 1280x720 32FC1 is 3.7 MB).
        if let Some(m) = img {
            f.image(&m);
        }
    }

    /// Wait until every subscribed topic has a message stamped after `after_s`, or `timeout`.
    fn wait_newer(&mut self, after_s: f64, timeout: Duration) -> bool {
        let deadline = Instant::now() + timeout;
        loop {
            self.drain();
            if self.frames.stamps(0.0).is_some_and(|t| t > after_s) {
                return true;
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return false;
            }
            // A poll error (EINTR) just retries until the deadline.
            let _ = self.poll.poll(&mut self.events, Some(left));
        }
    }

    fn frame(&self) -> SensorFrame {
        self.frames.frame(self.applied)
    }
}

impl Vehicle for Ros2Vehicle {
    /// Wait for a full sensor set and a subscriber on the drive topic (`startup_timeout_s`),
    /// then for a sensor set newer than the one in hand; nothing is published, so a car stays
    /// as it is.
    fn reset(&mut self, _seed: u64) -> Result<SensorFrame, EnvError> {
        let timeout = Duration::from_secs_f64(self.cfg.startup_timeout_s);
        let t0 = Instant::now();
        if !self.wait_newer(f64::NEG_INFINITY, timeout) {
            let t = &self.cfg.topics;
            let image = if self.image.is_some() { t.image.as_str() } else { "" };
            let refused = match self.frames.image_error() {
                Some(e) => format!("; images on {} were refused: {e}", t.image),
                None => String::new(),
            };
            return Err(EnvError::Vehicle(format!(
                "no sensor data on {} within {} s (domain {}){refused}; is the car or `agvrl-drive --serve-sim` running?",
                [t.scan.as_str(), &t.imu, &t.odom, &t.navsat, image]
                    .into_iter()
                    .filter(|n| !n.is_empty())
                    .collect::<Vec<_>>()
                    .join(", "),
                self.cfg.startup_timeout_s,
                self.cfg.domain_id
            )));
        }
        // A command sent before its reader is matched would be lost; wait for one that can
        // read it (a reader of another type or an incompatible QoS is no reader).
        loop {
            let found = self.drive_readers();
            if found.iter().any(|r| self.can_read(r)) {
                break;
            }
            if t0.elapsed() > timeout {
                let d = &self.cfg.topics.drive;
                let what = if found.is_empty() {
                    format!("nobody subscribes to {d}")
                } else {
                    let list: Vec<String> = found
                        .iter()
                        .map(|r| {
                            let q = match r.incompatible {
                                Some(p) => format!("incompatible QoS: {p:?}"),
                                None => (if r.reliable { "reliable" } else { "best effort" }).to_string(),
                            };
                            format!("{} ({q})", r.dds_type)
                        })
                        .collect();
                    format!(
                        "found only {} on {d}; none can take {} ({}, volatile)",
                        list.join(", "),
                        dds_type(DRIVE_TYPE),
                        match self.cfg.qos.drive.reliability {
                            Reliability::BestEffort => "best effort",
                            Reliability::Reliable => "reliable",
                        },
                    )
                };
                return Err(EnvError::Vehicle(format!(
                    "{what} within {} s (domain {})",
                    self.cfg.startup_timeout_s, self.cfg.domain_id
                )));
            }
            let _ = self.poll.poll(&mut self.events, Some(Duration::from_millis(5)));
        }
        if !self.lockstep {
            // The set in hand may be as old as the wait for the subscriber: start from a newer
            // one (a car whose sensors stopped meanwhile starts stale, and is stopped). In
            // lockstep the robot re-sends its set unchanged until the first command.
            let before = self.frames.stamps(0.0).unwrap_or(f64::NEG_INFINITY);
            let left = timeout
                .saturating_sub(t0.elapsed())
                .max(Duration::from_secs_f64(self.cfg.fresh_timeout_s));
            self.wait_newer(before, left);
        }
        self.applied = Control::default();
        self.awaiting = false;
        let f = self.frame();
        self.last_stamp_s = f.stamp_s;
        Ok(f)
    }

    fn actuate(&mut self, control: Control) -> Result<(), EnvError> {
        let cmd = mapping::drive_command(control, &self.cfg.drive, self.last_stamp_s, &self.cfg.topics.frame_id);
        match self.drive.publish(cmd) {
            Ok(()) => {}
            // The car's drive reader is behind (found by the soak: a loaded machine): this command
            // is lost like a dropped message, counted, and the next one supersedes it; the
            // motor controller holds the last command, zero after its own timeout.
            Err(ros2_client::WriteError::WouldBlock { .. }) => self.blocked_commands += 1,
            Err(e) => return Err(EnvError::Vehicle(format!("publishing {}: {e}", self.cfg.topics.drive))),
        }
        self.applied = mapping::clip(control, &self.cfg.drive);
        self.awaiting = true;
        Ok(())
    }

    fn sense(&mut self) -> Result<SensorFrame, EnvError> {
        if self.lockstep && self.awaiting {
            // A timeout is no error: the old frame goes out and the watchdog judges its age.
            self.wait_newer(self.last_stamp_s, Duration::from_secs_f64(self.cfg.fresh_timeout_s));
        } else {
            self.drain();
        }
        self.awaiting = false;
        let f = self.frame();
        if f.stamp_s.is_finite() {
            self.last_stamp_s = f.stamp_s;
        }
        Ok(f)
    }

    fn control_period_s(&self) -> f64 {
        // The car has no period of its own; the drive loop's rate rules.
        1.0 / 30.0
    }

    fn steering_limit_rad(&self) -> f64 {
        self.cfg.drive.steering_limit_rad
    }
}
