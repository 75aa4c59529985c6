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
* **Reset options** are the vector env's: ``set_options({"positions": X, "velocities": V})``
  with (N, n, 3) arrays (m, m/s) gives every cluster an exact initial state.
* **The batch is one object**: ``get_attr``/``set_attr``/``env_method`` act on the engine once.
* **One contract**: every argument is checked by the code that checks
  :class:`~tether_gym.sb3.SB3VecEnv`'s (:class:`~tether_gym.sb3.BatchVecEnv`), so the two
  adapters refuse the same inputs with the same errors.

An RLlib ``MultiAgentEnv`` can be the same kind of thin layer over :class:`AgentBatch`: the dicts
of :class:`~tether_gym.multiagent.TetherParallelEnv` (``"__all__"`` set from the cluster's flags).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from tether_gym._optional import needs_extra

with needs_extra("train", "the shared-policy SB3 VecEnv of the multi-agent env (AgentVecEnv)"):
    from stable_baselines3.common.vec_env.base_vec_env import VecEnvObs, VecEnvStepReturn

from tether_gym.envs.arguments import OBSERVATION_LIMIT, check_no_render
from tether_gym.multiagent.engine import AgentBatch
from tether_gym.sb3 import BatchVecEnv, float32_rewards

__all__ = ["AgentVecEnv", "make_agent_vec_env"]

_SCALARS = (bool, int, float, str)


class AgentVecEnv(BatchVecEnv):
    """N clusters x A agents as one SB3 ``VecEnv`` of ``N * A`` rows (see the module docstring).

    Every argument is checked as :class:`~tether_gym.sb3.SB3VecEnv` checks it, by the same code
    (:class:`~tether_gym.sb3.BatchVecEnv`): seeds, reset options, actions, indices, and the
    names and values of ``get_attr``, ``set_attr`` and ``env_method``. ``get_attr`` reads the
    adapter's attributes, then the engine's, then the task's; ``set_attr`` sets the engine's
    (``max_episode_steps``); ``env_method`` calls the task's (``set_difficulty``).

    Args:
        env_id: a tether-gym id.
        num_envs: N, the number of clusters.
        max_episode_steps: as for ``gym.make`` (default: the id's).
        communication, reward, local_observation_noise: the multi-agent options (see
            :class:`~tether_gym.multiagent.TetherParallelEnv`).
        **kwargs: the id's ``gym.make`` keyword arguments.

    Attributes:
        batch: the engine; ``task``: its batched task; ``cluster``: the nominal cluster;
        ``num_clusters``: N; ``num_agents``: A.
    """

    def __init__(
        self,
        env_id: str,
        num_envs: int,
        max_episode_steps: int | None = None,
        communication: Any = None,
        reward: str = "team",
        local_observation_noise: float = 0.0,
        render_mode: str | None = None,
        **kwargs: Any,
    ) -> None:
        from tether_gym.multiagent import env_arguments

        check_no_render(
            render_mode, "AgentVecEnv", f"render the single-agent env, gym.make({env_id!r}, render_mode='rgb_array')"
        )
        env_kwargs, steps = env_arguments(env_id, max_episode_steps, **kwargs)
        self.env_id = env_id
        self.batch = AgentBatch(num_envs, env_kwargs, steps, communication, reward, local_observation_noise)
        self.task = self.batch.task
        self.cluster = self.task.cluster
        self.num_clusters = self.batch.num_clusters
        self.num_agents = A = self.batch.num_agents
        self.render_mode = None
        observation_space = spaces.Box(-OBSERVATION_LIMIT, OBSERVATION_LIMIT, (self.batch.layout.size,), np.float32)
        super().__init__(
            self.num_clusters * A,
            observation_space,
            spaces.Box(-1.0, 1.0, (3,), np.float32),
            "rows: num_envs clusters x agents; x, y, z",
        )
        self._clusters = np.arange(self.num_clusters)
        self._state_shape = (self.num_clusters, self.cluster.num_nodes, 3)

    @property
    def max_episode_steps(self) -> int | None:
        """The engine's episode limit (set it with ``set_attr("max_episode_steps", n)``)."""
        return self.batch.max_episode_steps

    def _row_seeds(self, seed: int) -> list[int | None]:
        """Cluster b gets ``seed + b``; its rows share it."""
        return [seed + b for b in range(self.num_clusters) for _ in range(self.num_agents)]

    def _reset_batch(self, seeds: list[int | None], options: dict[str, Any] | None) -> VecEnvObs:
        """Reset every cluster with its rows' seed and the options' exact states, if any."""
        positions, velocities = self.task.check_reset_state(options, self._state_shape)
        self.batch.reset(self._clusters, seeds[:: self.num_agents], positions, velocities)
        self.reset_infos = self._scalar_infos(self._clusters, stepped=False)
        return self._rows(self.batch.observations())

    def _rows(self, observations: np.ndarray) -> np.ndarray:
        return observations.reshape(self.num_envs, -1)

    def _scalar_infos(self, clusters: np.ndarray, stepped: bool) -> list[dict[str, Any]]:
        """One dict per row of ``clusters``: its cluster's scalar info entries."""
        rows: list[dict[str, Any]] = []
        for b in clusters.tolist():
            scalars = {k: v for k, v in self.task.info(b, stepped=stepped).items() if isinstance(v, _SCALARS)}
            rows.extend(dict(scalars) for _ in range(self.num_agents))
        return rows

    def _step_batch(self, actions: np.ndarray) -> VecEnvStepReturn:
        """Step every cluster with the checked (N A, 3) row actions; see the module docstring."""
        batch = self.batch
        batch.step(batch.joint_actions(actions.reshape(self.num_clusters, self.num_agents, 3)))
        rewards = float32_rewards(batch.rewards().reshape(-1))
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
            rows = (ended[:, None] * self.num_agents + np.arange(self.num_agents)).reshape(-1)
            for row, info in zip(rows.tolist(), self._scalar_infos(ended, stepped=False), strict=True):
                self.reset_infos[row] = info
        dones = np.repeat(terminated | truncated, self.num_agents)
        return self._rows(observations), rewards, dones, infos

    # ------------------------------------------------------------------ where the batch's parts live
    def _attribute_owners(self) -> tuple[object, ...]:
        return (self, self.batch, self.task)

    def _setting_owner(self) -> object:
        return self.batch

    def _method_owner(self) -> object:
        return self.task


def make_agent_vec_env(env_id: str, num_envs: int, seed: int | None = None, **kwargs: Any) -> AgentVecEnv:
    """``AgentVecEnv(env_id, num_envs, **kwargs)`` with ``seed(seed)`` scheduled (cluster b gets
    ``seed + b``; None: a random base seed)."""
    env = AgentVecEnv(env_id, num_envs, **kwargs)
    env.seed(seed)
    return env
