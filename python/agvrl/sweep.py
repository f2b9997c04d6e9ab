"""Hyperparameter sweeps of ``agvrl train`` on Optuna.

One ``agvrl train`` process is one training; a trial trains one configuration once per seed
and its value is the mean of an ``eval.json`` key over the seeds (a number). Optuna is the engine: studies
live in a journal file on one machine or in any SQLAlchemy database (PostgreSQL) for many
machines, and workers are plain processes started however a cluster starts them.

    python -m agvrl.sweep run SWEEP.toml [--storage URL] [--study NAME] [--workers N]
    python -m agvrl.sweep worker SWEEP.toml --storage URL [--study NAME]   # one more worker
    python -m agvrl.sweep report --storage URL --study NAME [--out DIR]

SWEEP.toml::

    study = "ppo-racing"                  # default study name
    base = "../configs/default.toml"      # the run config every trial starts from (relative
                                          # to this file)
    trials = 12                           # trials in the study, over every worker and re-run
    seeds = [0]                           # each configuration trains once per seed
    runs_dir = "runs/sweeps"              # trial run directories (relative to the working dir)

    [train]                               # keys set on every trial (as `--set`)
    steps = 100000

    [objective]
    key = "mean_return"                   # an eval.json key with a number
    direction = "maximize"                # or "minimize"
    collisions = "penalty"                # "penalty", "constraint" or "ignore"
    penalty = 100.0                       # per collision per evaluation episode

    [space]                               # dotted run-config keys
    "ppo.learning_rate" = { log_uniform = [1e-5, 1e-3] }
    "ppo.ent_coef" = { uniform = [0.0, 0.02] }
    "ppo.n_epochs" = { int = [5, 20] }
    "ppo.batch_size" = { choice = [64, 128, 256] }

    [sampler]                             # "tpe" (default) or "random"
    name = "tpe"
    seed = 0

    [pruner]                              # "median" (default) or "none"
    name = "median"
    n_startup_trials = 3
    n_warmup_steps = 0

    [[enqueue]]                           # points to try first
    "ppo.learning_rate" = 3e-4

A trial whose training fails (a bad sampled value, a crash) is recorded as failed with its error
line and the study goes on; a pruned trial's training is stopped (SIGTERM: it writes a complete
run directory) and kept. Re-running the same command resumes the study. Training processes stop
when their worker dies, and workers when the driver dies.
"""

from __future__ import annotations

import argparse
import ctypes
import json
import math
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
import tomllib
from pathlib import Path
from typing import Any

WORKER_ENV_INDEX = ("SLURM_ARRAY_TASK_ID", "JOB_COMPLETION_INDEX")


class SweepError(ValueError):
    """A sweep file or option that cannot work."""


def _optuna():
    try:
        import optuna
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise SystemExit("agvrl.sweep needs Optuna: pip install 'agvrl[optuna]'") from e
    return optuna


# ---------------------------------------------------------------- the sweep file


