"""agvrl.f110: f1tenth_gym's interface (issue 71). The expected keys, shapes, dtypes and the
step signature are f1tenth_gym's, from its source at github.com/f1tenth/f1tenth_gym:
gym/f110_gym/envs/f110_env.py (`F110Env.reset` / `step` / `_check_done`),
gym/f110_gym/envs/base_classes.py (`Simulator.step`: the observation dict; `RaceCar`: 1080
beams over a 4.7 rad field of view), gym/f110_gym/envs/laser_models.py (`ScanSimulator2D`:
max_range 30 m) and docs/api/obv.rst (what each key holds)."""

import numpy as np
import pytest

from agvrl import f110
from conftest import ROOT

TRACK = ROOT / "assets" / "tracks" / "bean"
CENTRE = np.loadtxt(str(TRACK) + ".csv", delimiter=",", comments="#")

# base_classes.py, Simulator.step, plus f110_env.py's lap_times and lap_counts.
F110_KEYS = {
    "ego_idx",
    "scans",
    "poses_x",
    "poses_y",
    "poses_theta",
    "linear_vels_x",
    "linear_vels_y",
    "ang_vels_z",
    "collisions",
    "lap_times",
    "lap_counts",
}
# Lists of num_agents floats (obv.rst).
F110_LISTS = ("poses_x", "poses_y", "poses_theta", "linear_vels_x", "linear_vels_y", "ang_vels_z")
# np.zeros((num_agents,)) in f110_env.py / base_classes.py: float64 arrays.
F110_ARRAYS = ("collisions", "lap_times", "lap_counts")
# RaceCar(num_beams=1080, fov=4.7), ScanSimulator2D(max_range=30.0).
BEAMS, FOV_RAD, RANGE_M = 1080, 4.7, 30.0


def start_pose(k: int = 0, backwards: bool = False) -> list[float]:
    """The pose on the centre line at point k, heading along it (or against it)."""
    a, b = CENTRE[k], CENTRE[(k + 1) % len(CENTRE)]
    theta = float(np.arctan2(b[1] - a[1], b[0] - a[0]))
    return [float(a[0]), float(a[1]), theta + (np.pi if backwards else 0.0)]


def env(**kw):
    return f110.F110Env(map=str(TRACK), map_ext=".pgm", **kw)


def check_obs(obs, n):
    assert set(obs) == F110_KEYS
    assert isinstance(obs["ego_idx"], int)
    assert isinstance(obs["scans"], list) and len(obs["scans"]) == n
    for s in obs["scans"]:
        assert isinstance(s, np.ndarray) and s.shape == (BEAMS,) and s.dtype == np.float64
    for k in F110_LISTS:
        assert isinstance(obs[k], list) and len(obs[k]) == n, k
        assert all(isinstance(v, float) for v in obs[k]), k
    for k in F110_ARRAYS:
        assert isinstance(obs[k], np.ndarray) and obs[k].shape == (n,) and obs[k].dtype == np.float64, k


