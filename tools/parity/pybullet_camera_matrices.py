#!/usr/bin/env python3
"""PyBullet's own view and projection matrices for the cameras of agvrl's test
`view_and_projection_matrices_match_pybullet` (crates/sim/tests/camera_images.rs), which keeps this
output as its golden values. Prints all 16 entries of each matrix in PyBullet's order: a flat
column-major OpenGL matrix, entry [c * 4 + r] is row r, column c.

    python3 -m venv /tmp/pyb && /tmp/pyb/bin/pip install pybullet==3.2.7 numpy
    /tmp/pyb/bin/python tools/parity/pybullet_camera_matrices.py

Run with pybullet 3.2.7 (the manylinux wheel, CPython 3.11; it imports numpy). Both functions are
pure: no p.connect() is needed.
"""
import numpy as np
import pybullet as p

# (eye, target, up): the first looks straight down with y up; the second is oblique, z up, as
# a car's camera, so that no entry is trivially 0 or 1.
VIEWS = [
    ([1.0, 2.0, 3.0], [1.0, 2.0, 0.0], [0.0, 1.0, 0.0]),
    ([0.3, -1.2, 0.8], [2.0, 0.5, 0.1], [0.0, 0.0, 1.0]),
]
# (fov_deg, aspect, near, far): the second is agvrl's default camera (80 deg, 0.01-100 m) at 4:3.
PROJECTIONS = [
    (90.0, 2.0, 0.1, 10.0),
    (80.0, 4.0 / 3.0, 0.01, 100.0),
]


def row(m):
    """PyBullet computes in f32: print each entry as the shortest f32 literal that is exactly it."""
    assert all(float(np.float32(x)) == x for x in m)
    return "[" + ", ".join(str(np.float32(x)) for x in m) + "]"


def main():
    for eye, target, up in VIEWS:
        print(f"view eye={eye} target={target} up={up}")
        print(row(p.computeViewMatrix(eye, target, up)))
    for fov, aspect, near, far in PROJECTIONS:
        print(f"projection fov={fov} aspect={aspect!r} near={near} far={far}")
        print(row(p.computeProjectionMatrixFOV(fov, aspect, near, far)))


if __name__ == "__main__":
    main()
