#!/usr/bin/env python3
"""One driver's coverage over another's on the same episodes, with a bootstrap interval.

Reads two `agvrl eval --coverage-csv` files of the same episodes (the same env, layouts, preset,
`--episodes` and `--seed`), takes each episode's last coverage, and prints the ratio of the two
means and a paired percentile bootstrap interval over the episodes (RESAMPLES draws, fixed seed),
with the fraction of draws at or above THRESHOLD: how far one draw of episodes decides the ratio.

    tools/coverage-ratio.py [--threshold 0.97] [--resamples 10000] A.csv B.csv
"""

import argparse
import csv
import random
import sys


def finals(path):
    last = {}
    with open(path, newline="") as f:
        rows = csv.DictReader(f)
        if rows.fieldnames != ["episode", "step", "time_s", "coverage"]:
            sys.exit(f"{path}: not a coverage CSV (header {rows.fieldnames})")
        for r in rows:
            e, step = int(r["episode"]), int(r["step"])
            if e not in last or step >= last[e][0]:
                last[e] = (step, float(r["coverage"]))
    return {e: c for e, (_, c) in last.items()}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("a", help="the driver on top (coverage CSV)")
    ap.add_argument("b", help="the driver below (coverage CSV)")
    ap.add_argument("--threshold", type=float, default=0.97)
    ap.add_argument("--resamples", type=int, default=10000)
    args = ap.parse_args()
    a, b = finals(args.a), finals(args.b)
    if sorted(a) != sorted(b):
        sys.exit(f"the files hold different episodes ({len(a)} and {len(b)})")
    episodes = sorted(a)
    if not episodes or sum(b.values()) <= 0.0:
        sys.exit("no coverage to compare")

    def ratio(sample):
        return sum(a[e] for e in sample) / sum(b[e] for e in sample)

    rng = random.Random(0)
    draws = sorted(ratio([rng.choice(episodes) for _ in episodes]) for _ in range(args.resamples))
    lo, hi = draws[int(0.025 * len(draws))], draws[int(0.975 * len(draws)) - 1]
    above = sum(d >= args.threshold for d in draws) / len(draws)
    print(f"episodes={len(episodes)}")
    print(f"mean_a={sum(a.values()) / len(a):.4f} mean_b={sum(b.values()) / len(b):.4f}")
    print(f"ratio={ratio(episodes):.4f}")
    print(f"ratio_95_interval={lo:.3f},{hi:.3f}")
    print(f"draws_at_or_above_{args.threshold}={above:.3f}")


if __name__ == "__main__":
    main()
