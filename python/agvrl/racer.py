"""Classical racers, the lap times a racing policy should beat: pure pursuit along the track's
centre line (or a raceline CSV) and follow-the-gap from the LiDAR alone."""

from __future__ import annotations

import os

import numpy as np

from agvrl import _core


class Racer:
    """A scripted driver of a racing env: ``Racer("pure-pursuit", env)`` or
    ``Racer("follow-the-gap", env, speed_scale=0.75)``. ``act()`` returns the action it takes on
    the env's last frame (call it after ``reset`` and after every ``step``), in the env's action
    space, so it drives wherever a policy's actions go::

        env = agvrl.make("racing-circuit")
        racer = agvrl.Racer("pure-pursuit", env)
        obs, info = env.reset(seed=0)
        while True:
            obs, reward, terminated, truncated, info = env.step(racer.act())
            if terminated or truncated:
                break
    """

    def __init__(self, kind: str, env, speed_scale: float = 1.0, raceline: str | os.PathLike | None = None):
        self._env = env.unwrapped._core
        self._core = _core.Racer(kind, self._env, speed_scale, None if raceline is None else os.fspath(raceline))
        self.kind = kind

    def act(self) -> np.ndarray:
        """The racer's action on the env's last frame (float32)."""
        return self._core.act(self._env)
