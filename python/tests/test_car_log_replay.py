"""A car log written by another stack (PyPI's `rosbags`, MCAP storage, no `/agvrl/tick`) replays
through the policy as a live car would have read it: the watchdog stops the car on exactly the
ticks where the newest frame is stale (gaps, a sensor that stops) or holds a NaN range,
checked against the rule recomputed here from the script."""

import json
import math
import subprocess

import numpy as np

import agvrl

from conftest import need

T0 = 1_764_000_000 * 10**9  # a date: the stamps look like a real car's
RATE_HZ = 30.0
MAX_AGE_S = 2.0 / RATE_HZ  # the watchdog's default: two control periods
END_NS = 6 * 10**9
SCAN_GAP = (1_500_000_000, 1_800_000_000)  # scans lost
IMU_GAP = (3_000_000_000, 3_120_000_000)  # IMU samples lost
ODOM_STOPS = 4_000_000_000  # the odometry node dies
NAN_SCAN = 20  # this scan has one NaN range


def schedule():
    """(log ns, stamp ns, topic, index) of every message the scripted car sends."""
    out = []

    def stream(topic, offset_ns, period_ns, latency_ns, keep):
        k = 0
        while offset_ns + k * period_ns <= END_NS:
            t = offset_ns + k * period_ns
            if keep(t):
                out.append((T0 + t, T0 + t - latency_ns, topic, k))
            k += 1

    stream("/scan", 7_000_000, 33_333_333, 3_000_000, lambda t: not SCAN_GAP[0] <= t < SCAN_GAP[1])
    stream("/imu", 2_000_000, 10_000_000, 1_000_000, lambda t: not IMU_GAP[0] <= t < IMU_GAP[1])
    stream("/odom", 4_000_000, 20_000_000, 1_000_000, lambda t: t < ODOM_STOPS)
    return sorted(out)


def write_car_log(path):
    rosbag2, typesys = need("rosbags.rosbag2"), need("rosbags.typesys")
    ts = typesys.get_typestore(typesys.Stores.ROS2_JAZZY)
    T = ts.types
    Time = T["builtin_interfaces/msg/Time"]
    Header = T["std_msgs/msg/Header"]
    V3 = T["geometry_msgs/msg/Vector3"]
    Q = T["geometry_msgs/msg/Quaternion"]
    cov9, cov36 = np.zeros(9), np.zeros(36)

    def header(stamp_ns, frame):
        return Header(stamp=Time(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9), frame_id=frame)

    with rosbag2.Writer(path, version=9, storage_plugin=rosbag2.StoragePlugin.MCAP) as w:
        conns = {
            "/scan": w.add_connection("/scan", "sensor_msgs/msg/LaserScan", typestore=ts),
            "/imu": w.add_connection("/imu", "sensor_msgs/msg/Imu", typestore=ts),
            "/odom": w.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=ts),
        }
        # A topic agvrl has no decoder for: read around, never fatal.
        battery = w.add_connection("/battery", "sensor_msgs/msg/BatteryState", typestore=ts)
        b = T["sensor_msgs/msg/BatteryState"](
            header=header(T0, "base_link"), voltage=7.4, temperature=30.0, current=-1.0, charge=1.0, capacity=2.0,
            design_capacity=2.0, percentage=0.5, power_supply_status=2, power_supply_health=1,
            power_supply_technology=3, present=True, cell_voltage=np.zeros(2, dtype=np.float32),
            cell_temperature=np.zeros(2, dtype=np.float32), location="", serial_number="")
        w.write(battery, T0 + 1, ts.serialize_cdr(b, b.__msgtype__))
        for log, stamp, topic, k in schedule():
            x = 0.5 * (stamp - T0) * 1e-9  # driving ahead at 0.5 m/s
            if topic == "/scan":
                ranges = np.full(100, 2.0, dtype=np.float32)
                if k == NAN_SCAN:
                    ranges[50] = np.nan
                m = T["sensor_msgs/msg/LaserScan"](
                    header=header(stamp, "laser"), angle_min=-math.pi / 4, angle_max=math.pi / 4,
                    angle_increment=(math.pi / 2) / 99, time_increment=0.0, scan_time=1 / 30,
                    range_min=0.05, range_max=12.0, ranges=ranges, intensities=np.zeros(0, dtype=np.float32))
            elif topic == "/imu":
                m = T["sensor_msgs/msg/Imu"](
                    header=header(stamp, "base_link"), orientation=Q(x=0.0, y=0.0, z=0.0, w=1.0),
                    orientation_covariance=cov9, angular_velocity=V3(x=0.0, y=0.0, z=0.0),
                    angular_velocity_covariance=cov9, linear_acceleration=V3(x=0.0, y=0.0, z=9.81),
                    linear_acceleration_covariance=cov9)
            else:
                P = T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=x, y=0.0, z=0.0),
                                                orientation=Q(x=0.0, y=0.0, z=0.0, w=1.0))
                tw = T["geometry_msgs/msg/Twist"](linear=V3(x=0.5, y=0.0, z=0.0), angular=V3(x=0.0, y=0.0, z=0.0))
                m = T["nav_msgs/msg/Odometry"](
                    header=header(stamp, "odom"), child_frame_id="base_link",
                    pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=P, covariance=cov36),
                    twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=tw, covariance=cov36))
            w.write(conns[topic], log, ts.serialize_cdr(m, m.__msgtype__))


