"""A race of several cars as a PettingZoo ``ParallelEnv``."""

from __future__ import annotations

import secrets
from typing import Any

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

from agvrl import _core


def _box(bounds: tuple[np.ndarray, np.ndarray]) -> spaces.Box:
    low, high = bounds
    return spaces.Box(low=low, high=high, dtype=np.float32)


class AgvrlParallelEnv(ParallelEnv):
    """A multi-agent agvrl env (``agvrl.MULTI_ENV_IDS``) with PettingZoo's parallel API.

    Agents are ``car_0`` ... ``car_{n-1}`` (``race={"cars": n}``, two by default). Every car's
    observation and action spaces are its single-car racing env's. A car that crashes into a
    wall is terminated and leaves ``agents``; it stays on the track as an obstacle until the
    race ends. The time limit (``max_steps``) truncates every car at once. Each info carries
    ``race`` (``position``, ``distance_m``, ``contacts``, ``at_fault``, ``overtakes``,
    ``time_lost_s``, ``crashed``) besides the single-car keys; on the step the race ends every
    info of that step carries ``race_summary`` (per-car lists: ``order``, ``laps``,
    ``best_lap_s``, ``overtakes``, ``contacts``, ``at_fault``, ``time_lost_s``, ``crashed``).
    """

    metadata = {"name": "agvrl_race_v0", "render_modes": []}

    def __init__(self, env_id: str, **env_config: Any):
        self._core = _core.MultiEnv(env_id, env_config)
        self.env_id = env_id
        self.env_config = dict(env_config)
        self.possible_agents = [f"car_{i}" for i in range(self._core.n_agents)]
        self.agents: list[str] = []
        self.render_mode = None
        self._obs_space = _box(self._core.observation_bounds())
        self._act_space = _box(self._core.action_bounds())
        self._idle = np.zeros(self._act_space.shape, dtype=np.float32)
        self._seeded = False

    @property
    def dt(self) -> float:
        """Control period, seconds."""
        return self._core.dt

    def observation_space(self, agent: str) -> spaces.Box:
        return self._obs_space

    def action_space(self, agent: str) -> spaces.Box:
        return self._act_space

    def reset(self, seed: int | None = None, options: dict[str, Any] | None = None):
        if seed is None and not self._seeded:
            seed = secrets.randbits(63)
        if seed is not None:
            self._seeded = True
        obs = self._core.reset(seed)
        self.agents = list(self.possible_agents)
        return dict(zip(self.agents, obs)), {a: {} for a in self.agents}

    def step(self, actions: dict[str, Any]):
        missing = [a for a in self.agents if a not in actions]
        if missing:
            raise KeyError(f"no action for live agents {missing}")
        batch = [
            np.ascontiguousarray(actions[a], dtype=np.float32).reshape(-1) if a in self.agents else self._idle
            for a in self.possible_agents
        ]
        obs, rew, term, trunc, infos, summary = self._core.step(batch)
        live = [(i, a) for i, a in enumerate(self.possible_agents) if a in self.agents]
        if summary is not None:
            for i, _ in live:
                infos[i]["race_summary"] = summary
        out = tuple({a: v[i] for i, a in live} for v in (obs, rew, term, trunc, infos))
        self.agents = [a for i, a in live if not (term[i] or trunc[i])]
        return out

    def close(self):
        pass


def make_multi(env_id: str, **env_config: Any) -> AgvrlParallelEnv:
    """The multi-agent env ``env_id`` (``racing-duel``) with ``env_config`` (the keys of
    ``[env_config]`` in a run TOML, plus ``race={"cars": n, ...}``). Bad keys and values raise
    ``ValueError`` with the CLI's message."""
    return AgvrlParallelEnv(env_id, **env_config)
