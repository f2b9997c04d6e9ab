#!/usr/bin/env bash
# The validation score that picks which training of a search config ships (and the safety
# filter's settings): terminations over 50 held-out episodes per search scene, on the built-in
# maps and on new procedural layouts, without and with sim2real noise, with evaluation seeds from
# 1,000,000 (docs/search.md's table uses seed base 0, so the choice never sees the table's
# episodes). The rule: among the trainings within 2 terminations of the fewest, the one with the
# highest mean coverage ships (terminations first, since every target bounds them; coverage
# next, since the coverage targets are the ones a fresh training misses). It also prints the
# terminations of the same episodes without the filter (validation_bare_terminations), which
# the rule does not read.
#   tools/search-validate.sh POLICY [POLICY ...]
set -euo pipefail
cd "$(dirname "$0")/.."
[ $# -ge 1 ] || { echo "usage: $0 POLICY [POLICY ...]" >&2; exit 2; }
source tools/search-rows.sh
episodes=50
seed=1000000
row() {
  local out
  out=$("$bin" "${row_args[@]}")
  total=$((total + $(key collisions "$out")))
  coverage+=("$(key coverage "$out")")
  # The same episodes without the filter: reported beside the score, not part of the rule.
  out=$("$bin" "${row_args[@]}" --safety-filter off)
  bare=$((bare + $(key collisions "$out")))
}
for policy in "$@"; do
  total=0
  bare=0
  coverage=()
  search_rows row
  mean=$(python3 -c "import sys; v = [float(x) for x in sys.argv[1:]]; print(f'{sum(v) / len(v):.3f}')" "${coverage[@]}")
  echo "policy=$policy validation_terminations=$total validation_mean_coverage=$mean validation_bare_terminations=$bare episodes=800"
done
