//! `agvrl-drive --record DIR`: a drive as a rosbag2 bag. The sensor topics of the car's TOML
//! (names and types as a ROS 2 car publishes them), the commands on the drive topic,
//! `/tf_static` (base_link to the LiDAR and the camera), `/tf` (odom to base_link),
//! `/robot_description` (the URDF), and per tick `/agvrl/tick` (observation, raw action, the
//! control after the safety filter, watchdog event, inference time, lateness); the policy's
//! hash and settings go into an MCAP metadata record.

use crate::bag::{self, BagRecorder, BagSummary, BagWriter, Offered, Topic};
use crate::hardware::config::{DriveMapping, Topics};
use crate::hardware::frames::Subscribed;
use crate::hardware::{mapping, msg};
use crate::{DeployError, Tick};
use agvrl_envs::api::{Control, EnvError, MapInfo, SensorFrame, Vehicle};
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

/// Frame ids of the recorded messages (REP 105).
pub const BASE_FRAME: &str = "base_link";
/// The LiDAR's frame.
pub const LASER_FRAME: &str = "laser";
/// The camera's frame.
pub const CAMERA_FRAME: &str = "camera_link";
/// The odometry frame.
pub const ODOM_FRAME: &str = "odom";
/// Our tick topic.
pub const TICK_TOPIC: &str = "/agvrl/tick";

/// A sensor topic.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sensor {
    /// LaserScan.
    Scan,
    /// Imu.
    Imu,
    /// Odometry.
    Odom,
    /// NavSatFix.
    NavSat,
    /// Image.
    Image,
}

/// A message with a header stamp.
pub trait Stamped {
    /// The header stamp, seconds.
    fn stamp_s(&self) -> f64;
}

macro_rules! stamped {
    ($($t:ty),*) => {$(
        impl Stamped for $t {
            fn stamp_s(&self) -> f64 {
                self.header.stamp.as_secs()
            }
        }
    )*};
}
stamped!(msg::LaserScan, msg::Imu, msg::Odometry, msg::NavSatFix, msg::Image);

/// What a recording needs to know of the car.
pub struct Setup<'a> {
    /// Topic names (the car's TOML).
    pub topics: &'a Topics,
    /// The command scaling (throttle to speed) of the drive topic.
    pub drive: DriveMapping,
    /// Sensors to record.
    pub sensors: Subscribed,
    /// The car's LiDAR and camera mounts in base_link.
    pub lidar_b: agvrl_sim::msg::Pose3,
    /// The camera mount, when there is one.
    pub camera_b: Option<agvrl_sim::msg::Pose3>,
    /// The URDF text.
    pub urdf: Option<String>,
    /// Key/value pairs of the `agvrl` metadata record (policy hash, env settings).
    pub metadata: BTreeMap<String, String>,
    /// Stamps are simulated time (log time = stamp) rather than the wall clock.
    pub sim_time: bool,
}

#[derive(Clone, Copy, Default)]
struct Ix {
    scan: Option<usize>,
    imu: Option<usize>,
    odom: Option<usize>,
    navsat: Option<usize>,
    image: Option<usize>,
    drive: usize,
    tick: usize,
    tf: usize,
}

/// A drive being recorded.
pub struct DriveBag {
    rec: BagRecorder,
    ix: Ix,
    drive: DriveMapping,
    frame_id: String,
    sim_time: bool,
}

pub(crate) fn transform(parent: &str, child: &str, stamp_s: f64, p: &agvrl_sim::msg::Pose3) -> msg::TransformStamped {
    let ([tx, ty, tz], [rx, ry, rz, rw]) = (p.position_m, p.orientation_xyzw);
    msg::TransformStamped {
        header: mapping::header(stamp_s, parent),
        child_frame_id: child.into(),
        transform: msg::Transform {
            translation: msg::Vector3 {
                x: tx as f64,
                y: ty as f64,
                z: tz as f64,
            },
            rotation: msg::Quaternion {
                x: rx as f64,
                y: ry as f64,
                z: rz as f64,
                w: rw as f64,
            },
        },
    }
}