def load_spec(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Read and check a sweep TOML; relative paths in it are resolved against its folder."""
    path = Path(path)
    try:
        spec = tomllib.loads(path.read_text())
    except OSError as e:
        raise SweepError(f"cannot read {path}: {e}") from e
    except tomllib.TOMLDecodeError as e:
        raise SweepError(f"{path}: {e}") from e
    known = {"study", "base", "trials", "seeds", "runs_dir", "train", "objective", "space", "sampler", "pruner", "enqueue"}
    unknown = sorted(set(spec) - known)
    if unknown:
        raise SweepError(f"{path}: unknown key(s) {unknown}; known: {sorted(known)}")
    for key in ("base", "space"):
        if key not in spec:
            raise SweepError(f"{path}: missing '{key}'")
    spec["base"] = str((path.parent / spec["base"]).resolve())
    spec.setdefault("study", path.stem)
    spec.setdefault("trials", 10)
    spec.setdefault("seeds", [0])
    spec.setdefault("runs_dir", "runs/sweeps")
    spec.setdefault("train", {})
    spec.setdefault("enqueue", [])
    obj = spec.setdefault("objective", {})
    obj.setdefault("key", "mean_return")
    obj.setdefault("direction", "maximize")
    obj.setdefault("collisions", "penalty")
    obj.setdefault("penalty", 100.0)
    if obj["direction"] not in ("maximize", "minimize"):
        raise SweepError(f"{path}: objective.direction is 'maximize' or 'minimize'")
    if obj["collisions"] not in ("penalty", "constraint", "ignore"):
        raise SweepError(f"{path}: objective.collisions is 'penalty', 'constraint' or 'ignore'")
    if not isinstance(spec["trials"], int) or spec["trials"] < 1:
        raise SweepError(f"{path}: trials must be a positive integer")
    if not spec["seeds"] or not all(isinstance(s, int) and s >= 0 for s in spec["seeds"]):
        raise SweepError(f"{path}: seeds must be a list of non-negative integers")
    for name, dist in spec["space"].items():
        _check_dist(path, name, dist)
    spec.setdefault("sampler", {}).setdefault("name", "tpe")
    spec.setdefault("pruner", {}).setdefault("name", "median")
    if spec["sampler"]["name"] not in ("tpe", "random"):
        raise SweepError(f"{path}: sampler.name is 'tpe' or 'random'")
    if spec["pruner"]["name"] not in ("median", "none"):
        raise SweepError(f"{path}: pruner.name is 'median' or 'none'")
    if not Path(spec["base"]).is_file():
        raise SweepError(f"{path}: base run config {spec['base']} does not exist")
    return spec


def _check_dist(path: Path, name: str, dist: Any) -> None:
    forms = ("uniform", "log_uniform", "int", "log_int", "choice")
    if not isinstance(dist, dict) or len(dist) != 1 or next(iter(dist)) not in forms:
        raise SweepError(f"{path}: space.{name} must be one of {{ {' | '.join(f'{f} = ...' for f in forms)} }}")
    (form, args), = dist.items()
    if form == "choice":
        if not isinstance(args, list) or not args:
            raise SweepError(f"{path}: space.{name}: choice takes a non-empty list")
    elif not (isinstance(args, list) and len(args) == 2 and all(isinstance(a, (int, float)) for a in args) and args[0] <= args[1]):
        raise SweepError(f"{path}: space.{name}: {form} takes [low, high] with low <= high")
    elif form.startswith("log") and args[0] <= 0:
        raise SweepError(f"{path}: space.{name}: {form} needs low > 0")


def suggest(trial, name: str, dist: dict[str, Any]) -> Any:
    (form, args), = dist.items()
    if form == "uniform":
        return trial.suggest_float(name, float(args[0]), float(args[1]))
    if form == "log_uniform":
        return trial.suggest_float(name, float(args[0]), float(args[1]), log=True)
    if form == "int":
        return trial.suggest_int(name, int(args[0]), int(args[1]))
    if form == "log_int":
        return trial.suggest_int(name, int(args[0]), int(args[1]), log=True)
    return trial.suggest_categorical(name, args)


def toml_value(v: Any) -> str:
    """A Python value as the TOML literal `agvrl train --set KEY=VALUE` reads."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf")
        text = repr(v)
        return text if any(c in text for c in ".en") else text + ".0"
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    raise SweepError(f"cannot pass {v!r} to --set")


# ---------------------------------------------------------------- storage and study


def default_storage(spec: dict[str, Any]) -> str:
    return f"journal:{Path(spec['runs_dir']) / (spec['study'] + '.journal')}"


def open_storage(url: str):
    """``journal:PATH`` (a journal file; one machine or a shared file system) or a SQLAlchemy
    URL (``postgresql://user:password@host:5432/db``, ``sqlite:///x.db``)."""
    optuna = _optuna()
    if url.startswith("journal:"):
        path = Path(url[len("journal:"):])
        path.parent.mkdir(parents=True, exist_ok=True)
        from optuna.storages.journal import JournalFileBackend

        return optuna.storages.JournalStorage(JournalFileBackend(str(path)))
    if "://" not in url:
        raise SweepError(f"storage {url!r}: use journal:PATH or a database URL such as postgresql://...")
    import warnings

    # Heartbeats let a re-run fail the trials of a worker that died without a word.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
        return optuna.storages.RDBStorage(url, heartbeat_interval=30, grace_period=120)


