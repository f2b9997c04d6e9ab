#!/usr/bin/env python3
"""Kill `agvrl train` and `agvrl train --resume` with SIGKILL at chosen and random moments.

After every kill the run must be in one of two states, and a resume must finish it:
- a `.partial` directory (a new training) that `train --resume` continues, or that it refuses
  with a clear error when the kill came before the first checkpoint;
- a finished run directory exactly as it was before the resume that was killed.

Each finished run is checked: every file present, the policy readable (`agvrl policy`), the
metrics' steps increasing, without a gap or a repeat at a resume, and the run the same as the
one never killed: the same policy file, bit for bit, and the same metrics (all but the
wall-clock column). That holds because every run here restarts its episodes at each checkpoint
(`restart_episodes_at_checkpoints`), as a resume must: the envs' state is in no checkpoint.
Everything the learner owns comes back from the files.

A kill that came after the process had exited is not counted as a kill; the test fails when
no kill landed.

    tools/kill-test.py [--agvrl target/release/agvrl] [--kills 20] [--seed 0] [--full-disk]

Prints one line per kill and a table of the outcomes; exits 1 on any broken run.
"""

import argparse
import hashlib
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REQUIRED = ["config.toml", "policy.agvrl", "checkpoint.ckpt", "metrics.csv", "eval.txt", "eval.json"]
# A short racing run: 40 updates of 4 x 256 steps, a checkpoint every tenth, one evaluation
# episode; every run at the same seed, so each is held against the one never killed.
TRAIN = ["--env", "racing-oval", "--seed", "0", "--steps", "40960", "--n-envs", "4", "--set", "ppo.n_steps=256",
         "--set", "eval_episodes=1", "--set", "eval_max_steps=1500",
         "--set", "restart_episodes_at_checkpoints=true", "--progress", "json"]
MODES = ["update", "checkpoint", "evaluation", "random"]
# metrics.csv's wall-clock column, which no two runs share.
WALL_CLOCK = "steps_per_s"
# Per trial, whether its kill landed (the process still ran).
LANDED = []


def hashes(d: Path) -> dict:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(d.iterdir()) if p.is_file()}


def metric_steps(d: Path) -> list:
    lines = (d / "metrics.csv").read_text().splitlines()[1:]
    return [int(line.split(",")[0]) for line in lines]


def metrics_but_wall_clock(d: Path) -> list:
    header, *rows = (d / "metrics.csv").read_text().splitlines()
    skip = header.split(",").index(WALL_CLOCK)
    return [[v for k, v in enumerate(r.split(",")) if k != skip] for r in rows]


def same_as(d: Path, reference: Path):
    """`d` trained as `reference`, the run never killed: the same policy file and metrics."""
    if (d / "policy.agvrl").read_bytes() != (reference / "policy.agvrl").read_bytes():
        raise Broken(f"{d}/policy.agvrl differs from that of the run never killed")
    mine, theirs = metrics_but_wall_clock(d), metrics_but_wall_clock(reference)
    if mine != theirs:
        first = next((k for k, (a, b) in enumerate(zip(mine, theirs)) if a != b), min(len(mine), len(theirs)))
        raise Broken(f"{d}/metrics.csv differs from the run never killed from row {first + 1}: "
                     f"{mine[first] if first < len(mine) else None} against "
                     f"{theirs[first] if first < len(theirs) else None}")


class Broken(Exception):
    pass


def check_finished(agvrl: str, d: Path, expect_last_step=None):
    missing = [f for f in REQUIRED if not (d / f).is_file()]
    if missing:
        raise Broken(f"{d} is missing {missing}")
    steps = metric_steps(d)
    if steps != sorted(set(steps)):
        raise Broken(f"{d}: metrics steps repeat or go back: {steps}")
    if expect_last_step is not None and steps and steps[-1] != expect_last_step:
        raise Broken(f"{d}: metrics end at step {steps[-1]}, the run at {expect_last_step}")
    r = subprocess.run([agvrl, "policy", str(d / "policy.agvrl")], capture_output=True, text=True)
    if r.returncode != 0:
        raise Broken(f"{d}/policy.agvrl does not read: {r.stderr.strip()}")


