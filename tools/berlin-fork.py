#!/usr/bin/env python3
"""What XTENTH-CAR's shipped LiDAR sees at berlin's fork, from f1tenth_gym's map image.

    tools/berlin-fork.py MAPS/berlin.yaml [FOV_DEG]

berlin (f1tenth_gym 4fdb9c7) runs north up a 4 m channel; the way on turns left (west) between
two thin walls and round the upper one's tip at x = -4.1 m, and straight ahead lies a dead-end
bay. For poses heading north in the channel this prints whether a full-lock left turn started
there clears the walls (the car's body swept along the arc) and what the 90-degree, 100-ray,
12 m scan shows: how many rays reach past the upper wall's tip (the way on) and the free length
straight ahead. FOV_DEG (default 90, the shipped scan) widens the scan at the same 0.9-degree
spacing. Occupancy is the map's own rule (occupied above occupied_thresh).
"""

import math
import sys
from pathlib import Path

from PIL import Image

WHEELBASE_M = 0.33  # assets/vehicles/xtenth_car.urdf
MAX_STEER_RAD = 0.36  # assets/vehicles/xtenth_car.toml
LIDAR_AHEAD_M = 0.33  # the scan's origin ahead of the rear axle
HALF_WIDTH_M = 0.2
RAY_SPACING_DEG, RANGE_M = 90.0 / 99, 12.0
WAY_ON_X_M = -4.3  # west of the upper thin wall's tip
LOWER_WALL = ((-3.8, -7.0), (-1.6, -5.7))  # the lower thin wall, its root to its tip


def load(yaml_path):
    meta = {}
    for line in Path(yaml_path).read_text().splitlines():
        if ":" in line:
            k, v = line.split(":", 1)
            meta[k.strip()] = v.strip()
    img = Image.open(Path(yaml_path).parent / meta["image"]).convert("L")
    origin = [float(v) for v in meta["origin"].strip("[]").split(",")]
    res, thresh = float(meta["resolution"]), float(meta["occupied_thresh"])
    w, h = img.size
    px = img.load()

    def occupied(x, y):
        i, j = int((x - origin[0]) / res), h - 1 - int((y - origin[1]) / res)
        if not (0 <= i < w and 0 <= j < h):
            return True
        return (255 - px[i, j]) / 255.0 > thresh

    return occupied


def main():
    if len(sys.argv) not in (2, 3):
        sys.exit("usage: tools/berlin-fork.py MAPS/berlin.yaml [FOV_DEG]")
    occupied = load(sys.argv[1])
    fov = float(sys.argv[2]) if len(sys.argv) == 3 else 90.0
    n_rays = round(fov / RAY_SPACING_DEG) + 1
    radius = WHEELBASE_M / math.tan(MAX_STEER_RAD)

    def cast(x, y, a):
        r = 0.0
        while r < RANGE_M and not occupied(x + r * math.cos(a), y + r * math.sin(a)):
            r += 0.01
        return min(r, RANGE_M)

    def body_hits(x, y, yaw):
        c, s = math.cos(yaw), math.sin(yaw)
        for k in range(11):
            u = -0.08 + 0.05 * k
            for v in (-HALF_WIDTH_M, -HALF_WIDTH_M / 2, 0.0, HALF_WIDTH_M / 2, HALF_WIDTH_M):
                if occupied(x + u * c - v * s, y + u * s + v * c):
                    return True
        return False

    def in_corridor(x, y):
        (x0, y0), (x1, y1) = LOWER_WALL
        return y > y0 + (x - x0) * (y1 - y0) / (x1 - x0)

    def left_turn_clears(x, y):
        # Full lock from heading north round (x - R, y), through 150 degrees (to west-south-west),
        # heading west above the lower thin wall: into the way on, not back down the channel.
        if not in_corridor(x - radius, y + radius):
            return False
        for k in range(0, 151, 2):
            t = math.radians(k)
            if body_hits(x - radius + radius * math.cos(t), y + radius * math.sin(t), math.pi / 2 + t):
                return False
        return True

    print(f"turning_radius_m={radius:.2f} fov_deg={fov:g} rays={n_rays}")
    for x in (-1.5, -1.0, -0.5):
        ys = [round(-7.5 + 0.1 * i, 1) for i in range(31)]
        free = [y for y in ys if not body_hits(x, y, math.pi / 2)]
        window = [y for y in free if left_turn_clears(x, y)]
        runs = []
        for y in window:
            if runs and abs(y - runs[-1][1] - 0.1) < 1e-6:
                runs[-1][1] = y
            else:
                runs.append([y, y])
        span = ",".join(f"{a}..{b}" for a, b in runs) or "none"
        print(f"x={x} turn_window_y={span}")
        for y in free[::5]:
            lx, ly = x, y + LIDAR_AHEAD_M
            past_tip = 0
            for k in range(n_rays):
                a = math.pi / 2 + math.radians(-fov / 2 + fov * k / (n_rays - 1))
                if lx + cast(lx, ly, a) * math.cos(a) < WAY_ON_X_M:
                    past_tip += 1
            print(f"  y={y} rays_past_tip={past_tip} ahead_m={cast(lx, ly, math.pi / 2):.1f}")


if __name__ == "__main__":
    main()
