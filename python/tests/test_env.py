"""Single envs: Gymnasium's checker, settings, errors, info and rendering."""

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import agvrl


@pytest.mark.parametrize("env_id", agvrl.ENV_IDS)
def test_gymnasium_check_env_passes_on_every_id(env_id):
    env = gymnasium.make(f"agvrl/{env_id}-v0", max_steps=50)
    check_env(env.unwrapped)
    assert env.observation_space.dtype == np.float32
    assert env.action_space.dtype == np.float32
    obs, info = env.reset(seed=3)
    assert obs.dtype == np.float32 and env.observation_space.contains(obs)
    env.close()


def test_every_cli_env_id_is_registered():
    assert set(agvrl.ENV_IDS) == {
        "search-outdoor-20",
        "search-outdoor-50",
        "search-urban-20",
        "search-urban-50",
        "racing-oval",
        "racing-circuit",
        "pendulum",
    }
    for env_id in agvrl.ENV_IDS:
        assert f"agvrl/{env_id}-v0" in gymnasium.registry


def test_same_seed_same_actions_give_bitwise_equal_observations():
    def run():
        env = agvrl.make("search-urban-20")
        out = [env.reset(seed=11)[0]]
        rng = np.random.default_rng(0)
        for _ in range(40):
            obs, *_ = env.step(rng.uniform(-1, 1, 2).astype(np.float32))
            out.append(obs)
        return np.stack(out)

    assert np.array_equal(run(), run())


def test_unseeded_first_reset_draws_a_random_episode():
    a = agvrl.make("racing-oval").reset()[0]
    b = agvrl.make("racing-oval").reset()[0]
    assert not np.array_equal(a, b)


def test_settings_reach_the_env():
    env = agvrl.make("search-outdoor-20", lidar={"n_rays": 36}, max_steps=7)
    assert env.observation_space.shape[0] == agvrl.make("search-outdoor-20").observation_space.shape[0] - 64
    env.reset(seed=0)
    for t in range(7):
        _, _, terminated, truncated, _ = env.step(np.zeros(2, np.float32))
        if terminated:
            break
    assert truncated or terminated
    paper = agvrl.make("search-outdoor-20", preset="paper")
    assert paper.observation_space.shape == (100,)


def test_racing_info_is_plain_python():
    env = agvrl.make("racing-oval")
    _, info = env.reset(seed=1)
    assert set(info["reward_terms"]) >= {"throttle", "steering", "collision"}
    _, reward, _, _, info = env.step(np.array([1.0, 0.0], np.float32))
    assert isinstance(reward, float)
    assert isinstance(info["laps"], int) and isinstance(info["progress_laps"], float)
    assert reward == pytest.approx(sum(info["reward_terms"].values()))


def test_a_map_file_track_drives_like_the_oval(root):
    """``track=`` takes a ROS map YAML: the racing env drives the shipped bean track, a lap
    of its 65.9 m centre line, and a path to no file raises ValueError naming it."""
    yaml = str(root / "assets" / "tracks" / "bean.yaml")
    env = agvrl.make("racing-oval", track=yaml)
    obs, _ = env.reset(seed=2)
    assert env.observation_space.contains(obs)
    for _ in range(15):
        _, _, _, _, info = env.step(np.array([1.0, 0.0], np.float32))
    # Half a second from rest: some centimetres along a 65.9 m lap.
    assert 0.01 < info["progress_laps"] * 65.9 < 1.0
    with pytest.raises(ValueError, match="nope.yaml"):
        agvrl.make("racing-oval", track=str(root / "nope.yaml"))


def test_search_info_and_termination_cause():
    env = agvrl.make("search-urban-20")
    env.reset(seed=5)
    causes = set()
    for episode in range(6):
        env.reset(seed=100 + episode)
        ret = 0.0
        for steps in range(1, 1001):
            _, reward, terminated, truncated, info = env.step(np.array([1.0, 1.0], np.float32))
            ret += reward
            assert 0.0 <= info["coverage"] <= 1.0
            if terminated:
                causes.add(info["termination"])
            if terminated or truncated:
                # The episode's statistics arrive on its last step, and only there.
                assert info["episode"]["l"] == steps and info["episode"]["r"] == pytest.approx(ret)
                break
            assert "episode" not in info
    assert causes and causes <= set(agvrl.TERMINATION_CAUSES)


