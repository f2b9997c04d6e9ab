"""The Stable-Baselines3 VecEnv adapter (no SB3 needed to import or test it)."""

import numpy as np

import agvrl
import agvrl.sb3


def test_sb3_vec_env_reports_terminal_observations_like_single_envs():
    n = 3
    vec = agvrl.sb3.make_vec("search-urban-20", n, max_steps=200)
    vec.seed(40)
    obs = vec.reset()
    envs = [agvrl.make("search-urban-20", max_steps=200) for _ in range(n)]
    assert np.array_equal(obs, np.stack([e.reset(seed=40 + i)[0] for i, e in enumerate(envs)]))
    rng = np.random.default_rng(0)
    truncs = terms = 0
    for _ in range(600):
        # Mostly full throttle: collisions as well as time limits.
        a = rng.uniform([0.5, -1.0], [1.0, 1.0], (n, 2)).astype(np.float32)
        obs, rew, dones, infos = vec.step(a)
        assert rew.dtype == np.float32 and dones.dtype == np.bool_ and len(infos) == n
        for i, e in enumerate(envs):
            o, r, te, tr, info = e.step(a[i])
            assert rew[i] == np.float32(r)
            assert dones[i] == (te or tr)
            if te or tr:
                assert np.array_equal(infos[i]["terminal_observation"], o)
                assert infos[i]["TimeLimit.truncated"] == (tr and not te)
                assert infos[i]["episode"]["l"] == info["episode"]["l"]
                if te:
                    assert infos[i]["termination"] == info["termination"]
                truncs += tr and not te
                terms += te
                o, _ = e.reset()
            else:
                assert infos[i] == {}
            assert np.array_equal(obs[i], o)
    assert truncs and terms
    assert vec.env_is_wrapped(object) == [False] * n
    assert vec.get_attr("render_mode") == [None] * n
