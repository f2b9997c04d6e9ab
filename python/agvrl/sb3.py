"""Stable-Baselines3's ``VecEnv`` API over the Rust ``VecEnv`` (importable without SB3).

    from stable_baselines3 import PPO
    import agvrl.sb3
    model = PPO("MlpPolicy", agvrl.sb3.make_vec("racing-oval", 8)).learn(100_000)

SB3's semantics: same-step auto-reset, ``infos[i]["terminal_observation"]`` and
``infos[i]["TimeLimit.truncated"]`` on the step that ends an episode, plus ``episode``
(``r``, ``l``, ``t``) for SB3's logger and the env's metrics (``laps``, ``coverage``,
``termination``).
"""

from __future__ import annotations

import time
from typing import Any, Sequence

import numpy as np

from agvrl import _core
from agvrl.env import _box

try:  # SB3 treats only its own VecEnv subclasses as vector envs.
    from stable_baselines3.common.vec_env.base_vec_env import VecEnv as _Base
except ImportError:  # pragma: no cover - exercised where SB3 is missing

    class _Base:  # type: ignore[no-redef]
        """The part of SB3's ``VecEnv`` base this adapter relies on."""

        def __init__(self, num_envs, observation_space, action_space):
            self.num_envs = num_envs
            self.observation_space = observation_space
            self.action_space = action_space
            self.reset_infos = [{} for _ in range(num_envs)]
            self._seeds = [None for _ in range(num_envs)]
            self._options = [{} for _ in range(num_envs)]
            self.render_mode = None

        def _reset_seeds(self):
            self._seeds = [None for _ in range(self.num_envs)]

        def _reset_options(self):
            self._options = [{} for _ in range(self.num_envs)]

        def seed(self, seed=None):
            if seed is None:
                seed = int(np.random.randint(0, np.iinfo(np.uint32).max, dtype=np.uint32))
            self._seeds = [seed + idx for idx in range(self.num_envs)]
            return self._seeds

        def set_options(self, options=None):
            self._options = [dict(options or {}) for _ in range(self.num_envs)]

        def step(self, actions):
            self.step_async(actions)
            return self.step_wait()

        @property
        def unwrapped(self):
            return self


_METRICS = ("laps", "best_lap_s", "coverage", "distance_m")


class AgvrlSB3VecEnv(_Base):
    """``n_envs`` agvrl envs as an SB3 ``VecEnv`` (rewards float32, dones = terminated or
    truncated)."""

    def __init__(self, env_id: str, n_envs: int, threads: int | None = None, **env_config: Any):
        self._core = _core.VecEnv(env_id, n_envs, threads, "same_step", env_config)
        self.env_id = env_id
        self.render_mode = None
        self._actions: np.ndarray | None = None
        self._t0 = np.full(n_envs, time.time())
        super().__init__(n_envs, _box(self._core.observation_bounds()), _box(self._core.action_bounds()))

    def reset(self):
        seeds = [None if s is None else int(s) for s in self._seeds]
        obs, _ = self._core.reset(seeds, None)
        self.reset_infos = [{} for _ in range(self.num_envs)]
        self._t0[:] = time.time()
        self._reset_seeds()
        self._reset_options()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.ascontiguousarray(actions, dtype=np.float32).reshape(self.num_envs, -1)

    def step_wait(self):
        obs, rewards, terminated, truncated, infos = self._core.step(self._actions)
        dones = terminated | truncated
        out: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        if dones.any():
            now = time.time()
            final_obs = infos["final_obs"]
            final = infos["final_info"]
            for i in np.flatnonzero(dones):
                info = out[i]
                info["terminal_observation"] = final_obs[i]
                info["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
                info["episode"] = {
                    "r": float(infos["episode"]["r"][i]),
                    "l": int(infos["episode"]["l"][i]),
                    "t": round(now - self._t0[i], 6),
                }
                self._t0[i] = now
                code = int(final["termination"][i])
                if code:
                    info["termination"] = _core.TERMINATION_CAUSES[code - 1]
                for key in _METRICS:
                    if key in final and final[f"_{key}"][i]:
                        info[key] = final[key][i].item()
        return obs, rewards.astype(np.float32), dones, out

    def close(self) -> None:
        self._core = None

    def get_attr(self, attr_name: str, indices=None) -> list[Any]:
        return [getattr(self, attr_name, None) for _ in self._indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices=None) -> None:
        setattr(self, attr_name, value)

    def env_method(self, method_name: str, *args, indices=None, **kwargs) -> list[Any]:
        raise AttributeError(f"agvrl sub-envs live in Rust and have no method {method_name!r}")

    def env_is_wrapped(self, wrapper_class, indices=None) -> list[bool]:
        return [False for _ in self._indices(indices)]

    def get_images(self) -> Sequence[np.ndarray | None]:
        return [None for _ in range(self.num_envs)]

    def _indices(self, indices) -> list[int]:
        if indices is None:
            return list(range(self.num_envs))
        if isinstance(indices, int):
            return [indices]
        return list(indices)


def make_vec(env_id: str, n_envs: int, threads: int | None = None, **env_config: Any) -> AgvrlSB3VecEnv:
    """``n_envs`` envs ``env_id`` (settings as :func:`agvrl.make`) as an SB3 ``VecEnv``."""
    return AgvrlSB3VecEnv(env_id, n_envs, threads=threads, **env_config)