impl DriveBag {
    /// Create bag `dir` with the topics of `s` and start its writer thread; the static
    /// transforms, the URDF and the metadata go in first (stamped `t0_s`).
    pub fn create(dir: &Path, s: Setup<'_>, t0_s: f64) -> Result<Self, DeployError> {
        let mut w = BagWriter::create(dir)?;
        let mut add = |name: &str, ty: &str, offered: Offered| {
            w.add_topic(Topic {
                name: name.into(),
                ty: ty.into(),
                offered,
            })
        };
        let t = s.topics;
        let mut opt = |on: bool, name: &str, ty: &str| -> Result<Option<usize>, DeployError> {
            if on && !name.is_empty() {
                add(name, ty, Offered::Sensor).map(Some)
            } else {
                Ok(None)
            }
        };
        let mut ix = Ix {
            scan: opt(s.sensors.scan, &t.scan, "sensor_msgs/msg/LaserScan")?,
            imu: opt(s.sensors.imu, &t.imu, "sensor_msgs/msg/Imu")?,
            odom: opt(s.sensors.odom, &t.odom, "nav_msgs/msg/Odometry")?,
            navsat: opt(s.sensors.navsat, &t.navsat, "sensor_msgs/msg/NavSatFix")?,
            image: opt(s.sensors.image, &t.image, "sensor_msgs/msg/Image")?,
            ..Ix::default()
        };
        ix.drive = add(&t.drive, "ackermann_msgs/msg/AckermannDriveStamped", Offered::Reliable)?;
        ix.tick = add(TICK_TOPIC, "agvrl_msgs/msg/Tick", Offered::Reliable)?;
        ix.tf = add("/tf", "tf2_msgs/msg/TFMessage", Offered::Reliable)?;
        let tf_static = add("/tf_static", "tf2_msgs/msg/TFMessage", Offered::Latched)?;
        let description = add("/robot_description", "std_msgs/msg/String", Offered::Latched)?;
        let log = bag::ns(t0_s);
        let mut transforms = vec![transform(BASE_FRAME, LASER_FRAME, t0_s, &s.lidar_b)];
        if let Some(c) = &s.camera_b {
            transforms.push(transform(BASE_FRAME, CAMERA_FRAME, t0_s, c));
        }
        w.write(tf_static, log, log, &bag::cdr(&msg::TFMessage { transforms }))?;
        if let Some(u) = s.urdf {
            w.write(description, log, log, &bag::cdr(&msg::StdString { data: u }))?;
        }
        w.metadata("agvrl", s.metadata)?;
        Ok(Self {
            rec: BagRecorder::start(w),
            ix,
            drive: s.drive,
            frame_id: t.frame_id.clone(),
            sim_time: s.sim_time,
        })
    }

    /// Log time of a message stamped `stamp_s`: the stamp in simulated time, else now.
    fn log_ns(&self, stamp_s: f64) -> u64 {
        if self.sim_time {
            bag::ns(stamp_s)
        } else {
            bag::ns(crate::run_loop::wall_clock_s())
        }
    }

    fn put<M: serde::Serialize>(&self, index: Option<usize>, stamp_s: f64, m: &M) {
        if let Some(i) = index {
            let log = self.log_ns(stamp_s);
            self.rec.record(i, log, log, bag::cdr(m));
        }
    }

    /// Record the sensors of a simulated frame as the messages a car would publish, and
    /// odom to base_link on `/tf`.
    pub fn frame(&self, f: &SensorFrame, period_s: f32) {
        let t = f.stamp_s;
        if let Some(s) = &f.scan {
            self.put(self.ix.scan, t, &mapping::scan_msg(s, t, LASER_FRAME, period_s));
        }
        if let Some(i) = &f.imu {
            self.put(self.ix.imu, t, &mapping::imu_msg(i, t, &self.frame_id));
            if let Some(g) = &f.gps {
                let o = mapping::odom_msg(g, i, t, &self.frame_id);
                self.put(self.ix.odom, t, &o);
                self.put(Some(self.ix.tf), t, &odom_tf(&o));
            }
        }
        if let Some(geo) = f.gps.as_ref().and_then(|g| g.geodetic) {
            self.put(self.ix.navsat, t, &mapping::navsat_msg(&geo, t, "gps"));
        }
        if let Some(img) = &f.image {
            self.put(self.ix.image, t, &mapping::depth_image_msg(img, t, CAMERA_FRAME));
        }
    }

    /// Record a sensor message as it arrived (a ROS 2 car: every message, wall-clock receive
    /// time; its header stamp is the publish time).
    pub fn received<M: serde::Serialize + Stamped>(&self, which: Sensor, m: &M) {
        let index = match which {
            Sensor::Scan => self.ix.scan,
            Sensor::Imu => self.ix.imu,
            Sensor::Odom => self.ix.odom,
            Sensor::NavSat => self.ix.navsat,
            Sensor::Image => self.ix.image,
        };
        if let Some(i) = index {
            let log = bag::ns(crate::run_loop::wall_clock_s());
            self.rec.record(i, log, bag::ns(m.stamp_s()), bag::cdr(m));
        }
    }

