"""The Rust trainer from Python."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from agvrl import _core


@dataclass
class RunResult:
    """A finished run: its directory (config.toml, policy.agvrl, metrics.csv, eval.txt, plots)
    and the evaluation's ``key=value`` lines as a dict (numbers as floats)."""

    run_dir: Path
    metrics: dict[str, Any] = field(default_factory=dict)

    @property
    def policy_path(self) -> Path:
        return self.run_dir / "policy.agvrl"


def _parse(text: str) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for line in text.splitlines():
        key, sep, value = line.partition("=")
        if not sep:
            continue
        try:
            out[key] = float(value)
        except ValueError:
            out[key] = value
    return out


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
    run_dir, text = _core.train(config, None if out is None else os.fspath(out), overrides or None, device)
    return RunResult(Path(run_dir), _parse(text))
