#!/usr/bin/env bash
# The held-out search table of docs/search.md: a policy and the uniform random policy on the same
# 100 held-out episodes (1,000 steps) of every search scene, on the built-in maps and on new
# procedural layouts, without and with sim2real noise and randomisation.
#   tools/search-table.sh [POLICY] [EPISODES] [SEED] [FILTER]
# POLICY defaults to the shipped assets/policies/search.agvrl; SEED is the base of the
# evaluation seeds (`agvrl eval --seed`); FILTER (on or off) overrides the policy's safety
# filter setting for both the policy and the random policy (`agvrl eval --safety-filter`).
# RANDOM_POLICY=off skips the random policy (its columns print "-"), for comparing trainings.
# A policy with a reverse gear (action_mapping = "scaled_reverse") is also compared with the
# random policy of the forward-only car (the same settings with `--set env_config.action_mapping=scaled`): a random policy that
# reverses half the time covers less, and the ratio is taken against the better of the two.
set -euo pipefail
cd "$(dirname "$0")/.."
policy="${1:-assets/policies/search.agvrl}"
episodes="${2:-100}"
seed="${3:-0}"
filter="${4:-}"
source tools/search-rows.sh
forward=""
if "$bin" policy "$policy" | grep -q '^action_mapping = "scaled_reverse"'; then
  forward=1
fi
random="random"
[ -z "$forward" ] || random="random (same car / forward only)"
row() { # env layouts preset
  local args=("${row_args[@]}") p pc rt=- rc=- ratio=- r best f fc fi
  [ -z "$filter" ] || args+=(--safety-filter "$filter")
  p=$("$bin" "${args[@]}")
  pc=$(key coverage "$p")
  if [ "${RANDOM_POLICY:-on}" != off ]; then
    r=$("$bin" "${args[@]}" --random)
    rt=$(key collisions "$r"); rc=$(key coverage "$r"); best=$rc
    if [ -n "$forward" ]; then
      f=$("$bin" "${args[@]}" --random --set env_config.action_mapping=scaled)
      fc=$(key coverage "$f")
      rt="$rt / $(key collisions "$f")"; rc="$rc / $fc"
      best=$(python3 -c "print(max($best, $fc))")
    fi
    ratio=$(python3 -c "print(f'{$pc / max($best, 1e-9):.1f}x')")
  fi
  fi=$(key filter_interventions_per_episode "$p"); fi="${fi:-off}"
  echo "| $1 | $2 | $3 | $(key collisions "$p") | $pc | $fi | $rt | $rc | $ratio |"
}
echo "| scene | maps | preset | policy: terminations / $episodes | coverage | filter interventions / episode | $random: terminations | coverage | coverage ratio |"
echo "|---|---|---|---|---|---|---|---|---|"
search_rows row
