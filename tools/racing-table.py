#!/usr/bin/env python3
"""The lap-time table of docs/racing.md: a policy, pure pursuit and follow-the-gap on the same
held-out episodes of each track, under the map-track rules (contact ends an episode), each
episode 1.5 laps' time at the car's top speed from the start line.

    tools/racing-table.py --agvrl target/release/agvrl --policy FILE [--episodes 3]
        [--circuits 100] [--seed 0] [--track NAME=MAP.yaml ...] [--set KEY=VALUE ...] [--csv-dir DIR]

Rows: `circuits` (racing-circuit, one generated held-out circuit per episode, --circuits
episodes), the oval, and every --track. Per row and driver it prints the episodes lapped
without a crash, the crashes, the mean first lap over the lapped episodes, and the policy's
first lap over pure pursuit's on the episodes both lapped (the mean of the per-episode ratios).
Every --set goes to every driver: the classical racers drive the policy's car only when they get
its settings (the generalist's braking drive: --set env_config.brake_mps2=4).
The per-episode CSVs (`eval --episodes-csv`) stay in --csv-dir.
"""

import argparse
import csv
import os
import subprocess
import sys
import tempfile

RULES = [
    "--set", "env_config.racing.end_below_m=0",
    "--set", "env_config.racing.time_limit_laps=1.5",
    "--set", 'env_config.spawn="line"',
    "--max-steps", "1000000",
]
DRIVERS = ["policy", "pure-pursuit", "follow-the-gap"]


def run(agvrl, driver, policy, env, track, episodes, seed, csv_path, sets):
    cmd = [agvrl, "eval", "--episodes", str(episodes), "--seed", str(seed), "--env", env]
    cmd += ["--episodes-csv", csv_path] + RULES
    for s in sets:
        cmd += ["--set", s]
    cmd += ["--policy", policy] if driver == "policy" else ["--racer", driver]
    if track:
        cmd += ["--track", track]
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"{' '.join(cmd)}: {r.stderr.strip().splitlines()[-1] if r.stderr.strip() else r.returncode}")
    with open(csv_path) as f:
        return list(csv.DictReader(f))


def lapped(row):
    return row["ended"] == "time_limit" and int(row["laps"]) >= 1


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--agvrl", default="target/release/agvrl")
    ap.add_argument("--policy", required=True)
    ap.add_argument("--episodes", type=int, default=3, help="episodes per track")
    ap.add_argument("--circuits", type=int, default=100, help="held-out generated circuits (0: no row)")
    ap.add_argument("--seed", type=int, default=0, help="seed base of the episodes")
    ap.add_argument("--track", action="append", default=[], metavar="NAME=MAP.yaml")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="to every driver")
    ap.add_argument("--csv-dir", default=None)
    args = ap.parse_args()
    out = args.csv_dir or tempfile.mkdtemp(prefix="racing-table-")
    os.makedirs(out, exist_ok=True)
    rows = []
    if args.circuits > 0:
        rows.append(("circuits", "racing-circuit", None, args.circuits))
    rows.append(("oval", "racing-oval", None, args.episodes))
    for t in args.track:
        name, _, path = t.partition("=")
        if not path:
            sys.exit(f"--track {t}: expected NAME=MAP.yaml")
        rows.append((name, "racing-oval", path, args.episodes))
    print("| track | driver | lapped | crashes | mean first lap, s | vs pure pursuit |")
    print("|---|---|---|---|---|---|")
    for name, env, track, n in rows:
        got = {}
        for d in DRIVERS:
            got[d] = run(args.agvrl, d, args.policy, env, track, n, args.seed, os.path.join(out, f"{name}-{d}.csv"), args.set)
        for d in DRIVERS:
            eps = got[d]
            ok = [e for e in eps if lapped(e)]
            crashes = sum(e["ended"] not in ("time_limit",) for e in eps)
            first = [float(e["first_lap_s"]) for e in ok]
            mean = f"{sum(first) / len(first):.1f}" if first else "-"
            ratios = [
                float(a["first_lap_s"]) / float(b["first_lap_s"])
                for a, b in zip(eps, got["pure-pursuit"])
                if lapped(a) and lapped(b)
            ]
            vs = f"{sum(ratios) / len(ratios):.3f} ({len(ratios)})" if ratios and d != "pure-pursuit" else "-"
            print(f"| {name} | {d} | {len(ok)}/{len(eps)} | {crashes} | {mean} | {vs} |")
    print(f"csv_dir={out}")


if __name__ == "__main__":
    main()