def make_sampler(spec: dict[str, Any], worker: int):
    optuna = _optuna()
    s = spec["sampler"]
    # Workers start their random phases from different seeds, or they would all try the same
    # first points.
    seed = None if s.get("seed") is None else int(s["seed"]) + 1000 * worker
    if s["name"] == "random":
        return optuna.samplers.RandomSampler(seed=seed)
    kwargs: dict[str, Any] = {"seed": seed}
    if "n_startup_trials" in s:
        kwargs["n_startup_trials"] = int(s["n_startup_trials"])
    if spec["objective"]["collisions"] == "constraint":
        kwargs["constraints_func"] = lambda t: [float(t.user_attrs.get("collisions", 0))]
    return optuna.samplers.TPESampler(**kwargs)


def make_pruner(spec: dict[str, Any]):
    optuna = _optuna()
    p = spec["pruner"]
    if p["name"] == "none":
        return optuna.pruners.NopPruner()
    return optuna.pruners.MedianPruner(
        n_startup_trials=int(p.get("n_startup_trials", 3)),
        n_warmup_steps=int(p.get("n_warmup_steps", 0)),
    )


def open_study(spec: dict[str, Any], storage_url: str, study_name: str, worker: int = 0):
    """Create the study or join it (several workers may race to create it)."""
    optuna = _optuna()
    storage = open_storage(storage_url)
    for attempt in range(20):
        try:
            return optuna.create_study(
                storage=storage,
                study_name=study_name,
                direction=spec["objective"]["direction"],
                sampler=make_sampler(spec, worker),
                pruner=make_pruner(spec),
                load_if_exists=True,
            )
        except optuna.exceptions.DuplicatedStudyError:
            time.sleep(0.2 * (attempt + 1))
    raise RuntimeError(f"could not create or join study {study_name}")


def fail_dead_trials(study) -> int:
    """Mark as failed the running trials whose worker process on this host is gone (a sweep that
    was killed); returns how many. Trials of other hosts are left to heartbeats."""
    optuna = _optuna()
    host = socket.gethostname()
    n = 0
    for t in study.get_trials(deepcopy=False, states=(optuna.trial.TrialState.RUNNING,)):
        if t.user_attrs.get("host") != host:
            continue
        pid = t.user_attrs.get("pid")
        if pid is not None and _alive(int(pid)):
            continue
        study._storage.set_trial_user_attr(t._trial_id, "error", "its worker died")
        study._storage.set_trial_state_values(t._trial_id, optuna.trial.TrialState.FAIL)
        n += 1
    return n


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


# ---------------------------------------------------------------- one trial


def agvrl_command(explicit: str | None = None) -> list[str]:
    """The `agvrl` command: --agvrl, $AGVRL_BIN, `agvrl` on PATH, else this wheel's own CLI."""
    for c in (explicit, os.environ.get("AGVRL_BIN")):
        if c:
            return [c]
    found = shutil.which("agvrl")
    return [found] if found else [sys.executable, "-m", "agvrl"]


