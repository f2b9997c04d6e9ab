#!/usr/bin/env python3
"""f1tenth_gym's core Simulator (no gym, no rendering) timed on a map_server track: the peer
side of tools/f110-bench.sh (docs/speed.md). The project's copy of the shared anchor
anchors/f110/bench_f110.py; f1tenth_gym itself is never copied here (the user clones it).

Usage:  python f110_sim_bench.py MAP_YAML N_AGENTS [STEPS] [CENTERLINE_CSV]

  MAP_YAML        map_server YAML; the image beside it must share its stem (X.yaml -> X.png)
  N_AGENTS        cars on the track (e.g. 1, 2, 8)
  STEPS           timed simulator steps (default 5000)
  CENTERLINE_CSV  default: MAP_YAML with '_map.yaml' -> '_centerline.csv' (x_m, y_m, ...)

Env vars: F110_GYM_DIR (folder holding the f110_gym package; else found on sys.path),
SPEED (m/s, default 2.0), STEER (rad, default 0.02), SPACING (m along the centreline, 3.0),
WARMUP (untimed steps that trigger numba compilation, default 50),
RESET_ON_COLLISION (default 1: any collision flag puts all cars back at their start poses,
as an RL loop does on done; 0: keep stepping, f1tenth_gym then zeroes state[3:] every hit).

Everything else is f1tenth_gym's own default, as F110Env would set it: vehicle params,
timestep 0.01 s, RK4 integrator, 1080 beams over 4.7 rad, 30 m range, seed 12345, scan noise on.
Timed work is Simulator.step only; F110Env.step adds only a few numpy ops (lap check) on top.
"""
import importlib.util
import os
import sys
import time
import types

import numpy as np

# Import f110_gym.envs.base_classes without running the package __init__ files
# (they import gym 0.19 and pyglet). Stub the two package modules, then import.
root = os.environ.get("F110_GYM_DIR")
if root:
    pkg_dir = os.path.join(root, "f110_gym")
else:
    spec = importlib.util.find_spec("f110_gym")
    if spec is None:
        sys.exit("set F110_GYM_DIR to the folder that holds the f110_gym package")
    pkg_dir = list(spec.submodule_search_locations)[0]
for name, path in (("f110_gym", pkg_dir), ("f110_gym.envs", os.path.join(pkg_dir, "envs"))):
    mod = types.ModuleType(name)
    mod.__path__ = [path]
    sys.modules[name] = mod
from f110_gym.envs.base_classes import Integrator, RaceCar, Simulator  # noqa: E402

# F110Env's defaults (gym/f110_gym/envs/f110_env.py)
PARAMS = {'mu': 1.0489, 'C_Sf': 4.718, 'C_Sr': 5.4562, 'lf': 0.15875, 'lr': 0.17145,
          'h': 0.074, 'm': 3.74, 'I': 0.04712, 's_min': -0.4189, 's_max': 0.4189,
          'sv_min': -3.2, 'sv_max': 3.2, 'v_switch': 7.319, 'a_max': 9.51,
          'v_min': -5.0, 'v_max': 20.0, 'width': 0.31, 'length': 0.58}
SEED, TIMESTEP, INTEGRATOR = 12345, 0.01, Integrator.RK4


def start_poses(csv_path, n, spacing):
    """Car i at arc length i*spacing along the centreline, heading along it."""
    pts = np.loadtxt(csv_path, delimiter=",", comments="#")[:, :2]
    seg = np.diff(pts, axis=0)
    s = np.concatenate(([0.0], np.cumsum(np.hypot(seg[:, 0], seg[:, 1]))))
    poses = np.empty((n, 3))
    for i in range(n):
        k = min(np.searchsorted(s, i * spacing, side="right") - 1, len(seg) - 1)
        t = (i * spacing - s[k]) / max(s[k + 1] - s[k], 1e-9)
        poses[i, :2] = pts[k] + t * seg[k]
        poses[i, 2] = np.arctan2(seg[k, 1], seg[k, 0])
    return poses


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    map_yaml = os.path.abspath(sys.argv[1])
    n = int(sys.argv[2])
    steps = int(sys.argv[3]) if len(sys.argv) > 3 else 5000
    csv_path = sys.argv[4] if len(sys.argv) > 4 else map_yaml.replace("_map.yaml", "_centerline.csv")
    speed = float(os.environ.get("SPEED", 2.0))
    steer = float(os.environ.get("STEER", 0.02))
    spacing = float(os.environ.get("SPACING", 3.0))
    warmup = int(os.environ.get("WARMUP", 50))
    reset_on_collision = os.environ.get("RESET_ON_COLLISION", "1") != "0"

    sim = Simulator(PARAMS, n, SEED, time_step=TIMESTEP, integrator=INTEGRATOR)
    sim.set_map(map_yaml, ".png")  # f1tenth_gym appends the extension to the YAML's stem
    poses = start_poses(csv_path, n, spacing)
    controls = np.tile([steer, speed], (n, 1))  # columns: steering angle, velocity

    t0 = time.perf_counter()
    sim.reset(poses)
    for _ in range(warmup):  # first calls compile (or load cached) numba functions
        sim.step(controls)
    warmup_s = time.perf_counter() - t0

    sim.reset(poses)
    resets, first_collision = 0, -1
    t0 = time.perf_counter()
    for k in range(steps):
        obs = sim.step(controls)
        if obs["collisions"].any():  # like an RL loop on done: all cars back to the start
            resets += 1
            if first_collision < 0:
                first_collision = k
            if reset_on_collision:
                sim.reset(poses)
    seconds = time.perf_counter() - t0

    print(f"map={os.path.basename(map_yaml)}")
    print(f"agents={n}")
    print(f"beams={RaceCar.scan_simulator.num_beams}")
    print(f"timestep={TIMESTEP}")
    print(f"integrator={INTEGRATOR.name}")
    print(f"speed={speed}")
    print(f"steer={steer}")
    print(f"warmup_steps={warmup}")
    print(f"warmup_seconds={warmup_s:.3f}")
    print(f"steps={steps}")
    print(f"seconds={seconds:.3f}")
    print(f"steps_per_s={steps / seconds:.1f}")
    print(f"agent_steps_per_s={n * steps / seconds:.1f}")
    print(f"sim_seconds_per_wall_s={steps * TIMESTEP / seconds:.1f}")
    print(f"collision={int(first_collision >= 0)}")
    print(f"first_collision_step={first_collision}")
    print(f"collision_steps={resets}")
    print(f"reset_on_collision={int(reset_on_collision)}")


if __name__ == "__main__":
    main()
