"""Races of several cars: PettingZoo's own parallel API test, seeding, crashed cars leaving."""

import warnings

import numpy as np
import pytest

import agvrl

from conftest import ROOT, need

SWEEPERS = str(ROOT / "assets" / "tracks" / "sweepers.yaml")


def test_a_race_passes_pettingzoos_parallel_api_test_without_warnings():
    pettingzoo_test = need("pettingzoo.test")
    assert agvrl.MULTI_ENV_IDS == ("racing-duel",)
    for cfg in ({"max_steps": 200}, {"max_steps": 200, "track": SWEEPERS, "race": {"cars": 4}}):
        env = agvrl.make_multi("racing-duel", **cfg)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            pettingzoo_test.parallel_api_test(env, num_cycles=300)
        assert len(env.possible_agents) == cfg.get("race", {}).get("cars", 2)


def test_the_same_seed_and_actions_give_the_same_race():
    def run():
        env = agvrl.make_multi("racing-duel", track=SWEEPERS, max_steps=80)
        obs, _ = env.reset(seed=5)
        out = [obs]
        rng = np.random.default_rng(1)
        while env.agents:
            acts = {a: rng.uniform(-1, 1, 2).astype(np.float32) for a in env.agents}
            out.append(env.step(acts))
        return out

    a, b = run(), run()
    assert len(a) == len(b) == 81
    for x, y in zip(a[1:], b[1:]):
        for da, db in zip(x, y):
            assert da.keys() == db.keys()
            for k in da:
                if isinstance(da[k], np.ndarray):
                    assert np.array_equal(da[k], db[k])
                else:
                    assert da[k] == db[k]


def test_a_crashed_car_leaves_the_agents_and_the_race_goes_on():
    # The crash charge is a racing rule; a value of its own shows the setting reaches the race.
    env = agvrl.make_multi("racing-duel", track=SWEEPERS, max_steps=400, racing={"crash_penalty": -25.0})
    env.reset(seed=0)
    gone = None
    for _ in range(400):
        # car_0 steers hard left at half throttle; car_1 waits on the grid.
        acts = {a: np.array([0.0, 1.0] if a == "car_0" else [-1.0, 0.0], np.float32) for a in env.agents}
        obs, rew, term, trunc, info = env.step(acts)
        if gone is None and term.get("car_0"):
            assert info["car_0"]["reward_terms"]["collision"] == -25.0 and info["car_0"]["race"]["crashed"]
            assert rew["car_0"] == pytest.approx(sum(info["car_0"]["reward_terms"].values()))
            assert info["car_0"]["termination"] in agvrl.TERMINATION_CAUSES
            gone = True
            assert env.agents == ["car_1"]
        if not env.agents:
            assert trunc["car_1"]
            summary = info["car_1"]["race_summary"]
            assert summary["crashed"] == [True, False] and summary["order"] == [1, 0]
            break
    assert gone, "steering hard left crashes car_0"
    with pytest.raises(KeyError, match="car_1"):
        env.reset(seed=1)
        env.step({"car_0": np.zeros(2, np.float32)})


def test_bad_race_settings_read_as_the_cli_would():
    with pytest.raises(ValueError, match="cars must be 1 to 8"):
        agvrl.make_multi("racing-duel", race={"cars": 9})
    with pytest.raises(ValueError, match="racing-duel"):
        agvrl.make_multi("racing-oval")
    with pytest.raises(ValueError, match="make_multi"):
        agvrl.make("racing-duel")


def test_races_as_a_vector_env_end_a_race_at_its_first_crash_and_start_it_again():
    def run():
        envs = agvrl.make_race_vec("racing-duel", 2, track=SWEEPERS, max_steps=300)
        assert envs.num_envs == 4 and envs.cars == 2
        obs, _ = envs.reset(seed=3)
        assert obs.shape == (4,) + envs.single_observation_space.shape and obs.dtype == np.float32
        out = []
        # Race 0's car 0 steers hard left at half throttle; every other car waits on the grid.
        acts = np.tile(np.array([-1.0, 0.0], np.float32), (4, 1))
        acts[0] = [0.0, 1.0]
        for _ in range(300):
            obs, rew, term, trunc, info = envs.step(acts)
            out.append((obs.copy(), rew.copy(), term.copy(), trunc.copy()))
            if term[0]:
                break
        return out, info

    (a, info), (b, _) = run(), run()
    assert len(a) == len(b) and all(all(np.array_equal(x, y) for x, y in zip(p, q)) for p, q in zip(a, b))
    obs, rew, term, trunc = a[-1]
    assert term[0] and not term[1] and trunc[1], "the crash ends race 0: car 0 terminated, car 1 cut"
    assert not (term[2:] | trunc[2:]).any(), "race 1 goes on"
    assert list(info["_final_obs"]) == [True, True, False, False]
    assert not np.array_equal(info["final_obs"][0], obs[0]), "race 0 started again on the same step"
    assert info["final_info"][0]["termination"] in agvrl.TERMINATION_CAUSES
    assert rew[0] == pytest.approx(sum(info["reward_terms"][k][0] for k in info["reward_terms"]))
