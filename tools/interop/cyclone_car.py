#!/usr/bin/env python3
"""A fake ROS 2 car on Eclipse Cyclone DDS (PyPI `cyclonedds`), to check agvrl-drive's DDS
(RustDDS) against an independent implementation. It publishes LaserScan (a straight corridor),
Imu and Odometry stamped with the wall clock, subscribes AckermannDriveStamped on the drive
topic, checks every command it receives and prints `key=value` lines at exit.

    python3 tools/interop/cyclone_car.py --domain-id 42 --duration-s 8

Scenarios: --scan-stop-after-s (scans stop: agvrl-drive must command zero speed),
--drive-reader-delay-s (the drive reader joins late), --twist-reader (only a Twist reader on
the drive topic: agvrl-drive must refuse to start), --depth-image-hz (a depth camera: 32FC1
Images whose pixels code their own column and row; `--verify-image-trace TRACE` then checks
the camera part of agvrl-drive's observations against the crop and resize recomputed here).
See tools/interop/check-cyclone.sh.
"""

import argparse
import array
import json
import math
import os
import signal
import statistics
import struct
import sys
import threading
import time
from dataclasses import dataclass, field

from cyclonedds._clayer import ddspy_write
from cyclonedds.core import Listener, Policy, Qos
from cyclonedds.domain import Domain, DomainParticipant
from cyclonedds.idl import IdlStruct
import cyclonedds.idl.types as types
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic

# Discovery on loopback, no multicast. RustDDS announces itself (SPDP) only to the multicast
# group and to the well-known unicast discovery ports on localhost (7410 + 250 * domain + 2 * i,
# i < 12), so Cyclone must listen on one of those: ParticipantIndex auto. Measured here with
# index none: peers 127.0.0.1 without multicast never discovered (8 s); multicast forced on lo
# took ~8 s in 3 runs of 4. This config: under 0.3 s every run, also in a netns with only lo.
# CYCLONEDDS_URI, when set, replaces it.
LOOPBACK_XML = """<CycloneDDS><Domain Id="any"><General>
  <Interfaces><NetworkInterface name="lo"/></Interfaces>
  <AllowMulticast>false</AllowMulticast>
</General><Discovery>
  <ParticipantIndex>auto</ParticipantIndex>
  <Peers><Peer address="127.0.0.1"/></Peers>
</Discovery></Domain></CycloneDDS>"""


# ROS 2 messages as rmw types: `pkg::msg::dds_::Name_`, fields as the Jazzy .msg files.
@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: types.int32
    nanosec: types.uint32


@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time
    frame_id: str


@dataclass
class Vector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    x: types.float64
    y: types.float64
    z: types.float64


@dataclass
class Point(IdlStruct, typename="geometry_msgs::msg::dds_::Point_"):
    x: types.float64
    y: types.float64
    z: types.float64


