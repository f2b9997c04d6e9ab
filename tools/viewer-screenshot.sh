#!/usr/bin/env bash
# viewer-screenshot.sh FILE.rrd OUT.png: the official rerun web viewer (rerun-sdk 0.36.3) showing a
# recording with the layout it carries, rendered by headless Chromium (software WebGL).
# Needs: pip install rerun-sdk==0.36.3; apt-get install chromium.
set -euo pipefail
rrd=$1; out=$2
export RERUN_TELEMETRY_ENABLED=false
# Its own process group: `rerun` from pip is a wrapper around the viewer binary.
setsid rerun --serve-web --web-viewer-port 9090 "$rrd" > /dev/null 2>&1 &
server=$!
trap 'kill -- -$server 2> /dev/null || true' EXIT
for _ in $(seq 50); do curl -sf http://127.0.0.1:9090 > /dev/null && break; sleep 0.2; done
sleep 3 # the gRPC server loads the recording
# 90 s of virtual time lets the viewer load the recording over gRPC and draw it (the time
# series may still be empty; run it again). Some tries show only rerun's welcome page, a
# nearly empty PNG (11 KB against 400-500 KB for a drawn recording): try up to 4 times.
for try in 1 2 3 4; do
  chromium --headless=new --no-sandbox --disable-gpu-sandbox --use-angle=swiftshader \
    --enable-unsafe-swiftshader --ignore-gpu-blocklist --window-size=1600,1000 \
    --virtual-time-budget=90000 --screenshot="$out" \
    "http://127.0.0.1:9090/?url=rerun%2Bhttp%3A%2F%2Flocalhost%3A9876%2Fproxy&renderer=webgl" 2> /dev/null
  [ "$(stat -c %s "$out")" -gt 100000 ] && break
  echo "try $try showed the welcome page; again" >&2
done
echo "screenshot=$out"
