"""The native vector environment: N clusters stepped together by the batched core."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from tether_gym.cluster import Cluster
from tether_gym.envs.arguments import (
    OBSERVATION_LIMIT,
    EnvArgumentError,
    check_actions,
    check_max_episode_steps,
    check_no_render,
    check_num_envs,
    check_seed,
)
from tether_gym.envs.contract import END_REASONS, REWARD_TERM_KEYS
from tether_gym.envs.task import task_from_arguments
from tether_gym.limits import is_whole_number

__all__ = ["TetherClusterVectorEnv"]

#: Info keys that exist only after a step (a reset's info lacks them, as in the single env).
STEP_KEYS = (
    "substeps",
    "step_min",
    "step_max",
    "simulator_status",
    "peak_tension",
    *REWARD_TERM_KEYS,
    "end_reason",
)

#: The autoreset modes the native vector env implements (Gymnasium's ``DISABLED`` is not one).
AUTORESET_MODES = (AutoresetMode.SAME_STEP, AutoresetMode.NEXT_STEP)


def parse_autoreset_mode(mode: AutoresetMode | str) -> AutoresetMode:
    """``mode`` as an :class:`~gymnasium.vector.AutoresetMode`: the enum itself, its value
    (``"SameStep"``, ``"NextStep"``, as Gymnasium's ``SyncVectorEnv`` accepts) or its name in
    any case (``"same_step"``, ``"NEXT_STEP"``). Anything else, and ``DISABLED``, raises
    :class:`~tether_gym.envs.EnvArgumentError`."""
    names = {m.value.lower(): m for m in AutoresetMode} | {m.name.lower(): m for m in AutoresetMode}
    parsed = mode if isinstance(mode, AutoresetMode) else names.get(mode.lower()) if isinstance(mode, str) else None
    if parsed is AutoresetMode.DISABLED:
        raise EnvArgumentError(
            "autoreset_mode DISABLED is not supported by the native vector env (a sub-env would have to be reset "
            "through reset(options={'reset_mask': ...})); use AutoresetMode.NEXT_STEP or AutoresetMode.SAME_STEP"
        )
    if parsed is None:
        raise EnvArgumentError(
            f"autoreset_mode must be a gymnasium.vector.AutoresetMode or one of "
            f"{[m.value for m in AUTORESET_MODES] + [m.name.lower() for m in AUTORESET_MODES]}; got {mode!r}"
        )
    return parsed


class TetherClusterVectorEnv(VectorEnv):
    """N independent :class:`~tether_gym.envs.TetherClusterEnv` tasks, stepped as one batch.

    This is what ``gym.make_vec(id, num_envs=N)`` returns for every tether-gym id. The dynamics,
    observation, reward and end flags are those of the single env: each sub-env gives the same
    bits as a single env seeded the same way. The sub-envs differ from each other in these ways:
    - **Seeds.** Sub-env i is seeded with ``seed + i`` (or with ``seed[i]`` for a list).
    - **Sub-steps.** Each sub-env sub-steps at its own critical step.
    - **Divergence.** A sub-env that diverges or ends leaves the others untouched.

    **Autoreset** follows the ``autoreset_mode`` argument; ``metadata["autoreset_mode"]`` says
    which mode is in force. With ``NEXT_STEP`` (the default, as in Gymnasium's own vector envs,
    whose wrappers and RLlib's env runners expect it), ``step`` returns the ended sub-env's last
    observation and info as they are; the *next* ``step`` ignores that sub-env's action and
    resets it, returning the new episode's first observation, reward 0,
    ``terminated = truncated = False`` and the info of a reset.

    With ``SAME_STEP``, a sub-env that terminates or is truncated is reset within the same
    ``step``:
    - the returned observation is the new episode's first observation;
    - ``infos["final_obs"]`` (an object array) holds the last observation of the old episode;
    - ``infos["final_info"]`` (a dict of arrays) holds its last info;
    - ``infos["_final_obs"]`` and ``infos["_final_info"]`` mark which sub-envs ended.

    Same-step wastes no step of the batch on resets, and it is what Stable-Baselines3 expects:
    the SB3 adapter (:func:`tether_gym.sb3.make_sb3_vec_env`) and the project's evaluation code
    ask for it, ``gym.make_vec(id, num_envs=N, autoreset_mode=AutoresetMode.SAME_STEP)``.
    Gymnasium's vector wrappers (``RecordEpisodeStatistics``, ``NormalizeObservation``,
    ``NormalizeReward``, ``ClipAction``) need next-step, the default.

    Infos follow Gymnasium's vector layout: every key holds an (N, ...) array, and a boolean
    ``"_key"`` array marks the sub-envs that have it. A sub-env that was just reset has only the
    keys of a reset's info. ``end_reason`` is a string array.

    Args:
        num_envs: N.
        max_episode_steps: truncation after this many steps (``gym.make_vec`` passes the id's);
            None: never. Checked whenever it is set (also through SB3's ``set_attr``).
        render_mode: must be None (the native vector env does not render).
        autoreset_mode: ``AutoresetMode.NEXT_STEP`` (default) or ``AutoresetMode.SAME_STEP``, or
            their string values (``"SameStep"``, ``"NextStep"``) or names (``"same_step"``).
            ``DISABLED`` is not supported.
        preset, preset_kwargs, cluster, **task: as for :class:`~tether_gym.envs.TetherClusterEnv`.
    """

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}

    def __init__(
        self,
        num_envs: int = 1,
        preset: str = "tetrahedron",
        preset_kwargs: Mapping[str, Any] | None = None,
        cluster: Cluster | None = None,
        max_episode_steps: int | None = None,
        render_mode: str | None = None,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        **task: Any,
    ) -> None:
        mode = parse_autoreset_mode(autoreset_mode)
        check_no_render(
            render_mode,
            "the native vector env",
            "render a single env, gym.make(id, render_mode='rgb_array'), or use gym.make_vec(..., "
            "vectorization_mode='sync')",
        )
        self.num_envs = check_num_envs(num_envs)
        self.max_episode_steps = max_episode_steps  # checked by the property
        self.task = task_from_arguments(self.num_envs, preset, preset_kwargs, cluster, **task)
        self.cluster = self.task.cluster
        self.render_mode = None
        self.single_action_space = spaces.Box(-1.0, 1.0, (self.task.action_size,), np.float32)
        self.single_observation_space = spaces.Box(
            -OBSERVATION_LIMIT, OBSERVATION_LIMIT, (self.task.observation_size,), np.float32
        )
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self._rngs: list[np.random.Generator] = [seeding.np_random()[0] for _ in range(self.num_envs)]
        self._all = np.arange(self.num_envs)
        self._episode_steps = np.zeros(self.num_envs, dtype=np.int64)
        self._action_shape = (self.num_envs, self.task.action_size)
        self._reason_names = np.array(END_REASONS)
        self._running_names = self._reason_names[np.zeros(self.num_envs, dtype=np.int64)]
        # Per instance: the class attribute is only the default mode.
        self.metadata = {**type(self).metadata, "autoreset_mode": mode}
        #: Next-step mode: the sub-envs whose episode ended in the last step, reset by the next one.
        self._autoreset = np.zeros(self.num_envs, dtype=np.bool_) if mode is AutoresetMode.NEXT_STEP else None

    @property
    def max_episode_steps(self) -> int | None:
        """Truncation after this many steps of a sub-env's episode (None: never)."""
        return self._max_episode_steps

    @max_episode_steps.setter
    def max_episode_steps(self, steps: int | None) -> None:
        # Checked on every assignment (SB3's set_attr too), so a bad value never reaches step().
        self._max_episode_steps = check_max_episode_steps(steps)

    # ------------------------------------------------------------------ API
    def reset(
        self, *, seed: int | Sequence[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset every sub-env. ``seed``: an int >= 0 (sub-env i gets ``seed + i``), a list of N
        seeds (ints >= 0) or Nones, or None (keep the generators). ``options``: ``positions``
        and/or ``velocities``, (N, n, 3) arrays in m and m/s, for exact initial conditions.

        Seeds and options are checked before anything changes: a bad one raises
        :class:`~tether_gym.envs.EnvArgumentError` and leaves every sub-env as it was."""
        seeds = self._seeds(seed)
        positions, velocities = self.task.check_reset_state(options, (self.num_envs, self.cluster.num_nodes, 3))
        for i, value in enumerate(seeds):
            if value is not None:
                self._rngs[i] = seeding.np_random(value)[0]
        self.task.reset(self._rngs, self._all, positions, velocities)
        self._episode_steps[:] = 0
        if self._autoreset is not None:
            self._autoreset[:] = False
        observation = self.task.observe(self._rngs)
        return observation, self._infos(stepped=None)

    def _seeds(self, seed: Any) -> list[int | None]:
        """The seed of each sub-env (None: keep its generator) from ``reset``'s ``seed``, checked."""
        if seed is None:
            return [None] * self.num_envs
        if is_whole_number(seed):
            first = check_seed("seed", seed)
            assert first is not None  # a whole number gives an int (or an error)
            return [first + i for i in range(self.num_envs)]
        if not isinstance(seed, (list, tuple, np.ndarray)) or (isinstance(seed, np.ndarray) and seed.ndim != 1):
            raise EnvArgumentError(
                f"seed must be an int >= 0 (sub-env i gets seed + i), a list of {self.num_envs} seeds (ints >= 0 or "
                f"None), or None; got {seed!r}"
            )
        seeds = list(seed.tolist() if isinstance(seed, np.ndarray) else seed)
        if len(seeds) != self.num_envs:
            raise EnvArgumentError(f"seed must be an int or a list of {self.num_envs} seeds; got {len(seeds)} seeds")
        return [check_seed(f"seed[{i}]", value) for i, value in enumerate(seeds)]

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        a = check_actions("actions", actions, self._action_shape, "num_envs, 3 per thruster")
        if self._autoreset is not None:
            return self._step_next_step(a, self._autoreset)
        task = self.task
        task.step(np.ascontiguousarray(a), rngs=self._rngs)
        self._episode_steps += 1
        rewards = task.rewards()
        terminated = task.terminated()
        truncated = self._truncated()
        observation = task.observe(self._rngs)
        done = terminated | truncated
        if not done.any():
            return observation, rewards, terminated, truncated, self._infos(stepped=np.ones(self.num_envs, bool))
        ended = np.flatnonzero(done)
        final_info = self._infos(stepped=np.ones(self.num_envs, bool), rows=done)
        final_obs = np.full(self.num_envs, None, dtype=object)
        for i in ended:
            final_obs[i] = observation[i].copy()
        task.reset([self._rngs[i] for i in ended], ended)
        self._episode_steps[ended] = 0
        observation[ended] = task.observe([self._rngs[i] for i in ended], ended)
        infos = self._infos(stepped=~done)
        infos.update(final_obs=final_obs, _final_obs=done.copy(), final_info=final_info, _final_info=done.copy())
        return observation, rewards, terminated, truncated, infos

    def _truncated(self) -> np.ndarray:
        """(N,) bool: the sub-envs whose episode has reached ``max_episode_steps``."""
        if self._max_episode_steps is None:
            return np.zeros(self.num_envs, dtype=np.bool_)
        return self._episode_steps >= self._max_episode_steps

    def _step_next_step(
        self, a: np.ndarray, pending: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """:meth:`step` in next-step autoreset mode, on checked actions ``a``: the sub-envs in
        ``pending`` (whose episode ended in the last step) are reset instead of stepped, the
        others step; the sub-envs that end now are pending for the next call.

        The order of work per sub-env is that of a single env (step, observe; or reset, observe),
        each drawing only from its own generator, so every sub-env gives a single env's bits."""
        task = self.task
        stepped = ~pending
        any_pending = bool(pending.any())
        task.step(np.ascontiguousarray(a), active=stepped if any_pending else None, rngs=self._rngs)
        self._episode_steps[stepped] += 1
        rewards = task.rewards()
        terminated = task.terminated()
        truncated = self._truncated()
        if not any_pending:
            observation = task.observe(self._rngs)
        else:
            # A pending sub-env's generator must not draw observation noise for the old episode.
            observation = np.empty((self.num_envs, task.observation_size), dtype=np.float32)
            kept = np.flatnonzero(stepped)
            if kept.size:
                observation[kept] = task.observe([self._rngs[i] for i in kept], kept)
            ended = np.flatnonzero(pending)
            ended_rngs = [self._rngs[i] for i in ended]
            task.reset(ended_rngs, ended)
            self._episode_steps[ended] = 0
            observation[ended] = task.observe(ended_rngs, ended)
            rewards[ended] = 0.0
            terminated[ended] = False
            truncated[ended] = False
        np.logical_or(terminated, truncated, out=pending)
        # All reset, none stepped: a reset's infos, without the step keys (as Gymnasium's).
        infos = self._infos(stepped=stepped if stepped.any() else None)
        return observation, rewards, terminated, truncated, infos

    def set_difficulty(self, difficulty: float) -> None:
        """Scale initial conditions, randomisation and disturbances of every sub-env by
        ``difficulty`` in [0, 1] from their next reset on (with SB3: ``env_method("set_difficulty",
        d)``)."""
        self.task.set_difficulty(difficulty)

    def close_extras(self, **kwargs: Any) -> None:
        """Nothing to release: the batch lives in this process."""

    # ------------------------------------------------------------------ infos
    def _infos(self, stepped: np.ndarray | None, rows: np.ndarray | None = None) -> dict[str, Any]:
        """Vector infos: copies of the task's info arrays, each with its ``_key`` mask.

        ``stepped`` marks the sub-envs whose info includes the per-step keys (None: a reset, no
        step keys at all); ``rows`` restricts every key to those sub-envs (for ``final_info``);
        entries outside a mask are zero, as Gymnasium's vector envs leave them."""
        arrays = self.task.info_arrays(stepped is not None, copy=True)
        if "end_reason" in arrays:
            codes = arrays["end_reason"]
            # Most steps end no episode: a copy of the all-running names is 3 us cheaper than a lookup.
            arrays["end_reason"] = self._running_names.copy() if not codes.any() else self._reason_names[codes]
        # One allocation for all the masks (each key gets its own row, so they stay independent).
        masks = np.empty((len(arrays), self.num_envs), dtype=np.bool_)
        infos: dict[str, Any] = {}
        if rows is None and (stepped is None or stepped.all()):  # every step without an episode end
            masks[:] = True
            for row, (key, array) in enumerate(arrays.items()):
                infos[key] = array
                infos["_" + key] = masks[row]
            return infos
        present_all = np.ones(self.num_envs, dtype=np.bool_) if rows is None else rows
        present_step = present_all if stepped is None else present_all & stepped
        for row, (key, array) in enumerate(arrays.items()):
            present = present_step if key in STEP_KEYS else present_all
            masks[row] = present
            if rows is None and present is present_all:
                infos[key] = array
            else:
                mask = present.reshape((-1,) + (1,) * (array.ndim - 1))
                infos[key] = np.where(mask, array, np.zeros((), dtype=array.dtype))
            infos["_" + key] = masks[row]
        return infos
