#!/usr/bin/env bash
# Run on a quiet machine; maturin must be on PATH.
# tools/cold-build-times.sh: a fresh clone of this checkout with a cold target directory (/tmp/cold): the builds of
# the README's two commands in order, then the wheel; prints key=value times (docs/speed.md, "Builds").
set -e
src=$(cd "$(dirname "$0")/.." && pwd)
rm -rf /tmp/cold && git clone -q "$src" /tmp/cold && cd /tmp/cold
export CARGO_TARGET_DIR=/tmp/cold/target CARGO_TERM_COLOR=never
git log --oneline | head -1
s=$(date +%s); cargo build --release -p agvrl --bin agvrl > /tmp/cold-run.log 2>&1; e=$(date +%s); echo "cargo_run_build_s=$((e-s))"
s=$(date +%s); cargo test --workspace --release --no-run > /tmp/cold-test.log 2>&1; e=$(date +%s); echo "cargo_test_build_s=$((e-s))"
grep -c "Compiling" /tmp/cold-test.log | sed 's/^/test_build_units_compiled=/'
s=$(date +%s); (cd python && maturin build --release --out /tmp/cold/wheels > /tmp/cold-wheel.log 2>&1); e=$(date +%s); echo "wheel_build_s=$((e-s))"
grep -c "Compiling" /tmp/cold-wheel.log | sed 's/^/wheel_units_compiled=/'
