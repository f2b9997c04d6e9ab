"""f1tenth_gym's interface on agvrl's simulator: code written for ``f110_gym`` runs by changing
its import.

    import numpy as np
    from agvrl.f110 import F110Env

    env = F110Env(map="assets/tracks/bean", map_ext=".pgm", num_agents=1, timestep=0.01)
    obs, step_reward, done, info = env.reset(poses=np.array([[0.0, 0.0, 0.0]]))
    while not done:
        obs, step_reward, done, info = env.step(np.array([[steer, speed]]))

``agvrl.f110.make("f110_gym:f110-v0", **kwargs)`` stands in for ``gym.make`` with the same id.

The observation dict, the step reward (the timestep), ``done`` (the ego collided, or every car
finished two laps) and the lap counting are f1tenth_gym's (gym/f110_gym/envs/f110_env.py,
re-derived, not copied). Underneath is agvrl's physics: every car is a rapier body of
``vehicle`` (agvrl's XTENTH-CAR unless set) in one world, so cars and walls collide for real;
a step is one agvrl control period of ``timestep`` seconds (physics substeps of at most 1/120 s);
the speed command is held by the classical racers' speed controller (agvrl's
``CarLimits::throttle``: the drive's steady-state throttle plus a proportional term, braking at
``brake_mps2``). See docs/python.md, "f1tenth_gym's interface".
"""

from __future__ import annotations

import os
import warnings
from typing import Any, Callable

import numpy as np

from agvrl._core import F110Sim

#: The gym id f1tenth_gym registers (``gym.make('f110_gym:f110-v0')``).
ENV_ID = "f110_gym:f110-v0"

#: f1tenth_gym's scan noise: Gaussian, this standard deviation, metres (ScanSimulator2D).
SCAN_NOISE_STD_M = 0.01
#: The finish zone: a car is near its start when its squared distance there is at most this,
#: m^2, after a lateral slack of ``_SLACK_M`` either side of the ego's start heading.
_NEAR_START_M2 = 0.1
_SLACK_M = 2.0
#: Zone changes of two laps (leave and come back, twice).
_TWO_LAPS = 4

# f1tenth_gym's keyword arguments agvrl has no counterpart for: accepted and ignored (with a
# warning), so code that passes them still runs.
_IGNORED = ("params", "integrator", "lidar_dist")