class Trainer:
    """Runs the trainings of one trial and follows their JSON progress lines."""

    def __init__(self, spec: dict[str, Any], agvrl: list[str], threads: int):
        self.spec = spec
        self.agvrl = agvrl
        self.threads = threads
        self.proc: subprocess.Popen | None = None

    def stop(self) -> None:
        """Ask the running training to stop (it writes a complete run directory) and wait."""
        p = self.proc
        if p is not None and p.poll() is None:
            p.send_signal(signal.SIGTERM)
            try:
                p.wait(timeout=300)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()

    def __call__(self, trial) -> float:
        optuna = _optuna()
        spec = self.spec
        trial.set_user_attr("host", socket.gethostname())
        trial.set_user_attr("pid", os.getpid())
        params = {name: suggest(trial, name, dist) for name, dist in spec["space"].items()}
        sets = {**spec["train"], **params, "threads": self.threads}
        runs_dir = Path(spec["runs_dir"])
        runs_dir.mkdir(parents=True, exist_ok=True)
        values, collisions, episodes, dirs = [], 0.0, 0.0, []
        offset = 0
        for seed in spec["seeds"]:
            name = f"{trial.study.study_name}-t{trial.number:04d}-s{seed}"
            out = runs_dir / name
            cmd = [*self.agvrl, "train", "--config", spec["base"], "--seed", str(seed), "--progress", "json", "--out", str(out)]
            for k, v in sets.items():
                cmd += ["--set", f"{k}={toml_value(v)}"]
            log = runs_dir / f"{name}.log"
            env = {**os.environ, "RAYON_NUM_THREADS": str(self.threads)}
            with open(log, "w") as err:
                self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=err, text=True, env=env)
                done = None
                last = 0
                try:
                    for line in self.proc.stdout:
                        try:
                            msg = json.loads(line)
                        except json.JSONDecodeError:
                            continue
                        if msg.get("event") == "progress":
                            last = int(msg["steps"])
                            if msg.get("mean_return") is not None:
                                trial.report(float(msg["mean_return"]), offset + last)
                                if trial.should_prune():
                                    trial.set_user_attr("run_dirs", dirs + [str(out)])
                                    self.stop()
                                    raise optuna.TrialPruned(f"pruned at step {offset + last}")
                        elif msg.get("event") == "done":
                            done = msg
                finally:
                    self.stop()
                    code = self.proc.wait()
                    self.proc = None
            offset += last
            if code != 0 or done is None:
                error = _error_line(log) or f"agvrl train exited with status {code}"
                trial.set_user_attr("error", error)
                trial.set_user_attr("log", str(log))
                raise RuntimeError(error)
            dirs.append(done["run_dir"])
            m = done["metrics"]
            key = spec["objective"]["key"]
            if key not in m or not isinstance(m[key], (int, float)):
                raise RuntimeError(f"the evaluation of {done['run_dir']} has no number '{key}'")
            values.append(float(m[key]))
            collisions += float(m.get("collisions", 0))
            episodes += float(m.get("episodes", 0))
        trial.set_user_attr("run_dirs", dirs)
        trial.set_user_attr("collisions", collisions)
        trial.set_user_attr("seed_values", values)
        value = sum(values) / len(values)
        obj = spec["objective"]
        if obj["collisions"] == "penalty" and collisions:
            penalty = float(obj["penalty"]) * collisions / max(episodes, 1.0)
            value += -penalty if obj["direction"] == "maximize" else penalty
        return value


def _error_line(log: Path) -> str | None:
    try:
        lines = log.read_text(errors="replace").splitlines()
    except OSError:
        return None
    errors = [l for l in lines if l.startswith("error:")]
    return (errors[-1] if errors else (lines[-1] if lines else None))


# ---------------------------------------------------------------- workers


def _die_with_parent() -> None:
    """SIGTERM this process when its parent exits (Linux)."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        PR_SET_PDEATHSIG = 1
        libc.prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
    except (OSError, AttributeError):
        pass


def worker_index(explicit: int | None) -> int:
    if explicit is not None:
        return explicit
    for var in WORKER_ENV_INDEX:
        if os.environ.get(var, "").strip().isdigit():
            return int(os.environ[var])
    return 0


def worker_name(index: int) -> str:
    for var in WORKER_ENV_INDEX:
        if os.environ.get(var, "").strip().isdigit():
            return f"{var}={os.environ[var]}@{socket.gethostname()}"
    return f"worker{index}@{socket.gethostname()}"


class BudgetLock:
    """Serialises "count the trials, then start one" across every worker of a study, so the study
    ends with exactly `trials` trials however many workers race for the last ones: an advisory
    lock in PostgreSQL, a file lock beside a journal. Other databases run unlocked (a worker
    may then start a trial or two past the budget)."""

    def __init__(self, storage_url: str, study_name: str):
        import zlib

        self.key = zlib.crc32(study_name.encode())
        self.file = None
        self.conn = None
        if storage_url.startswith("journal:"):
            # Not PATH.lock: Optuna's own journal lock uses that name.
            self.path = storage_url[len("journal:"):] + ".budget-lock"
        elif storage_url.startswith("postgresql"):
            import sqlalchemy

            self.engine = sqlalchemy.create_engine(storage_url)
            self.path = None
        else:
            self.path = None
            self.engine = None

    def __enter__(self):
        if self.path is not None:
            import fcntl

            self.file = open(self.path, "a")
            fcntl.flock(self.file, fcntl.LOCK_EX)
        elif getattr(self, "engine", None) is not None:
            import sqlalchemy

            self.conn = self.engine.connect()
            self.conn.execute(sqlalchemy.text("SELECT pg_advisory_lock(:k)"), {"k": self.key})
        return self

    def __exit__(self, *exc):
        if self.file is not None:
            self.file.close()
            self.file = None
        if self.conn is not None:
            import sqlalchemy

            self.conn.execute(sqlalchemy.text("SELECT pg_advisory_unlock(:k)"), {"k": self.key})
            self.conn.close()
            self.conn = None


def _heartbeat(trial):
    """Optuna's heartbeat for the trial (RDB storages with heartbeats on), as `optimize` runs it."""
    try:
        from optuna.storages._heartbeat import get_heartbeat_thread
    except ImportError:  # pragma: no cover - other Optuna versions
        import contextlib

        return contextlib.nullcontext()
    return get_heartbeat_thread(trial._trial_id, trial.study._storage)


