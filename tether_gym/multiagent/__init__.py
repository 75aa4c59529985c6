"""Decentralised control: every satellite with a thruster is its own agent.

::

    from tether_gym.multiagent import parallel_env

    env = parallel_env("TetherHub-v0", communication={"hops": 1, "delay": 2})
    observations, infos = env.reset(seed=0)
    while env.agents:
        actions = {agent: env.action_space(agent).sample() for agent in env.agents}
        observations, rewards, terminations, truncations, infos = env.step(actions)

* :func:`parallel_env` makes the PettingZoo ``ParallelEnv``
  (:class:`~tether_gym.multiagent.parallel.TetherParallelEnv`) of any registered id.
* :func:`tether_gym.multiagent.sb3.make_agent_vec_env` presents agents x clusters as one SB3
  ``VecEnv`` for a shared policy (parameter sharing), without SuperSuit.
* :class:`~tether_gym.multiagent.engine.AgentBatch` is the batched engine both are thin layers
  over, itself a thin layer over the batched task.

The PettingZoo env needs the ``multiagent`` extra (``pip install "tether-gym[multiagent]"``); the
engine alone (what the decentralised controllers of ``agents`` use) does not.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from tether_gym.multiagent.engine import (
    CABLE_FIELDS,
    REWARD_MODES,
    AgentBatch,
    Communication,
    LocalLayout,
    LocalSensors,
)

if TYPE_CHECKING:
    from tether_gym.multiagent.parallel import TetherParallelEnv

__all__ = [
    "CABLE_FIELDS",
    "REWARD_MODES",
    "AgentBatch",
    "Communication",
    "LocalLayout",
    "LocalSensors",
    "TetherParallelEnv",
    "env_arguments",
    "parallel_env",
]


def env_arguments(
    env_id: str, max_episode_steps: int | None = None, **kwargs: Any
) -> tuple[dict[str, Any], int | None]:
    """The env's keyword arguments as ``gym.make(env_id, **kwargs)`` builds them (the id's
    registered ones, overridden by ``kwargs``) and its episode limit (``max_episode_steps``,
    or the id's; None or -1 means none, as for ``gym.make``), checked by
    :func:`~tether_gym.envs.arguments.check_max_episode_steps`.

    Raises:
        ValueError: ``env_id`` is not a tether-gym id (the message lists them).
    """
    import gymnasium as gym

    from tether_gym.registration import ENV_IDS

    if not isinstance(env_id, str) or env_id not in ENV_IDS:
        raise ValueError(f"unknown env id {env_id!r}; tether-gym ids are {list(ENV_IDS)}")
    spec = gym.spec(env_id)
    from tether_gym.envs.arguments import check_max_episode_steps

    steps = spec.max_episode_steps if max_episode_steps is None else max_episode_steps
    return {**spec.kwargs, **kwargs}, check_max_episode_steps(steps)


def parallel_env(env_id: str, max_episode_steps: int | None = None, **kwargs: Any) -> TetherParallelEnv:
    """The PettingZoo ``ParallelEnv`` of ``env_id``: one agent per satellite with a thruster.

    Args:
        env_id: a tether-gym id, e.g. ``"TetherTetrahedron-v0"``.
        max_episode_steps: as for ``gym.make`` (default: the id's; -1: no limit).
        **kwargs: ``gym.make``'s keyword arguments for the id (``preset_kwargs``, any task setting
            such as ``observation_noise`` or ``thrusters``), checked the same way, and the
            multi-agent options ``communication``, ``reward`` and ``local_observation_noise``
            (see :class:`~tether_gym.multiagent.parallel.TetherParallelEnv`).
    """
    from tether_gym.multiagent.parallel import TetherParallelEnv

    env_kwargs, steps = env_arguments(env_id, max_episode_steps, **kwargs)
    return TetherParallelEnv(env_id, max_episode_steps=steps, **env_kwargs)


def __getattr__(name: str) -> Any:
    # TetherParallelEnv on first use: importing the engine must not need PettingZoo.
    if name == "TetherParallelEnv":
        from tether_gym.multiagent.parallel import TetherParallelEnv

        return TetherParallelEnv
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
