#!/usr/bin/env python3
"""Stable-Baselines3's side of the PPO parity trace on Pendulum-v1: rl-zoo3's settings (as
../shared/anchors/sb3/pendulum_parity.py), one line per update with the figures SB3 logs under
`train/` plus the gradient norm before clipping, then the score on the 100 shared start states
(crates/rl/data/pendulum_start_states.json). agvrl's side prints the same lines:
`cargo run --release -p agvrl-rl --example parity -- ppo_zoo 0,1,2,3,4 --trace`.

    python tools/parity/sb3_pendulum_trace.py --algo ppo_zoo --seeds 0,1,2,3,4
"""
import argparse
import json
import os

import numpy as np

STATES = os.path.join(os.path.dirname(__file__), "../../crates/rl/data/pendulum_start_states.json")


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--algo", default="ppo_zoo", choices=["ppo_zoo", "ppo_zoo_gaussian"])
    p.add_argument("--seeds", default="0,1,2,3,4")
    p.add_argument("--steps", type=int, default=100_000)
    p.add_argument("--threads", type=int, default=1)
    a = p.parse_args()
    import gymnasium as gym
    import torch as th
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env

    th.set_num_threads(a.threads)
    norms = []
    clip = th.nn.utils.clip_grad_norm_

    def clip_and_record(params, max_norm, *args, **kw):
        n = clip(params, max_norm, *args, **kw)
        norms.append(float(n))
        return n

    th.nn.utils.clip_grad_norm_ = clip_and_record
    states = json.load(open(STATES))
    scores = []
    for seed in [int(s) for s in a.seeds.split(",")]:
        m = PPO("MlpPolicy", make_vec_env("Pendulum-v1", n_envs=4, seed=seed), seed=seed, verbose=0, device="cpu",
                n_steps=1024, gae_lambda=0.95, gamma=0.9, n_epochs=10, ent_coef=0.0, learning_rate=1e-3,
                clip_range=0.2, use_sde=(a.algo == "ppo_zoo"), sde_sample_freq=4)
        train = m.train

        def traced(seed=seed, m=m, train=train):
            norms.clear()
            train()
            v = m.logger.name_to_value
            ep = [e["r"] for e in m.ep_info_buffer]
            print(f"update seed={seed} steps={m.num_timesteps} approx_kl={v['train/approx_kl']:.5f} "
                  f"clip_fraction={v['train/clip_fraction']:.4f} pg_loss={v['train/policy_gradient_loss']:.5f} "
                  f"value_loss={v['train/value_loss']:.4f} explained_variance={v['train/explained_variance']:.4f} "
                  f"std={v.get('train/std', float('nan')):.4f} grad_norm={np.mean(norms):.4f} "
                  f"mean_return={np.mean(ep) if ep else float('nan'):.1f}", flush=True)

        m.train = traced
        m.learn(a.steps)
        e = gym.make("Pendulum-v1").unwrapped
        e.reset(seed=0)
        total = 0.0
        for th_, thd in states:
            e.state = np.array([th_, thd])
            obs = e._get_obs()
            for _ in range(200):
                act, _ = m.predict(obs, deterministic=True)
                obs, r, *_ = e.step(act)
                total += float(r)
        scores.append(total / len(states))
        print(f"peer=sb3 algo={a.algo} seed={seed} steps={a.steps} mean_return={scores[-1]:.2f}", flush=True)
    print(f"peer=sb3 algo={a.algo} seeds={len(scores)} mean_return={np.mean(scores):.2f}")


if __name__ == "__main__":
    main()
