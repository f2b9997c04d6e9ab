"""Sweeps on Optuna: a real PostgreSQL server and the journal backend, local workers, failed
trials, no orphaned trainings, and the cluster recipes' workers."""

import getpass
import glob
import json
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

from conftest import need

optuna = sweep = None


@pytest.fixture(autouse=True)
def _optuna_and_the_sweep_module():
    """Every test here needs Optuna (agvrl.sweep imports it)."""
    global optuna, sweep
    optuna = need("optuna")
    sweep = need("agvrl.sweep")


BASE = """env = "pendulum"
algo = "ppo"
steps = 2048
n_envs = 2
eval_episodes = 1
[ppo]
n_steps = 256
batch_size = 64
n_epochs = 2
"""


def write_sweep(d: Path, trials: int = 6, extra: str = "") -> Path:
    (d / "base.toml").write_text(BASE)
    spec = d / "sweep.toml"
    spec.write_text(
        f"""study = "pendulum-test"
base = "base.toml"
trials = {trials}
seeds = [0]
runs_dir = "{d / 'runs'}"

[objective]
key = "mean_return"
direction = "maximize"

[space]
"ppo.learning_rate" = {{ log_uniform = [1e-4, 1e-2] }}
"ppo.gae_lambda" = {{ uniform = [0.8, 0.99] }}

[sampler]
name = "random"
seed = 3

[pruner]
name = "none"

# A point the trainer rejects: recorded as failed, and the study goes on.
[[enqueue]]
"ppo.learning_rate" = 1e-3
"ppo.gae_lambda" = 1.5
{extra}"""
    )
    return spec


def agvrl_processes(marker: str) -> list[int]:
    """Processes whose command line mentions `marker` (a test's own folder)."""
    out = []
    for cmdline in glob.glob("/proc/[0-9]*/cmdline"):
        try:
            text = Path(cmdline).read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        if marker in text and "train" in text:
            out.append(int(cmdline.split("/")[2]))
    return out


def run_sweep(bins, spec: Path, storage: str, workers: int = 2, wheel_cli: bool = False):
    env = {**os.environ, "AGVRL_BIN": str(bins / "agvrl")}
    if wheel_cli:
        # No binary named: the trainings run the wheel's own `agvrl` script.
        del env["AGVRL_BIN"]
        env["PATH"] = f"{Path(sys.executable).parent}:/usr/bin:/bin"
    r = subprocess.run(
        [sys.executable, "-m", "agvrl.sweep", "run", str(spec), "--storage", storage, "--workers", str(workers), "--threads", "1"],
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
    )
    assert r.returncode == 0, r.stdout + r.stderr
    return r


def check_study(storage: str, d: Path, trials: int = 6):
    study = optuna.load_study(study_name="pendulum-test", storage=sweep.open_storage(storage))
    ts = study.get_trials()
    assert len(ts) == trials, [(t.number, t.state) for t in ts]
    failed = [t for t in ts if t.state == optuna.trial.TrialState.FAIL]
    complete = [t for t in ts if t.state == optuna.trial.TrialState.COMPLETE]
    assert len(failed) == 1 and len(complete) == trials - 1
    assert failed[0].params["ppo.gae_lambda"] == 1.5
    assert "gamma and gae_lambda must lie in [0, 1]" in failed[0].user_attrs["error"]
    for t in complete:
        assert t.value is not None and -2000 < t.value < 0
        (run_dir,) = t.user_attrs["run_dirs"]
        assert json.loads((Path(run_dir) / "eval.json").read_text())["mean_return"] == t.value
        eval_txt = (Path(run_dir) / "eval.txt").read_text()
        printed = float(next(l for l in eval_txt.splitlines() if l.startswith("mean_return=")).split("=")[1])
        assert abs(printed - t.value) <= 0.005
        assert "threads = 1" in (Path(run_dir) / "config.toml").read_text()
        lr = t.params["ppo.learning_rate"]
        assert f"learning_rate = {lr!r}" in (Path(run_dir) / "config.toml").read_text()
    workers = {t.user_attrs["worker"] for t in ts}
    assert len(workers) == 2, workers
    assert not agvrl_processes(str(d)), "no training outlives the sweep"
    return study


@pytest.fixture
def postgres():
    """A real PostgreSQL server in a temporary directory on a loopback port, run as a non-root
    user, stopped at the end."""
    found = sorted(glob.glob("/usr/lib/postgresql/*/bin/initdb"))
    if not found:
        pytest.skip("PostgreSQL server binaries not found (apt-get install postgresql)")
    bindir = Path(found[-1]).parent
    as_root = os.geteuid() == 0
    user = "postgres" if as_root else getpass.getuser()
    tmp = Path(tempfile.mkdtemp(prefix="agvrl-pg-"))
    os.chmod(tmp, 0o755)
    data = tmp / "data"
    if as_root:
        shutil.chown(tmp, user=user)

    def pg(*args):
        cmd = [str(bindir / args[0]), *args[1:]]
        if as_root:
            cmd = ["runuser", "-u", user, "--", *cmd]
        return subprocess.run(cmd, capture_output=True, text=True, check=True)

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    pg("initdb", "-D", str(data), "-A", "trust", "-U", "agvrl")
    pg("pg_ctl", "-D", str(data), "-l", str(tmp / "log"), "-w", "start", "-o", f"-c listen_addresses=127.0.0.1 -p {port} -k {tmp}")
    try:
        pg("createdb", "-h", "127.0.0.1", "-p", str(port), "-U", "agvrl", "sweeps")
        yield f"postgresql://agvrl@127.0.0.1:{port}/sweeps"
    finally:
        pg("pg_ctl", "-D", str(data), "-m", "fast", "-w", "stop")
        shutil.rmtree(tmp, ignore_errors=True)