def run_worker(spec, storage_url, study_name, threads, agvrl, index) -> int:
    """Run trials until the study holds `trials` of them; returns how many this worker ran."""
    import warnings

    optuna = _optuna()
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    TrialState = optuna.trial.TrialState
    study = open_study(spec, storage_url, study_name, index)
    trainer = Trainer(spec, agvrl, threads)
    name = worker_name(index)
    lock = BudgetLock(storage_url, study_name)

    def on_term(signum, frame):
        raise KeyboardInterrupt(f"signal {signum}")

    signal.signal(signal.SIGTERM, on_term)
    ran = 0
    started = (TrialState.RUNNING, TrialState.COMPLETE, TrialState.PRUNED, TrialState.FAIL)
    while True:
        if isinstance(study._storage, optuna.storages.RDBStorage):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
                optuna.storages.fail_stale_trials(study)
        with lock:
            if len(study.get_trials(deepcopy=False, states=started)) >= spec["trials"]:
                break
            # Takes an enqueued point first, else a new trial.
            trial = study.ask()
            trial.set_user_attr("worker", name)
        ran += 1
        value, state, error = None, TrialState.COMPLETE, ""
        try:
            with _heartbeat(trial):
                value = trainer(trial)
        except optuna.TrialPruned:
            state = TrialState.PRUNED
        except RuntimeError as e:
            state, error = TrialState.FAIL, str(e)
        except BaseException:
            trainer.stop()
            study.tell(trial, state=TrialState.FAIL)
            raise
        frozen = study.tell(trial, value, state=None if state == TrialState.COMPLETE else state)
        print(f"worker={name} trial={frozen.number} state={frozen.state.name} value={frozen.value} {error}".rstrip(), flush=True)
    return ran


def run(spec, storage_url, study_name, workers, threads, agvrl) -> None:
    optuna = _optuna()
    study = open_study(spec, storage_url, study_name)
    stale = fail_dead_trials(study)
    if stale:
        print(f"marked {stale} trial(s) of a dead sweep as failed")
    # An enqueued point runs once over every re-run: skip it when a trial holds those values.
    held = [{**t.system_attrs.get("fixed_params", {}), **t.params} for t in study.get_trials(deepcopy=False)]
    for point in spec["enqueue"]:
        if not any(all(h.get(k) == v for k, v in point.items()) for h in held):
            study.enqueue_trial(point)
    existing = len(study.trials)
    print(f"study={study_name} storage={storage_url} trials={existing}/{spec['trials']} workers={workers} threads_per_trial={threads}", flush=True)
    t0 = time.time()
    if workers == 1:
        run_worker(spec, storage_url, study_name, threads, agvrl, 0)
    else:
        procs = []
        base = [sys.executable, "-m", "agvrl.sweep", "worker", spec["_file"], "--storage", storage_url, "--study", study_name, "--threads", str(threads)]
        if len(agvrl) == 1:
            base += ["--agvrl", agvrl[0]]
        try:
            for i in range(workers):
                procs.append(subprocess.Popen([*base, "--worker-index", str(i)]))
            codes = [p.wait() for p in procs]
        except KeyboardInterrupt:
            for p in procs:
                p.send_signal(signal.SIGTERM)
            for p in procs:
                p.wait()
            raise
        if any(codes):
            print(f"workers exited with {codes}", file=sys.stderr)
    report(storage_url, study_name, None, top=3)
    print(f"sweep_s={time.time() - t0:.1f}")


