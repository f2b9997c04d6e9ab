#!/usr/bin/env python3
"""Episodes that stop gaining ground, from `agvrl eval --coverage-csv` files.

For each CSV (`episode,step,time_s,coverage`), prints how many episodes covered no new cell over
their last CONTROLS controls (default 400, 13 s), and the mean coverage they stopped at. An
episode that ended early counts by its last row.

    tools/coverage-stalls.py [--controls N] LABEL=FILE.csv [LABEL=FILE.csv ...]
"""

import argparse
import csv
import sys
from collections import defaultdict


def stalls(path, controls):
    episodes = defaultdict(list)
    with open(path, newline="") as f:
        rows = csv.DictReader(f)
        if rows.fieldnames != ["episode", "step", "time_s", "coverage"]:
            sys.exit(f"{path}: not a coverage CSV (header {rows.fieldnames})")
        for r in rows:
            episodes[int(r["episode"])].append((int(r["step"]), float(r["coverage"])))
    stalled = []
    for curve in episodes.values():
        curve.sort()
        last_step, last = curve[-1]
        before = [c for s, c in curve if s <= last_step - controls]
        if before and before[-1] == last:
            stalled.append(last)
    return len(episodes), stalled


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--controls", type=int, default=400)
    ap.add_argument("files", nargs="+", metavar="LABEL=FILE.csv")
    a = ap.parse_args()
    for spec in a.files:
        label, _, path = spec.rpartition("=")
        n, stalled = stalls(path, a.controls)
        mean = f"{sum(stalled) / len(stalled):.3f}" if stalled else "-"
        print(f"driver={label or path} episodes={n} stalled_last_{a.controls}={len(stalled)} stalled_mean_coverage={mean}")


if __name__ == "__main__":
    main()