    /// Record an Odometry message as it arrived, and its pose as odom to base_link on `/tf`.
    pub fn received_odom(&self, m: &msg::Odometry) {
        self.received(Sensor::Odom, m);
        let log = bag::ns(crate::run_loop::wall_clock_s());
        let publish = bag::ns(m.header.stamp.as_secs());
        self.rec.record(self.ix.tf, log, publish, bag::cdr(&odom_tf(m)));
    }

    /// Record a command sent on the drive topic, computed from the frame stamped `stamp_s`.
    pub fn command(&self, c: Control, stamp_s: f64) {
        let m = mapping::drive_command(c, &self.drive, stamp_s, &self.frame_id);
        self.put(Some(self.ix.drive), stamp_s, &m);
    }

    /// Record what tick `t` did.
    pub fn tick(&self, t: &Tick) {
        let (observation, action) = t.inference.clone().unwrap_or_default();
        let m = msg::Tick {
            header: mapping::header(t.stamp_s, BASE_FRAME),
            tick: t.index,
            observation,
            action,
            throttle: t.control.throttle,
            steering_rad: t.control.steering_rad,
            intervention: format!("{:?}", t.intervention).to_lowercase(),
            event: t.event.as_ref().map_or(String::new(), |e| format!("{e:?}")),
            infer_us: t.infer_us,
            late_s: t.late_s,
            clock_s: t.now_s,
            sensed_s: if self.sim_time { t.stamp_s } else { t.sensed_wall_s },
        };
        self.put(Some(self.ix.tick), t.stamp_s, &m);
    }

    /// Drain the queue and close the bag (summary, `metadata.yaml`).
    pub fn finish(self) -> Result<BagSummary, DeployError> {
        self.rec.finish()
    }
}

/// odom to base_link: the pose of an Odometry message.
fn odom_tf(o: &msg::Odometry) -> msg::TFMessage {
    msg::TFMessage {
        transforms: vec![msg::TransformStamped {
            header: mapping::header(o.header.stamp.as_secs(), ODOM_FRAME),
            child_frame_id: BASE_FRAME.into(),
            transform: mapping::odom_transform(o),
        }],
    }
}

/// The car side of a recording: its topics, sensors and command scaling, and its clock.
pub struct BagCar<'a> {
    /// Topic names.
    pub topics: &'a Topics,
    /// Sensors to record.
    pub sensors: Subscribed,
    /// The command scaling of the drive topic.
    pub drive: DriveMapping,
    /// Simulated time (log time = stamp, the bag starts at 0) rather than the wall clock.
    pub sim_time: bool,
}

/// Create bag `dir` for a drive of `env` (settings `env_cfg`) by the policy file `policy`
/// (`None`: another driver, as `agvrl eval --random`): the car's URDF, mounts, and in the
/// metadata the policy file's SHA-256 and the settings.
pub fn for_policy(
    dir: &Path,
    policy: Option<&Path>,
    env: &str,
    env_cfg: &agvrl_envs::EnvConfig,
    car: BagCar<'_>,
) -> Result<DriveBag, DeployError> {
    use sha2::Digest;
    let model = env_cfg
        .sim
        .vehicle_model()
        .map_err(|e| DeployError::Config(format!("the env's vehicle: {e}")))?;
    let urdf = agvrl_sim::assets::AssetSource::Embedded
        .read(&format!("vehicles/{}.urdf", model.name))
        .ok();
    let (name, hash) = match policy {
        Some(p) => {
            let bytes = std::fs::read(p).map_err(|source| DeployError::Io {
                path: p.to_path_buf(),
                source,
            })?;
            let hash = sha2::Sha256::digest(&bytes)
                .iter()
                .map(|b| format!("{b:02x}"))
                .collect();
            (p.display().to_string(), hash)
        }
        None => ("none".to_string(), String::new()),
    };
    let metadata = BTreeMap::from([
        ("policy".to_string(), name),
        ("policy_sha256".to_string(), hash),
        ("env".to_string(), env.to_string()),
        ("env_config".to_string(), toml::to_string(env_cfg).unwrap_or_default()),
        ("agvrl_drive".to_string(), env!("CARGO_PKG_VERSION").to_string()),
    ]);
    let setup = Setup {
        topics: car.topics,
        drive: car.drive,
        sensors: car.sensors,
        lidar_b: model.lidar_mount(),
        camera_b: model.camera_mount(),
        urdf,
        metadata,
        sim_time: car.sim_time,
    };
    let t0_s = if car.sim_time {
        0.0
    } else {
        crate::run_loop::wall_clock_s()
    };
    DriveBag::create(dir, setup, t0_s)
}

