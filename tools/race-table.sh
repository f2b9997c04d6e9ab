#!/usr/bin/env bash
# The self-play results of docs/racing.md for one duel policy: DUEL against LONE (a single-car
# policy) on both shipped tracks, DUEL against itself, and both policies alone (lap times).
# Usage: tools/race-table.sh DUEL.agvrl LONE.agvrl [RACES] [SEED]
set -euo pipefail
duel=$1 lone=$2 races=${3:-100} seed=${4:-1000}
agvrl=${AGVRL:-target/release/agvrl}
# The paper's racing rules on the tracks, the rules docs/racing.md's self-play figures were
# measured under (a map track's own default is contact only with a progress reward).
rules=(--set env_config.racing.end_below_m=0.8 --set 'env_config.racing.reward="paper"'
  --set env_config.racing.crash_penalty=-50.0 --set env_config.racing.stall_after_s=0.0)
row() { # label, then race arguments: a line per car
  "$agvrl" race "${@:2}" "${rules[@]}" --races "$races" --seed "$seed" | grep '^car=' | sed "s|^|$1 |"
}
for t in bean sweepers; do
  row "vs-lone track=$t" --policy "$duel" --policy "$lone" --track "assets/tracks/$t.yaml"
  row "self track=$t" --policy "$duel" --track "assets/tracks/$t.yaml"
  row "alone track=$t" --policy "$duel" --cars 1 --track "assets/tracks/$t.yaml"
  row "lone-alone track=$t" --policy "$lone" --cars 1 --track "assets/tracks/$t.yaml"
done
