#!/usr/bin/env bash
# The held-out search table of the bare policy (docs/search.md): a policy with its safety filter
# off (the bare network) and on, on the same 100 held-out episodes (1,000 steps) of every search scene, on
# the built-in maps and on new procedural layouts, without and with sim2real noise and
# randomisation; beside it the frontier explorer and the map-aware planner on the same car and
# episodes, behind the filter they were tuned behind (the policy's training shield,
# `--safety-filter train`: they drive at full throttle and leave braking to the filter).
#   tools/search-safety-table.sh [POLICY] [EPISODES] [SEED]
# POLICY defaults to the shipped assets/policies/search.agvrl; SEED is the base of the
# evaluation seeds (`agvrl eval --seed`). PLANNERS=off skips the two planners (their columns
# print "-"), for comparing trainings. CSV_DIR=DIR also writes every driver's coverage-over-time
# CSV there (DIR/<env>-<maps>-<preset>-<driver>.csv, for `agvrl coverage-plot`).
set -euo pipefail
cd "$(dirname "$0")/.."
policy="${1:-assets/policies/search.agvrl}"
episodes="${2:-100}"
seed="${3:-0}"
source tools/search-rows.sh
ratio() { python3 -c "print(f'{$1 / max($2, 1e-9):.2f}')"; }
row() { # env layouts preset
  local b f q m bc fc fr=- pl=- pf=-
  run() { # driver name, extra args
    local name=$1
    shift
    if [ -n "${CSV_DIR:-}" ]; then
      mkdir -p "$CSV_DIR"
      "$bin" "${row_args[@]}" "$@" --coverage-csv "$CSV_DIR/$env-$layouts-$preset-$name.csv"
    else
      "$bin" "${row_args[@]}" "$@"
    fi
  }
  local env=$1 layouts=$2 preset=$3
  b=$(run bare --safety-filter off)
  f=$(run policy --safety-filter on)
  bc=$(key coverage "$b"); fc=$(key coverage "$f")
  if [ "${PLANNERS:-on}" != off ]; then
    q=$(run frontier --safety-filter train --planner frontier)
    fr="$(key collisions "$q"), $(key coverage "$q")"
    pf=$(ratio "$fc" "$(key coverage "$q")")
    m=$(run planner --safety-filter train --planner map)
    pl=$(key coverage "$m")
  fi
  echo "| $env | $layouts | $preset | $(key collisions "$b") | $bc | $(ratio "$bc" "$fc") | $(key collisions "$f") | $fc | $(key filter_corrections_per_episode "$f") | $(key filter_backouts_per_episode "$f") ($(key filter_backout_ticks_per_episode "$f")) | $(key clearance_mean_m "$b") / $(key clearance_p5_m "$b"); $(key clearance_mean_m "$f") / $(key clearance_p5_m "$f") | $(key steering_change_mean_rad "$b"); $(key steering_change_mean_rad "$f") | $fr | $pf | $pl |"
}
echo "| scene | maps | noise | bare: terminations | bare: coverage | bare / filtered coverage | filtered: terminations | filtered: coverage | corrections / episode (steered + braked) | back-outs / episode (reversing ticks) | r_m mean / 5th pct, m (bare; filtered) | steering change / control, rad (bare; filtered) | frontier: terminations, coverage | policy / frontier | map planner: coverage |"
echo "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
search_rows row