def test_observation_and_step_signature_are_f1tenth_gyms():
    e = env(num_agents=2, timestep=0.01, scan_noise=False)
    assert e._sim.lidar == (BEAMS, pytest.approx(FOV_RAD), RANGE_M)
    out = e.reset(poses=np.array([start_pose(0), start_pose(20)]))
    # reset and step return (obs, step_reward, done, info); the reward is the timestep.
    for _ in range(3):
        assert isinstance(out, tuple) and len(out) == 4
        obs, step_reward, done, info = out
        check_obs(obs, 2)
        assert step_reward == 0.01 and isinstance(done, bool) and not done
        assert isinstance(info, dict) and info["checkpoint_done"].shape == (2,)
        assert obs["collisions"].tolist() == [0.0, 0.0]
        assert all(0.0 <= s.min() and s.max() <= RANGE_M for s in obs["scans"])
        out = e.step(np.array([[0.0, 1.0], [0.0, 1.0]]))
    # The cars stand where reset put them; a step advances the world by `timestep`.
    assert obs["poses_x"][1] == pytest.approx(start_pose(20)[0], abs=0.05)
    # reset takes one step with no input, as f1tenth_gym's does: four steps in all.
    assert e.sim_time_s == pytest.approx(4 * 0.01) and e.current_time == pytest.approx(4 * 0.01)
    # The scan sees the car ahead: car 0's straight-ahead beam (the middle one) reads ~2 m.
    assert 1.0 < obs["scans"][0][BEAMS // 2] < 2.2


class PurePursuit:
    """A small pure-pursuit planner over the centre line (the role of waypoint_follow.py's)."""

    def __init__(self, waypoints: np.ndarray, wheelbase_m: float):
        self.wp, self.wheelbase_m = waypoints, wheelbase_m

    def plan(self, x: float, y: float, theta: float, lookahead_m: float, speed_mps: float):
        i = int(np.argmin(np.hypot(self.wp[:, 0] - x, self.wp[:, 1] - y)))
        ahead = np.roll(self.wp, -i, axis=0)
        far = np.hypot(ahead[:, 0] - x, ahead[:, 1] - y) >= lookahead_m
        gx, gy = ahead[int(np.argmax(far))]
        # The goal in the car's frame; the arc through it has curvature 2 y / d^2.
        dx, dy = gx - x, gy - y
        lateral = -np.sin(theta) * dx + np.cos(theta) * dy
        steer = np.arctan(2.0 * self.wheelbase_m * lateral / (dx * dx + dy * dy))
        return speed_mps, steer


def test_waypoint_follow_loop_completes_a_lap():
    e = env(num_agents=1, timestep=0.01)
    planner = PurePursuit(CENTRE, wheelbase_m=0.3)
    obs, step_reward, done, info = e.reset(np.array([start_pose(0)]))
    laptime, steps = 0.0, 0
    while not done and steps < 5000:
        speed, steer = planner.plan(obs["poses_x"][0], obs["poses_y"][0], obs["poses_theta"][0], 0.8, e.top_speed)
        obs, step_reward, done, info = e.step(np.array([[steer, speed]]))
        laptime += step_reward
        steps += 1
        if obs["lap_counts"][0] >= 1:
            break
    assert obs["lap_counts"][0] >= 1, (steps, obs["poses_x"], obs["poses_y"])
    assert obs["collisions"][0] == 0.0 and not done
    # The lap time is the sim time at the lap's end (reset's own step included, as in
    # f1tenth_gym): a lap of the centre line at about the car's top speed.
    lap_m = np.hypot(*np.diff(np.vstack([CENTRE, CENTRE[:1]]), axis=0).T).sum()
    assert obs["lap_times"][0] == pytest.approx(laptime + step_reward, abs=1e-6)
    assert lap_m / e.top_speed < laptime < 1.3 * lap_m / e.top_speed
    assert obs["linear_vels_x"][0] == pytest.approx(e.top_speed, rel=0.15)


def test_cars_driven_into_each_other_collide():
    e = env(num_agents=2, timestep=0.01)
    # Head on along the start straight, 3 m apart.
    obs, _, done, _ = e.reset(np.array([start_pose(0), start_pose(30, backwards=True)]))
    steps = 0
    while not done and steps < 400:
        obs, _, done, _ = e.step(np.array([[0.0, 1.5], [0.0, 1.5]]))
        steps += 1
        if not done:
            assert obs["collisions"].tolist() == [0.0, 0.0]
    assert done and obs["collisions"].tolist() == [1.0, 1.0], (steps, obs["poses_x"], obs["poses_y"])
    # They met between their starts, not at a wall.
    assert CENTRE[0][0] < obs["poses_x"][0] < obs["poses_x"][1] < CENTRE[30][0]
    # The collision flag holds until the next reset.
    obs, _, done, _ = e.step(np.array([[0.0, -1.0], [0.0, -1.0]]))
    assert obs["collisions"].tolist() == [1.0, 1.0]
    obs, _, done, _ = e.reset(np.array([start_pose(0), start_pose(30, backwards=True)]))
    assert obs["collisions"].tolist() == [0.0, 0.0] and not done


def test_f1tenth_gym_keywords_and_make():
    # f1tenth_gym's own vehicle keywords are accepted and ignored, loudly; unknown ones fail.
    with pytest.warns(UserWarning, match="params"):
        e = f110.make("f110_gym:f110-v0", map=str(TRACK), map_ext=".pgm", num_agents=1, params={"mu": 1.0})
    assert e.vehicle == "xtenth_car" and e.num_agents == 1
    with pytest.raises(TypeError, match="nonsense"):
        env(nonsense=1)
    with pytest.raises(FileNotFoundError, match="bean.png"):
        f110.F110Env(map=str(TRACK), map_ext=".png")
    # The steering command is an angle, clamped to the car's limit: past the limit it turns as
    # at the limit, and at the limit about tan(limit) / tan(limit / 2) as fast as at half of it.
    def yaw_rate(steer: float) -> float:
        obs, *_ = e.reset(np.array([start_pose(0)]))
        for _ in range(60):
            obs, *_ = e.step(np.array([[steer, 1.0]]))
        return obs["ang_vels_z"][0]

    full, past, half = yaw_rate(e.steer_max), yaw_rate(10.0), yaw_rate(e.steer_max / 2)
    assert past == pytest.approx(full)
    expected = np.tan(e.steer_max) / np.tan(e.steer_max / 2)
    assert full / half == pytest.approx(expected, rel=0.15), (full, half)