def expected_events():
    """Per tick, the event a live car's watchdog raises: tick k at start + k periods (start:
    when every sensor has spoken), each reading the newest message received by then."""
    msgs = schedule()
    start = max(min(m[0] for m in msgs if m[2] == t) for t in ("/scan", "/imu", "/odom"))
    end = msgs[-1][0]
    events, ticks = [], []
    k = 0
    while (t := start + round(k * 1e9 / RATE_HZ)) <= end:
        newest = {}
        for log, stamp, topic, i in msgs:
            if log <= t:
                newest[topic] = (stamp, i)
        oldest = min(s for s, _ in newest.values())
        age = (t - oldest) * 1e-9
        # No tick lies near the limit, so float rounding cannot flip a verdict.
        assert abs(age - MAX_AGE_S) > 1e-5, (k, age)
        if age > MAX_AGE_S:
            events.append("Stale")
        elif newest["/scan"][1] == NAN_SCAN:
            events.append("NotFinite")
        else:
            events.append("")
        ticks.append(t)
        k += 1
    return ticks, events


def test_a_rosbags_car_log_replays_and_the_watchdog_reacts_as_live(bins, root, tmp_path):
    bag = tmp_path / "carlog"
    write_car_log(bag)
    policy = root / "assets/policies/racing-oval-ppo.agvrl"
    ticks, want = expected_events()
    # Every kind of fault is in the script.
    assert want.count("NotFinite") >= 1 and want.count("Stale") > 60 and want.count("") > 100

    r = agvrl.replay(bag, policy)
    assert r.bag.types["/scan"] == "sensor_msgs/msg/LaserScan"
    assert len(r.bag.log_ns["/scan"]) == sum(1 for m in schedule() if m[2] == "/scan")
    got = [e.split(" ")[0].split("{")[0] for e in r.ticks["event"]]
    # The tick clock, seconds since the epoch as float64 (to 0.24 us at today's dates).
    assert len(r.ticks["clock_s"]) == len(ticks)
    assert np.abs(r.ticks["clock_s"] - np.array(ticks) * 1e-9).max() < 1e-6
    diff = [(k, w, g) for k, (w, g) in enumerate(zip(want, got)) if w != g]
    assert not diff, diff[:10]
    # The policy acted on every tick without an event, and on none with one.
    acted = ~np.isnan(r.ticks["action"]).any(axis=1)
    assert np.array_equal(acted, np.array([w == "" for w in want]))
    assert np.all(r.ticks["throttle"][~acted] == 0.0)
    # No recorded commands in a car log: the recorded columns are empty (NaN).
    assert np.isnan(r.ticks["recorded_action"]).all()

    run = subprocess.run([bins / "agvrl-drive", "--policy", policy, "--replay", bag, "--fast", "--quiet"],
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    summary = dict(kv.split("=", 1) for kv in run.stdout.split() if "=" in kv)
    assert int(summary["ticks"]) == len(want)
    assert int(summary["events"]) == sum(1 for w in want if w)
    # The topic without a decoder: a row with its size, a warning, not an error.
    dump = subprocess.run([bins / "agvrl-drive", "--dump", bag], capture_output=True, text=True)
    assert dump.returncode == 0, dump.stderr
    battery = [json.loads(line) for line in dump.stdout.splitlines() if '"/battery"' in line]
    assert len(battery) == 1 and battery[0]["msg"] is None and battery[0]["bytes"] > 0
    assert "1 messages of types without a decoder" in dump.stderr
    assert isinstance(r.bag.messages["/battery"][0], bytes)
    check = subprocess.run([bins / "agvrl-drive", "--policy", policy, "--replay", bag, "--fast", "--check"],
                           capture_output=True, text=True)
    assert check.returncode != 0 and "no recorded commands" in check.stderr, check.stderr
