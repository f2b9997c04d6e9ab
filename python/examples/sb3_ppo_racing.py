"""Stable-Baselines3 PPO on agvrl's racing-oval through agvrl.sb3, evaluated like `agvrl eval`.

    pip install stable-baselines3 torch   # plus the agvrl wheel
    python python/examples/sb3_ppo_racing.py [--steps 300000] [--seed 0]

Same env settings, PPO settings and step budget as the Rust default job (configs/default.toml:
8 envs, n_steps 256, batch 256, 10 epochs, lr 3e-4, gamma 0.99), then 3 deterministic
evaluation episodes of 3,000 steps on held-out seeds; prints key=value lines (laps,
collisions, best lap, wall time).
"""

import argparse
import time

import numpy as np
import torch
from stable_baselines3 import PPO

import agvrl
import agvrl.sb3


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--steps", type=int, default=300_000)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--threads", type=int, default=2)
    a = p.parse_args()
    torch.set_num_threads(a.threads)
    env = agvrl.sb3.make_vec("racing-oval", 8, max_steps=1000)
    env.seed(a.seed)
    model = PPO(
        "MlpPolicy",
        env,
        n_steps=256,
        batch_size=256,
        n_epochs=10,
        learning_rate=3e-4,
        gamma=0.99,
        seed=a.seed,
        device="cpu",
        verbose=0,
    )
    t0 = time.time()
    model.learn(total_timesteps=a.steps)
    train_s = time.time() - t0
    laps = collisions = 0
    best = float("inf")
    for k in range(3):
        ev = agvrl.make("racing-oval", max_steps=3000, held_out=True)
        obs, _ = ev.reset(seed=a.seed + 1_000_000 + k)
        while True:
            action, _ = model.predict(obs, deterministic=True)
            obs, _, terminated, truncated, info = ev.step(action)
            if terminated or truncated:
                laps += info["laps"]
                collisions += terminated
                best = min(best, info.get("best_lap_s", float("inf")))
                break
    print(f"sb3_ppo env=racing-oval steps={model.num_timesteps} seed={a.seed}")
    print(f"train_s={train_s:.1f}")
    print(f"steps_per_s={model.num_timesteps / train_s:.0f}")
    best_s = f"{best:.2f}" if np.isfinite(best) else "none"
    print(f"episodes=3 laps={laps} collisions={collisions} best_lap_s={best_s}")


if __name__ == "__main__":
    main()
