#!/usr/bin/env bash
# The aarch64 agvrl-drive under qemu-aarch64-static, checked against the x86_64 build:
#  0. it is static and at most 12 MB;
#  1. it laps the oval in the simulator with the shipped racing policy, with no watchdog event
#     and no termination, and its summary line is x86_64's (timings aside);
#  2. on the x86_64 run's observations its actions match x86_64's to 1e-4, and the other way;
#  3. over DDS on loopback it drives an x86_64 `--serve-sim` robot (lockstep) for 300 ticks,
#     every command received;
#  4. the camera-only racing policy (the host CNN: NEON kernels here, AVX2/AVX-512 on x86_64)
#     laps the oval from the simulator's depth frames, and each build's actions match the
#     other's on its observations to 1e-4.
#
#   tools/check-aarch64.sh AARCH64_AGVRL_DRIVE X86_64_AGVRL_DRIVE
set -euo pipefail
cd "$(dirname "$0")/.."
a64="${1:?usage: tools/check-aarch64.sh AARCH64_BIN X86_64_BIN}"
x86="${2:?usage: tools/check-aarch64.sh AARCH64_BIN X86_64_BIN}"
policy=assets/policies/racing-oval-ppo.agvrl
qemu=(qemu-aarch64-static)
tmp=$(mktemp -d)
trap 'kill $(jobs -p) 2> /dev/null || true; rm -rf "$tmp"' EXIT
fail() {
  echo "check-aarch64: FAIL: $*" >&2
  exit 1
}
field() { # field KEY LINE
  tr ' ' '\n' <<< "$2" | sed -n "s/^$1=//p"
}
# The summary without what depends on the machine's speed.
steady() {
  sed -E 's/ (infer_us_p50|infer_us_p99|tick_us_p99|tick_us_max|wall_s|cpu_pct|rss_mb)=[^ ]+//g' <<< "$1"
}

# readelf (binutils, there with gcc): the machine, and no program interpreter (static).
readelf -h "$a64" | grep -q 'Machine:.*AArch64' || fail "$a64 is not an aarch64 binary"
if readelf -l "$a64" | grep -q INTERP; then fail "$a64 is dynamically linked"; fi

bytes=$(stat -c %s "$a64")
echo "aarch64 binary: $bytes bytes"
[ "$bytes" -le 12000000 ] || fail "$a64 is $bytes bytes, over 12 MB"

# 1. One lap in the simulator (1,200 ticks at 30 Hz: 40 s; a lap takes ~31 s).
sum_a64=$("${qemu[@]}" "$a64" --policy "$policy" --steps 1200 --quiet --trace "$tmp/a64.jsonl" | tail -1)
sum_x86=$("$x86" --policy "$policy" --steps 1200 --quiet --trace "$tmp/x86.jsonl" | tail -1)
echo "aarch64: $sum_a64"
echo "x86_64:  $sum_x86"
[ "$(field events "$sum_a64")" = 0 ] || fail "watchdog events on aarch64"
[ "$(field terminations "$sum_a64")" = 0 ] || fail "terminations on aarch64"
[ "$(field laps "$sum_a64")" -ge 1 ] || fail "no lap on aarch64"
[ "$(steady "$sum_a64")" = "$(steady "$sum_x86")" ] || fail "summaries differ: '$(steady "$sum_a64")' vs '$(steady "$sum_x86")'"

# 2. The same observations give the same actions.
"${qemu[@]}" "$a64" --policy "$policy" --check-trace "$tmp/x86.jsonl" --tolerance 1e-4 || fail "aarch64 actions on x86_64's observations"
"$x86" --policy "$policy" --check-trace "$tmp/a64.jsonl" --tolerance 1e-4 || fail "x86_64 actions on aarch64's observations"

# 3. Two architectures on one DDS domain: the x86_64 robot, the aarch64 driver.
domain=$((100 + RANDOM % 100))
"$x86" --serve-sim racing-oval --steps 300 --domain-id "$domain" > "$tmp/robot.out" 2> "$tmp/robot.err" &
robot=$!
sum_dds=$("${qemu[@]}" "$a64" --vehicle ros2 --domain-id "$domain" --policy "$policy" --steps 300 --quiet 2> "$tmp/drive.err" | tail -1) \
  || fail "aarch64 driver over DDS: $(cat "$tmp/drive.err")"
for _ in $(seq 100); do kill -0 "$robot" 2> /dev/null || break; sleep 0.1; done
kill "$robot" 2> /dev/null && fail "the robot did not finish its 300 ticks: $(cat "$tmp/robot.err")"
wait "$robot" || fail "the x86_64 robot failed: $(cat "$tmp/robot.err")"
sum_robot=$(tail -1 "$tmp/robot.out")
echo "aarch64 driver over DDS: $sum_dds"
echo "x86_64 robot:            $sum_robot"
[ "$(field ticks "$sum_dds")" = 300 ] && [ "$(field events "$sum_dds")" = 0 ] || fail "driver: $sum_dds"
[ "$(field commands "$sum_robot")" -ge 300 ] && [ "$(field terminations "$sum_robot")" = 0 ] || fail "robot: $sum_robot"
# 4. The camera policy. Closed loop, the two builds' rounding may steer apart, so the summaries
#    are not compared; the actions on the same observations are.
camera=assets/policies/racing-oval-camera.agvrl
cam_a64=$("${qemu[@]}" "$a64" --policy "$camera" --steps 1200 --quiet --trace "$tmp/cam-a64.jsonl" | tail -1)
cam_x86=$("$x86" --policy "$camera" --steps 1200 --quiet --trace "$tmp/cam-x86.jsonl" | tail -1)
echo "aarch64 camera: $cam_a64"
echo "x86_64 camera:  $cam_x86"
[ "$(field events "$cam_a64")" = 0 ] && [ "$(field terminations "$cam_a64")" = 0 ] || fail "camera policy on aarch64: $cam_a64"
[ "$(field laps "$cam_a64")" -ge 1 ] || fail "no lap from the camera on aarch64: $cam_a64"
"${qemu[@]}" "$a64" --policy "$camera" --check-trace "$tmp/cam-x86.jsonl" --tolerance 1e-4 || fail "aarch64 camera actions on x86_64's observations"
"$x86" --policy "$camera" --check-trace "$tmp/cam-a64.jsonl" --tolerance 1e-4 || fail "x86_64 camera actions on aarch64's observations"
echo "check-aarch64: ok"
