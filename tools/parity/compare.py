#!/usr/bin/env python3
"""Compare agvrl's and Stable-Baselines3's PPO on Pendulum over many seeds, from the trace logs of
`cargo run --release -p agvrl-rl --example parity -- ALGO SEEDS --trace` and
`python tools/parity/sb3_pendulum_trace.py --algo ALGO --seeds SEEDS` (several logs per side are
concatenated). Prints key=value lines (means, medians, trimmed means, bootstrap intervals of the
differences, the spread of 5-seed means) and, with --plot, draws the learning curves and the
score distributions of both sides.

    python tools/parity/compare.py --agvrl a.log --sb3 s1.log s2.log --label gsde --plot out.png
"""
import argparse
import re
from collections import defaultdict

import numpy as np

LINE = re.compile(r"(\w+)=(\S+)")


def parse(paths):
    """(scores by seed, trace by seed: list of dicts per update)."""
    scores, trace = {}, defaultdict(list)
    for path in paths:
        for line in open(path):
            kv = dict(LINE.findall(line))
            if line.startswith("update "):
                trace[int(kv["seed"])].append({k: float(v) for k, v in kv.items() if k != "seed"})
            elif line.startswith("peer=") and "seed" in kv:
                scores[int(kv["seed"])] = float(kv["mean_return"])
    return scores, trace


def trimmed(x, cut=0.1):
    x = np.sort(x)
    k = int(len(x) * cut)
    return x[k:len(x) - k].mean()


def bootstrap(a, b, stat, n=20000, seed=0):
    rng = np.random.default_rng(seed)
    d = [stat(rng.choice(a, len(a))) - stat(rng.choice(b, len(b))) for _ in range(n)]
    return np.percentile(d, [5, 95])


def five_seed_means(x, n=20000, seed=1):
    rng = np.random.default_rng(seed)
    return np.array([rng.choice(x, 5, replace=False).mean() for _ in range(n)])


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--agvrl", nargs="+", required=True)
    p.add_argument("--sb3", nargs="+", required=True)
    p.add_argument("--label", default="ppo")
    p.add_argument("--plot")
    a = p.parse_args()
    sides = {"agvrl": parse(a.agvrl), "sb3": parse(a.sb3)}
    x = {k: np.array([v[0][s] for s in sorted(v[0])]) for k, v in sides.items()}
    for k, v in x.items():
        seeds = sorted(sides[k][0])
        first5 = [sides[k][0][s] for s in range(5) if s in sides[k][0]]
        f5 = five_seed_means(v)
        print(f"side={k} label={a.label} seeds={len(v)} seed_range={seeds[0]}-{seeds[-1]} mean={v.mean():.2f} "
              f"median={np.median(v):.2f} trimmed_mean_10={trimmed(v):.2f} worse_than_250={int((v < -250).sum())} "
              f"seeds_0_4_mean={np.mean(first5):.2f} five_seed_mean_p5={np.percentile(f5, 5):.1f} "
              f"five_seed_mean_p95={np.percentile(f5, 95):.1f}")
    ag, sb = x["agvrl"], x["sb3"]
    for name, stat in [("mean", np.mean), ("median", np.median), ("trimmed_mean_10", trimmed)]:
        lo, hi = bootstrap(ag, sb, stat)
        print(f"diff label={a.label} stat={name} agvrl_minus_sb3={stat(ag) - stat(sb):.2f} ci90_low={lo:.2f} "
              f"ci90_high={hi:.2f}")
    wins = (ag[:, None] > sb[None, :]).mean()
    print(f"diff label={a.label} p_agvrl_seed_beats_sb3_seed={wins:.3f}")
    # Per-update figures, averaged over seeds at each update index.
    keys = ["approx_kl", "clip_fraction", "std", "explained_variance", "grad_norm", "value_loss", "mean_return"]
    curves = {}
    for k, (sc, tr) in sides.items():
        tr = {s: t for s, t in tr.items() if s in sc}  # finished seeds only
        n_up = min(len(t) for t in tr.values())
        curves[k] = {q: np.array([[t[i][q] for i in range(n_up)] for t in tr.values()]) for q in keys}
        curves[k]["steps"] = np.array([tr[next(iter(tr))][i]["steps"] for i in range(n_up)])
        m = {q: np.nanmean(curves[k][q], axis=0) for q in keys}
        print(f"trace side={k} label={a.label} updates={n_up} " + " ".join(
            f"{q}_first={m[q][0]:.4f} {q}_mid={m[q][n_up // 2]:.4f} {q}_last={m[q][-1]:.4f}" for q in keys))
    if a.plot:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, ax = plt.subplots(2, 3, figsize=(15, 8))
        colours = {"agvrl": "tab:blue", "sb3": "tab:orange"}
        for (q, title), axis in zip([("mean_return", "training episode return"), ("std", "exploration std (mean)"),
                                     ("approx_kl", "approx_kl (last epoch)"), ("clip_fraction", "clip fraction"),
                                     ("grad_norm", "gradient norm before clipping")], ax.flat):
            for k, c in curves.items():
                y = c[q]
                axis.plot(c["steps"], np.nanmedian(y, axis=0), color=colours[k], label=f"{k} median")
                axis.fill_between(c["steps"], np.nanpercentile(y, 25, axis=0), np.nanpercentile(y, 75, axis=0),
                                  color=colours[k], alpha=0.2)
            axis.set_title(title)
            axis.set_xlabel("env steps")
            axis.legend()
        axis = ax.flat[5]
        bins = np.linspace(min(ag.min(), sb.min()) - 5, max(ag.max(), sb.max()) + 5, 30)
        for k, v in x.items():
            axis.hist(v, bins=bins, alpha=0.5, color=colours[k], label=f"{k} ({len(v)} seeds, median {np.median(v):.1f})")
        axis.set_title("score on the 100 shared start states")
        axis.set_xlabel("mean return")
        axis.legend()
        fig.suptitle(f"PPO on Pendulum-v1, rl-zoo3 settings ({a.label}): agvrl vs Stable-Baselines3 "
                     "(lines: median over seeds, bands: 25-75 %)")
        fig.tight_layout()
        fig.savefig(a.plot, dpi=90)
        print(f"plot={a.plot}")


if __name__ == "__main__":
    main()
