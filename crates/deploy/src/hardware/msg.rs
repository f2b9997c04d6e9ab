//! ROS 2 message structs, field for field as their `.msg` files (Jazzy), so serde's CDR
//! encoding is the wire layout any ROS 2 node or DDS implementation expects. Fixed-size
//! arrays stay arrays (no length prefix); `float32[]` and `string` are CDR sequences.

use serde::de::{SeqAccess, Visitor};
use serde::ser::SerializeTuple;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// `builtin_interfaces/Time`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Time {
    /// Whole seconds.
    pub sec: i32,
    /// Nanoseconds in [0, 1e9).
    pub nanosec: u32,
}

impl Time {
    /// The time `t_s` seconds (negative or non-finite reads 0).
    pub fn from_secs(t_s: f64) -> Self {
        if !(t_s.is_finite() && t_s > 0.0) {
            return Self::default();
        }
        let sec = t_s.floor();
        let nanosec = (((t_s - sec) * 1e9).round() as u32).min(999_999_999);
        Self {
            sec: sec.min(i32::MAX as f64) as i32,
            nanosec,
        }
    }

    /// Seconds.
    pub fn as_secs(&self) -> f64 {
        self.sec as f64 + self.nanosec as f64 * 1e-9
    }
}

/// `std_msgs/Header`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// Acquisition time.
    pub stamp: Time,
    /// Frame the data is expressed in.
    pub frame_id: String,
}

/// `geometry_msgs/Vector3`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Vector3 {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
}

/// `geometry_msgs/Point`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Point {
    /// x, metres.
    pub x: f64,
    /// y, metres.
    pub y: f64,
    /// z, metres.
    pub z: f64,
}

/// `geometry_msgs/Quaternion`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Quaternion {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
    /// w.
    pub w: f64,
}

impl Default for Quaternion {
    fn default() -> Self {
        Self {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 1.0,
        }
    }
}

/// `geometry_msgs/Pose`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    /// Position, metres.
    pub position: Point,
    /// Orientation.
    pub orientation: Quaternion,
}

/// `geometry_msgs/Twist`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Twist {
    /// Linear velocity, m/s.
    pub linear: Vector3,
    /// Angular velocity, rad/s.
    pub angular: Vector3,
}

/// A `float64[36]` (row-major 6x6 covariance). serde derives arrays only up to 32.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Covariance6(pub [f64; 36]);

impl Default for Covariance6 {
    fn default() -> Self {
        Self([0.0; 36])
    }
}

impl Serialize for Covariance6 {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut t = s.serialize_tuple(36)?;
        for v in &self.0 {
            t.serialize_element(v)?;
        }
        t.end()
    }
}

impl<'de> Deserialize<'de> for Covariance6 {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = Covariance6;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("36 float64")
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Covariance6, A::Error> {
                let mut out = [0.0; 36];
                for (i, v) in out.iter_mut().enumerate() {
                    *v = seq
                        .next_element()?
                        .ok_or_else(|| serde::de::Error::invalid_length(i, &self))?;
                }
                Ok(Covariance6(out))
            }
        }
        d.deserialize_tuple(36, V)
    }
}

/// `geometry_msgs/PoseWithCovariance`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PoseWithCovariance {
    /// Pose.
    pub pose: Pose,
    /// Covariance (x, y, z, rot x, rot y, rot z).
    pub covariance: Covariance6,
}

/// `geometry_msgs/TwistWithCovariance`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TwistWithCovariance {
    /// Twist.
    pub twist: Twist,
    /// Covariance.
    pub covariance: Covariance6,
}

/// `sensor_msgs/LaserScan` (REP 117: +inf no return, -inf too close, NaN invalid).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LaserScan {
    /// Header.
    pub header: Header,
    /// Bearing of the first ray, rad.
    pub angle_min: f32,
    /// Bearing of the last ray, rad.
    pub angle_max: f32,
    /// Angle between rays, rad.
    pub angle_increment: f32,
    /// Time between rays, s.
    pub time_increment: f32,
    /// Time between scans, s.
    pub scan_time: f32,
    /// Smallest valid range, m.
    pub range_min: f32,
    /// Largest valid range, m.
    pub range_max: f32,
    /// Ranges, m.
    pub ranges: Vec<f32>,
    /// Intensities (device units; may be empty).
    pub intensities: Vec<f32>,
}

