"""Bags of `agvrl-drive --record` read by independent readers: PyPI's `mcap` with
`mcap-ros2-support`, and `rosbags`. Every message of every topic decodes in both, and its fields
equal agvrl-drive's own decode (`agvrl-drive --dump`), message for message."""

import json
import math
import subprocess

import numpy as np
import pytest

import agvrl

from conftest import need


def plain(o):
    """A decoded message as JSON-like data (NaN and infinities as None, as serde_json writes)."""
    if isinstance(o, dict):
        return {k: plain(v) for k, v in o.items()}
    if hasattr(o, "__dataclass_fields__"):
        return {k: plain(getattr(o, k)) for k in o.__dataclass_fields__ if k != "__msgtype__"}
    if hasattr(o, "__slots__"):
        return {k: plain(getattr(o, k)) for k in o.__slots__ if not k.startswith("_")}
    if isinstance(o, (bytes, bytearray)):
        return list(o)
    if isinstance(o, np.ndarray):
        return [plain(v) for v in o.tolist()]
    if isinstance(o, (list, tuple)):
        return [plain(v) for v in o]
    if isinstance(o, (float, np.floating)):
        return float(o) if math.isfinite(o) else None
    if isinstance(o, np.integer):
        return int(o)
    return o


def differences(ours, theirs, path=""):
    """Where `theirs` differs from `ours`."""
    if isinstance(ours, dict):
        if not isinstance(theirs, dict):
            return [f"{path}: {theirs!r} is no message"]
        return [d for k, v in ours.items() for d in differences(v, theirs.get(k, "<missing>"), f"{path}.{k}")]
    if isinstance(ours, list):
        if not isinstance(theirs, list) or len(ours) != len(theirs):
            return [f"{path}: lengths {len(ours)} vs {len(theirs) if isinstance(theirs, list) else theirs!r}"]
        return [d for i, (a, b) in enumerate(zip(ours, theirs)) for d in differences(a, b, f"{path}[{i}]")]
    if isinstance(ours, float) or isinstance(theirs, float):
        # A float32 field: the other reader gives its exact value, serde_json its shortest
        # decimal; a float64 field must match exactly.
        f32_field = theirs is not None and float(np.float32(theirs)) == theirs
        same = ours == theirs or (ours is not None and f32_field and np.float32(ours) == np.float32(theirs))
        return [] if same else [f"{path}: {ours!r} vs {theirs!r}"]
    return [] if ours == theirs else [f"{path}: {ours!r} vs {theirs!r}"]


def by_topic(rows):
    out = {}
    for topic, msg in rows:
        out.setdefault(topic, []).append(msg)
    return out


def test_a_recorded_drive_reads_the_same_in_mcap_ros2_and_rosbags(bins, root, tmp_path):
    mcap_reader, mcap_ros2 = need("mcap.reader"), need("mcap_ros2.decoder")
    rosbags_highlevel = need("rosbags.highlevel")
    bag = tmp_path / "drive"
    # The camera policy: its bag holds a depth Image too.
    run = subprocess.run(
        [bins / "agvrl-drive", "--policy", root / "assets/policies/racing-oval-camera.agvrl",
         "--steps", "60", "--quiet", "--record", bag],
        capture_output=True, text=True, check=True)
    assert "bag_messages=" in run.stdout
    dump = subprocess.run([bins / "agvrl-drive", "--dump", bag], capture_output=True, text=True, check=True)
    ours = by_topic((r["topic"], r["msg"]) for r in map(json.loads, dump.stdout.splitlines()))
    assert {"/scan", "/imu", "/odom", "/drive", "/tf", "/tf_static", "/robot_description", "/agvrl/tick",
            "/zed/zed_node/depth/depth_registered"} <= set(ours)

    with open(bag / "drive_0.mcap", "rb") as f:
        reader = mcap_reader.make_reader(f, decoder_factories=[mcap_ros2.DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        via_mcap = by_topic((ch.topic, plain(m)) for _, ch, _, m in reader.iter_decoded_messages())
    with rosbags_highlevel.AnyReader([bag]) as reader:
        via_rosbags = by_topic((c.topic, plain(reader.deserialize(raw, c.msgtype)))
                               for c, _, raw in reader.messages())

    for name, theirs in [("mcap-ros2-support", via_mcap), ("rosbags", via_rosbags)]:
        assert set(theirs) == set(ours), name
        for topic, msgs in ours.items():
            assert len(theirs[topic]) == len(msgs), f"{name} {topic}"
            for i, (a, b) in enumerate(zip(msgs, theirs[topic])):
                diff = differences(a, b)
                assert not diff, f"{name} {topic} #{i}: {diff[:5]}"


def test_read_bag_and_replay_give_the_drive_as_numpy_arrays(bins, root, tmp_path):
    bag = tmp_path / "drive"
    policy = root / "assets/policies/racing-oval-camera.agvrl"
    subprocess.run([bins / "agvrl-drive", "--policy", policy, "--steps", "60", "--quiet", "--record", bag],
                   capture_output=True, check=True)
    dump = subprocess.run([bins / "agvrl-drive", "--dump", bag], capture_output=True, text=True, check=True)
    ours = by_topic((r["topic"], r["msg"]) for r in map(json.loads, dump.stdout.splitlines()))

    b = agvrl.read_bag(bag)
    assert b.damage is None and set(b.messages) == set(ours)
    for topic, msgs in ours.items():
        assert len(b.messages[topic]) == len(msgs), topic
        for i, (a, m) in enumerate(zip(msgs, b.messages[topic])):
            diff = differences(a, plain(m))
            assert not diff, f"{topic} #{i}: {diff[:5]}"
    scans = b.arrays("/scan")
    assert scans["ranges"].shape == (60, 100) and scans["log_ns"].shape == (60,)
    assert scans["header.frame_id"][0] == "laser"
    image = b.arrays("/zed/zed_node/depth/depth_registered")
    assert isinstance(image["data"][0], bytes) and len(image["data"][0]) == 64 * 48 * 4
    with pytest.raises(KeyError, match="/scan"):
        b.arrays("/nope")

    r = agvrl.replay(bag, policy)
    ticks = b.arrays("/agvrl/tick")
    assert r.ticks["action"].shape == (60, 2) and r.ticks["observation"].shape[0] == 60
    assert np.array_equal(r.ticks["recorded_action"], ticks["action"])
    # The same binary code on the same data and CPU: the same actions and commands, bit for bit.
    assert np.array_equal(r.ticks["action"], r.ticks["recorded_action"])
    assert r.max_difference() == 0.0 and r.bad_messages == 0
    assert all(e == "" for e in r.ticks["event"])
    with pytest.raises(ValueError, match="no .mcap file"):
        agvrl.replay(tmp_path, policy)
