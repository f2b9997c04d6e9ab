#!/usr/bin/env python3
"""Faults on the wire between a car's stack and its sensors, over real DDS on loopback.

Each row starts `agvrl-drive --serve-sim racing-oval --realtime --faults SPEC` (the sender
injects the faults: this kernel has no netem) and `agvrl-drive --vehicle ros2 --realtime` with
the shipped racing policy at 30 Hz, then checks the drive's summary against the outcome written
down before the run. Prints one table row per fault; exits 1 when a row breaks its expectation.

    tools/fault-matrix.py [--seconds 20] [--bin target/release] [--domain 71]
"""

import argparse
import re
import subprocess
import sys

PERIOD_MS = 1000 / 30
BOUND_MS = 150  # the longest time from the last fresh frame to a zero command we accept
START = 90  # tick at which the timed faults begin (3 s in)

# (faults, what must happen, check on the drive's summary). Every row also needs
# stop_after_frame_ms_max <= BOUND_MS and stamp_back == 0 (no older frame acted on as new).
ROWS = [
    ("", "a perfect wire: the car drives every tick", lambda s: s["driving_share"] >= 0.99 and s["stops"] == 0),
    ("delay_ms=200", "every frame is older than 2 periods (66.7 ms) on arrival: the car never drives",
     lambda s: s["driving_share"] == 0.0),
    ("delay_ms=50,jitter_ms=20", "frames arrive 30-70 ms old: a tick whose newest frame passed 66.7 ms "
     "stops the car, the next fresh one drives it; never a stale frame acted on",
     lambda s: 0.0 < s["driving_share"] < 1.0),
    ("loss=0.2", "a lost message leaves the last one, which stays fresh for 2 periods: short stops "
     "only where two in a row are lost; the car mostly drives", lambda s: s["driving_share"] >= 0.7),
    ("duplicate=0.2,reorder=0.2", "a copy or an overtaken message is dropped as not newer: "
     "the car drives on, and no older frame is ever acted on", lambda s: s["driving_share"] >= 0.7),
    (f"outage={START}+30", "1 s without any message: one stop within the bound, then driving again "
     "within a period of the first message back", lambda s: s["stops"] == 1 and s["resume_ms_max"] <= 2 * PERIOD_MS),
    (f"mute=imu@{START}", "the IMU stops while the scans go on: the frame (its oldest sensor) goes "
     "stale, the car stops within the bound and stays stopped", lambda s: s["stops"] == 1),
    (f"clock_step=0.5@{START}", "the stamps jump 0.5 s ahead: frames from the future cannot be judged, "
     "so the car stops within a period or two and stays stopped", lambda s: s["stops"] == 1),
    (f"clock_step=-0.5@{START}", "the stamps jump 0.5 s back: every new frame is stale on arrival, "
     "and an older stamp never replaces a newer one: the car stops and stays stopped",
     lambda s: s["stops"] == 1),
]


def summary(line: str) -> dict:
    out = {}
    for k, v in re.findall(r"(\w+)=(\S+)", line):
        try:
            out[k] = float(v)
        except ValueError:
            out[k] = v
    return out


def run_row(b: str, faults: str, seconds: int, domain: int) -> tuple:
    ticks = seconds * 30
    robot = [f"{b}/agvrl-drive", "--serve-sim", "racing-oval", "--realtime", "--domain-id", str(domain),
             "--steps", str(ticks + 60)] + (["--faults", faults] if faults else [])
    drive = [f"{b}/agvrl-drive", "--policy", "assets/policies/racing-oval-ppo.agvrl", "--vehicle", "ros2",
             "--realtime", "--domain-id", str(domain), "--steps", str(ticks), "--quiet"]
    r = subprocess.Popen(robot, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    d = subprocess.run(drive, capture_output=True, text=True)
    rout, rerr = r.communicate(timeout=seconds + 60)
    if d.returncode != 0 or r.returncode != 0:
        raise RuntimeError(f"{faults}: drive rc {d.returncode} {d.stderr[-300:]} robot rc {r.returncode} {rerr[-300:]}")
    return summary(d.stdout.strip().splitlines()[-1]), summary(rout.strip().splitlines()[-1])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=int, default=20)
    ap.add_argument("--bin", default="target/release")
    ap.add_argument("--domain", type=int, default=71)
    a = ap.parse_args()
    print("| faults | expected | driving share | stops | last fresh frame to zero command, max (ms) | "
          "resume, max (ms) | older frames acted on | wire: lost / withheld / duplicated / held back | holds |")
    print("|---|---|---|---|---|---|---|---|---|")
    broken = 0
    for faults, expected, check in ROWS:
        s, w = run_row(a.bin, faults, a.seconds, a.domain)
        ok = check(s) and s["stop_after_frame_ms_max"] <= BOUND_MS and s["stamp_back"] == 0
        broken += not ok
        wire = f"{int(w['wire_lost'])} / {int(w['wire_withheld'])} / {int(w['wire_duplicated'])} / {int(w['wire_held_back'])}"
        print(f"| `{faults or 'none'}` | {expected} | {s['driving_share']:.3f} | {int(s['stops'])} | "
              f"{s['stop_after_frame_ms_max']:.1f} | {s['resume_ms_max']:.1f} | {int(s['stamp_back'])} | {wire} | "
              f"{'yes' if ok else '**no**'} |", flush=True)
    print(f"rows={len(ROWS)} broken={broken} seconds_per_row={a.seconds}")
    sys.exit(1 if broken else 0)


if __name__ == "__main__":
    main()
