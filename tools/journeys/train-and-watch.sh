#!/usr/bin/env bash
# Journey (a), as the README's "Train, evaluate, watch" tells it: train the default job, evaluate
# it with a plot, and verify its recording with the rerun CLI. Fails on any step that breaks.
#   tools/journeys/train-and-watch.sh [AGVRL_BINARY]
set -euo pipefail
repo=$(cd "$(dirname "$0")/../.." && pwd)
agvrl=$(realpath "${1:-$repo/target/release/agvrl}")
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cd "$work"
ln -s "$repo/configs" configs
ln -s "$repo/assets" assets
"$agvrl" envs > envs.txt && grep -q racing-oval envs.txt
# The default job (configs/default.toml), as `cargo run --release` runs it.
"$agvrl" train --seed 0 --progress none > train.txt
run=$(ls -d runs/*/)
for f in config.toml metrics.csv policy.agvrl eval.txt eval.json eval.rrd learning_curve.png; do
  [ -s "$run/$f" ] || { echo "journey: $run$f missing" >&2; exit 1; }
done
"$agvrl" eval --run "$run" --episodes 5 --plot paths.png > eval.txt
grep -q '^lapped=' eval.txt
[ "$(head -c 8 paths.png | od -An -tx1 | tr -d ' \n')" = 89504e470d0a1a0a ] || { echo "journey: paths.png is no PNG" >&2; exit 1; }
RERUN_TELEMETRY_ENABLED=false rerun rrd verify "$run/eval.rrd"
echo "journey=train-and-watch ok=true $(grep -E '^(laps|lapped|terminations)=' eval.txt | tr '\n' ' ')"
