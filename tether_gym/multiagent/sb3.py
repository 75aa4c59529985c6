"""Agents x clusters as one Stable-Baselines3 ``VecEnv``: a shared policy with parameter sharing.

:class:`AgentVecEnv` steps N clusters of one id at once on the batched engine
(:class:`~tether_gym.multiagent.engine.AgentBatch`) and presents each agent of each cluster as
one row: ``num_envs = N * A``, row ``b * A + k`` is agent k of cluster b. Its observation space
is one agent's local observation and its action space one thruster's (3,) command, so one SB3
policy, trained on every row, is the policy of every satellite (parameter sharing). No
SuperSuit: this is the same thin adapter as :class:`tether_gym.sb3.SB3VecEnv`, with the agent
axis folded into the batch::

    from stable_baselines3 import PPO
    from tether_gym.multiagent.sb3 import make_agent_vec_env

    env = make_agent_vec_env("TetherHub-v0", num_envs=16, seed=0)  # 16 clusters x 7 agents = 112 rows
    model = PPO("MlpPolicy", env, device="cpu").learn(100_000)

How it matches SB3's conventions (as :mod:`tether_gym.sb3` does):

* **Autoreset** is same-step: when a cluster's episode ends, every row of the cluster is done,
  and the cluster is reset within the step; each of its rows' infos holds
  ``"terminal_observation"`` (that agent's last local observation) and ``"TimeLimit.truncated"``,
  plus the cluster's scalar info entries (``vibration_energy``, ``end_reason``, ...). Rows of
  clusters that did not end get empty infos.
* **Rewards** are per row: the team reward (every agent of a cluster gets the cluster's reward)
  or the shares (``reward="shares"``).
* **Seeds**: ``seed(s)`` gives cluster b the seed ``s + b`` at the next ``reset()`` (its rows
  share it), so cluster b starts as a single-agent env reset with ``s + b``.
* **The batch is one object**: ``get_attr``/``env_method`` act on the engine once.

An RLlib ``MultiAgentEnv`` can be the same kind of thin layer over :class:`AgentBatch`: the dicts
of :class:`~tether_gym.multiagent.TetherParallelEnv` (``"__all__"`` set from the cluster's flags).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from tether_gym._optional import needs_extra

with needs_extra("train", "the shared-policy SB3 VecEnv of the multi-agent env (AgentVecEnv)"):
    from stable_baselines3.common.vec_env import VecEnv
    from stable_baselines3.common.vec_env.base_vec_env import VecEnvIndices, VecEnvObs, VecEnvStepReturn

from tether_gym.envs.arguments import OBSERVATION_LIMIT, EnvArgumentError, as_real_array
from tether_gym.multiagent.engine import AgentBatch

__all__ = ["AgentVecEnv", "make_agent_vec_env"]

_SCALARS = (bool, int, float, str)


class AgentVecEnv(VecEnv):
    """N clusters x A agents as one SB3 ``VecEnv`` of ``N * A`` rows (see the module docstring).

    Args:
        env_id: a tether-gym id.
        num_envs: N, the number of clusters.
        max_episode_steps: as for ``gym.make`` (default: the id's).
        communication, reward, local_observation_noise: the multi-agent options (see
            :class:`~tether_gym.multiagent.TetherParallelEnv`).
        **kwargs: the id's ``gym.make`` keyword arguments.

    Attributes:
        batch: the engine; ``task``: its batched task; ``num_clusters``: N; ``num_agents``: A.
    """

    def __init__(
        self,
        env_id: str,
        num_envs: int,
        max_episode_steps: int | None = None,
        communication: Any = None,
        reward: str = "team",
        local_observation_noise: float = 0.0,
        **kwargs: Any,
    ) -> None:
        from tether_gym.multiagent import env_arguments

        env_kwargs, steps = env_arguments(env_id, max_episode_steps, **kwargs)
        self.env_id = env_id
        self.batch = AgentBatch(num_envs, env_kwargs, steps, communication, reward, local_observation_noise)
        self.task = self.batch.task
        self.num_clusters = self.batch.num_clusters
        self.num_agents = A = self.batch.num_agents
        self.render_mode = None
        observation_space = spaces.Box(-OBSERVATION_LIMIT, OBSERVATION_LIMIT, (self.batch.layout.size,), np.float32)
        super().__init__(self.num_clusters * A, observation_space, spaces.Box(-1.0, 1.0, (3,), np.float32))
        self._actions: np.ndarray | None = None
        self._clusters = np.arange(self.num_clusters)
        self._action_shape = (self.num_envs, 3)

    @property
    def max_episode_steps(self) -> int | None:
        return self.batch.max_episode_steps

    def seed(self, seed: int | None = None) -> Sequence[int | None]:
        """Schedule the seeds ``seed + b`` of the clusters for the next :meth:`reset` (None: a
        random base seed); returns one per row (the rows of a cluster share its seed)."""
        if seed is None:
            seed = int(np.random.randint(0, 2**31 - 1))
        clusters = self.batch.check_seeds([seed + b for b in range(self.num_clusters)])
        self._seeds = [s for s in clusters for _ in range(self.num_agents)]
        return self._seeds

    def reset(self) -> VecEnvObs:
        """Reset every cluster (with the scheduled seeds, used once); returns (N A, size) rows."""
        scheduled = any(s is not None for s in self._seeds)
        seeds = self._seeds[:: self.num_agents] if scheduled else [None] * self.num_clusters
        if self._options and any(self._options):
            raise EnvArgumentError("AgentVecEnv takes no reset options (exact initial states): use parallel_env")
        self.batch.reset(self._clusters, seeds)
        self._reset_seeds()
        self._reset_options()
        self._actions = None
        return self._rows(self.batch.observations())

    def _rows(self, observations: np.ndarray) -> np.ndarray:
        return observations.reshape(self.num_envs, -1)

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self) -> VecEnvStepReturn:
        """Step every cluster with the (N A, 3) row actions; see the module docstring."""
        if self._actions is None:
            raise RuntimeError("step_wait() called without a pending step_async(actions)")
        actions, self._actions = self._actions, None
        a = as_real_array("actions", actions, f"a {self._action_shape} array of thrust commands in [-1, 1]")
        if a.shape != self._action_shape:
            raise EnvArgumentError(f"actions must have shape {self._action_shape} (one row per agent); got {a.shape}")
        if not np.isfinite(a).all():
            raise EnvArgumentError("actions contain NaN or inf; thrust commands must be finite numbers in [-1, 1]")
        batch = self.batch
        batch.step(batch.joint_actions(a.reshape(self.num_clusters, self.num_agents, 3)))
        rewards = batch.rewards().reshape(-1).astype(np.float32)
        terminated, truncated = batch.terminated(), batch.truncated()
        ended = np.flatnonzero(terminated | truncated)
        observations = batch.observations()
        infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        if ended.size:
            for b in ended.tolist():
                scalars = {k: v for k, v in self.task.info(b).items() if isinstance(v, _SCALARS)}
                timeout = bool(truncated[b] and not terminated[b])
                for k in range(self.num_agents):
                    infos[b * self.num_agents + k] = {
                        **scalars,
                        "terminal_observation": observations[b, k].copy(),
                        "TimeLimit.truncated": timeout,
                    }
            batch.reset(ended, [None] * ended.size)
            observations[ended] = batch.observations(ended)
        dones = np.repeat(terminated | truncated, self.num_agents)
        return self._rows(observations), rewards, dones, infos

    # ------------------------------------------------------------------ the batch as one object
    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """The adapter's (or else the engine's) attribute, once per requested row."""
        value = getattr(self, attr_name) if hasattr(self, attr_name) else getattr(self.batch, attr_name)
        return [value for _ in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        """Set an engine attribute for the whole batch (``indices`` must be None)."""
        if indices is not None:
            raise ValueError(f"set_attr({attr_name!r}) acts on the whole batch: pass indices=None")
        setattr(self.batch, attr_name, value)

    def env_method(
        self, method_name: str, *method_args: Any, indices: VecEnvIndices = None, **method_kwargs: Any
    ) -> list[Any]:
        """Call the task's method once (e.g. ``set_difficulty``); its result once per requested row."""
        targets = list(self._get_indices(indices))
        if not targets:
            return []
        result = getattr(self.task, method_name)(*method_args, **method_kwargs)
        return [result for _ in targets]

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None) -> list[bool]:
        return [False for _ in self._get_indices(indices)]

    def render(self, mode: str | None = None) -> np.ndarray | None:
        warnings.warn("AgentVecEnv does not render; render a single-agent env instead", stacklevel=2)
        return None

    def get_images(self) -> Sequence[np.ndarray | None]:
        warnings.warn("AgentVecEnv does not render; get_images() returns no images", stacklevel=2)
        return [None] * self.num_envs

    def close(self) -> None:
        """Nothing to release: the batch lives in this process."""


def make_agent_vec_env(env_id: str, num_envs: int, seed: int | None = None, **kwargs: Any) -> AgentVecEnv:
    """``AgentVecEnv(env_id, num_envs, **kwargs)`` with ``seed(seed)`` scheduled (cluster b gets
    ``seed + b``; None: a random base seed)."""
    env = AgentVecEnv(env_id, num_envs, **kwargs)
    env.seed(seed)
    return env
