"""agvrl from Python: every agvrl env as a Gymnasium env and vector env, trained policies,
and the Rust trainer.

    import agvrl
    env = agvrl.make("racing-oval")                 # a gymnasium.Env
    envs = agvrl.make_vec("racing-oval", 8)         # a gymnasium.vector.VectorEnv (Rust VecEnv)
    policy = agvrl.Policy.load("runs/x/policy.agvrl")
    r = agvrl.replay("drive", "runs/x/policy.agvrl")   # a recorded bag through the policy
    run = agvrl.train("configs/default.toml")       # same run directory as `agvrl train`
    race = agvrl.make_multi("racing-duel")          # a pettingzoo.ParallelEnv (needs pettingzoo)

Importing the package registers every env with Gymnasium as ``agvrl/<id>-v0``.
"""

from typing import Any

from agvrl._core import TERMINATION_CAUSES, env_ids as _env_ids, multi_env_ids as _multi_env_ids
from agvrl.bag import Bag, Replay, read_bag, replay
from agvrl.env import AgvrlEnv, make
from agvrl.policy import Policy
from agvrl.racer import Racer
from agvrl.training import RunResult, train
from agvrl.vector import AgvrlVectorEnv, make_vec

#: Every env id, as ``agvrl envs`` lists them.
ENV_IDS: tuple[str, ...] = tuple(_env_ids())
#: The multi-agent env ids (``make_multi``).
MULTI_ENV_IDS: tuple[str, ...] = tuple(_multi_env_ids())


def _multi(name: str):
    """``agvrl.multi``'s ``name``; the module needs PettingZoo."""
    try:
        from agvrl import multi
    except ModuleNotFoundError as e:
        if e.name != "pettingzoo":
            raise
        raise ModuleNotFoundError(
            f"agvrl.{name} needs PettingZoo: pip install 'pettingzoo>=1.24'", name="pettingzoo"
        ) from e
    return getattr(multi, name)


def make_multi(env_id: str, **env_config: Any):
    """A race of several cars as a ``pettingzoo.ParallelEnv`` (see ``agvrl.multi``); needs
    the ``pettingzoo`` package (``pip install agvrl[multi]``)."""
    return _multi("make_multi")(env_id, **env_config)


def make_race_vec(env_id: str, num_races: int, **env_config: Any):
    """``num_races`` races as a ``gymnasium.vector.VectorEnv`` with a row per car, for training
    one shared policy on every car (see ``agvrl.multi.AgvrlRaceVectorEnv``); needs
    ``pettingzoo``, as ``make_multi``."""
    return _multi("make_race_vec")(env_id, num_races, **env_config)


def _register() -> None:
    import gymnasium

    for env_id in ENV_IDS:
        name = f"agvrl/{env_id}-v0"
        if name in gymnasium.registry:
            continue
        gymnasium.register(
            id=name,
            entry_point="agvrl.env:_entry_point",
            vector_entry_point="agvrl.vector:_vector_entry_point",
            kwargs={"env_id": env_id},
        )


_register()

__all__ = [
    "ENV_IDS",
    "MULTI_ENV_IDS",
    "TERMINATION_CAUSES",
    "AgvrlEnv",
    "AgvrlVectorEnv",
    "Bag",
    "Policy",
    "Racer",
    "Replay",
    "RunResult",
    "make",
    "make_multi",
    "make_race_vec",
    "make_vec",
    "read_bag",
    "replay",
    "train",
]