def start(cmd):
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def kill_when(p, mode: str, watch: Path, rng: random.Random, span: float) -> str:
    """Kill `p` at the moment `mode` names (`random`: within `span` seconds, the time the same
    command took unkilled); returns what it was doing then, starting with "killed" or "exited"
    (the kill came too late)."""
    if mode == "update":
        # After the k-th progress line (k random), a random few ms into the next update.
        k = rng.randint(1, 3)
        for _ in range(k):
            if not p.stdout.readline():
                break
        time.sleep(rng.uniform(0.0, 0.3))
    elif mode == "checkpoint":
        # After the first checkpoint, as soon as a temporary file shows in the run directory
        # (the next checkpoint or the metrics being written): the write under way.
        t0 = time.monotonic()
        while p.poll() is None and time.monotonic() - t0 < 120 and not (watch / "checkpoint.ckpt").exists():
            time.sleep(0.001)
        while p.poll() is None and time.monotonic() - t0 < 120:
            try:
                if any(n.startswith(".tmp") for n in os.listdir(watch)):
                    break
            except FileNotFoundError:
                pass
    elif mode == "evaluation":
        # After the policy file is written: the run's evaluation, plots and recording.
        t0 = time.monotonic()
        while p.poll() is None and time.monotonic() - t0 < 120 and not (watch / "eval.txt").exists():
            if (watch / "policy.agvrl").exists() and (watch / "policy.agvrl").stat().st_mtime > t0 - 1:
                time.sleep(rng.uniform(0.0, 0.15))
                break
            time.sleep(0.002)
    else:
        time.sleep(rng.uniform(0.0, 0.9 * span))
    state = "exited" if p.poll() is not None else "killed"
    LANDED.append(state == "killed")
    if state == "killed":
        p.send_signal(signal.SIGKILL)
    p.wait()
    temps = [n for n in os.listdir(watch) if n.startswith(".tmp")] if watch.exists() else []
    return state + (f" with {temps[0]} open" if temps else "")


def resume(agvrl: str, d: Path, more=None):
    cmd = [agvrl, "train", "--resume", str(d), "--progress", "json"]
    if more:
        cmd += ["--steps", str(more)]
    return subprocess.run(cmd, capture_output=True, text=True)


def trial_new(agvrl, root: Path, i: int, mode: str, rng, reference: Path, span: float) -> str:
    out = root / f"run-{i}"
    partial = Path(f"{out}.partial")
    p = start([agvrl, "train", "--out", str(out)] + TRAIN)
    state = kill_when(p, mode, partial, rng, span)
    if out.exists():
        check_finished(agvrl, out)
        same_as(out, reference)
        return f"{state}; the run had finished, as the one never killed"
    if not partial.is_dir():
        raise Broken(f"neither {out} nor {partial} exists after the kill")
    had_ckpt = (partial / "checkpoint.ckpt").exists()
    r = resume(agvrl, partial)
    if not had_ckpt:
        if r.returncode == 0 or "no checkpoint" not in r.stderr:
            raise Broken(f"resuming {partial} without a checkpoint: rc {r.returncode}: {r.stderr[-300:]}")
        return f"{state} before the first checkpoint: resume refuses it ({r.stderr.strip().splitlines()[-1]})"
    if r.returncode != 0:
        raise Broken(f"resuming {partial}: {r.stderr[-500:]}")
    if partial.exists() or not out.is_dir():
        raise Broken(f"the resumed {partial} was not published as {out}")
    check_finished(agvrl, out, 40960)
    same_as(out, reference)
    return f"{state}; resumed to the end, as the one never killed"


def trial_resume(agvrl, root: Path, i: int, finished: Path, mode: str, rng, reference: Path, span: float) -> str:
    """Kill a resume (8192 more steps) of a copy of `finished`, then resume it by 2048 steps:
    as `reference`, `finished` resumed by 2048 steps unkilled."""
    done = root / f"resume-{i}"
    shutil.copytree(finished, done)
    before = hashes(done)
    last = metric_steps(done)[-1]
    p = start([agvrl, "train", "--resume", str(done), "--steps", "8192", "--progress", "json"])
    staging = Path(f"{done}.resume.partial")
    state = kill_when(p, mode, staging, rng, span)
    after = hashes(done)
    if after != before:
        changed = sorted(k for k in set(before) | set(after) if before.get(k) != after.get(k))
        # A resume that got to its end swaps the whole directory: every file is the new run's.
        if "exited" in state:
            check_finished(agvrl, done)
            return f"{state}; the resume had finished"
        raise Broken(f"{done} changed under a killed resume: {changed}")
    steps_before = last
    r = resume(agvrl, done, 2048)
    if r.returncode != 0:
        raise Broken(f"resuming {done} after a killed resume: {r.stderr[-500:]}")
    if staging.exists():
        raise Broken(f"{staging} is left after a finished resume")
    check_finished(agvrl, done)
    got = metric_steps(done)
    if got[-1] <= steps_before:
        raise Broken(f"{done}: the resume added no metrics ({got[-1]} <= {steps_before})")
    same_as(done, reference)
    return f"{state}; unchanged, and the next resume finished as the one never killed"


