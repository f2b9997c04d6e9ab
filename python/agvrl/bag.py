"""Bags of ``agvrl-drive --record`` and ``agvrl eval --record`` (rosbag2, MCAP storage) from
Python: the decoded messages of every topic, and a bag replayed through a policy, as numpy
arrays.

    import agvrl
    bag = agvrl.read_bag("drive")                    # every message, decoded
    scans = bag.arrays("/scan")                      # {"log_ns": (N,), "ranges": (N, 100), ...}
    r = agvrl.replay("drive", "assets/policies/racing-oval-ppo.agvrl")
    (r.ticks["action"] - r.ticks["recorded_action"]).max()   # 0.0 on the same CPU
"""

from __future__ import annotations

import numbers
import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from agvrl import _core


@dataclass
class Bag:
    """The intact messages of a bag, in log order, per topic."""

    #: Topic to its ROS type (``sensor_msgs/msg/LaserScan``).
    types: dict[str, str]
    #: Topic to its messages, each a dict of the ``.msg`` file's fields (bytes for ``uint8[]``).
    messages: dict[str, list[Any]]
    #: Topic to the messages' log times, ns (receive time; simulated time counts from 0).
    log_ns: dict[str, np.ndarray]
    #: Where a damaged bag stopped being readable (``None`` when intact).
    damage: str | None = None

    def arrays(self, topic: str) -> dict[str, np.ndarray]:
        """The messages of ``topic`` as columns: one array per field (nested fields joined by
        dots, ``pose.pose.position.x``), stacked over messages (a list field of one length
        gives a 2-D array; bytes, strings and lists of messages stay lists). Plus ``log_ns``."""
        if topic not in self.messages:
            raise KeyError(f"{topic!r}: the bag's topics are {sorted(self.messages)}")
        rows = [_flatten(m) for m in self.messages[topic]]
        out: dict[str, Any] = {"log_ns": self.log_ns[topic]}
        for key in rows[0] if rows else ():
            out[key] = _stack([r.get(key) for r in rows])
        return out


def _flatten(m: Any, prefix: str = "", out: dict[str, Any] | None = None) -> dict[str, Any]:
    out = {} if out is None else out
    if isinstance(m, dict):
        for k, v in m.items():
            _flatten(v, f"{prefix}{k}.", out)
    else:
        out[prefix[:-1]] = m
    return out


def _stack(values: list[Any]) -> Any:
    if all(isinstance(v, numbers.Number) and not isinstance(v, bool) for v in values):
        return np.asarray(values)
    if all(isinstance(v, bool) for v in values):
        return np.asarray(values, dtype=bool)
    if all(isinstance(v, list) and all(isinstance(x, numbers.Number) for x in v) for v in values):
        if len({len(v) for v in values}) == 1:
            return np.asarray(values)
        return [np.asarray(v) for v in values]
    return values


def read_bag(path: str | os.PathLike[str]) -> Bag:
    """Read bag directory ``path`` (or its ``.mcap`` file's directory). A damaged bag gives its
    intact messages and says where it stopped in ``damage``; an unreadable one raises
    ``ValueError`` naming the file."""
    rows, damage = _core.bag_messages(os.fspath(path))
    types: dict[str, str] = {}
    messages: dict[str, list[Any]] = {}
    times: dict[str, list[int]] = {}
    for topic, ty, log_ns, msg in rows:
        types.setdefault(topic, ty)
        messages.setdefault(topic, []).append(msg)
        times.setdefault(topic, []).append(log_ns)
    log_ns = {t: np.asarray(v, dtype=np.uint64) for t, v in times.items()}
    return Bag(types=types, messages=messages, log_ns=log_ns, damage=damage)


@dataclass
class Replay:
    """A bag replayed through a policy, open loop, as ``agvrl-drive --replay`` does."""

    #: The bag's messages.
    bag: Bag
    #: One row per recorded tick: ``tick``, ``clock_s``, ``stamp_s``, the replay's
    #: ``observation``, ``action`` (NaN rows where the watchdog stopped the car),
    #: ``throttle``, ``steering_rad`` and ``event`` beside ``recorded_observation``,
    #: ``recorded_action``, ``recorded_throttle``, ``recorded_steering_rad``,
    #: ``recorded_event``.
    ticks: dict[str, Any] = field(default_factory=dict)
    #: Sensor messages that did not decode (skipped, as a live car skips them).
    bad_messages: int = 0

    def max_difference(self) -> float:
        """The largest |replayed - recorded| over actions and controls (NaN rows, where one
        side did not act, compare equal when both are NaN)."""
        t = self.ticks
        diffs = [
            np.abs(t["action"] - t["recorded_action"]),
            np.abs(t["throttle"] - t["recorded_throttle"]),
            np.abs(t["steering_rad"] - t["recorded_steering_rad"]),
        ]
        return float(max((np.nanmax(d) if d.size and not np.all(np.isnan(d)) else 0.0) for d in diffs))


def replay(
    bag: str | os.PathLike[str],
    policy: str | os.PathLike[str],
    *,
    config: str | os.PathLike[str] | None = None,
    set: tuple[str, ...] | list[str] = (),
    seed: int = 0,
) -> Replay:
    """Replay ``bag`` through the policy file ``policy`` (its embedded settings; ``set``
    overrides them as ``agvrl train --set KEY=VALUE``). ``config`` is the car's TOML for a car
    log (topic names, scan mapping); without it the scans are taken to have the policy's own
    rays. Raises ``ValueError`` for a bag or policy that cannot be read or do not fit."""
    ticks = _core.replay_bag(
        os.fspath(bag),
        os.fspath(policy),
        None if config is None else os.fspath(config),
        [str(s) for s in set],
        seed,
    )
    bad = int(ticks.pop("bad_messages"))
    ticks.pop("damage")
    return Replay(bag=read_bag(bag), ticks=ticks, bad_messages=bad)
