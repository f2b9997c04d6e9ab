#!/usr/bin/env python3
"""Draw a race track as a ROS map_server map (PGM + YAML), the way the shipped tracks in
assets/tracks/ were made: a closed Catmull-Rom spline through control points is the centre line,
free space lies within half the width of it, walls of a fixed thickness beyond, unknown (205)
outside. The map frame's origin is the start, heading +x.

    tools/make-track.py NAME OUT_DIR [--csv]

--csv also writes NAME.csv (the centre line, x, y in metres); without it agvrl traces the centre
line through the free space."""

import argparse
import math
import os

import numpy as np

RES = 0.05  # metres per pixel
WALL_M = 0.15  # wall thickness
MARGIN_M = 1.0  # unknown border around the walls

# Control points (metres) and width (metres) of each shipped track. The first point is the
# start; the second gives the racing direction.
TRACKS = {
    # A 2.4 m wide bean: a long straight, a sharp kink between two slow corners, fast sweepers.
    "bean": (
        2.4,
        [(0, 0), (8, 0), (14, 0.5), (17.5, 3.5), (16.5, 8), (12, 8.5), (9, 6.5), (6, 8.5),
         (2, 11), (-4, 11), (-8.5, 8), (-8, 3.5), (-5, 0.6)],
    ),
    # A 3 m wide sprint track with two long straights joined by fast sweepers: room to pass.
    "sweepers": (
        3.0,
        [(0, 0), (10, 0), (18, 1.5), (22, 6), (20, 11), (12, 13), (4, 12.5), (-4, 14),
         (-10, 11), (-11, 5), (-7, 1)],
    ),
}


def catmull_rom(points, samples_per_seg=200):
    """Dense points of the closed centripetal Catmull-Rom spline through `points`."""
    p = np.asarray(points, dtype=float)
    n = len(p)
    out = []
    for i in range(n):
        p0, p1, p2, p3 = p[(i - 1) % n], p[i], p[(i + 1) % n], p[(i + 2) % n]

        def tj(ti, a, b):
            return ti + np.linalg.norm(b - a) ** 0.5

        t0 = 0.0
        t1 = tj(t0, p0, p1)
        t2 = tj(t1, p1, p2)
        t3 = tj(t2, p2, p3)
        for t in np.linspace(t1, t2, samples_per_seg, endpoint=False):
            a1 = (t1 - t) / (t1 - t0) * p0 + (t - t0) / (t1 - t0) * p1
            a2 = (t2 - t) / (t2 - t1) * p1 + (t - t1) / (t2 - t1) * p2
            a3 = (t3 - t) / (t3 - t2) * p2 + (t - t2) / (t3 - t2) * p3
            b1 = (t2 - t) / (t2 - t0) * a1 + (t - t0) / (t2 - t0) * a2
            b2 = (t3 - t) / (t3 - t1) * a2 + (t - t1) / (t3 - t1) * a3
            out.append((t2 - t) / (t2 - t1) * b1 + (t - t1) / (t2 - t1) * b2)
    return np.array(out)


def resample(line, step):
    """Points every `step` metres along the closed polyline `line`."""
    closed = np.vstack([line, line[:1]])
    seg = np.linalg.norm(np.diff(closed, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    targets = np.arange(0.0, s[-1], step)
    x = np.interp(targets, s, closed[:, 0])
    y = np.interp(targets, s, closed[:, 1])
    return np.stack([x, y], axis=1)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("name", choices=sorted(TRACKS))
    ap.add_argument("out_dir")
    ap.add_argument("--csv", action="store_true", help="also write NAME.csv, the centre line")
    a = ap.parse_args()
    width, ctrl = TRACKS[a.name]
    dense = catmull_rom(ctrl)
    lo = dense.min(axis=0) - width / 2 - WALL_M - MARGIN_M
    hi = dense.max(axis=0) + width / 2 + WALL_M + MARGIN_M
    w, h = (int(math.ceil((hi[0] - lo[0]) / RES)), int(math.ceil((hi[1] - lo[1]) / RES)))
    # Pixel centres in the world; image row 0 is the top (largest y).
    xs = lo[0] + (np.arange(w) + 0.5) * RES
    ys = lo[1] + (h - np.arange(h) - 0.5) * RES
    gx, gy = np.meshgrid(xs, ys)
    px = np.stack([gx.ravel(), gy.ravel()], axis=1)
    d = np.full(len(px), np.inf)
    fine = resample(dense, RES / 2)
    for k in range(0, len(fine), 256):
        c = fine[k : k + 256]
        dd = np.sqrt(((px[:, None, :] - c[None, :, :]) ** 2).sum(axis=2)).min(axis=1)
        d = np.minimum(d, dd)
    img = np.full(len(px), 205, dtype=np.uint8)
    img[d < width / 2] = 254
    img[(d >= width / 2) & (d < width / 2 + WALL_M)] = 0
    img = img.reshape(h, w)
    os.makedirs(a.out_dir, exist_ok=True)
    base = os.path.join(a.out_dir, a.name)
    with open(base + ".pgm", "wb") as f:
        f.write(b"P5\n%d %d\n255\n" % (w, h))
        f.write(img.tobytes())
    with open(base + ".yaml", "w") as f:
        f.write(
            f"image: {a.name}.pgm\nresolution: {RES}\norigin: [{lo[0]:.3f}, {lo[1]:.3f}, 0.0]\n"
            "negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n"
        )
    if a.csv:
        with open(base + ".csv", "w") as f:
            f.write("# x_m, y_m\n")
            for x, y in resample(dense, 0.1):
                f.write(f"{x:.3f}, {y:.3f}\n")
    lap = np.linalg.norm(np.diff(np.vstack([dense, dense[:1]]), axis=0), axis=1).sum()
    print(f"track={a.name} lap_m={lap:.1f} width_m={width} image_px={w}x{h}")


if __name__ == "__main__":
    main()
