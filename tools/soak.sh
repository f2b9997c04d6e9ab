#!/usr/bin/env bash
# A soak of the car loop: agvrl-drive against agvrl-drive --serve-sim over DDS on loopback, in
# lockstep, for TICKS ticks (default 1,000,000), sampling both processes' resident memory every
# 5 s. Prints the drive's summary (events=0: no watchdog event), the robot's, and for each
# process the RSS at the first sample, at the last, and the least-squares slope.
#   tools/soak.sh [TICKS] [DOMAIN_ID]
# REALTIME=1 runs both sides on wall-clock deadlines at 30 Hz instead (30 minutes: 54000 ticks);
# the drive's summary then counts late ticks (a tick that starts more than a period after its
# deadline) and gives the p99 and max tick time.
set -euo pipefail
TICKS=${1:-1000000}
DOMAIN=${2:-61}
B=${AGVRL_BIN_DIR:-target/release}/agvrl-drive
POLICY=${POLICY:-assets/policies/racing-oval-ppo.agvrl}
OUT=$(mktemp -d)
RT=${REALTIME:+--realtime}
"$B" --serve-sim racing-oval --domain-id "$DOMAIN" --steps 0 $RT >"$OUT/robot.out" 2>"$OUT/robot.err" &
ROBOT=$!
"$B" --policy "$POLICY" --vehicle ros2 --domain-id "$DOMAIN" --steps "$TICKS" --quiet $RT >"$OUT/drive.out" 2>"$OUT/drive.err" &
DRIVE=$!
rss() { awk '/VmRSS/ {print $2 / 1024}' "/proc/$1/status" 2>/dev/null || echo na; }
T0=$(date +%s.%N)
echo "t_s,drive_rss_mb,robot_rss_mb" >"$OUT/rss.csv"
while kill -0 "$DRIVE" 2>/dev/null; do
  sleep 5
  kill -0 "$DRIVE" 2>/dev/null || break
  echo "$(echo "$(date +%s.%N) - $T0" | bc),$(rss "$DRIVE"),$(rss "$ROBOT")" >>"$OUT/rss.csv"
done
rc=0
wait "$DRIVE" || rc=$?
kill -INT "$ROBOT" 2>/dev/null || true
sleep 1
kill "$ROBOT" 2>/dev/null || true
tail -1 "$OUT/drive.out"
python3 - "$OUT/rss.csv" <<'PY'
import csv, sys
rows = [r for r in csv.DictReader(open(sys.argv[1])) if "na" not in r.values()]
t = [float(r["t_s"]) for r in rows]
for who in ("drive", "robot"):
    y = [float(r[f"{who}_rss_mb"]) for r in rows]
    n = len(y)
    mt, my = sum(t) / n, sum(y) / n
    slope = sum((a - mt) * (b - my) for a, b in zip(t, y)) / max(sum((a - mt) ** 2 for a in t), 1e-9)
    print(f"{who}_rss_mb_first={y[0]:.1f} {who}_rss_mb_last={y[-1]:.1f} {who}_rss_mb_max={max(y):.1f} "
          f"{who}_rss_slope_mb_per_hour={slope * 3600:.2f} samples={n} span_s={t[-1] - t[0]:.0f}")
PY
echo "rss samples: $OUT/rss.csv"
if [ "$rc" != 0 ]; then
  echo "the drive failed (exit $rc): $(tail -1 "$OUT/drive.err")"
  exit 1
fi