# ---------------------------------------------------------------- report


def report(storage_url: str, study_name: str, out: str | None, top: int = 5) -> None:
    """Print the best trials; with `out`, also write PNGs of the objective against trials and of
    the parameters' importance."""
    optuna = _optuna()
    study = optuna.load_study(study_name=study_name, storage=open_storage(storage_url))
    trials = study.get_trials(deepcopy=False)
    states: dict[str, int] = {}
    for t in trials:
        states[t.state.name] = states.get(t.state.name, 0) + 1
    print(f"study={study_name} trials={len(trials)} " + " ".join(f"{k.lower()}={v}" for k, v in sorted(states.items())))
    done = [t for t in trials if t.state == optuna.trial.TrialState.COMPLETE]
    done.sort(key=lambda t: t.value, reverse=study.direction == optuna.study.StudyDirection.MAXIMIZE)
    for rank, t in enumerate(done[:top], 1):
        params = " ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in t.params.items())
        print(f"best{rank} trial={t.number} value={t.value:.4f} {params} run_dirs={','.join(t.user_attrs.get('run_dirs', []))}")
    for t in trials:
        if t.state == optuna.trial.TrialState.FAIL:
            print(f"failed trial={t.number} error={t.user_attrs.get('error', '?')}")
    if out is None:
        return
    import matplotlib

    matplotlib.use("Agg")
    import warnings

    import matplotlib.pyplot as plt
    from optuna.visualization import matplotlib as ovm

    outdir = Path(out)
    outdir.mkdir(parents=True, exist_ok=True)

    def save(plot, name: str, height: float) -> None:
        with warnings.catch_warnings():
            # Optuna marks its matplotlib plots experimental.
            warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
            ax = plot(study)
        ax.figure.set_size_inches(8, height)
        ax.figure.tight_layout()
        ax.figure.savefig(outdir / name, dpi=100)
        plt.close(ax.figure)
        print(f"wrote {outdir / name}")

    save(ovm.plot_optimization_history, "optimization_history.png", 5)
    if len(done) >= 2 and study.best_trial.params:
        save(ovm.plot_param_importances, "param_importances.png", 4)


# ---------------------------------------------------------------- command line


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m agvrl.sweep", description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    for name in ("run", "worker"):
        s = sub.add_parser(name, help="run the sweep with local workers" if name == "run" else "join a sweep as one worker (clusters)")
        s.add_argument("spec", help="the sweep TOML")
        s.add_argument("--storage", help="journal:PATH (default: <runs_dir>/<study>.journal) or a database URL")
        s.add_argument("--study", help="study name (default: the file's `study`)")
        s.add_argument("--threads", type=int, help="threads per training (default: cores / workers)")
        s.add_argument("--agvrl", help="the agvrl binary (default: $AGVRL_BIN, agvrl on PATH, else this wheel's CLI)")
        if name == "run":
            s.add_argument("--workers", type=int, default=1, help="local worker processes")
        else:
            s.add_argument("--worker-index", type=int, help="this worker's index (default: $SLURM_ARRAY_TASK_ID or $JOB_COMPLETION_INDEX)")
    r = sub.add_parser("report", help="print the best trials and write plots")
    r.add_argument("--storage", required=True)
    r.add_argument("--study", required=True)
    r.add_argument("--out", help="folder for optimization_history.png and param_importances.png")
    r.add_argument("--top", type=int, default=5)
    a = p.parse_args(argv)
    try:
        if a.cmd == "report":
            report(a.storage, a.study, a.out, a.top)
            return 0
        spec = load_spec(a.spec)
        spec["_file"] = str(Path(a.spec).resolve())
        study = a.study or spec["study"]
        storage = a.storage or default_storage(spec)
        agvrl = agvrl_command(a.agvrl)
        if a.cmd == "run":
            if a.workers < 1:
                raise SweepError("--workers must be at least 1")
            threads = a.threads or max(1, (os.cpu_count() or 1) // a.workers)
            run(spec, storage, study, a.workers, threads, agvrl)
        else:
            _die_with_parent()
            threads = a.threads or 1
            run_worker(spec, storage, study, threads, agvrl, worker_index(a.worker_index))
        return 0
    except SweepError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
