"""One agvrl env as a ``gymnasium.Env``."""

from __future__ import annotations

import secrets
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces

from agvrl import _core


def _box(bounds: tuple[np.ndarray, np.ndarray]) -> spaces.Box:
    low, high = bounds
    return spaces.Box(low=low, high=high, dtype=np.float32)


class AgvrlEnv(gymnasium.Env):
    """An agvrl env (``agvrl envs`` lists the ids) with Gymnasium 1.x semantics.

    Observations and actions are float32 ``Box`` spaces. The env carries its own time limit
    (``max_steps``, truncation). ``reset(seed=s)`` reseeds the episode stream; ``reset()``
    continues it (a first unseeded reset draws a random seed). ``info`` is a dict of plain
    values: ``reward_terms``, ``termination`` (on a terminating step: one of
    ``agvrl.TERMINATION_CAUSES``), racing (``laps``, ``progress_laps``, ``last_lap_s``,
    ``best_lap_s``) or search (``coverage``, ``distance_m``, ``subjects_found``,
    ``subjects_total``, ``find_times_s``, ``filter_interventions``) metrics, and ``episode`` (``r``, ``l``) when an
    episode ends.

    ``render_mode="rgb_array"``: ``render()`` returns the scene from above with the car and its
    LiDAR rays, or the vehicle camera's RGB when the env has a camera (``camera={...}``).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 30}

    def __init__(self, env_id: str, render_mode: str | None = None, render_size: int = 480, **env_config: Any):
        self._core = _core.Env(env_id, env_config)
        self.env_id = env_id
        self.env_config = dict(env_config)
        self.observation_space = _box(self._core.observation_bounds())
        self.action_space = _box(self._core.action_bounds())
        vehicle = self._core.renders
        self.metadata = {
            "render_modes": ["rgb_array"] if vehicle else [],
            "render_fps": round(1.0 / self._core.dt),
        }
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode {render_mode!r} is not supported by {env_id}; "
                f"supported: {self.metadata['render_modes'] or 'none'}"
            )
        self.render_mode = render_mode
        self.render_size = int(render_size)
        self._seeded = False

    @property
    def dt(self) -> float:
        """Control period, seconds."""
        return self._core.dt

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        if seed is None and not self._seeded:
            seed = secrets.randbits(63)
        if seed is not None:
            self._seeded = True
        return self._core.reset(seed)

    def step(self, action):
        a = np.ascontiguousarray(action, dtype=np.float32).reshape(-1)
        return self._core.step(a)

    def render(self):
        if self.render_mode is None:
            gymnasium.logger.warn(
                "render() called without a render_mode; make the env with render_mode='rgb_array'"
            )
            return None
        return self._core.render(self.render_size)

    def close(self):
        pass


def make(env_id: str, render_mode: str | None = None, **env_config: Any) -> AgvrlEnv:
    """The env ``env_id`` with ``env_config`` (the keys of ``[env_config]`` in a run TOML,
    nested tables as dicts, plus ``preset="default" | "paper" | "sim2real"`` to start from).
    Unknown keys and bad values raise ``ValueError`` with the CLI's message."""
    return AgvrlEnv(env_id, render_mode=render_mode, **env_config)


def _entry_point(env_id: str, render_mode: str | None = None, **env_config: Any) -> AgvrlEnv:
    return AgvrlEnv(env_id, render_mode=render_mode, **env_config)
