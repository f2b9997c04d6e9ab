#!/usr/bin/env python3
"""How often a fresh 100-episode table meets "coverage >= 0.97 x the explorer's" on every row.

Reads the coverage CSVs that `CSV_DIR=DIR tools/search-safety-table.sh POLICY 100 SEED` writes
(DIR/<env>-<maps>-<preset>-<driver>.csv), from one or more draws of episodes (one DIR per seed
base). For every row it pools the draws' episodes, takes each episode's last coverage, and draws
RESAMPLES tables of EPISODES episodes from the pool (paired: an episode brings both drivers'
coverage), the way a fresh seed base draws them. It prints, per row, the pooled ratio of the
means and the fraction of drawn tables at or above THRESHOLD, then the product over the rows
(the rows draw their episodes independently): the chance that one fresh table meets every row.
The last column does the same for a driver whose pooled ratio is exactly AS_RATIO on every row
(the drawn ratios scaled by AS_RATIO over the pooled one; 1 by default): the chance for a driver
as good as the explorer, with this pair's spread from episode to episode.

    tools/frontier-odds.py [--a policy] [--b frontier] [--threshold 0.97] [--as-ratio 1.0] DIR [DIR ...]
"""

import argparse
import glob
import os
import random
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from importlib import import_module

finals = import_module("coverage-ratio").finals


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dirs", nargs="+", help="coverage CSV directories, one per draw")
    ap.add_argument("--a", default="policy", help="the driver on top (file suffix)")
    ap.add_argument("--b", default="frontier", help="the driver below (file suffix)")
    ap.add_argument("--threshold", type=float, default=0.97)
    ap.add_argument("--episodes", type=int, default=100, help="episodes per drawn table")
    ap.add_argument("--resamples", type=int, default=4000)
    ap.add_argument("--as-ratio", type=float, default=1.0, help="the last column's pooled ratio")
    args = ap.parse_args()
    rows = sorted(
        os.path.basename(p)[: -len(f"-{args.a}.csv")]
        for p in glob.glob(os.path.join(args.dirs[0], f"*-{args.a}.csv"))
    )
    if not rows:
        sys.exit(f"{args.dirs[0]}: no *-{args.a}.csv")
    rng = random.Random(0)
    chance, chance_at = 1.0, 1.0
    print(f"row ratio tables_at_or_above_{args.threshold} the_same_at_ratio_{args.as_ratio}")
    for row in rows:
        pairs = []
        for d in args.dirs:
            paths = [os.path.join(d, f"{row}-{driver}.csv") for driver in (args.a, args.b)]
            for path in paths:
                if not os.path.isfile(path):
                    sys.exit(f"{path}: missing (every DIR needs both drivers' files of every row)")
            a, b = finals(paths[0]), finals(paths[1])
            if sorted(a) != sorted(b):
                sys.exit(f"{d}/{row}: the drivers' files hold different episodes")
            pairs += [(a[e], b[e]) for e in sorted(a)]
        pooled = sum(p[0] for p in pairs) / max(sum(p[1] for p in pairs), 1e-12)
        above = above_at = 0
        for _ in range(args.resamples):
            s = [rng.choice(pairs) for _ in range(args.episodes)]
            r = sum(p[0] for p in s) / max(sum(p[1] for p in s), 1e-12)
            above += r >= args.threshold
            above_at += r * args.as_ratio / pooled >= args.threshold
        p, q = above / args.resamples, above_at / args.resamples
        chance *= p
        chance_at *= q
        print(f"{row} {pooled:.3f} {p:.3f} {q:.3f}")
    print(f"rows={len(rows)} episodes_pooled_per_row={len(pairs)} draws={len(args.dirs)}")
    print(f"every_row_chance={chance:.3f} every_row_chance_at_ratio_{args.as_ratio}={chance_at:.3f}")


if __name__ == "__main__":
    main()