/// A vehicle whose frames and commands go into a bag as well (`frames`: record the frames'
/// sensors, for a simulated car; a ROS 2 car's messages are recorded as they arrive).
pub struct Recorded<V> {
    inner: V,
    bag: Arc<DriveBag>,
    frames: bool,
    recorded_any: bool,
    last_stamp_s: f64,
}

impl<V: Vehicle> Recorded<V> {
    /// Wrap `inner`.
    pub fn new(inner: V, bag: Arc<DriveBag>, frames: bool) -> Self {
        Self {
            inner,
            bag,
            frames,
            recorded_any: false,
            last_stamp_s: 0.0,
        }
    }

    fn seen(&mut self, f: &SensorFrame) {
        // The first tick senses the reset's frame again: the same messages, recorded once.
        if self.frames && !(self.recorded_any && f.stamp_s == self.last_stamp_s) {
            self.bag.frame(f, self.inner.control_period_s() as f32);
            self.recorded_any = true;
        }
        self.last_stamp_s = f.stamp_s;
    }
}

impl<V: Vehicle> Vehicle for Recorded<V> {
    fn reset(&mut self, seed: u64) -> Result<SensorFrame, EnvError> {
        let f = self.inner.reset(seed)?;
        self.seen(&f);
        Ok(f)
    }

    fn actuate(&mut self, control: Control) -> Result<(), EnvError> {
        self.bag.command(control, self.last_stamp_s);
        self.inner.actuate(control)
    }

    fn sense(&mut self) -> Result<SensorFrame, EnvError> {
        let f = self.inner.sense()?;
        self.seen(&f);
        Ok(f)
    }

    fn control_period_s(&self) -> f64 {
        self.inner.control_period_s()
    }

    fn steering_limit_rad(&self) -> f64 {
        self.inner.steering_limit_rad()
    }

    fn map(&self) -> Option<&MapInfo> {
        self.inner.map()
    }
}

/// What to do with a decoded bag message: its typed value handed over as `serde::Serialize`.
pub trait Decoded {
    /// The result.
    type Out;
    /// Turn message `m` into the result.
    fn decoded<M: serde::Serialize>(self, m: &M) -> Result<Self::Out, String>;
}

/// Decode bag message `m` by its ROS type and hand it to `to`; an error for a type without a
/// decoder here or bytes that do not decode.
pub fn decode_into<D: Decoded>(m: &bag::BagMessage, to: D) -> Result<D::Out, String> {
    fn d<M: serde::de::DeserializeOwned + serde::Serialize, D: Decoded>(data: &[u8], to: D) -> Result<D::Out, String> {
        to.decoded(&bag::decode::<M>(data)?)
    }
    let b = &m.data;
    match m.ty.as_str() {
        "sensor_msgs/msg/LaserScan" => d::<msg::LaserScan, D>(b, to),
        "sensor_msgs/msg/Imu" => d::<msg::Imu, D>(b, to),
        "nav_msgs/msg/Odometry" => d::<msg::Odometry, D>(b, to),
        "sensor_msgs/msg/NavSatFix" => d::<msg::NavSatFix, D>(b, to),
        "sensor_msgs/msg/Image" => d::<msg::Image, D>(b, to),
        "ackermann_msgs/msg/AckermannDriveStamped" => d::<msg::AckermannDriveStamped, D>(b, to),
        "tf2_msgs/msg/TFMessage" => d::<msg::TFMessage, D>(b, to),
        "std_msgs/msg/String" => d::<msg::StdString, D>(b, to),
        "agvrl_msgs/msg/Tick" => d::<msg::Tick, D>(b, to),
        other => Err(format!("no decoder for {other}")),
    }
}

/// A bag message decoded by its ROS type, as JSON (field names as in the `.msg` files), for
/// `agvrl-drive --dump` and comparisons with other readers.
pub fn decode_json(m: &bag::BagMessage) -> Result<serde_json::Value, String> {
    struct Json;
    impl Decoded for Json {
        type Out = serde_json::Value;
        fn decoded<M: serde::Serialize>(self, m: &M) -> Result<serde_json::Value, String> {
            serde_json::to_value(m).map_err(|e| e.to_string())
        }
    }
    decode_into(m, Json)
}
