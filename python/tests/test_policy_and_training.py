"""Policies and the trainer from Python against the Rust CLI and agvrl-drive."""

import json
import subprocess
import sys

import numpy as np
import pytest

import agvrl


def cli(bins, *args, cwd=None):
    return subprocess.run([str(bins / "agvrl"), *args], capture_output=True, text=True, cwd=cwd)


@pytest.fixture(scope="module")
def cli_run(bins, tmp_path_factory):
    """A tiny racing policy trained by the CLI."""
    out = tmp_path_factory.mktemp("cli") / "run"
    r = cli(bins, "train", "--steps", "2048", "--seed", "3", "--out", str(out))
    assert r.returncode == 0, r.stderr
    return out


def test_policy_trained_by_the_cli_acts_as_agvrl_drive(bins, cli_run, tmp_path):
    trace = tmp_path / "trace.jsonl"
    r = subprocess.run(
        [str(bins / "agvrl-drive"), "--run", str(cli_run), "--steps", "300", "--trace", str(trace), "--quiet"],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stderr
    rows = [json.loads(line) for line in trace.read_text().splitlines()]
    assert len(rows) == 300
    policy = agvrl.Policy.load(cli_run / "policy.agvrl")
    obs = np.array([row["obs"] for row in rows], np.float32)
    drive = np.array([row["action"] for row in rows], np.float32)
    one_by_one = np.stack([policy.act(o) for o in obs])
    assert np.array_equal(one_by_one, drive), np.abs(one_by_one - drive).max()
    assert np.array_equal(policy.act(obs), drive), "a batch gives the rows' actions"


def test_policy_settings_rebuild_the_env_it_was_trained_for(cli_run):
    policy = agvrl.Policy.load(cli_run / "policy.agvrl")
    env_id, env_config = policy.settings()
    assert env_id == "racing-oval" and env_config["max_steps"] == 1000
    env = agvrl.make(env_id, **env_config)
    assert env.observation_space.shape == policy.observation_shape
    assert policy.algorithm == "ppo"


def test_shipped_search_policy_drives_the_python_env(root):
    policy = agvrl.Policy.load(root / "assets/policies/search.agvrl")
    env_id, cfg = policy.settings()
    env = agvrl.make("search-outdoor-20", **cfg)
    obs, _ = env.reset(seed=7)
    for _ in range(200):
        obs, _, terminated, truncated, _ = env.step(policy.act(obs))
        assert not terminated
        if truncated:
            break


def test_corrupted_or_missing_policy_file_raises_value_error(cli_run, tmp_path):
    data = (cli_run / "policy.agvrl").read_bytes()
    bad = tmp_path / "cut.agvrl"
    bad.write_bytes(data[: len(data) // 2])
    with pytest.raises(ValueError, match="cut.agvrl"):
        agvrl.Policy.load(bad)
    with pytest.raises(ValueError, match="missing.agvrl"):
        agvrl.Policy.load(tmp_path / "missing.agvrl")
    policy = agvrl.Policy.load(cli_run / "policy.agvrl")
    with pytest.raises(ValueError, match="observation shape"):
        policy.act(np.zeros(5, np.float32))


def test_bad_settings_read_as_the_cli_prints_them(bins, tmp_path):
    cases = [
        ({"bogus_key": 1}, "bogus_key = 1"),
        ({"max_steps": "many"}, 'max_steps = "many"'),
    ]
    for kwargs, line in cases:
        with pytest.raises(ValueError) as py_err:
            agvrl.make("racing-oval", **kwargs)
        cfg = tmp_path / "bad.toml"
        cfg.write_text(f'env = "racing-oval"\n[env_config]\n{line}\n')
        r = cli(bins, "train", "--config", str(cfg), "--out", str(tmp_path / "never"))
        assert r.returncode != 0
        message = str(py_err.value).removeprefix("env_config: ")
        assert message in r.stderr, (message, r.stderr)
    with pytest.raises(ValueError) as py_err:
        agvrl.make("racing-moon")
    r = cli(bins, "train", "--env", "racing-moon", "--out", str(tmp_path / "never"))
    assert str(py_err.value) in r.stderr


def test_train_from_python_writes_the_cli_run_directory(workdir):
    run = agvrl.train(
        {"env": "pendulum", "algo": "ppo", "n_envs": 4, "eval_episodes": 2, "ppo": {"n_steps": 256}},
        out=workdir / "run",
        steps=2048,
        seed=1,
    )
    assert run.run_dir == workdir / "run"
    for name in ("config.toml", "policy.agvrl", "metrics.csv", "eval.txt", "eval.json", "learning_curve.png"):
        assert (run.run_dir / name).is_file(), name
    assert run.metrics == json.loads((run.run_dir / "eval.json").read_text())
    # Typed, not guessed from text: counts are ints, flags bools, the episode ends a list.
    assert run.metrics["steps"] == 2048 and run.metrics["episodes"] == 2
    assert isinstance(run.metrics["steps"], int) and run.metrics["interrupted"] is False
    assert run.metrics["ended"] == ["time_limit", "time_limit"]
    assert "steps = 2048" in (run.run_dir / "config.toml").read_text()
    policy = agvrl.Policy.load(run.policy_path)
    env = agvrl.make("pendulum")
    obs, _ = env.reset(seed=0)
    assert policy.act(obs).shape == (1,)


def test_train_rejects_bad_configs_before_starting(workdir):
    with pytest.raises(ValueError, match="unknown algo 'dqn'"):
        agvrl.train({"env": "pendulum", "algo": "dqn"}, out=workdir / "a")
    with pytest.raises(ValueError, match="unknown field `stepz`"):
        agvrl.train({"env": "pendulum"}, out=workdir / "b", stepz=3)
    with pytest.raises(ValueError, match="cannot read"):
        agvrl.train(workdir / "missing.toml")
    # A device this wheel was built without (the default wheel has flex only).
    with pytest.raises(ValueError, match="--features ndarray"):
        agvrl.train({"env": "pendulum"}, out=workdir / "c", device="ndarray")
    assert not (workdir / "a").exists() and not (workdir / "b").exists()
    assert not (workdir / "c").exists()


def test_train_takes_a_config_file(root, workdir):
    run = agvrl.train(root / "configs/default.toml", out=workdir / "r", steps=1024, n_envs=2, eval_episodes=1, eval_max_steps=50)
    assert run.metrics["steps"] >= 1024
    assert 'env = "racing-oval"' in (run.run_dir / "config.toml").read_text()


def test_ctrl_c_stops_training_with_a_complete_run_directory(workdir):
    import signal
    import sys
    import time

    script = (
        "import agvrl\n"
        "agvrl.train({'env': 'pendulum', 'algo': 'ppo', 'steps': 50_000_000, 'eval_episodes': 1}, out='run')\n"
    )
    # A shell that starts the suite in the background leaves SIGINT ignored, and children
    # inherit that; the child gets the default back, as an interactive Python has it.
    p = subprocess.Popen(
        [sys.executable, "-c", script],
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    # The run directory is claimed as run.partial before training starts.
    deadline = time.time() + 60
    while not (workdir / "run.partial" / "config.toml").exists():
        assert time.time() < deadline and p.poll() is None, p.stderr.read()
        time.sleep(0.05)
    time.sleep(1.0)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=120)
    assert p.returncode != 0 and "KeyboardInterrupt" in err, err
    eval_txt = (workdir / "run" / "eval.txt").read_text()
    assert "interrupted=true" in eval_txt
    assert (workdir / "run" / "policy.agvrl").is_file()
    assert not (workdir / "run.partial").exists()


def test_the_wheel_carries_the_agvrl_command_line(bins):
    wheel = subprocess.run([sys.executable, "-m", "agvrl", "envs"], capture_output=True, text=True)
    assert wheel.returncode == 0, wheel.stderr
    assert wheel.stdout == cli(bins, "envs").stdout
    bad = subprocess.run([sys.executable, "-m", "agvrl", "train", "--env", "racing-moon"], capture_output=True, text=True)
    assert bad.returncode == 1 and "unknown env id 'racing-moon'" in bad.stderr