def test_two_workers_share_a_study_in_postgresql(bins, postgres, tmp_path):
    spec = write_sweep(tmp_path)
    r = run_sweep(bins, spec, postgres)
    assert "best1 trial=" in r.stdout and "failed trial=" in r.stdout
    check_study(postgres, tmp_path)


def test_two_workers_share_a_study_in_a_journal_file_and_a_rerun_resumes(bins, tmp_path):
    spec = write_sweep(tmp_path)
    storage = f"journal:{tmp_path / 'study.journal'}"
    run_sweep(bins, spec, storage)
    check_study(storage, tmp_path)
    # The same command with a larger budget continues the study: two more trials.
    spec.write_text(spec.read_text().replace("trials = 6", "trials = 8"))
    run_sweep(bins, spec, storage)
    study = optuna.load_study(study_name="pendulum-test", storage=sweep.open_storage(storage))
    assert len(study.trials) == 8
    assert sum(t.state == optuna.trial.TrialState.FAIL for t in study.trials) == 1, "the bad point runs once"


def test_report_prints_the_best_trials_and_writes_plots(bins, tmp_path):
    spec = write_sweep(tmp_path, trials=4)
    storage = f"journal:{tmp_path / 'study.journal'}"
    run_sweep(bins, spec, storage, workers=1, wheel_cli=True)
    out = tmp_path / "report"
    r = subprocess.run(
        [sys.executable, "-m", "agvrl.sweep", "report", "--storage", storage, "--study", "pendulum-test", "--out", str(out)],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stderr
    assert "trials=4 complete=3 fail=1" in r.stdout
    best = [l for l in r.stdout.splitlines() if l.startswith("best")]
    values = [float(l.split("value=")[1].split()[0]) for l in best]
    assert values == sorted(values, reverse=True) and len(values) == 3
    for png in ("optimization_history.png", "param_importances.png"):
        assert (out / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize("var", ["SLURM_ARRAY_TASK_ID", "JOB_COMPLETION_INDEX"])
def test_a_cluster_worker_joins_the_study_under_its_index(bins, root, tmp_path, var):
    spec = write_sweep(tmp_path, trials=1)
    spec.write_text(spec.read_text().split("# A point")[0])
    storage = f"journal:{tmp_path / 'study.journal'}"
    env = {**os.environ, "AGVRL_BIN": str(bins / "agvrl"), var: "3", "AGVRL_SWEEP_STORAGE": storage, "PYTHON": sys.executable}
    for other in sweep.WORKER_ENV_INDEX:
        if other != var:
            env.pop(other, None)
    if var == "SLURM_ARRAY_TASK_ID":
        cmd = ["bash", str(root / "tools/cluster/slurm-sweep.sh"), str(spec)]
    else:
        # The container command of the Indexed Job manifest, as Kubernetes runs it.
        manifest = (root / "tools/cluster/sweep-job.yaml").read_text()
        assert "completionMode: Indexed" in manifest
        assert '"-m", "agvrl.sweep", "worker"' in manifest
        cmd = [sys.executable, "-m", "agvrl.sweep", "worker", str(spec), "--storage", storage, "--threads", "1"]
    r = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    study = optuna.load_study(study_name="pendulum-test", storage=sweep.open_storage(storage))
    (t,) = study.trials
    assert t.state == optuna.trial.TrialState.COMPLETE
    assert t.user_attrs["worker"].startswith(f"{var}=3@")


def test_killing_the_driver_leaves_no_training_behind(bins, tmp_path):
    spec = write_sweep(tmp_path, trials=4)
    spec.write_text(spec.read_text().replace("steps = 2048", "steps = 100000000").split("# A point")[0])
    (tmp_path / "base.toml").write_text(BASE.replace("steps = 2048", "steps = 100000000"))
    env = {**os.environ, "AGVRL_BIN": str(bins / "agvrl")}
    storage = f"journal:{tmp_path / 'study.journal'}"
    p = subprocess.Popen(
        [sys.executable, "-m", "agvrl.sweep", "run", str(spec), "--storage", storage, "--workers", "2", "--threads", "1"],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    deadline = time.time() + 60
    while len(agvrl_processes(str(tmp_path))) < 2:
        assert time.time() < deadline, "the trainings did not start"
        time.sleep(0.1)
    p.kill()
    p.wait()
    deadline = time.time() + 120
    while agvrl_processes(str(tmp_path)):
        assert time.time() < deadline, f"orphans: {agvrl_processes(str(tmp_path))}"
        time.sleep(0.2)
    # Stopped trainings still leave complete run directories.
    runs = [d for d in (tmp_path / "runs").iterdir() if d.is_dir() and not d.name.endswith(".partial")]
    assert runs and all((d / "eval.txt").is_file() for d in runs)


def test_bad_sweep_files_are_refused_with_the_reason(tmp_path):
    spec = write_sweep(tmp_path)
    bad = spec.read_text().replace("log_uniform = [1e-4, 1e-2]", "log_uniform = [0, 1e-2]")
    spec.write_text(bad)
    with pytest.raises(sweep.SweepError, match="log_uniform needs low > 0"):
        sweep.load_spec(spec)
    spec.write_text(bad.replace('study = "pendulum-test"', 'study = "x"\nstudyy = 1'))
    with pytest.raises(sweep.SweepError, match="unknown key"):
        sweep.load_spec(spec)
    assert sweep.toml_value(1e-05) == "1e-05" and sweep.toml_value(3.0) == "3.0"
    assert sweep.toml_value("fixed") == '"fixed"' and sweep.toml_value(True) == "true"
