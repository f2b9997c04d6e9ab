#!/usr/bin/env bash
# Racing speed beside f1tenth_gym, in one sitting (docs/speed.md): the same generated 400 m
# circuit (seed 7, 2.2 m wide) as a map for f1tenth_gym's own Simulator (0.01 s RK4 steps, a
# 1,080-beam scan every step) and in `agvrl bench --only circuit` (30 Hz control, a 1,081-beam
# scan every control period), 1, 2 and 8 cars; simulated seconds per wall second and LiDAR scans
# per wall second, both sides timed in turn in every round, with agvrl / f1tenth_gym ratios.
#
# Usage: tools/f110-bench.sh F1TENTH_GYM_CHECKOUT [ROUNDS]
#   F1TENTH_GYM_CHECKOUT  a clone of github.com/f1tenth/f1tenth_gym (its package is gym/f110_gym)
#   ROUNDS                rounds of both sides (default 3); the table gives medians
# Env: AGVRL (default $CARGO_TARGET_DIR/release/agvrl, else target/release/agvrl; build it with
#   `cargo build --release --bin agvrl`), F110_VENV (default ~/.cache/agvrl-f110-venv: made
#   here with pinned versions), STEPS_1 / STEPS_2 / STEPS_8 (f1tenth_gym steps a run, default
#   3000 / 1500 / 500), MAP_DIR (where the circuit's map goes, default a temporary folder).
set -euo pipefail
gym=${1:?usage: tools/f110-bench.sh F1TENTH_GYM_CHECKOUT [ROUNDS]}
rounds=${2:-3}
here=$(cd "$(dirname "$0")" && pwd)
agvrl=${AGVRL:-${CARGO_TARGET_DIR:-target}/release/agvrl}
venv=${F110_VENV:-$HOME/.cache/agvrl-f110-venv}
pkg=$gym/gym
[ -d "$pkg/f110_gym/envs" ] || pkg=$gym
[ -f "$pkg/f110_gym/envs/base_classes.py" ] || {
  echo "no f110_gym package under $gym (expected gym/f110_gym/envs/base_classes.py)" >&2
  exit 2
}
[ -x "$agvrl" ] || {
  echo "no agvrl binary at $agvrl: cargo build --release --bin agvrl, or set AGVRL" >&2
  exit 2
}
# f1tenth_gym's own pins (gym 0.19, numpy <= 1.22) do not install on Python 3.11; its
# simulator core needs only these. Versions that installed together on Python 3.11, 2026-11-29.
pins=(numpy==1.26.4 numba==0.68.1 llvmlite==0.50.0 scipy==1.17.1 PyYAML==6.0.4 pillow==13.0.0)
if ! "$venv/bin/python" -c 'import numba, scipy, yaml, PIL' 2>/dev/null; then
  python3 -m venv "$venv"
  "$venv/bin/pip" install -q "${pins[@]}"
fi
map=${MAP_DIR:-$(mktemp -d)}
"$agvrl" circuit --seed 7 --set 'length_m=[400,400]' --set 'width_m=[2.2,2.2]' --out "$map" >/dev/null
yaml=$map/circuit-7.yaml csv=$map/circuit-7.csv
log=$(mktemp)
echo "machine: $(uname -m), $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs)"
echo "date: $(date -u +%F) load: $(cut -d' ' -f1-3 /proc/loadavg)"
echo "f1tenth_gym: $(git -C "$gym" rev-parse --short HEAD 2>/dev/null || echo unknown) agvrl: $(git -C "$here/.." rev-parse --short HEAD 2>/dev/null || echo unknown)"
for r in $(seq "$rounds"); do
  "$agvrl" bench --only circuit | grep '^circuit=' | sed "s/^/side=agvrl round=$r /" >>"$log"
  for n in 1 2 8; do
    steps_var=STEPS_$n
    steps=${!steps_var:-$((3000 / (n == 8 ? 6 : n)))}
    F110_GYM_DIR=$pkg "$venv/bin/python" -W ignore "$here/f110_sim_bench.py" "$yaml" "$n" "$steps" "$csv" |
      tr '\n' ' ' | sed "s/^/side=f110 round=$r /; s/\$/\n/" >>"$log"
  done
done
python3 - "$log" <<'PY'
import re, statistics, sys
rows = [dict(re.findall(r"(\S+?)=(\S+)", l)) for l in open(sys.argv[1]) if l.strip()]
def fig(side, r, n):
    for d in rows:
        if d["side"] != side or int(d["round"]) != r:
            continue
        if side == "agvrl" and int(d["cars"]) == n:
            return float(d[f"circuit_cars{n}_sim_s_per_wall_s"]), float(d[f"circuit_cars{n}_scans_per_s"])
        if side == "f110" and int(d["agents"]) == n:
            return float(d["sim_seconds_per_wall_s"]), float(d["agent_steps_per_s"])
    return None
rounds = sorted({int(d["round"]) for d in rows})
med = statistics.median
print("cars | f110 sim-s/wall-s | agvrl sim-s/wall-s | ratio | f110 scans/s | agvrl scans/s | ratio")
for n in (1, 2, 8):
    pairs = [(fig("f110", r, n), fig("agvrl", r, n)) for r in rounds]
    pairs = [(f, a) for f, a in pairs if f and a]
    if not pairs:
        print(f"{n} | missing")
        continue
    f_sim, a_sim = med(f[0] for f, _ in pairs), med(a[0] for _, a in pairs)
    f_scan, a_scan = med(f[1] for f, _ in pairs), med(a[1] for _, a in pairs)
    # Ratios within each round (one sitting), then their median.
    r_sim = med(a[0] / f[0] for f, a in pairs)
    r_scan = med(a[1] / f[1] for f, a in pairs)
    print(f"{n} | {f_sim:.1f} | {a_sim:.1f} | {r_sim:.1f}x | {f_scan:.0f} | {a_scan:.0f} | {r_scan:.1f}x")
    print(f"f110_cars{n}_sim_s_per_wall_s={f_sim:.1f} agvrl_cars{n}_sim_s_per_wall_s={a_sim:.1f} "
          f"ratio_cars{n}_sim_s={r_sim:.2f} f110_cars{n}_scans_per_s={f_scan:.0f} "
          f"agvrl_cars{n}_scans_per_s={a_scan:.0f} ratio_cars{n}_scans={r_scan:.2f} rounds={len(pairs)}")
PY
echo "raw lines: $log"
