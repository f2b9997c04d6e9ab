"""Python against Rust on the same envs, in one run: prints key=value lines.

    python python/benchmarks/bench_envs.py [--steps N] [--reps R] [--env racing-oval] [--n-envs 8]

Each repetition times the Rust loop (agvrl._core.bench_rust: the same VecEnv or env, random
actions drawn in Rust) and the Python loop (agvrl.make_vec / agvrl.make, random actions from
numpy every step) back to back; ratios are medians of per-repetition ratios, so machine noise
hits both sides of each ratio alike.
"""

import argparse
import statistics
import time

import numpy as np

import agvrl
from agvrl import _core


def py_vec(env_id, n, steps, threads, seed):
    vec = agvrl.make_vec(env_id, n, threads=threads)
    vec.reset(seed=seed)
    rng = np.random.default_rng(seed)
    t0 = time.perf_counter()
    for _ in range(steps):
        vec.step(rng.uniform(-1.0, 1.0, (n, 2)).astype(np.float32))
    return steps * n / (time.perf_counter() - t0)


def py_single(env_id, steps, seed):
    env = agvrl.make(env_id)
    env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    t0 = time.perf_counter()
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(rng.uniform(-1.0, 1.0, 2).astype(np.float32))
        if terminated or truncated:
            env.reset()
    return steps / (time.perf_counter() - t0)


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--env", default="racing-oval")
    p.add_argument("--n-envs", type=int, default=8)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--steps", type=int, default=2000, help="vector steps per repetition")
    p.add_argument("--reps", type=int, default=5)
    a = p.parse_args()
    rv, pv, rs, ps = [], [], [], []
    for r in range(a.reps):
        rv.append(_core.bench_rust(a.env, a.n_envs, a.steps, a.threads, r))
        pv.append(py_vec(a.env, a.n_envs, a.steps, a.threads, r))
        rs.append(_core.bench_rust(a.env, 0, a.steps * 2, None, r))
        ps.append(py_single(a.env, a.steps * 2, r))
    med = statistics.median
    print(f"py_bench env={a.env} n_envs={a.n_envs} threads={a.threads} steps={a.steps} reps={a.reps}")
    print(f"rust_vec_steps_per_s={med(rv):.0f}")
    print(f"py_vec_steps_per_s={med(pv):.0f}")
    print(f"py_vec_ratio={med(p / r for p, r in zip(pv, rv)):.3f}")
    print(f"rust_single_steps_per_s={med(rs):.0f}")
    print(f"py_single_steps_per_s={med(ps):.0f}")
    print(f"py_single_ratio={med(p / r for p, r in zip(ps, rs)):.3f}")


if __name__ == "__main__":
    main()
