#!/usr/bin/env bash
# Journey (d), as docs/deploy.md's "On a Jetson" tells it, with qemu standing in for the board:
# a car.toml from the shipped example, and the aarch64 agvrl-drive driving the simulated car (an
# x86_64 `--serve-sim` robot) over DDS on loopback with that config.
#   tools/journeys/deploy.sh AARCH64_AGVRL_DRIVE X86_64_AGVRL_DRIVE
set -euo pipefail
repo=$(cd "$(dirname "$0")/../.." && pwd)
a64=$(realpath "$1"); x86=$(realpath "$2")
work=$(mktemp -d)
robot=
trap '[ -n "$robot" ] && kill "$robot" 2> /dev/null; rm -rf "$work"' EXIT
cd "$work"
domain=$(( ($$ % 200) + 20 ))
# The car's config: the example with this machine's DDS domain.
sed "s/^domain_id = 0 /domain_id = $domain /" "$repo/crates/deploy/car.example.toml" > car.toml
grep -q "^domain_id = $domain " car.toml
cp "$repo/assets/policies/racing-oval-ppo.agvrl" .
"$x86" --serve-sim racing-oval --steps 300 --domain-id "$domain" > robot.out 2> robot.err &
robot=$!
summary=$(qemu-aarch64-static "$a64" --vehicle ros2 --config car.toml --policy racing-oval-ppo.agvrl \
    --steps 300 --quiet | tail -1)
wait "$robot"; robot=
echo "$summary" | grep -q ' ticks=300 events=0 terminations=0 ' \
    || { echo "journey: the aarch64 drive: $summary" >&2; cat robot.err >&2; exit 1; }
echo "journey=deploy ok=true $(echo "$summary" | grep -o 'ticks=[0-9]* events=[0-9]*')"
