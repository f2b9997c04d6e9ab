"""The vector env against single envs stepped in a loop, in each Gymnasium autoreset mode."""

import gymnasium
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import agvrl

N = 4
# Short episodes and wild steering: both truncations and collisions happen within the test.
CFG = {"max_steps": 30}


def actions(rng, n):
    return rng.uniform(-1, 1, (n, 2)).astype(np.float32)


def singles(env_id, seed):
    envs = [agvrl.make(env_id, **CFG) for _ in range(N)]
    obs = np.stack([e.reset(seed=seed + i)[0] for i, e in enumerate(envs)])
    return envs, obs


@pytest.mark.parametrize("env_id", ["search-urban-20", "racing-oval"])
def test_next_step_equals_single_envs_reset_on_the_following_step(env_id):
    vec = agvrl.make_vec(env_id, N, threads=2, autoreset_mode="next_step", **CFG)
    envs, ref = singles(env_id, 7)
    obs, _ = vec.reset(seed=7)
    assert np.array_equal(obs, ref)
    rng = np.random.default_rng(1)
    ended = np.zeros(N, bool)
    ends = resets = 0
    for _ in range(100):
        a = actions(rng, N)
        obs, rew, term, trunc, info = vec.step(a)
        for i, e in enumerate(envs):
            if ended[i]:
                o, _ = e.reset()
                assert (rew[i], term[i], trunc[i]) == (0.0, False, False)
                ended[i] = False
                resets += 1
            else:
                o, r, te, tr, _ = e.step(a[i])
                assert (rew[i], term[i], trunc[i]) == (r, te, tr)
                ended[i] = te or tr
                ends += ended[i]
            assert np.array_equal(obs[i], o)
    assert ends >= N and resets >= N


@pytest.mark.parametrize("env_id", ["search-urban-20", "racing-oval"])
def test_same_step_equals_single_envs_with_final_obs(env_id):
    vec = agvrl.make_vec(env_id, N, threads=2, autoreset_mode="same_step", **CFG)
    envs, ref = singles(env_id, 3)
    assert np.array_equal(vec.reset(seed=3)[0], ref)
    rng = np.random.default_rng(2)
    ends = 0
    for _ in range(100):
        a = actions(rng, N)
        obs, rew, term, trunc, info = vec.step(a)
        for i, e in enumerate(envs):
            o, r, te, tr, single_info = e.step(a[i])
            assert (rew[i], term[i], trunc[i]) == (r, te, tr)
            if te or tr:
                ends += 1
                assert info["_final_obs"][i] and info["_final_info"][i]
                assert np.array_equal(info["final_obs"][i], o)
                final = info["final_info"]
                assert final["termination"][i] == (
                    agvrl.TERMINATION_CAUSES.index(single_info["termination"]) + 1 if te else 0
                )
                assert info["episode"]["l"][i] == single_info["episode"]["l"]
                o, _ = e.reset()
            elif "_final_obs" in info:
                assert not info["_final_obs"][i]
            assert np.array_equal(obs[i], o)
    assert ends >= N


@pytest.mark.parametrize("env_id", ["search-urban-20", "racing-oval"])
def test_disabled_equals_single_envs_reset_by_mask(env_id):
    vec = agvrl.make_vec(env_id, N, threads=2, autoreset_mode="disabled", **CFG)
    envs, ref = singles(env_id, 21)
    assert np.array_equal(vec.reset(seed=21)[0], ref)
    rng = np.random.default_rng(3)
    resets = 0
    for t in range(100):
        a = actions(rng, N)
        obs, rew, term, trunc, _ = vec.step(a)
        for i, e in enumerate(envs):
            o, r, te, tr, _ = e.step(a[i])
            assert (rew[i], term[i], trunc[i]) == (r, te, tr)
            assert np.array_equal(obs[i], o)
        done = term | trunc
        if done.any():
            with pytest.raises(RuntimeError, match="needs reset"):
                vec.step(a)
            seeds = [1000 * t + i for i in range(N)]
            obs, _ = vec.reset(seed=seeds, options={"reset_mask": done})
            for i, e in enumerate(envs):
                if done[i]:
                    resets += 1
                    assert np.array_equal(obs[i], e.reset(seed=seeds[i])[0])
    assert resets >= N


def test_rows_do_not_depend_on_the_thread_count():
    rng = np.random.default_rng(4)
    a = [actions(rng, 6) for _ in range(60)]
    runs = []
    for threads in (1, 2, 3):
        vec = agvrl.make_vec("search-outdoor-20", 6, threads=threads, **CFG)
        out = [vec.reset(seed=9)[0]]
        out += [vec.step(x)[0] for x in a]
        runs.append(np.stack(out))
    assert np.array_equal(runs[0], runs[1]) and np.array_equal(runs[0], runs[2])


def test_vector_arrays_and_infos_have_gymnasium_shapes():
    vec = agvrl.make_vec("racing-oval", 3)
    obs, info = vec.reset(seed=0)
    assert obs.shape == (3,) + vec.single_observation_space.shape and obs.dtype == np.float32
    obs, rew, term, trunc, info = vec.step(vec.action_space.sample())
    assert rew.shape == (3,) and rew.dtype == np.float64
    assert term.dtype == np.bool_ and trunc.dtype == np.bool_
    assert info["laps"].shape == (3,) and info["_laps"].all()
    assert info["reward_terms"]["throttle"].shape == (3,)
    assert vec.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP


def test_gymnasium_make_vec_uses_the_rust_vector_env():
    vec = gymnasium.make_vec("agvrl/racing-oval-v0", num_envs=8, vectorization_mode="vector_entry_point")
    assert isinstance(vec.unwrapped, agvrl.AgvrlVectorEnv)
    obs, _ = vec.reset(seed=0)
    assert obs.shape[0] == 8
    vec.step(vec.action_space.sample())
    vec.close()
    single = gymnasium.make("agvrl/racing-oval-v0")
    assert single.unwrapped.env_id == "racing-oval"


def test_nan_in_one_row_raises_and_steps_no_env():
    vec = agvrl.make_vec("racing-oval", 2, threads=2)
    ref = agvrl.make_vec("racing-oval", 2, threads=2)
    vec.reset(seed=5)
    ref.reset(seed=5)
    bad = np.array([[0.5, 0.0], [np.nan, 0.0]], np.float32)
    with pytest.raises(ValueError, match="env 1: action element 0 is not finite"):
        vec.step(bad)
    a = np.array([[0.5, 0.0], [0.5, 0.0]], np.float32)
    assert np.array_equal(vec.step(a)[0], ref.step(a)[0])


def test_wrong_action_shape_and_bad_vector_settings_raise_value_error():
    vec = agvrl.make_vec("racing-oval", 2)
    vec.reset(seed=0)
    with pytest.raises(ValueError, match="shape"):
        vec.step(np.zeros((3, 2), np.float32))
    with pytest.raises(ValueError, match="autoreset_mode"):
        agvrl.AgvrlVectorEnv("racing-oval", 2, autoreset_mode="sometimes")
    with pytest.raises(ValueError, match="unknown field `nope`"):
        agvrl.make_vec("racing-oval", 2, nope=True)
    with pytest.raises(ValueError, match="num_envs"):
        agvrl.make_vec("racing-oval", 0)
