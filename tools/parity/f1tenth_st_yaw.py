#!/usr/bin/env python3
"""Steady-cornering yaw rates of f1tenth_gym's single-track model, the golden values of agvrl-sim's
`f1tenth::steady_cornering_yaw_rate_against_f1tenth_gyms_single_track_model` test, and its heading
change braking to a stop with the wheels turned a little, the golden value of
`f1tenth::braking_hard_the_f1tenth_car_turns_in_as_f1tenth_gyms_model_does`.

Two independent routes, which must agree:
1. Closed form (always): the steady state of the linear single-track model with f1tenth_gym's
   published parameters (gym/f110_gym/envs/f110_env.py). At zero longitudinal acceleration its
   tyre forces are mu * C_S * F_z * alpha with F_z,f = m g lr / L and F_z,r = m g lf / L, so the
   understeer gradient is K = (1/C_Sf - 1/C_Sr) / mu (rad per g) and, at front wheel angle delta
   and speed v, yaw rate r = v delta / (L + K v^2 / g). (Kinematic: r = v tan(delta) / L.)
2. Integration (when the f1tenth_gym checkout is present): f1tenth_gym's own
   `vehicle_dynamics_st`, loaded by path from the mirror (its `numba.njit` replaced by the
   identity, so only numpy is needed), integrated by RK4 at constant delta and v for 20 s.

Run: python3 tools/parity/f1tenth_st_yaw.py [PATH/TO/f1tenth_gym checkout or bare git dir]
(default /work/.mirror/f1tenth+f1tenth_gym/repo). Tested with Python 3.12, numpy 2.4.
"""
import math
import os
import subprocess
import sys
import tempfile
import types

P = dict(mu=1.0489, C_Sf=4.718, C_Sr=5.4562, lf=0.15875, lr=0.17145, h=0.074, m=3.74, I=0.04712,
         s_min=-0.4189, s_max=0.4189, sv_min=-3.2, sv_max=3.2, v_switch=7.319, a_max=9.51,
         v_min=-5.0, v_max=20.0)
G = 9.81
CASES = [(3.0, 0.04), (6.0, 0.04), (5.0, 0.1)]  # (speed m/s, front wheel angle rad)
# Braking from speed v0 at a constant deceleration with the wheels held at delta, from straight
# running: (v0 m/s, deceleration m/s^2, front wheel angle rad).
BRAKING = [(9.0, 6.0, 0.01), (9.0, 9.51, 0.01), (9.0, 4.0, 0.01)]


def closed_form(v, delta):
    L = P["lf"] + P["lr"]
    k = (1.0 / P["C_Sf"] - 1.0 / P["C_Sr"]) / P["mu"]
    return v * delta / (L + k * v * v / G), k


def load_gym(src):
    """f1tenth_gym's dynamic_models module, from a checkout or a bare git dir, numba stubbed."""
    rel = "gym/f110_gym/envs/dynamic_models.py"
    if os.path.isfile(os.path.join(src, rel)):
        text = open(os.path.join(src, rel)).read()
    else:
        text = subprocess.run(["git", "-C", src, "show", f"HEAD:{rel}"], check=True,
                              capture_output=True, text=True).stdout
    numba = types.ModuleType("numba")
    numba.njit = lambda *a, **k: (a[0] if a and callable(a[0]) else (lambda f: f))
    sys.modules["numba"] = numba
    path = os.path.join(tempfile.mkdtemp(), "f110_dynamic_models.py")
    open(path, "w").write(text)
    mod = types.ModuleType("f110_dynamic_models")
    mod.__file__ = path
    exec(compile(text, path, "exec"), mod.__dict__)
    return mod


def integrate(dm, v, delta, t_end=20.0, dt=1e-3):
    import numpy as np
    args = tuple(P[k] for k in ["mu", "C_Sf", "C_Sr", "lf", "lr", "h", "m", "I", "s_min", "s_max",
                                "sv_min", "sv_max", "v_switch", "a_max", "v_min", "v_max"])
    x = np.array([0.0, 0.0, delta, v, 0.0, 0.0, 0.0])
    u = np.array([0.0, 0.0])
    f = lambda s: dm.vehicle_dynamics_st(s, u, *args)
    for _ in range(int(t_end / dt)):
        k1 = f(x); k2 = f(x + dt / 2 * k1); k3 = f(x + dt / 2 * k2); k4 = f(x + dt * k3)
        x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return x[5], x[6]


def brake(dm, v0, decel, delta, dt=1e-3):
    """Heading change (rad) and path length (m) of f1tenth_gym's model braking to a stop."""
    import numpy as np
    args = tuple(P[k] for k in ["mu", "C_Sf", "C_Sr", "lf", "lr", "h", "m", "I", "s_min", "s_max",
                                "sv_min", "sv_max", "v_switch", "a_max", "v_min", "v_max"])
    x = np.array([0.0, 0.0, delta, v0, 0.0, 0.0, 0.0])
    u = np.array([0.0, -decel])
    f = lambda s: dm.vehicle_dynamics_st(s, u, *args)
    length = 0.0
    while x[3] > 0.05:
        k1 = f(x); k2 = f(x + dt / 2 * k1); k3 = f(x + dt / 2 * k2); k4 = f(x + dt * k3)
        length += x[3] * dt
        x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return x[4], length


def main():
    src = sys.argv[1] if len(sys.argv) > 1 else "/work/.mirror/f1tenth+f1tenth_gym/repo"
    L = P["lf"] + P["lr"]
    dm = None
    try:
        dm = load_gym(src)
    except Exception as e:  # no checkout: the closed form alone
        print(f"# f1tenth_gym not loaded ({e}); closed form only")
    for v, delta in CASES:
        r, k = closed_form(v, delta)
        kin = v * math.tan(delta) / L
        line = f"v={v} delta={delta}: closed_form_yaw={r:.4f} kinematic_yaw={kin:.4f} K={k:.5f} rad/g"
        if dm is not None:
            ri, beta = integrate(dm, v, delta)
            line += f" f1tenth_gym_st_yaw={ri:.4f} beta={beta:.4f}"
            assert abs(ri - r) / r < 1e-3, "integration and closed form disagree"
        print(line)
    if dm is not None:
        for v0, decel, delta in BRAKING:
            turned, length = brake(dm, v0, decel, delta)
            print(f"braking v0={v0} decel={decel} delta={delta}: f1tenth_gym_st_turned={turned:.4f} rad "
                  f"({math.degrees(turned):.1f} deg) path={length:.3f} m (v0^2/2a {v0 * v0 / 2 / decel:.3f})")


if __name__ == "__main__":
    main()
