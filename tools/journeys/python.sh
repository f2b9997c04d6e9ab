#!/usr/bin/env bash
# Journey (c), as docs/python.md tells it, with the wheel installed in PYTHON's environment:
# a Gymnasium env and vector env, a PettingZoo race, a policy file driving a lap; and the
# Stable-Baselines3 adapter when stable_baselines3 is installed (it needs torch, which CI does not
# install: that part runs by hand; the script says which parts ran).
#   tools/journeys/python.sh [PYTHON]
set -euo pipefail
repo=$(cd "$(dirname "$0")/../.." && pwd)
python=${1:-python3}
cd "$repo"
"$python" - <<'PY'
import importlib.util

import gymnasium
import numpy as np

import agvrl

env = gymnasium.make("agvrl/racing-oval-v0")
obs, info = env.reset(seed=0)
for _ in range(30):
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
assert env.observation_space.contains(obs), "an observation outside its space"

envs = agvrl.make_vec("search-urban-20", 4, preset="sim2real")
obs, infos = envs.reset(seed=42)
obs, rewards, terminated, truncated, infos = envs.step(envs.action_space.sample())
assert obs.shape[0] == 4

race = agvrl.make_multi("racing-duel", track="assets/tracks/bean.yaml", max_steps=100)
obs, infos = race.reset(seed=0)
while race.agents:
    obs, rewards, terms, truncs, infos = race.step({a: race.action_space(a).sample() for a in race.agents})

policy = agvrl.Policy.load("assets/policies/racing-oval-ppo.agvrl")
single = agvrl.make("racing-oval")
obs, _ = single.reset(seed=0)
laps = 0
for _ in range(1200):
    obs, reward, terminated, truncated, info = single.step(policy.act(obs))
    laps = info["laps"]
    if terminated or truncated:
        break
assert laps >= 1, f"the shipped policy drove {laps} laps in 40 s"

parts = "gymnasium vector pettingzoo policy"
if importlib.util.find_spec("stable_baselines3"):
    from stable_baselines3 import PPO

    import agvrl.sb3

    model = PPO("MlpPolicy", agvrl.sb3.make_vec("racing-oval", 2), n_steps=64, batch_size=64, seed=0)
    model.learn(256)
    parts += " sb3"
print(f"journey=python ok=true parts={parts.replace(' ', ',')}")
PY
