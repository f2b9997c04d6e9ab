import importlib
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
        pytest.skip("agvrl / agvrl-drive not built: run `cargo build --release` (or set AGVRL_BIN_DIR)")
    return d


def need(module: str):
    """`module` for a test that needs it; without it the test is skipped (a failure in CI)."""
    try:
        return importlib.import_module(module)
    except ImportError as e:
        pytest.skip(f"{module} is not installed ({e}): pip install it, as .ci/run does")


def _no_skips() -> bool:
    # .ci/run sets CI itself, so a run by hand checks as the CI runner does.
    return bool(os.environ.get("CI"))


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    """In CI a skipped test is a failed one: a missing binary, server or package would otherwise
    leave its tests unrun and the run green."""
    report = (yield).get_result()
    if report.skipped and _no_skips() and not hasattr(report, "wasxfail"):
        report.outcome = "failed"
        report.longrepr = f"skipped in CI (CI is set): {report.longrepr}"


@pytest.hookimpl(hookwrapper=True)
def pytest_make_collect_report(collector):
    report = (yield).get_result()
    if report.skipped and _no_skips():
        report.outcome = "failed"
        report.longrepr = f"module skipped in CI (CI is set): {report.longrepr}"


@pytest.fixture(scope="session")
def root() -> Path:
    return ROOT


@pytest.fixture
def workdir(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    return tmp_path


def have(cmd: str) -> bool:
    return shutil.which(cmd) is not None