class F110Env:
    """f1tenth_gym's ``F110Env`` (gym 0.19 style: ``reset(poses)`` and ``step(actions)`` return
    ``(obs, step_reward, done, info)``) over agvrl's multi-car simulator.

    ``map``: the map YAML's path without ``.yaml`` (a map_server track, as f1tenth_gym's);
    ``map_ext``: the image's extension (the image beside the YAML must exist; the YAML's
    ``image`` is what loads). ``num_agents`` cars (1 to 8), car ``ego_idx`` the ego;
    ``timestep``: seconds per step; ``vehicle``: an agvrl vehicle name or vehicle TOML (default
    agvrl's XTENTH-CAR); ``seed``: the scan noise's seed (re-drawn from it at every reset, as
    f1tenth_gym does); ``scan_noise``: False for noiseless scans; ``brake_mps2``: the drive's
    braking deceleration (the real car's ESC: 3 m/s^2); ``speed_gain``: the speed controller's
    throttle per m/s of error.
    """

    metadata = {"render.modes": ["human", "human_fast"]}

    def __init__(
        self,
        map: str | os.PathLike[str] | None = None,
        map_ext: str = ".png",
        num_agents: int = 2,
        timestep: float = 0.01,
        vehicle: str | None = None,
        seed: int = 12345,
        ego_idx: int = 0,
        scan_noise: bool = True,
        brake_mps2: float = 3.0,
        speed_gain: float = 1.0,
        **kwargs: Any,
    ) -> None:
        unknown = sorted(set(kwargs) - set(_IGNORED))
        if unknown:
            raise TypeError(f"F110Env got unexpected keyword arguments {unknown}")
        for k in sorted(kwargs):
            warnings.warn(
                f"F110Env: {k!r} is f1tenth_gym's and has no agvrl counterpart; ignored "
                "(the vehicle is agvrl's `vehicle`)",
                stacklevel=2,
            )
        if map is None:
            raise ValueError(
                "F110Env needs map=PATH_WITHOUT_EXT (f1tenth_gym's built-in maps are not shipped; "
                "agvrl's tracks are in assets/tracks, e.g. map='assets/tracks/bean', map_ext='.pgm')"
            )
        if not 0 <= ego_idx < num_agents:
            raise ValueError(f"ego_idx must be in [0, {num_agents}), got {ego_idx}")
        self.seed = seed
        self.num_agents = int(num_agents)
        self.timestep = float(timestep)
        self.ego_idx = int(ego_idx)
        self.scan_noise = bool(scan_noise)
        self._settings = dict(vehicle=vehicle, brake_mps2=brake_mps2, speed_gain=speed_gain)
        self._sim: F110Sim
        self.update_map(map, map_ext)
        self._callbacks: list[Callable[..., Any]] = []
        self._ready = False
        self.current_obs: dict[str, Any] | None = None

    # --- the simulator ---------------------------------------------------------------------

    def update_map(self, map_path: str | os.PathLike[str], map_ext: str) -> None:
        """Load another map (``map_path`` without ``.yaml``); the cars need a ``reset`` after."""
        base = os.fspath(map_path)
        if base.endswith(".yaml"):
            base = base[: -len(".yaml")]
        ext = map_ext if map_ext.startswith(".") else "." + map_ext
        for f in (base + ".yaml", base + ext):
            if not os.path.isfile(f):
                raise FileNotFoundError(f"F110Env: no map file {f}")
        self.map_path, self.map_ext = base + ".yaml", ext
        self._sim = F110Sim(base + ".yaml", self.num_agents, self.timestep, **self._settings)
        self._ready = False

    @property
    def vehicle(self) -> str:
        """The agvrl vehicle the cars are."""
        return self._sim.vehicle

    @property
    def steer_max(self) -> float:
        """The steering limit, rad: steering commands are clamped to +-this."""
        return self._sim.steer_max

    @property
    def top_speed(self) -> float:
        """The car's top speed at full throttle on flat ground, m/s."""
        return self._sim.top_speed

    # --- f1tenth_gym's API ----------------------------------------------------------------

    def reset(self, poses: Any) -> tuple[dict[str, Any], float, bool, dict[str, Any]]:
        """Put the cars at ``poses`` ((num_agents, 3): x, y, theta) and take one step with no
        input, as f1tenth_gym does: ``(obs, step_reward, done, info)``."""
        poses = np.asarray(poses, dtype=np.float64).reshape(self.num_agents, 3)
        self._sim.reset(np.ascontiguousarray(poses))
        self._rng = np.random.default_rng(self.seed)
        self.current_time = 0.0
        self.start_xs, self.start_ys = poses[:, 0].copy(), poses[:, 1].copy()
        self.start_thetas = poses[:, 2].copy()
        t = -self.start_thetas[self.ego_idx]
        self._start_rot = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
        self.near_starts = np.ones(self.num_agents, dtype=bool)
        self.toggle_list = np.zeros(self.num_agents)
        self.lap_counts = np.zeros(self.num_agents)
        self.lap_times = np.zeros(self.num_agents)
        self._ready = True
        return self.step(np.zeros((self.num_agents, 2)))

    def step(self, action: Any) -> tuple[dict[str, Any], float, bool, dict[str, Any]]:
        """One step of ``timestep`` seconds; ``action`` is (num_agents, 2): steering angle (rad,
        clamped to the car's limit) and speed (m/s). Returns ``(obs, step_reward, done, info)``."""
        if not self._ready:
            raise RuntimeError("F110Env: call reset(poses) before step")
        a = np.ascontiguousarray(np.asarray(action, dtype=np.float64).reshape(self.num_agents, 2))
        scans, poses, vels, collisions, self.sim_time_s = self._sim.step(a)
        if self.scan_noise:
            scans = scans + self._rng.normal(0.0, SCAN_NOISE_STD_M, size=scans.shape)
        self.current_time += self.timestep
        self.poses_x, self.poses_y = poses[:, 0], poses[:, 1]
        self.collisions = collisions
        done, finished = self._check_done()
        obs = {
            "ego_idx": self.ego_idx,
            "scans": list(scans),
            "poses_x": list(poses[:, 0]),
            "poses_y": list(poses[:, 1]),
            "poses_theta": list(poses[:, 2]),
            "linear_vels_x": list(vels[:, 0]),
            "linear_vels_y": list(vels[:, 1]),
            "ang_vels_z": list(vels[:, 2]),
            "collisions": collisions,
            "lap_times": self.lap_times.copy(),
            "lap_counts": self.lap_counts.copy(),
        }
        self.current_obs = obs
        return obs, self.timestep, done, {"checkpoint_done": finished}

    def _check_done(self) -> tuple[bool, np.ndarray]:
        """f1tenth_gym's finish zone, in our words: each car's offset from its own start, turned
        into the ego's start heading; along the heading it counts in full, across it only beyond
        a slack of 2 m either side. A car is near its start while the squared offset is at most
        0.1 m^2; every change of near/away is a toggle, two toggles a lap, and a car's lap time
        runs until its fourth toggle. Done when the ego collided or every car made two laps."""
        d = self._start_rot @ np.stack((self.poses_x - self.start_xs, self.poses_y - self.start_ys))
        along, across = d[0], d[1]
        across = np.where(across > _SLACK_M, across - _SLACK_M, np.where(across < -_SLACK_M, -_SLACK_M - across, 0.0))
        near = along**2 + across**2 <= _NEAR_START_M2
        changed = near != self.near_starts
        self.toggle_list += changed
        self.near_starts = near
        self.lap_counts = self.toggle_list // 2
        running = self.toggle_list < _TWO_LAPS
        self.lap_times[running] = self.current_time
        finished = self.toggle_list >= _TWO_LAPS
        return bool(self.collisions[self.ego_idx]) or bool(np.all(finished)), finished

    # --- rendering: agvrl has no pyglet window; these keep f1tenth_gym code running ----------

    def add_render_callback(self, callback_func: Callable[..., Any]) -> None:
        """Kept for f1tenth_gym code; agvrl draws no window, so callbacks are never called."""
        self._callbacks.append(callback_func)

    def render(self, mode: str = "human") -> None:
        """Does nothing: agvrl has no pyglet window (``agvrl view`` and rerun show races)."""
        if mode not in self.metadata["render.modes"]:
            raise ValueError(f"render mode must be one of {self.metadata['render.modes']}, got {mode!r}")

    def update_params(self, params: dict[str, Any], index: int = -1) -> None:
        """f1tenth_gym's vehicle parameters have no agvrl counterpart: pick ``vehicle`` instead."""
        raise NotImplementedError("F110Env: the cars are agvrl vehicles; choose one with vehicle=NAME")

    def close(self) -> None:
        """Nothing to release."""


def make(env_id: str = ENV_ID, **kwargs: Any) -> F110Env:
    """``gym.make('f110_gym:f110-v0', **kwargs)``'s stand-in."""
    if env_id.split(":")[-1] != "f110-v0":
        raise ValueError(f"unknown env id {env_id!r}: agvrl.f110 provides {ENV_ID!r}")
    return F110Env(**kwargs)
