import os
import shutil
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _bin_dir() -> Path | None:
    """Where `cargo build --release` put agvrl and agvrl-drive (AGVRL_BIN_DIR overrides)."""
    candidates = []
    if os.environ.get("AGVRL_BIN_DIR"):
        candidates.append(Path(os.environ["AGVRL_BIN_DIR"]))
    if os.environ.get("CARGO_TARGET_DIR"):
        candidates.append(Path(os.environ["CARGO_TARGET_DIR"]) / "release")
    candidates.append(ROOT / "target" / "release")
    for c in candidates:
        if (c / "agvrl").is_file() and (c / "agvrl-drive").is_file():
            return c
    return None


@pytest.fixture(scope="session")
def bins() -> Path:
    """The release CLI binaries; tests that compare with them fail in CI without them."""
    d = _bin_dir()
    if d is None:
        msg = "agvrl / agvrl-drive not built: run `cargo build --release` (or set AGVRL_BIN_DIR)"
        if os.environ.get("CI"):
            pytest.fail(msg)
        pytest.skip(msg)
    return d


@pytest.fixture(scope="session")
def root() -> Path:
    return ROOT


@pytest.fixture
def workdir(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    return tmp_path


def have(cmd: str) -> bool:
    return shutil.which(cmd) is not None
