"""A batch of agvrl envs, stepped by the Rust ``VecEnv``, as a ``gymnasium.vector.VectorEnv``."""

from __future__ import annotations

import secrets
from typing import Any, Sequence

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from agvrl import _core
from agvrl.env import _box


_NAMES = {
    AutoresetMode.NEXT_STEP: "next_step",
    AutoresetMode.SAME_STEP: "same_step",
    AutoresetMode.DISABLED: "disabled",
}
_MODES = {name: mode for mode, name in _NAMES.items()} | {mode.value: mode for mode in _NAMES}


class AgvrlVectorEnv(VectorEnv):
    """``num_envs`` agvrl envs of one id, stepped together in Rust on ``threads`` threads with
    the GIL released. Observations, rewards and flags are numpy arrays filled by Rust, one row
    per env; ``infos`` follows Gymnasium's vector form (arrays with ``_key`` masks; ``termination``
    holds codes, 0 for none and ``k`` for ``agvrl.TERMINATION_CAUSES[k - 1]``).

    Seeding as Gymnasium's: ``reset(seed=s)`` seeds sub-env ``i`` with ``s + i``, a list seeds
    each env, ``None`` continues every env's stream (random seeds on the first reset).

    Auto-reset (``autoreset_mode``):

    * ``next_step`` (default): the step after an episode ends resets that env (its action is
      ignored) and returns its first observation with reward 0, not terminated, not truncated.
    * ``same_step``: the ending step returns the next episode's first observation;
      ``infos["final_obs"]`` and ``infos["final_info"]`` (masked by ``_final_obs``,
      ``_final_info``) hold what the ended episode's last step returned.
    * ``disabled``: an ended env must be reset with ``reset(options={"reset_mask": mask})``
      before it steps again; stepping it raises.
    """

    def __init__(
        self,
        env_id: str,
        num_envs: int,
        threads: int | None = None,
        autoreset_mode: str | AutoresetMode = AutoresetMode.NEXT_STEP,
        **env_config: Any,
    ):
        mode = _MODES.get(autoreset_mode, autoreset_mode)
        if not isinstance(mode, AutoresetMode):
            raise ValueError(
                f"unknown autoreset_mode {autoreset_mode!r}; use next_step, same_step or disabled"
            )
        self._core = _core.VecEnv(env_id, num_envs, threads, _NAMES[mode], env_config)
        self.env_id = env_id
        self.num_envs = num_envs
        self.single_observation_space = _box(self._core.observation_bounds())
        self.single_action_space = _box(self._core.action_bounds())
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.metadata = {
            "autoreset_mode": mode,
            "render_modes": [],
            "render_fps": round(1.0 / self._core.dt),
        }
        self.render_mode = None
        self._seeded = False

    @property
    def threads(self) -> int:
        """Threads stepping the envs."""
        return self._core.threads

    def reset(self, *, seed: int | Sequence[int | None] | None = None, options: dict[str, Any] | None = None):
        if isinstance(seed, (int, np.integer)):
            super().reset(seed=int(seed))
        if seed is None:
            if not self._seeded:
                base = secrets.randbits(62)
                seeds = [base + i for i in range(self.num_envs)]
            else:
                seeds = [None] * self.num_envs
        elif isinstance(seed, (int, np.integer)):
            seeds = [int(seed) + i for i in range(self.num_envs)]
        else:
            seeds = [None if s is None else int(s) for s in seed]
            if len(seeds) != self.num_envs:
                raise ValueError(
                    f"If seeds are passed as a list the length must match num_envs={self.num_envs} but got length={len(seeds)}."
                )
        mask = None
        if options and "reset_mask" in options:
            m = options["reset_mask"]
            if not isinstance(m, np.ndarray) or m.dtype != np.bool_ or m.shape != (self.num_envs,):
                raise ValueError(f"options['reset_mask'] must be a bool numpy array of shape ({self.num_envs},)")
            if not m.any():
                raise ValueError("options['reset_mask'] must reset at least one env")
            mask = [bool(x) for x in m]
        self._seeded = True
        return self._core.reset(seeds, mask)

    def step(self, actions):
        return self._core.step(np.ascontiguousarray(actions, dtype=np.float32))

    def close_extras(self, **kwargs: Any):
        self._core = None


def make_vec(
    env_id: str,
    num_envs: int,
    threads: int | None = None,
    autoreset_mode: str = "next_step",
    **env_config: Any,
) -> AgvrlVectorEnv:
    """``num_envs`` envs ``env_id`` with ``env_config`` (as :func:`agvrl.make`), stepped by the
    Rust ``VecEnv`` on ``threads`` threads (default: the cores available)."""
    return AgvrlVectorEnv(env_id, num_envs, threads=threads, autoreset_mode=autoreset_mode, **env_config)


def _vector_entry_point(env_id: str, num_envs: int = 1, render_mode: str | None = None, **kwargs: Any) -> AgvrlVectorEnv:
    if render_mode is not None:
        raise ValueError("agvrl vector envs do not render; render a single env from agvrl.make")
    return AgvrlVectorEnv(env_id, num_envs, **kwargs)