def test_nan_action_raises_and_never_reaches_the_car():
    env = agvrl.make("racing-oval")
    first, _ = env.reset(seed=2)
    with pytest.raises(ValueError, match="not finite"):
        env.step(np.array([np.nan, 0.0], np.float32))
    with pytest.raises(ValueError, match="action has 3 elements, the action space has 2"):
        env.step(np.zeros(3, np.float32))
    # The car did not move: the next valid step equals a fresh env's first step.
    fresh = agvrl.make("racing-oval")
    assert np.array_equal(fresh.reset(seed=2)[0], first)
    a = np.array([0.5, 0.1], np.float32)
    assert np.array_equal(env.step(a)[0], fresh.step(a)[0])


def test_step_before_reset_raises_runtime_error():
    with pytest.raises(RuntimeError, match="reset"):
        agvrl.make("racing-oval").step(np.zeros(2, np.float32))


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"bogus_key": 1}, "unknown field `bogus_key`"),
        ({"max_steps": "many"}, "invalid type: string"),
        ({"lidar": {"n_rays": -3}}, "invalid value"),
        ({"preset": "moon"}, "unknown preset 'moon'"),
        ({"max_steps": 0}, "max_steps must be at least 1"),
        ({"noise": object()}, "cannot be a setting"),
    ],
)
def test_bad_settings_raise_value_error(kwargs, message):
    with pytest.raises(ValueError, match=message):
        agvrl.make("racing-oval", **kwargs)


def test_unknown_env_id_lists_the_valid_ids():
    with pytest.raises(ValueError, match="unknown env id 'racing-moon'; valid ids: search-outdoor-20"):
        agvrl.make("racing-moon")


def test_rgb_array_render_is_a_top_view_with_the_car():
    env = agvrl.make("racing-oval", render_mode="rgb_array", render_size=200)
    env.reset(seed=0)
    img = env.render()
    assert img.dtype == np.uint8 and img.ndim == 3 and img.shape[2] == 3
    assert max(img.shape[:2]) == 200
    blue = (img[:, :, 2] > 200) & (img[:, :, 0] < 60) & (img[:, :, 1] < 60)
    assert blue.sum() > 4, "the car is drawn"
    red = (img[:, :, 0] > 180) & (img[:, :, 1] < 120) & (img[:, :, 2] < 120)
    assert red.sum() > 20, "LiDAR hits are drawn"
    env.step(np.array([1.0, 0.0], np.float32))
    for _ in range(30):
        env.step(np.array([1.0, 0.0], np.float32))
    moved = env.render()
    assert not np.array_equal(moved, img)


def test_rgb_array_render_is_the_camera_frame_when_there_is_a_camera():
    env = agvrl.make("racing-oval", render_mode="rgb_array", camera={"width": 64, "height": 48})
    env.reset(seed=0)
    img = env.render()
    assert img.shape == (48, 64, 3) and img.std() > 0


def test_pendulum_has_no_render_mode():
    with pytest.raises(ValueError, match="render_mode"):
        agvrl.make("pendulum", render_mode="rgb_array")


def test_a_rust_panic_reaches_python_as_runtime_error():
    from agvrl import _core

    with pytest.raises(RuntimeError, match="internal error \\(Rust panic\\): boom"):
        _core._panic_for_test("boom")
    # The interpreter and the package carry on.
    assert agvrl.make("pendulum").reset(seed=0)[0].shape == (3,)


def test_numpy_scalars_are_settings():
    env = agvrl.make("search-outdoor-20", max_steps=np.int64(7), lidar={"n_rays": np.int32(36)}, brake_mps2=np.float32(2.0))
    assert env.observation_space.shape == agvrl.make("search-outdoor-20", max_steps=7, lidar={"n_rays": 36}).observation_space.shape


@pytest.mark.parametrize("kind", ["pure-pursuit", "follow-the-gap"])
def test_a_racer_laps_a_generated_circuit_through_the_env(kind):
    # Held-out circuit 0 at the seed eval uses: pure pursuit and follow-the-gap both lap it
    # (`agvrl eval --racer KIND --env racing-circuit --seed 0`).
    env = agvrl.make("racing-circuit", max_steps=20_000, held_out=True, spawn="line")
    racer = agvrl.Racer(kind, env)
    env.reset(seed=0)
    laps = 0
    for _ in range(20_000):
        obs, reward, terminated, truncated, info = env.step(racer.act())
        assert not terminated, info
        laps = info["laps"]
        if laps >= 1 or truncated:
            break
    assert laps >= 1


def test_a_racer_names_what_is_wrong():
    env = agvrl.make("racing-oval")
    with pytest.raises(ValueError, match="pure-pursuit or follow-the-gap"):
        agvrl.Racer("slow-poke", env)
    with pytest.raises(ValueError, match="speed_scale"):
        agvrl.Racer("pure-pursuit", env, speed_scale=0.0)
    with pytest.raises(RuntimeError, match="reset"):
        agvrl.Racer("pure-pursuit", env).act()
