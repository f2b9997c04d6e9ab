"""The Rust trainer from Python."""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from agvrl import _core


@dataclass
class RunResult:
    """A finished run: its directory (config.toml, policy.agvrl, metrics.csv, eval.txt,
    eval.json, plots) and its evaluation as a dict, eval.json's object: eval.txt's keys with
    typed values at full precision (``None`` where eval.txt says ``none`` or ``not_reached``)."""

    run_dir: Path
    metrics: dict[str, Any] = field(default_factory=dict)

    @property
    def policy_path(self) -> Path:
        return self.run_dir / "policy.agvrl"


def train(
    config: str | os.PathLike[str] | dict[str, Any],
    out: str | os.PathLike[str] | None = None,
    device: str = "flex",
    **overrides: Any,
) -> RunResult:
    """Train as ``agvrl train --config`` does, in this process with the GIL released.

    ``config`` is a run TOML's path or a dict of its keys; ``overrides`` set keys on top
    (``steps=20_000``, ``seed=1``, ``env_config={"max_steps": 500}``). The run directory is
    ``out``, else ``runs/<date-time>-<env>-<algo>``. Ctrl-C stops after the current update
    with a complete run directory, then raises ``KeyboardInterrupt``. Bad settings raise
    ``ValueError`` before anything starts.
    """
    if not isinstance(config, dict):
        config = os.fspath(config)
    run_dir, report = _core.train(config, None if out is None else os.fspath(out), overrides or None, device)
    return RunResult(Path(run_dir), json.loads(report))
