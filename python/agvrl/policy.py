"""Trained policies (``policy.agvrl`` files) from Python."""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from agvrl import _core


class Policy:
    """A policy file written by ``agvrl train`` (or ``agvrl.train``), for inference.

    ``act`` runs the same Rust code as ``agvrl-drive``, so the same observation gives the same
    action on the same CPU.
    """

    def __init__(self, core: _core.Policy):
        self._core = core

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> "Policy":
        """Load ``path``; a truncated or corrupted file raises ``ValueError``."""
        return cls(_core.Policy(os.fspath(path)))

    @property
    def path(self) -> str:
        return os.fspath(self._core.path)

    @property
    def algorithm(self) -> str:
        """``ppo`` or ``sac``."""
        return self._core.algorithm

    @property
    def observation_shape(self) -> tuple[int]:
        return (len(self._core.observation_bounds()[0]),)

    @property
    def action_shape(self) -> tuple[int]:
        return (len(self._core.action_bounds()[0]),)

    def settings(self) -> tuple[str, dict[str, Any]] | None:
        """``(env_id, env_config)`` of the run that made the policy (the ``.toml`` beside it,
        or its run directory's ``config.toml``); ``agvrl.make(env_id, **env_config)`` builds
        the env it was trained for. ``None`` without such a file."""
        return self._core.settings()

    def seed(self, seed: int) -> None:
        """Reseed the sampling of stochastic actions."""
        self._core.seed(seed)

    def act(self, obs, deterministic: bool = True) -> np.ndarray:
        """Actions for one observation ``(obs_dim,)`` or a batch ``(n, obs_dim)``."""
        return self._core.act(np.ascontiguousarray(obs, dtype=np.float32), deterministic)

    def __repr__(self) -> str:
        return f"Policy({self.path!r}, algorithm={self.algorithm!r})"
