"""A race of several cars as a PettingZoo ``ParallelEnv``, and races as a Gymnasium vector env
with a row per car (one shared policy)."""

from __future__ import annotations

import secrets
from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space
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
    ``race`` (``position``, ``distance_m``, ``contacts``, ``at_fault``, ``encounters``,
    ``passes``, ``time_lost_s``, ``crashed``) besides the single-car keys; on the step the race
    ends every info of that step carries ``race_summary`` (per-car lists: ``order``, ``laps``,
    ``best_lap_s``, ``distance_m``, ``start_place``, ``encounters``, ``passes``, ``contacts``,
    ``at_fault``, ``time_lost_s``, ``crashed``). docs/racing.md, "Race figures", defines them.
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


class AgvrlRaceVectorEnv(VectorEnv):
    """``num_races`` races of one multi-agent env as a ``gymnasium.vector.VectorEnv`` for
    training one shared policy: every car is a row (race ``r``'s car ``i`` is row
    ``r * cars + i``), so ``num_envs = num_races * cars``, and every car acts on the policy's
    action.

    For training, a race ends when any of its cars is done: a car that crashed is terminated,
    the others are truncated (they bootstrap from ``infos["final_obs"]``), and the race starts
    again on the same step (Gymnasium's ``same_step`` auto-reset: the rows return the next
    race's first observations; ``infos["final_obs"]`` and ``infos["final_info"]``, masked by
    ``_final_obs`` and ``_final_info``, hold what the ended race's last step returned). So no
    row ever steps a car that is out of its race. ``infos`` otherwise carries ``reward_terms``
    (a dict of arrays) and ``race_position`` (each car's place). ``reset(seed=s)`` seeds race
    ``r`` with ``s + r``.
    """

    def __init__(self, env_id: str, num_races: int, **env_config: Any):
        if num_races < 1:
            raise ValueError(f"num_races must be at least 1, got {num_races}")
        self._races = [_core.MultiEnv(env_id, env_config) for _ in range(num_races)]
        self.env_id = env_id
        self.cars = self._races[0].n_agents
        self.num_envs = num_races * self.cars
        self.single_observation_space = _box(self._races[0].observation_bounds())
        self.single_action_space = _box(self._races[0].action_bounds())
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.metadata = {
            "autoreset_mode": AutoresetMode.SAME_STEP,
            "render_modes": [],
            "render_fps": round(1.0 / self._races[0].dt),
        }
        self.render_mode = None
        self._seeded = False

    def _rows(self, per_race: list[list[np.ndarray]]) -> np.ndarray:
        return np.stack([o for race in per_race for o in race]).astype(np.float32)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        if seed is None and not self._seeded:
            seed = secrets.randbits(62)
        if seed is not None:
            self._seeded = True
        obs = [r.reset(None if seed is None else seed + k) for k, r in enumerate(self._races)]
        return self._rows(obs), {}

    def step(self, actions):
        a = np.ascontiguousarray(actions, dtype=np.float32).reshape(self.num_envs, -1)
        n, c = self.num_envs, self.cars
        obs = np.empty((n, self.single_observation_space.shape[0]), np.float32)
        rew = np.zeros(n)
        term = np.zeros(n, bool)
        trunc = np.zeros(n, bool)
        terms: dict[str, np.ndarray] = {}
        position = np.zeros(n, np.int64)
        final_obs = np.full(n, None, dtype=object)
        final_info = np.full(n, None, dtype=object)
        ended = np.zeros(n, bool)
        for k, race in enumerate(self._races):
            rows = slice(k * c, (k + 1) * c)
            o, r, te, tr, infos, _ = race.step([a[i] for i in range(rows.start, rows.stop)])
            over = any(te[i] or tr[i] for i in range(c))
            for i in range(c):
                row = k * c + i
                obs[row], rew[row], term[row] = o[i], r[i], te[i]
                trunc[row] = tr[i] or (over and not te[i])
                position[row] = infos[i]["race"]["position"]
                for name, v in infos[i]["reward_terms"].items():
                    terms.setdefault(name, np.zeros(n))[row] = v
            if over:
                first = race.reset(None)
                for i in range(c):
                    row = k * c + i
                    final_obs[row], final_info[row] = obs[row].copy(), infos[i]
                    obs[row] = first[i]
                    ended[row] = True
        info: dict[str, Any] = {
            "reward_terms": terms,
            "_reward_terms": np.ones(n, bool),
            "race_position": position,
            "_race_position": np.ones(n, bool),
        }
        if ended.any():
            info |= {"final_obs": final_obs, "_final_obs": ended, "final_info": final_info, "_final_info": ended}
        return obs, rew, term, trunc, info

    def close_extras(self, **kwargs):
        pass


def make_race_vec(env_id: str, num_races: int, **env_config: Any) -> AgvrlRaceVectorEnv:
    """``num_races`` races of ``env_id`` as a vector env, a row per car (see
    ``AgvrlRaceVectorEnv``): one shared policy trains on every car."""
    return AgvrlRaceVectorEnv(env_id, num_races, **env_config)