def full_disk(agvrl, root: Path) -> list:
    """A 12 MB tmpfs: a training into it fails with a clear error; a resume of a finished run
    on it that runs out of space leaves the run as it was."""
    lines = []
    mnt = root / "small"
    mnt.mkdir()
    m = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=12m", "tmpfs", str(mnt)], capture_output=True, text=True)
    if m.returncode != 0:
        return [f"full disk: skipped (mount tmpfs: {m.stderr.strip()})"]
    try:
        # SAC's checkpoint holds its replay buffer: far more than 12 MB.
        r = subprocess.run([agvrl, "train", "--out", str(mnt / "big"), "--env", "racing-oval", "--algo", "sac",
                            "--steps", "3000", "--n-envs", "2", "--set", "sac.learning_starts=100",
                            "--set", "eval_episodes=1", "--progress", "none"],
                           capture_output=True, text=True)
        err = r.stderr.strip().splitlines()[-1] if r.stderr.strip() else ""
        ok = r.returncode != 0 and "No space left on device" in r.stderr
        print(f"full disk, new training: rc={r.returncode} error: {err}", flush=True)
        if not ok:
            raise Broken(f"a training on a full disk: rc {r.returncode}, stderr {r.stderr[-400:]}")
        shutil.rmtree(mnt / "big.partial", ignore_errors=True)
        # A finished run on the small disk, then a resume that cannot fit its copy.
        r = subprocess.run([agvrl, "train", "--out", str(mnt / "small-run")] + TRAIN, capture_output=True, text=True)
        if r.returncode != 0:
            raise Broken(f"the small run does not fit 12 MB: {r.stderr[-300:]}")
        before = hashes(mnt / "small-run")
        filler = mnt / "filler"
        try:
            with open(filler, "wb") as f:
                while True:
                    f.write(b"\0" * 4096)
        except OSError:
            pass
        r = resume(agvrl, mnt / "small-run", 2048)
        err = r.stderr.strip().splitlines()[-1] if r.stderr.strip() else ""
        print(f"full disk, resume: rc={r.returncode} error: {err}", flush=True)
        if r.returncode == 0 or hashes(mnt / "small-run") != before:
            raise Broken("a resume on a full disk succeeded or changed the run")
        filler.unlink()
        r = resume(agvrl, mnt / "small-run", 2048)
        if r.returncode != 0:
            raise Broken(f"resuming after space came back: {r.stderr[-300:]}")
        check_finished(agvrl, mnt / "small-run")
        lines.append("full disk, resume after freeing space: finished")
    finally:
        subprocess.run(["umount", str(mnt)])
    return lines


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--agvrl", default="target/release/agvrl")
    ap.add_argument("--kills", type=int, default=20)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--full-disk", action="store_true", help="also fill a small tmpfs (needs root)")
    a = ap.parse_args()
    rng = random.Random(a.seed)
    root = Path(tempfile.mkdtemp(prefix="agvrl-kill-"))
    outcomes = []
    try:
        # The runs never killed: a training (the new trainings' reference, and the run the
        # resume kills resume), and that run resumed by 2048 steps (the resumes' reference).
        done, resumed = root / "done", root / "done-resumed"
        t0 = time.monotonic()
        r = subprocess.run([a.agvrl, "train", "--out", str(done)] + TRAIN, capture_output=True, text=True)
        if r.returncode != 0:
            sys.exit(f"the first training failed: {r.stderr[-500:]}")
        train_s = time.monotonic() - t0
        check_finished(a.agvrl, done, 40960)
        shutil.copytree(done, resumed)
        t0 = time.monotonic()
        r = resume(a.agvrl, resumed, 2048)
        if r.returncode != 0:
            sys.exit(f"the reference resume failed: {r.stderr[-500:]}")
        # The resume killed (by 8192 steps) takes longer: a random kill within this lands.
        resume_s = time.monotonic() - t0
        check_finished(a.agvrl, resumed)
        for i in range(a.kills):
            mode = MODES[i % len(MODES)]
            of = "train" if (i // len(MODES)) % 2 == 0 else "resume"
            t0 = time.monotonic()
            try:
                if of == "train":
                    what = trial_new(a.agvrl, root, i, mode, rng, done, train_s)
                else:
                    what = trial_resume(a.agvrl, root, i, done, mode, rng, resumed, resume_s)
                ok = True
            except Broken as e:
                what, ok = f"BROKEN: {e}", False
            outcomes.append((i, of, mode, ok, what))
            print(f"kill {i:2} {of:6} {mode:10} {'ok' if ok else 'BROKEN'} {time.monotonic() - t0:5.1f}s  {what}", flush=True)
        if a.full_disk:
            try:
                for line in full_disk(a.agvrl, root):
                    print(line)
            except Broken as e:
                print(f"full disk: BROKEN: {e}")
                outcomes.append((-1, "disk", "full", False, str(e)))
    finally:
        shutil.rmtree(root, ignore_errors=True)
    bad = [o for o in outcomes if not o[3]]
    landed = sum(LANDED)
    print(f"kills={landed} exited_before_the_kill={len(LANDED) - landed} broken={len(bad)}")
    if LANDED and not landed:
        print("no kill landed: every process had exited first")
    sys.exit(1 if bad or (LANDED and not landed) else 0)


if __name__ == "__main__":
    main()