@dataclass
class Quaternion(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    x: types.float64
    y: types.float64
    z: types.float64
    w: types.float64


@dataclass
class Pose(IdlStruct, typename="geometry_msgs::msg::dds_::Pose_"):
    position: Point
    orientation: Quaternion


@dataclass
class PoseWithCovariance(IdlStruct, typename="geometry_msgs::msg::dds_::PoseWithCovariance_"):
    pose: Pose
    covariance: types.array[types.float64, 36]


@dataclass
class Twist(IdlStruct, typename="geometry_msgs::msg::dds_::Twist_"):
    linear: Vector3
    angular: Vector3


@dataclass
class TwistWithCovariance(IdlStruct, typename="geometry_msgs::msg::dds_::TwistWithCovariance_"):
    twist: Twist
    covariance: types.array[types.float64, 36]


@dataclass
class LaserScan(IdlStruct, typename="sensor_msgs::msg::dds_::LaserScan_"):
    header: Header
    angle_min: types.float32
    angle_max: types.float32
    angle_increment: types.float32
    time_increment: types.float32
    scan_time: types.float32
    range_min: types.float32
    range_max: types.float32
    ranges: types.sequence[types.float32]
    intensities: types.sequence[types.float32]


@dataclass
class Imu(IdlStruct, typename="sensor_msgs::msg::dds_::Imu_"):
    header: Header
    orientation: Quaternion
    orientation_covariance: types.array[types.float64, 9]
    angular_velocity: Vector3
    angular_velocity_covariance: types.array[types.float64, 9]
    linear_acceleration: Vector3
    linear_acceleration_covariance: types.array[types.float64, 9]


@dataclass
class Odometry(IdlStruct, typename="nav_msgs::msg::dds_::Odometry_"):
    header: Header
    child_frame_id: str
    pose: PoseWithCovariance
    twist: TwistWithCovariance


@dataclass
class Image(IdlStruct, typename="sensor_msgs::msg::dds_::Image_"):
    header: Header
    height: types.uint32
    width: types.uint32
    encoding: str
    is_bigendian: types.uint8
    step: types.uint32
    data: types.sequence[types.uint8]


@dataclass
class AckermannDrive(IdlStruct, typename="ackermann_msgs::msg::dds_::AckermannDrive_"):
    steering_angle: types.float32
    steering_angle_velocity: types.float32
    speed: types.float32
    acceleration: types.float32
    jerk: types.float32


@dataclass
class AckermannDriveStamped(IdlStruct, typename="ackermann_msgs::msg::dds_::AckermannDriveStamped_"):
    header: Header
    drive: AckermannDrive


def ros_time(t_s):
    sec = math.floor(t_s)
    return Time(sec=sec, nanosec=min(int(round((t_s - sec) * 1e9)), 999_999_999))


def dds_topic(name):
    return "rt/" + name.lstrip("/")


def corridor_scan(n_rays, fov_rad, half_width_m, range_max_m):
    """A straight corridor centred on the car: range to the side walls, +inf ahead (REP 117)."""
    a0, inc = -fov_rad / 2, fov_rad / (n_rays - 1)
    out = []
    for i in range(n_rays):
        s = abs(math.sin(a0 + i * inc))
        r = half_width_m / s if s > 1e-9 else math.inf
        out.append(r if r <= range_max_m else math.inf)
    return a0, inc, out


def coded_depth(k, n):
    """Depth of pixel k (row-major) of n: 0.3 + 7.5 k / n metres, so a reading names its pixel."""
    return 0.3 + 7.5 * k / n


def depth_image(w, h):
    """A 32FC1 little-endian image of coded depths."""
    px = array.array("f", (coded_depth(k, w * h) for k in range(w * h)))
    if sys.byteorder != "little":
        px.byteswap()
    return px.tobytes()


class PrestampedImage:
    """An Image serialized once; each write patches only its stamp. Serializing 1 MB of uint8
    takes ~90 ms in cyclonedds' Python, longer than the 50 Hz loop's period."""

    def __init__(self, writer, w, h, frame_id):
        self.writer = writer
        ser = Image(Header(Time(0, 0), frame_id), h, w, "32FC1", 0, 4 * w, depth_image(w, h)).serialize()
        assert ser[:2] == b"\x00\x01", "little-endian plain CDR"  # the stamp follows at offset 4
        self.ser = bytearray(ser.ljust((len(ser) + 3) & ~3, b"\0"))

    def write(self, stamp):
        struct.pack_into("<iI", self.ser, 4, stamp.sec, stamp.nanosec)
        if ddspy_write(self.writer._ref, bytes(self.ser)) < 0:
            raise RuntimeError("writing an image failed")


def compare_bag_dump(commands_path, dump_path):
    """The car's received commands against the bag's /drive topic, in order, field for field
    (both float32 on the wire: equal bits). Prints key=value lines; exit 1 on a difference."""
    with open(commands_path) as f:
        got = [json.loads(line) for line in f]
    with open(dump_path) as f:
        rows = [json.loads(line) for line in f]
    bag = [r["msg"] for r in rows if r["topic"] == "/drive"]
    bag = [(m["header"]["stamp"]["sec"] + m["header"]["stamp"]["nanosec"] * 1e-9, m["drive"]["speed"],
            m["drive"]["steering_angle"]) for m in bag]
    car = [(c["stamp_s"], c["speed"], c["steering"]) for c in got]
    # The car's keep-last-1 reader may miss a command; every one it got is in the bag, in order.
    it = iter(bag)
    missing = sum(not any(abs(b[0] - c[0]) < 1e-6 and b[1:] == c[1:] for b in it) for c in car)
    print(f"bag_commands={len(bag)}\ncar_commands={len(car)}\ncar_commands_not_in_bag={missing}")
    return 0 if car and not missing and len(bag) >= len(car) else 1


def verify_image_trace(a):
    """Check the camera part of each traced observation: depth / depth_max of the source pixel
    that the crop (centre window with the policy's vertical field of view and aspect) and the
    nearest-pixel resize pick. Prints key=value lines; exit 1 on a wrong pixel."""
    w, h = (int(v) for v in a.image_size.split("x"))
    pw, ph = (int(v) for v in a.policy_image.split("x"))
    ch = h * math.tan(math.radians(a.policy_vfov_deg) / 2) / math.tan(math.radians(a.image_vfov_deg) / 2)
    cw = ch * pw / ph
    x0, y0 = (w - cw) / 2, (h - ch) / 2
    want = [coded_depth(min(h - 1, math.floor(y0 + (y + 0.5) * ch / ph)) * w
                        + min(w - 1, math.floor(x0 + (x + 0.5) * cw / pw)), w * h) / a.depth_max_m
            for y in range(ph) for x in range(pw)]
    rows = wrong = worst = 0
    with open(a.verify_image_trace) as f:
        for line in f:
            img = json.loads(line)["obs"][-pw * ph:]
            rows += 1
            for got, exp in zip(img, want):
                err = abs(got - exp)
                worst = max(worst, err)
                # Neighbouring pixels differ by 7.5 / (w h depth_max); f32 rounding is far below.
                wrong += err > 0.25 * 7.5 / (w * h * a.depth_max_m)
    print(f"image_rows={rows}\nimage_pixels_checked={rows * pw * ph}\nimage_pixels_wrong={wrong}\n"
          f"image_max_abs_err={worst:.3g}")
    return 0 if rows and not wrong else 1


@dataclass
class Command:
    recv_s: float
    stamp_s: float
    frame_id: str
    speed: float
    steering: float
    rest: tuple  # steering_angle_velocity, acceleration, jerk


@dataclass
class Log:
    lock: threading.Lock = field(default_factory=threading.Lock)
    cmds: list = field(default_factory=list)
    decode_errors: int = 0


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--domain-id", type=int, default=0)
    p.add_argument("--duration-s", type=float, default=10.0, help="run this long, then report")
    p.add_argument("--rate-hz", type=float, default=50.0, help="sensor rate (agvrl-drive ticks at 30 Hz)")
    p.add_argument("--scan-stop-after-s", type=float, default=None, help="stop publishing scans at this time")
    p.add_argument("--drive-reader-delay-s", type=float, default=0.0, help="create the drive reader this late")
    p.add_argument("--twist-reader", action="store_true",
                   help="only a geometry_msgs/Twist reader on the drive topic (agvrl-drive must refuse it)")
    p.add_argument("--drive-reader-qos", choices=["volatile", "transient_local", "xcdr2"], default="volatile",
                   help="the drive reader's QoS; the last two cannot match agvrl-drive's writer")
    p.add_argument("--scan-topic", default="/scan")
    p.add_argument("--imu-topic", default="/imu")
    p.add_argument("--odom-topic", default="/odom")
    p.add_argument("--drive-topic", default="/drive")
    p.add_argument("--frame-id", default="base_link", help="expected header.frame_id of the commands")
    p.add_argument("--max-speed-mps", type=float, default=1.79, help="full-throttle speed (config drive.max_speed_mps)")
    p.add_argument("--steering-limit-rad", type=float, default=0.36)
    p.add_argument("--n-rays", type=int, default=100)
    p.add_argument("--fov-deg", type=float, default=90.0)
    p.add_argument("--range-max-m", type=float, default=12.0)
    p.add_argument("--corridor-half-width-m", type=float, default=1.5)
    p.add_argument("--depth-image-hz", type=float, default=0.0, help="publish depth Images at this rate")
    p.add_argument("--image-topic", default="/zed/zed_node/depth/depth_registered")
    p.add_argument("--image-size", default="672x376", help="WxH of the published image (ZED 2 VGA)")
    p.add_argument("--image-vfov-deg", type=float, default=70.0, help="its vertical field of view")
    p.add_argument("--commands-out", metavar="FILE",
                   help="write every command received as a JSON line (stamp_s, speed, steering)")
    p.add_argument("--compare-bag-dump", nargs=2, metavar=("COMMANDS", "DUMP"),
                   help="compare a --commands-out file with the /drive messages of `agvrl-drive --dump`")
    p.add_argument("--verify-image-trace", metavar="TRACE",
                   help="check agvrl-drive's --trace instead of running the car")
    p.add_argument("--policy-image", default="64x48", help="the policy camera's WxH")
    p.add_argument("--policy-vfov-deg", type=float, default=70.0)
    p.add_argument("--depth-max-m", type=float, default=8.0, help="observation depth that reads 1")
    a = p.parse_args()
    if a.verify_image_trace:
        sys.exit(verify_image_trace(a))
    if a.compare_bag_dump:
        sys.exit(compare_bag_dump(*a.compare_bag_dump))

    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())

    # The Domain object must outlive the participant for its config to hold.
    domain = None
    if not os.environ.get("CYCLONEDDS_URI"):
        domain = Domain(a.domain_id, LOOPBACK_XML)
    dp = DomainParticipant(a.domain_id)
    # ROS 2 sensor data: best effort, keep last 1, volatile (as a real car's drivers).
    sensor_qos = Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(1), Policy.Durability.Volatile)
    # --drive-reader-qos other than `volatile` asks what agvrl-drive's volatile XCDR1 writer cannot
    # offer: the reader never matches, so agvrl-drive should not count it as a reader.
    drive_qos = Qos(Policy.Reliability.Reliable(max_blocking_time=100_000_000), Policy.History.KeepLast(1),
                    *{"volatile": [Policy.Durability.Volatile],
                      "transient_local": [Policy.Durability.TransientLocal],
                      "xcdr2": [Policy.Durability.Volatile,
                                Policy.DataRepresentation(use_xcdrv2_representation=True)]}[a.drive_reader_qos])
    scan_w = DataWriter(dp, Topic(dp, dds_topic(a.scan_topic), LaserScan), sensor_qos)
    imu_w = DataWriter(dp, Topic(dp, dds_topic(a.imu_topic), Imu), sensor_qos)
    odom_w = DataWriter(dp, Topic(dp, dds_topic(a.odom_topic), Odometry), sensor_qos)
    image_w = None
    if a.depth_image_hz > 0:
        image_w = DataWriter(dp, Topic(dp, dds_topic(a.image_topic), Image), sensor_qos)
        iw, ih = (int(v) for v in a.image_size.split("x"))
        image = PrestampedImage(image_w, iw, ih, "zed_left_camera_optical_frame")
    images = 0

    log = Log()
    published_stamps = set()  # (sec, nanosec) of every sensor set, to check command stamps against

    def on_drive(reader):
        now = time.time()  # receive time, taken before decoding
        try:
            samples = reader.take(N=64)
        except Exception as e:  # a sample Cyclone could not decode
            with log.lock:
                log.decode_errors += 1
            print(f"decode error: {e}", file=sys.stderr)
            return
        with log.lock:
            for m in samples:
                if not getattr(m.sample_info, "valid_data", False):
                    continue
                d = m.drive
                log.cmds.append(Command(now, m.header.stamp.sec + m.header.stamp.nanosec * 1e-9, m.header.frame_id,
                                        d.speed, d.steering_angle, (d.steering_angle_velocity, d.acceleration, d.jerk)))

    def make_drive_reader():
        if a.twist_reader:
            return DataReader(dp, Topic(dp, dds_topic(a.drive_topic), Twist), drive_qos)
        return DataReader(dp, Topic(dp, dds_topic(a.drive_topic), AckermannDriveStamped), drive_qos,
                          listener=Listener(on_data_available=on_drive))

    a0, inc, ranges = corridor_scan(a.n_rays, math.radians(a.fov_deg), a.corridor_half_width_m, a.range_max_m)
    zeros9, zeros36 = [0.0] * 9, [0.0] * 36
    period = 1.0 / a.rate_hz
    wheelbase = 0.33
    v = x = 0.0  # a first-order speed plant, so the policy sees the speed it asked for
    t0 = time.time()
    drive_reader = make_drive_reader() if a.drive_reader_delay_s <= 0 else None
    reader_created_s = t0 if drive_reader else None
    last_scan_s = last_scan_stamp = None
    scans = 0
    k = 0
    while not stop.is_set():
        k += 1
        deadline = t0 + k * period
        now = time.time()
        if now - t0 >= a.duration_s:
            break
        if now < deadline:
            time.sleep(deadline - now)
        now = time.time()
        el = now - t0
        if drive_reader is None and el >= a.drive_reader_delay_s:
            drive_reader = make_drive_reader()
            reader_created_s = now
        with log.lock:
            last = log.cmds[-1] if log.cmds else None
        cmd_v, steer = (last.speed, last.steering) if last and now - last.recv_s < 0.5 else (0.0, 0.0)
        if not (math.isfinite(cmd_v) and math.isfinite(steer)):
            cmd_v = steer = 0.0
        v += (cmd_v - v) * min(1.0, period / 0.3)
        yaw_rate = v * math.tan(steer) / wheelbase
        x += v * period
        stamp = ros_time(now)
        published_stamps.add((stamp.sec, stamp.nanosec))
        if a.scan_stop_after_s is None or el < a.scan_stop_after_s:
            scan_w.write(LaserScan(Header(stamp, "laser"), a0, a0 + inc * (a.n_rays - 1), inc, 0.0, period,
                                   0.05, a.range_max_m, ranges, []))
            last_scan_s, last_scan_stamp = time.time(), stamp
            scans += 1
        if image_w is not None and el * a.depth_image_hz >= images:
            image.write(stamp)
            images += 1
        imu_w.write(Imu(Header(stamp, a.frame_id), Quaternion(0.0, 0.0, 0.0, 1.0), zeros9,
                        Vector3(0.0, 0.0, yaw_rate), zeros9, Vector3(0.0, 0.0, 9.81), zeros9))
        odom_w.write(Odometry(Header(stamp, "odom"), a.frame_id,
                              PoseWithCovariance(Pose(Point(x, 0.0, 0.0), Quaternion(0.0, 0.0, 0.0, 1.0)), zeros36),
                              TwistWithCovariance(Twist(Vector3(v, 0.0, 0.0), Vector3(0.0, 0.0, yaw_rate)), zeros36)))

    time.sleep(0.2)  # commands still in flight
    with log.lock:
        cmds = list(log.cmds)
        decode_errors = log.decode_errors
    if a.commands_out:
        with open(a.commands_out, "w") as f:
            for c in cmds:
                f.write(json.dumps({"stamp_s": c.stamp_s, "speed": c.speed, "steering": c.steering}) + "\n")
    report(a, cmds, decode_errors, published_stamps, t0, reader_created_s, scans, last_scan_s, last_scan_stamp)
    if image_w is not None:
        print(f"images_published={images}")
    del domain


