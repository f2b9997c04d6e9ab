#!/usr/bin/env bash
# Journey (b), as docs/racing.md's "Your own track" tells it, on the shipped bean map: the
# reference lap of pure pursuit, the generalist, the per-track recipe trained on the track (300k
# steps a run, from seed 0), which must lap, and every driver's lap times.
#   tools/journeys/own-track.sh [AGVRL_BINARY]
set -euo pipefail
repo=$(cd "$(dirname "$0")/../.." && pwd)
agvrl=$(realpath "${1:-$repo/target/release/agvrl}")
map=$repo/assets/tracks/bean.yaml
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cd "$work"
ln -s "$repo/configs" configs
ln -s "$repo/assets" assets
lapped() { sed -n 's/^lapped=\([0-9]*\)\/.*/\1/p' "$1"; }
"$agvrl" eval --racer pure-pursuit --track "$map" --episodes 3 \
    --max-steps 1000000 --set env_config.racing.time_limit_laps=1.5 > pp.txt
"$agvrl" eval --policy assets/policies/racing-any-track.agvrl --env racing-oval \
    --track "$map" --episodes 3 --max-steps 1000000 --plot laps.png > generalist.txt
"$agvrl" train --track "$map" --seed 0 --progress none > train.txt
run=$(ls -d runs/*/)
"$agvrl" eval --run "$run" --episodes 3 --max-steps 1000000 \
    --set env_config.racing.time_limit_laps=1.5 > trained.txt
python3 "$repo/tools/racing-table.py" --agvrl "$agvrl" --policy "$run/policy.agvrl" --circuits 0 \
    --track "bean=$map" > table.md
cat table.md
for f in pp generalist trained; do
  [ "$(lapped $f.txt)" -ge 1 ] || { echo "journey: $f lapped none of 3"; cat $f.txt; exit 1; } >&2
done
echo "journey=own-track ok=true pure_pursuit_lapped=$(lapped pp.txt)/3 generalist_lapped=$(lapped generalist.txt)/3 trained_lapped=$(lapped trained.txt)/3"