/// `sensor_msgs/Imu`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Imu {
    /// Header.
    pub header: Header,
    /// Orientation.
    pub orientation: Quaternion,
    /// Its covariance (-1 in [0]: unknown).
    pub orientation_covariance: [f64; 9],
    /// Angular velocity, rad/s, body frame.
    pub angular_velocity: Vector3,
    /// Its covariance.
    pub angular_velocity_covariance: [f64; 9],
    /// Linear acceleration (specific force), m/s^2, body frame.
    pub linear_acceleration: Vector3,
    /// Its covariance.
    pub linear_acceleration_covariance: [f64; 9],
}

/// `nav_msgs/Odometry`: pose in `header.frame_id`, twist in `child_frame_id` (the body).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Odometry {
    /// Header.
    pub header: Header,
    /// Body frame.
    pub child_frame_id: String,
    /// Pose.
    pub pose: PoseWithCovariance,
    /// Twist, body frame.
    pub twist: TwistWithCovariance,
}

/// `sensor_msgs/NavSatStatus`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct NavSatStatus {
    /// -1 no fix, 0 fix, 1 SBAS, 2 GBAS.
    pub status: i8,
    /// Bit mask of services (1 GPS).
    pub service: u16,
}

/// `sensor_msgs/NavSatFix`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct NavSatFix {
    /// Header.
    pub header: Header,
    /// Fix status.
    pub status: NavSatStatus,
    /// Latitude, degrees north.
    pub latitude: f64,
    /// Longitude, degrees east.
    pub longitude: f64,
    /// Altitude above the WGS84 ellipsoid, m.
    pub altitude: f64,
    /// Position covariance, m^2 (ENU).
    pub position_covariance: [f64; 9],
    /// 0 unknown, 1 approximated, 2 diagonal known, 3 known.
    pub position_covariance_type: u8,
}

/// `ackermann_msgs/AckermannDrive`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct AckermannDrive {
    /// Virtual centre wheel angle, rad, positive left.
    pub steering_angle: f32,
    /// Steering rate limit, rad/s (0: as fast as possible).
    pub steering_angle_velocity: f32,
    /// Forward speed, m/s.
    pub speed: f32,
    /// Acceleration limit, m/s^2 (0: as fast as possible).
    pub acceleration: f32,
    /// Jerk limit, m/s^3 (0: as fast as possible).
    pub jerk: f32,
}

/// `ackermann_msgs/AckermannDriveStamped`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct AckermannDriveStamped {
    /// Header.
    pub header: Header,
    /// The command.
    pub drive: AckermannDrive,
}

/// `sensor_msgs/Image`: `height` rows of `step` bytes each; `data` is a CDR byte sequence.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Image {
    /// Header (stamp: acquisition time; frame_id: the optical frame).
    pub header: Header,
    /// Rows.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// Pixel encoding (`32FC1`, `16UC1`, `rgb8`, ...).
    pub encoding: String,
    /// 1 when multi-byte pixels are big-endian.
    pub is_bigendian: u8,
    /// Bytes per row.
    pub step: u32,
    /// Pixels, `step * height` bytes.
    #[serde(with = "serde_bytes")]
    pub data: Vec<u8>,
}

/// `geometry_msgs/Transform`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Transform {
    /// Translation, metres.
    pub translation: Vector3,
    /// Rotation.
    pub rotation: Quaternion,
}

/// `geometry_msgs/TransformStamped`: `child_frame_id`'s pose in `header.frame_id`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TransformStamped {
    /// Header (frame_id: the parent frame).
    pub header: Header,
    /// The child frame.
    pub child_frame_id: String,
    /// The child's pose in the parent.
    pub transform: Transform,
}

/// `tf2_msgs/TFMessage`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TFMessage {
    /// Transforms.
    pub transforms: Vec<TransformStamped>,
}

/// `std_msgs/String`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct StdString {
    /// The text.
    pub data: String,
}

/// `agvrl_msgs/Tick`: one control tick of `agvrl-drive` (schema in `bag/ros2msg.txt`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Tick {
    /// stamp: the sensor frame's stamp.
    pub header: Header,
    /// Tick number since start.
    pub tick: u64,
    /// The observation the policy saw (empty when the watchdog stopped the car).
    pub observation: Vec<f32>,
    /// The policy's raw action (empty when it did not run).
    pub action: Vec<f32>,
    /// Throttle sent, after the safety filter.
    pub throttle: f64,
    /// Steering angle sent, rad.
    pub steering_rad: f64,
    /// What the safety filter did.
    pub intervention: String,
    /// A watchdog event ("" when none).
    pub event: String,
    /// Checks, observation and inference, microseconds.
    pub infer_us: f64,
    /// How late the tick started after its deadline, seconds.
    pub late_s: f64,
    /// The watchdog's clock on this tick, seconds.
    pub clock_s: f64,
    /// When the tick read its frame, on the bag's log clock, seconds.
    pub sensed_s: f64,
}