def report(a, cmds, decode_errors, published_stamps, t0, reader_created_s, scans, last_scan_s, last_scan_stamp):
    out = {}
    out["scans_published"] = scans
    out["drive_reader"] = "twist" if a.twist_reader else "ackermann"
    out["drive_reader_created_s"] = f"{reader_created_s - t0:.3f}" if reader_created_s else "never"
    out["commands"] = len(cmds)
    out["decode_errors"] = decode_errors
    lim = a.steering_limit_rad + 1e-6
    # agvrl-drive prints the full-throttle speed to 2 decimals (1.79; sent as 1.7906): 0.005 slack.
    vmax = a.max_speed_mps + 0.005
    stamp_set = {round(s[0] + s[1] * 1e-9, 6) for s in published_stamps}
    bad = {
        "bad_frame_id": sum(c.frame_id != a.frame_id for c in cmds),
        "bad_speed": sum(not (math.isfinite(c.speed) and -vmax <= c.speed <= vmax)
                         for c in cmds),
        "bad_steering": sum(not (math.isfinite(c.steering) and abs(c.steering) <= lim) for c in cmds),
        # agvrl-drive leaves the limits at 0: "as fast as possible".
        "bad_limits": sum(any(r != 0.0 for r in c.rest) for c in cmds),
        # A command's stamp is the sensor set it was computed from: one we published.
        "bad_stamp": sum(round(c.stamp_s, 6) not in stamp_set for c in cmds),
    }
    out.update(bad)
    out["fields_ok"] = int(decode_errors == 0 and not any(bad.values())) if cmds else "na"
    if cmds:
        # Sensor stamp to command receipt, while scans flow (later commands carry the last scan's stamp).
        live = [c for c in cmds if last_scan_s is None or a.scan_stop_after_s is None or c.recv_s <= last_scan_s]
        lat = sorted(c.recv_s - c.stamp_s for c in live or cmds)
        out["stamp_to_receive_ms_p50"] = f"{1e3 * statistics.median(lat):.1f}"
        out["stamp_to_receive_ms_max"] = f"{1e3 * lat[-1]:.1f}"
        out["first_command_s"] = f"{cmds[0].recv_s - t0:.3f}"
        out["first_command_stamp_age_ms"] = f"{1e3 * (cmds[0].recv_s - cmds[0].stamp_s):.1f}"
        out["speed_max"] = f"{max(c.speed for c in cmds):.3f}"
        out["speed_mean"] = f"{statistics.fmean(c.speed for c in cmds):.3f}"
        out["nonzero_commands"] = sum(c.speed != 0.0 for c in cmds)
        gaps = [b.recv_s - a_.recv_s for a_, b in zip(cmds, cmds[1:])]
        if gaps:
            out["command_gap_ms_max"] = f"{1e3 * max(gaps):.1f}"
    if a.scan_stop_after_s is not None and last_scan_s is not None:
        ls = last_scan_stamp.sec + last_scan_stamp.nanosec * 1e-9
        after = [c for c in cmds if c.recv_s > last_scan_s]
        first_zero = next((c for c in after if c.speed == 0.0), None)
        out["last_scan_s"] = f"{last_scan_s - t0:.3f}"
        out["commands_after_last_scan"] = len(after)
        out["nonzero_after_last_scan"] = sum(c.speed != 0.0 for c in after)
        # Commands computed from the last scan's sensor set (the frame's stamp is its oldest topic).
        out["nonzero_on_last_scan"] = sum(c.speed != 0.0 and abs(c.stamp_s - ls) < 1e-6 for c in cmds)
        out["nonzero_after_first_zero"] = (
            sum(c.speed != 0.0 for c in after if c.recv_s > first_zero.recv_s) if first_zero else "na")
        out["last_scan_to_first_zero_ms"] = f"{1e3 * (first_zero.recv_s - last_scan_s):.1f}" if first_zero else "na"
    for k, v in out.items():
        print(f"{k}={v}")
    sys.stdout.flush()


if __name__ == "__main__":
    main()
