#!/usr/bin/env bash
# The validation score that picks which training of a search config ships: terminations over
# 50 held-out episodes per search scene, on the built-in maps and on new procedural layouts,
# with evaluation seeds from 1,000,000 (the README's table uses seed base 0, so the choice never
# sees the table's episodes). Fewer is better.
#   tools/search-validate.sh POLICY [POLICY ...]
set -euo pipefail
cd "$(dirname "$0")/.."
bin="${AGVRL:-${CARGO_TARGET_DIR:-target}/release/agvrl}"
[ -x "$bin" ] || cargo build --release -q
[ $# -ge 1 ] || { echo "usage: $0 POLICY [POLICY ...]" >&2; exit 2; }
for policy in "$@"; do
  total=0
  for layouts in builtin procedural; do
    for env in search-outdoor-20 search-urban-20 search-outdoor-50 search-urban-50; do
      n=$("$bin" eval --policy "$policy" --env "$env" --episodes 50 --seed 1000000 --layouts "$layouts" --max-steps 1000 \
        | sed -n 's/^collisions=//p')
      total=$((total + n))
    done
  done
  echo "policy=$policy validation_terminations=$total episodes=400"
done
