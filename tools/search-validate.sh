#!/usr/bin/env bash
# The validation score that picks which training of a search config ships (and the safety
# filter's settings): terminations over 50 held-out episodes per search scene, on the built-in
# maps and on new procedural layouts, without and with sim2real noise, with evaluation seeds from
# 1,000,000 (docs/search.md's table uses seed base 0, so the choice never sees the table's
# episodes), with the filter on (validation_terminations) and off (validation_bare_terminations,
# the same 800 episodes). The rule, for several policies: those within 2 filtered terminations
# of the fewest; of them, those within 10 bare terminations of the fewest (the bare policy's
# bounds are the primary target; 10 of 800 is under one episode per 100-episode row); of them,
# the highest mean filtered coverage (the coverage targets are the ones a fresh training misses
# next). It prints `picked=POLICY` last.
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
scores=()
for policy in "$@"; do
  total=0
  bare=0
  coverage=()
  search_rows row
  mean=$(python3 -c "import sys; v = [float(x) for x in sys.argv[1:]]; print(f'{sum(v) / len(v):.3f}')" "${coverage[@]}")
  echo "policy=$policy validation_terminations=$total validation_mean_coverage=$mean validation_bare_terminations=$bare episodes=800"
  scores+=("$policy $total $bare $mean")
done
printf '%s\n' "${scores[@]}" | python3 -c '
import sys
rows = [(p, int(f), int(b), float(c)) for p, f, b, c in (l.split() for l in sys.stdin)]
rows = [r for r in rows if r[1] <= min(r[1] for r in rows) + 2]
rows = [r for r in rows if r[2] <= min(r[2] for r in rows) + 10]
print("picked=" + max(rows, key=lambda r: r[3])[0])'
