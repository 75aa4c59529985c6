"""The PettingZoo ``ParallelEnv`` of every tether-gym id: one agent per satellite with a thruster."""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium import spaces

from tether_gym._optional import needs_extra

with needs_extra("multiagent", "the PettingZoo multi-agent env (tether_gym.multiagent.parallel_env)"):
    from pettingzoo import ParallelEnv

from tether_gym.envs.arguments import OBSERVATION_LIMIT, EnvArgumentError, check_actions, check_no_render, check_seed
from tether_gym.envs.task import RESET_OPTION_KEYS
from tether_gym.limits import short_repr
from tether_gym.multiagent.engine import AgentBatch

__all__ = ["TetherParallelEnv"]


class TetherParallelEnv(ParallelEnv[str, np.ndarray, np.ndarray]):
    """Decentralised vibration damping: every satellite with a thruster is its own agent.

    Made by :func:`tether_gym.multiagent.parallel_env` (``parallel_env(id, **kwargs)``, the
    keyword arguments of ``gym.make``). The cluster, the dynamics, the reward and the episode
    ends are those of the single-agent env of the same id and arguments: with the team reward
    and the same joint action, ``state()`` and every reward, termination and truncation are
    bit-identical to the single-agent env's observation, reward and end flags.

    **Agents** ``"satellite_<node>"``, one per thruster, in the task's thruster order
    (``possible_agents``). All agents live and end together: when the cluster's episode ends,
    every agent is terminated (a failure) or truncated (the time limit), and ``agents`` becomes
    empty until the next ``reset``.

    **Actions**: a dict with one ``Box(-1, 1, (3,), float32)`` thrust command per live agent, in
    units of its ``max_thrust`` (the single-agent env's commands of that thruster; clipped, and
    with ``thrust_limit="magnitude"`` scaled back to length 1). A missing agent, an unknown
    name, a command of the wrong shape, NaN or inf raises
    :class:`~tether_gym.envs.EnvArgumentError` and leaves the env as it was.

    **Observations** are local: see :mod:`tether_gym.multiagent.engine` for the layout
    (:attr:`layout`): the satellite's cables (direction, neighbour's relative velocity,
    elongation, tension ratio; padded to the id's largest number of cables per agent, with a
    ``present`` flag), its own thrust, and with ``communication`` its partners' measurements,
    ``delay`` steps late.

    **State**: ``state()`` is the single-agent env's observation (``state_space``), for
    centralised critics.

    **Rewards**: ``reward="team"`` (default) gives every agent the single-agent reward;
    ``reward="shares"`` splits each reward term between the agents (weights documented in
    :meth:`~tether_gym.multiagent.engine.AgentBatch.rewards`), the shares summing to the team
    reward.

    **Infos**: every agent's info is the single-agent env's info dict (one shared object per
    step: copy it before changing it).

    Args:
        env_id: the registered id (for the name and ``metadata``).
        max_episode_steps: truncation after this many steps (the id's, unless given).
        communication: None (off, the default), ``{"hops": h}`` (agents within h cables) or
            ``{"range": r}`` (agents within r m in the nominal shape), with optional
            ``"delay": k`` control steps.
        reward: ``"team"`` or ``"shares"``.
        local_observation_noise: std of Gaussian noise on the local observations' measured
            entries, in their units (seeded: a reset seed fixes it; independent of the task's
            draws, so it never changes ``state()``).
        render_mode: must be None (render a single-agent env instead).
        **env_kwargs: the single-agent env's arguments (preset, preset_kwargs, cluster, task
            settings), checked as ``gym.make`` checks them.
    """

    metadata = {"name": "tether_parallel_v0", "render_modes": [], "is_parallelizable": True}

    def __init__(
        self,
        env_id: str,
        max_episode_steps: int | None = None,
        communication: Any = None,
        reward: str = "team",
        local_observation_noise: float = 0.0,
        render_mode: str | None = None,
        **env_kwargs: Any,
    ) -> None:
        check_no_render(
            render_mode,
            "the multi-agent env",
            f"render the single-agent env, gym.make({env_id!r}, render_mode='rgb_array')",
        )
        self.env_id = env_id
        self.batch = AgentBatch(1, env_kwargs, max_episode_steps, communication, reward, local_observation_noise)
        self.render_mode = None
        self.metadata = {**self.metadata, "name": env_id}
        self.task = self.batch.task
        self.cluster = self.task.cluster
        self.layout = self.batch.layout
        self.possible_agents = list(self.batch.graph.names)
        self.agents: list[str] = []
        self._index = {name: k for k, name in enumerate(self.possible_agents)}
        self._observation_space = spaces.Box(-OBSERVATION_LIMIT, OBSERVATION_LIMIT, (self.layout.size,), np.float32)
        self._action_space = spaces.Box(-1.0, 1.0, (3,), np.float32)
        self.state_space = spaces.Box(-OBSERVATION_LIMIT, OBSERVATION_LIMIT, (self.task.observation_size,), np.float32)
        self._zero = np.zeros(1, dtype=np.int64)
        self._info: dict[str, Any] = {}

    def observation_space(self, agent: str) -> spaces.Box:
        """The local observation space (the same object for every agent and call)."""
        self._check_name(agent)
        return self._observation_space

    def action_space(self, agent: str) -> spaces.Box:
        """The (3,) thrust command space (the same object for every agent and call)."""
        self._check_name(agent)
        return self._action_space

    @property
    def max_episode_steps(self) -> int | None:
        return self.batch.max_episode_steps

    def _check_name(self, agent: Any) -> None:
        # A str first: an unhashable name (a list) would raise a bare TypeError in the lookup.
        if not isinstance(agent, str) or agent not in self._index:
            raise EnvArgumentError(f"unknown agent {short_repr(agent)}; the agents are {self.possible_agents}")

    # ------------------------------------------------------------------ API
    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, dict[str, Any]]]:
        """Start an episode, as the single-agent env's ``reset(seed=seed, options=options)``.
        ``options`` may hold ``"positions"``/``"velocities"`` ((n, 3) arrays, m and m/s); other
        keys are warned about and ignored (PettingZoo's API test passes options of its own)."""
        seed = check_seed("seed", seed)
        exact = options
        if isinstance(options, Mapping):
            extra = sorted(set(options) - set(RESET_OPTION_KEYS), key=repr)
            if extra:
                warnings.warn(
                    f"reset options {extra} are not tether-gym options and are ignored; the options are "
                    f"{list(RESET_OPTION_KEYS)}",
                    stacklevel=2,
                )
                exact = {key: value for key, value in options.items() if key in RESET_OPTION_KEYS}
        positions, velocities = self.task.check_reset_state(exact, (self.cluster.num_nodes, 3))
        self.batch.reset(self._zero, [seed], positions, velocities)
        self.agents = list(self.possible_agents)
        self._info = self.task.info(0, stepped=False)
        return self._observations(), {agent: self._info for agent in self.agents}

    def step(
        self, actions: Mapping[str, Any]
    ) -> tuple[
        dict[str, np.ndarray],
        dict[str, float],
        dict[str, bool],
        dict[str, bool],
        dict[str, dict[str, Any]],
    ]:
        """Apply one thrust command per live agent for one control interval."""
        joint = self._joint_action(actions)
        batch = self.batch
        batch.step(joint)
        rewards = batch.rewards()[0].tolist()
        terminated = bool(batch.terminated()[0])
        truncated = bool(batch.truncated()[0])
        self._info = self.task.info(0)
        names = self.agents
        observations = self._observations()
        out = (
            observations,
            dict(zip(names, rewards, strict=True)),
            dict.fromkeys(names, terminated),
            dict.fromkeys(names, truncated),
            {agent: self._info for agent in names},
        )
        if terminated or truncated:
            self.agents = []
        return out

    def _joint_action(self, actions: Any) -> np.ndarray:
        """(1, 3 A) joint action from the agents' dict, checked."""
        if not self.agents:
            raise EnvArgumentError(
                "no live agents (the episode has ended, or the env was never reset): call reset() before step()"
            )
        if not isinstance(actions, Mapping):
            raise EnvArgumentError(
                f"actions must be a dict from agent name to a (3,) thrust command, e.g. "
                f"{{{self.possible_agents[0]!r}: [0.0, 0.0, 0.0], ...}}; got {short_repr(actions)}"
            )
        unknown = [name for name in actions if name not in self._index]
        if unknown:
            raise EnvArgumentError(f"unknown agent(s) {short_repr(unknown)} in actions; the agents are {self.agents}")
        missing = [name for name in self.agents if name not in actions]
        if missing:
            raise EnvArgumentError(
                f"no action for agent(s) {missing}: every live agent needs a (3,) thrust command each step "
                "(send zeros for no thrust)"
            )
        joint = np.empty((1, 3 * len(self.possible_agents)))
        for name, k in self._index.items():
            # The single-agent env's check of its action, per agent.
            joint[0, 3 * k : 3 * k + 3] = check_actions(f"action of {name}", actions[name], (3,), "x, y, z")
        return joint

    def _observations(self) -> dict[str, np.ndarray]:
        local = self.batch.observations()[0]
        return {name: local[k] for name, k in self._index.items()}

    def state(self) -> np.ndarray:
        """The global observation (the single-agent env's, float32, ``state_space``) of the last
        reset or step; a copy."""
        return self.batch.states[0].copy()

    def render(self) -> None:
        """Not supported (``render_mode`` is always None)."""
        warnings.warn("the multi-agent env does not render; render the single-agent env instead", stacklevel=2)

    def close(self) -> None:
        """Nothing to release."""
