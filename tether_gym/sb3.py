"""Stable-Baselines3 adapter for Gymnasium vector environments with same-step autoreset.

SB3 trains on its own :class:`~stable_baselines3.common.vec_env.VecEnv` API and ships no bridge
from Gymnasium's :class:`gymnasium.vector.VectorEnv`. :class:`SB3VecEnv` is that bridge, thin on
purpose: one ``venv.step`` per SB3 step, no per-env Python loop except over the sub-envs that
ended in that step. It is what you want for the native batch
:class:`~tether_gym.envs.TetherClusterVectorEnv` (``gym.make_vec(id, num_envs=N)``), which steps
N clusters in one process far faster than SB3's ``DummyVecEnv`` over N single envs.
:func:`make_sb3_vec_env` builds it in the same-step autoreset mode that SB3 needs::

    from stable_baselines3 import PPO
    from tether_gym.sb3 import make_sb3_vec_env

    env = make_sb3_vec_env("TetherTetrahedron-v0", num_envs=64, seed=0)
    model = PPO("MlpPolicy", env, device="cpu").learn(100_000)

How the two APIs are matched (N = ``num_envs``):

* **Autoreset.** SB3 expects a sub-env that ends to be reset within the same ``step`` and the
  last observation of the old episode to be in ``info["terminal_observation"]``. That is
  Gymnasium's *same-step* autoreset (``metadata["autoreset_mode"] == AutoresetMode.SAME_STEP``),
  and only such vector envs are accepted. Gymnasium's vector envs, the native one included,
  default to next-step autoreset; :func:`make_sb3_vec_env` asks for same-step itself. By hand:
  ``gym.make_vec(id, num_envs=N, autoreset_mode=AutoresetMode.SAME_STEP)`` for the native env,
  ``gym.make_vec(..., vectorization_mode="sync", vector_kwargs={"autoreset_mode":
  AutoresetMode.SAME_STEP})`` for Gymnasium's ``SyncVectorEnv`` and ``AsyncVectorEnv``.
* **Step outputs.** ``obs`` as the vector env returns it ((N, *obs_shape)); ``rewards`` (N,)
  float32; ``dones`` (N,) bool = ``terminated | truncated``; ``infos``, a list of N dicts.
* **Info dicts.** To keep a step cheap at N = 1024, the dict of a sub-env that did *not* end is
  **empty**: per-step diagnostics (reward terms, energies, ...) are not copied into N Python
  dicts. A sub-env that ended gets:

  - ``"terminal_observation"``: the last observation of the finished episode (as SB3 expects);
  - ``"TimeLimit.truncated"``: ``truncated and not terminated`` (SB3 bootstraps the value on it);
  - every *scalar* entry of ``infos["final_info"]`` present for it, as a Python scalar, e.g.
    ``vibration_energy`` (J), ``propellant_used`` (N*s), ``end_reason`` (str), ``time`` (s).
    Array entries (``tensions``, ``thrust``, ...) are left out; nested dicts (e.g. Gymnasium's
    ``"episode"``) are handled recursively.

  The full Gymnasium info dict of the latest ``reset``/``step`` (every key, (N, ...) arrays
  with ``"_key"`` masks, including ``final_info`` and ``final_obs``) stays available, uncopied,
  as :attr:`SB3VecEnv.vector_infos`.
* **Reset infos.** ``reset_infos[i]`` holds the scalar entries of sub-env i's latest reset info:
  all N after :meth:`SB3VecEnv.reset`, and the ended sub-envs' after an autoreset (as SB3's
  ``DummyVecEnv`` does).
* **Rewards** are checked: a reward that is not finite in float32 raises ``ValueError`` (SB3
  would silently train on it). tether-gym's envs never return one: a step whose reward would not
  be finite ends as ``numerics_diverged`` with a finite reward, reported in the ended sub-env's
  info as ``end_reason``.
* **Seeds and options** follow SB3: ``seed(s)`` schedules seeds ``s, s+1, ..., s+N-1`` for the
  next ``reset()``, which passes them to the vector env as a list, so sub-env i gets ``s + i``.
  ``set_options(...)`` schedules options for the next ``reset()``. A Gymnasium vector env takes
  **one** options dict for the whole batch (tether-gym: ``positions``/``velocities`` as
  (N, n, 3) arrays), so the options must be the same for every sub-env, which is what
  ``set_options(dict)`` gives. Seeds and options are used once.
* **The batch is one object.** There are no per-sub-env Python objects to address, so
  ``get_attr``/``set_attr``/``env_method`` act on the vector env itself (see each method), and
  ``env_is_wrapped`` is False everywhere (no per-env ``gym.Wrapper``).
* **Rendering** is not supported: ``render()`` warns and returns None. Render a single
  :class:`~tether_gym.envs.TetherClusterEnv` with ``render_mode="rgb_array"`` instead.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Mapping, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv

from tether_gym._optional import needs_extra

with needs_extra("train", "the Stable-Baselines3 adapter (tether_gym.sb3)"):
    from stable_baselines3.common.vec_env import VecEnv
    from stable_baselines3.common.vec_env.base_vec_env import VecEnvIndices, VecEnvObs, VecEnvStepReturn

__all__ = ["SB3VecEnv", "make_sb3_vec_env", "ppo_env_share"]

#: numpy dtype kinds copied into the info dicts as Python scalars: bool, int, uint, float,
#: complex, str, bytes; and object ("O"), element by element, for the elements that are scalars
#: (Gymnasium's SyncVectorEnv keeps string infos in object arrays).
_SCALAR_KINDS = frozenset("biufcUSO")
_SCALAR_TYPES = (str, bytes, bool, int, float, complex, np.generic)

#: Top-level keys of a same-step vector info dict that are not info entries of the new episode.
_FINAL_KEYS = ("final_obs", "final_info")


def _autoreset_mode(venv: VectorEnv) -> AutoresetMode | None:
    """The vector env's declared autoreset mode (None if it declares none or an unknown one)."""
    mode = (getattr(venv, "metadata", None) or {}).get("autoreset_mode")
    if isinstance(mode, AutoresetMode) or mode is None:
        return mode
    try:
        return AutoresetMode(mode)
    except ValueError:
        return None


def _scalar_rows(
    infos: Mapping[str, Any], rows: np.ndarray, num_envs: int, skip: Sequence[str] = ()
) -> list[dict[str, Any]]:
    """Per-sub-env dicts of the scalar entries of a Gymnasium vector info dict.

    Args:
        infos: vector infos: ``key -> (N,) or (N, ...) array`` with optional ``"_key"`` bool
            masks, possibly nested (a dict value is itself such an info dict).
        rows: (k,) indices of the sub-envs wanted.
        num_envs: N (arrays of another length are not per-sub-env and are skipped).
        skip: top-level keys to ignore.

    Returns:
        k dicts; dict j holds, for every (N,) array of a scalar dtype whose mask (if any) is set
        at ``rows[j]``, that element as a Python scalar (object arrays: only the scalar
        elements). One ``tolist`` per key, not one numpy access per element.
    """
    out: list[dict[str, Any]] = [{} for _ in range(len(rows))]
    for key, value in infos.items():
        if key.startswith("_") or key in skip:
            continue
        if isinstance(value, Mapping):
            for row, nested in zip(out, _scalar_rows(value, rows, num_envs), strict=True):
                if nested:
                    row[key] = nested
            continue
        if (
            not isinstance(value, np.ndarray)
            or value.ndim != 1
            or value.shape[0] != num_envs
            or value.dtype.kind not in _SCALAR_KINDS
        ):
            continue
        values = value[rows].tolist()
        mask = infos.get("_" + key)
        present = [True] * len(values) if mask is None else np.asarray(mask)[rows].tolist()
        if value.dtype.kind == "O":
            present = [p and isinstance(item, _SCALAR_TYPES) for p, item in zip(present, values, strict=True)]
            values = [item.item() if isinstance(item, np.generic) else item for item in values]
        for row, item, p in zip(out, values, present, strict=True):
            if p:
                row[key] = item
    return out


def _same_options(options: Sequence[Mapping[str, Any]]) -> bool:
    """Whether every per-env options dict is the same (same keys, equal values)."""
    first = options[0]
    for other in options[1:]:
        if other is first:
            continue
        if set(other) != set(first):
            return False
        for key, value in first.items():
            a, b = value, other[key]
            if a is b:
                continue
            if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
                if not np.array_equal(np.asarray(a), np.asarray(b)):
                    return False
            elif a != b:
                return False
    return True


class SB3VecEnv(VecEnv):
    """A Gymnasium same-step-autoreset :class:`~gymnasium.vector.VectorEnv` as an SB3 ``VecEnv``.

    See the module docstring for the mapping between the two APIs. Works with VecNormalize,
    VecMonitor and the other SB3 ``VecEnvWrapper`` classes on top.

    Args:
        venv: the vector env, e.g. ``gym.make_vec("tether_gym:TetherTetrahedron-v0", num_envs=N,
            autoreset_mode=AutoresetMode.SAME_STEP)``. Its ``metadata["autoreset_mode"]`` must be
            ``AutoresetMode.SAME_STEP``. The adapter
            owns it: :meth:`close` closes it.

    Attributes:
        venv: the wrapped vector env.
        vector_infos: the Gymnasium info dict of the latest ``reset``/``step`` (not copied).
        observation_space, action_space: the vector env's *single* spaces (SB3's convention).

    Raises:
        TypeError: ``venv`` is not a Gymnasium ``VectorEnv``.
        ValueError: its autoreset mode is not same-step.
    """

    def __init__(self, venv: VectorEnv) -> None:
        if not isinstance(venv, VectorEnv):
            raise TypeError(
                f"SB3VecEnv wraps a gymnasium.vector.VectorEnv (e.g. gym.make_vec(id, num_envs=N)); got "
                f"{type(venv).__name__}. For a single gymnasium.Env use SB3's DummyVecEnv or make_vec_env."
            )
        mode = _autoreset_mode(venv)
        if mode is not AutoresetMode.SAME_STEP:
            declared = "declares no autoreset mode" if mode is None else f"has autoreset mode {mode.value!r}"
            raise ValueError(
                "SB3VecEnv needs a vector env with same-step autoreset (metadata['autoreset_mode'] == "
                "AutoresetMode.SAME_STEP): SB3 expects an ended sub-env to be reset within the same step, "
                "with its last observation in info['terminal_observation']; "
                f"{type(venv).__name__} {declared}. "
                "tether_gym.sb3.make_sb3_vec_env(id, num_envs) builds one; by hand, the native vector env takes "
                "gym.make_vec(id, num_envs=N, autoreset_mode=AutoresetMode.SAME_STEP), and Gymnasium's "
                "SyncVectorEnv/AsyncVectorEnv gym.make_vec(..., vector_kwargs={'autoreset_mode': "
                "AutoresetMode.SAME_STEP})."
            )
        self.venv = venv
        self.vector_infos: dict[str, Any] = {}
        self._actions: np.ndarray | None = None
        super().__init__(int(venv.num_envs), venv.single_observation_space, venv.single_action_space)
        self._all = np.arange(self.num_envs)
        # SB3's base class replaces metadata by its render modes; keep the vector env's entries too.
        self.metadata = {**dict(getattr(venv, "metadata", {}) or {}), **self.metadata}

    # ------------------------------------------------------------------ reset / step
    def reset(self) -> VecEnvObs:
        """Reset every sub-env; returns the (N, *obs_shape) observation batch.

        Uses the seeds scheduled by :meth:`seed` (passed as a list of N; none scheduled: the
        generators continue) and the options scheduled by ``set_options`` (one dict for the
        batch), then forgets both. Fills ``reset_infos`` with N dicts of scalar info entries.

        Raises:
            ValueError: the scheduled options differ between sub-envs.
        """
        seeds = None if all(s is None for s in self._seeds) else list(self._seeds)
        options = self._batch_options()
        # Gymnasium declares one seed for a whole VectorEnv; the native and the sync vector envs
        # take one per sub-env.
        obs, infos = self.venv.reset(seed=seeds, options=options)  # type: ignore[arg-type]
        self._reset_seeds()
        self._reset_options()
        self._actions = None
        self.vector_infos = infos
        self.reset_infos = _scalar_rows(infos, self._all, self.num_envs, skip=_FINAL_KEYS)
        return obs

    def seed(self, seed: int | None = None) -> Sequence[int | None]:
        """Schedule the seeds ``seed, seed + 1, ..., seed + N - 1`` for the next :meth:`reset`
        (None: a random base seed, as SB3 does); returns them.

        Raises:
            ValueError: ``seed`` is not None or a whole number >= 0 (nothing is scheduled).
        """
        if seed is not None and (
            isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)) or seed < 0
        ):
            raise ValueError(
                f"seed must be a whole number >= 0 (an int; sub-env i gets seed + i) or None; got {seed!r}"
            )
        return super().seed(None if seed is None else int(seed))

    def _batch_options(self) -> dict[str, Any] | None:
        """SB3's per-env options as the one options dict of a Gymnasium vector env's reset."""
        options = list(self._options) if self._options is not None else []
        if not any(options):
            return None
        if len(options) != self.num_envs or not _same_options(options):
            raise ValueError(
                "a Gymnasium vector env takes one options dict for the whole batch, so SB3VecEnv needs "
                "the same options for every sub-env: call set_options(dict) with batch-level values (for "
                "tether-gym, 'positions'/'velocities' as (num_envs, n, 3) arrays), not a list of different "
                "per-env dicts"
            )
        return dict(options[0])

    def step_async(self, actions: np.ndarray) -> None:
        """Store the (N, *action_shape) action batch for :meth:`step_wait` (the step is synchronous)."""
        self._actions = actions

    def step_wait(self) -> VecEnvStepReturn:
        """Step the batch with the stored actions.

        Returns:
            obs: (N, *obs_shape) observations; an ended sub-env's is its new episode's first one.
            rewards: (N,) float32.
            dones: (N,) bool, ``terminated | truncated``.
            infos: N dicts: empty for sub-envs that did not end; for those that ended,
                ``terminal_observation``, ``TimeLimit.truncated`` and the scalar ``final_info``
                entries (see the module docstring).
        """
        if self._actions is None:
            raise RuntimeError("step_wait() called without a pending step_async(actions)")
        actions, self._actions = self._actions, None
        obs, rewards, terminated, truncated, infos = self.venv.step(actions)
        self.vector_infos = infos
        with np.errstate(over="ignore"):  # a float64 reward beyond float32's range: reported below
            rewards32 = np.asarray(rewards, dtype=np.float32)
        if not np.isfinite(rewards32).all():
            bad = np.flatnonzero(~np.isfinite(rewards32))
            raise ValueError(
                f"the vector env returned rewards that are not finite in float32 for sub-envs {bad.tolist()} "
                f"({np.asarray(rewards)[bad].tolist()}); SB3 would train on NaN or inf. tether-gym envs end such a "
                "step as numerics_diverged with a finite reward; for other envs, fix the reward or wrap the env in "
                "SB3's VecCheckNan to find where it comes from"
            )
        terminated = np.asarray(terminated, dtype=bool)
        truncated = np.asarray(truncated, dtype=bool)
        dones = terminated | truncated
        step_infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        if dones.any():
            self._fill_ended(np.flatnonzero(dones), terminated, truncated, infos, step_infos)
        return obs, rewards32, dones, step_infos

    def _fill_ended(
        self,
        ended: np.ndarray,
        terminated: np.ndarray,
        truncated: np.ndarray,
        infos: Mapping[str, Any],
        step_infos: list[dict[str, Any]],
    ) -> None:
        """Fill the info dicts (and ``reset_infos``) of the sub-envs ``ended``; see the module docstring."""
        final_obs = infos.get("final_obs")
        has_final = np.asarray(infos.get("_final_obs", np.zeros(self.num_envs, dtype=bool)), dtype=bool)
        if final_obs is None or not has_final[ended].all():
            missing = ended[~has_final[ended]] if final_obs is not None else ended
            raise RuntimeError(
                f"sub-envs {missing.tolist()} ended but the vector env gave no infos['final_obs'] for them; "
                "a same-step autoreset vector env must report the last observation of every ended sub-env"
            )
        final_rows = _scalar_rows(infos.get("final_info", {}), ended, self.num_envs)
        reset_rows = _scalar_rows(infos, ended, self.num_envs, skip=_FINAL_KEYS)
        for i, final, new in zip(ended.tolist(), final_rows, reset_rows, strict=True):
            final["terminal_observation"] = final_obs[i]
            final["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
            step_infos[i] = final
            self.reset_infos[i] = new

    # ------------------------------------------------------------------ the batch as one object
    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """The vector env's attribute ``attr_name``, once per requested index (the same object:
        the batch is one object, so e.g. ``get_attr("task")`` gives the shared batched task).

        Raises:
            AttributeError: the vector env has no such attribute (``has_attr`` relies on it).
        """
        value = getattr(self.venv, attr_name)
        return [value for _ in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        """Set ``attr_name`` once on the vector env: the value is **shared** by every sub-env
        (e.g. ``set_attr("max_episode_steps", 100)``). Setting it for only some sub-envs is
        impossible, so ``indices`` must be None or cover all N.

        Raises:
            ValueError: ``indices`` names only some of the sub-envs.
        """
        self._require_all(indices, f"set_attr({attr_name!r})")
        setattr(self.venv, attr_name, value)

    def env_method(
        self, method_name: str, *method_args: Any, indices: VecEnvIndices = None, **method_kwargs: Any
    ) -> list[Any]:
        """Call the vector env's method ``method_name`` **once** (it acts on the whole batch, so
        calling it once per sub-env would repeat its effect N times) and return its result once
        per requested index (the same object). No call is made if no index is requested.
        """
        targets = list(self._get_indices(indices))
        if not targets:
            return []
        result = getattr(self.venv, method_name)(*method_args, **method_kwargs)
        return [result for _ in targets]

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None) -> list[bool]:
        """False for each requested index: the sub-envs of a vector env are not ``gym.Wrapper``
        chains (a Monitor cannot wrap them; use SB3's VecMonitor on top of this adapter)."""
        return [False for _ in self._get_indices(indices)]

    def _require_all(self, indices: VecEnvIndices, what: str) -> None:
        if indices is None:
            return
        requested = {int(i) for i in self._get_indices(indices)}
        if requested != set(range(self.num_envs)):
            raise ValueError(
                f"{what} acts on the whole batch (one vector env object shared by all {self.num_envs} "
                f"sub-envs); it cannot target only the sub-envs {sorted(requested)}. Pass indices=None."
            )

    # ------------------------------------------------------------------ rendering / closing
    def render(self, mode: str | None = None) -> np.ndarray | None:
        """Not supported: warns and returns None (no image)."""
        warnings.warn(
            f"SB3VecEnv does not render (asked for mode={mode!r}); render a single env instead, e.g. "
            "gym.make('TetherTetrahedron-v0', render_mode='rgb_array').",
            stacklevel=2,
        )
        return None

    def get_images(self) -> Sequence[np.ndarray | None]:
        """Not supported: warns and returns N Nones."""
        warnings.warn("SB3VecEnv does not render; get_images() returns no images", stacklevel=2)
        return [None] * self.num_envs

    def close(self) -> None:
        """Close the vector env."""
        self.venv.close()


def make_sb3_vec_env(env_id: str, num_envs: int, seed: int | None = None, **kwargs: Any) -> SB3VecEnv:
    """``SB3VecEnv(gym.make_vec(env_id, num_envs=num_envs, **kwargs))`` in same-step autoreset, seeded.

    The vector env is asked for same-step autoreset, which SB3 needs: through the native env's
    ``autoreset_mode`` argument, or ``vector_kwargs`` for ``vectorization_mode="sync"``/``"async"``.
    An explicit mode in ``kwargs`` (or ``vector_kwargs``) is passed on as given, and one other than
    same-step is refused by :class:`SB3VecEnv`.

    Args:
        env_id: a registered id, e.g. ``"TetherTetrahedron-v0"``.
        num_envs: N.
        seed: the first reset gives sub-env i the seed ``seed + i``; None draws a random base
            seed (as SB3's ``make_vec_env`` does).
        **kwargs: passed to ``gym.make_vec`` and through it to the env, e.g.
            ``max_episode_steps=100``, ``preset_kwargs={...}``, ``observation_noise=0.01``.
    """
    if kwargs.get("vectorization_mode") in (None, "vector_entry_point", gym.VectorizeMode.VECTOR_ENTRY_POINT):
        kwargs.setdefault("autoreset_mode", AutoresetMode.SAME_STEP)
    else:
        kwargs["vector_kwargs"] = {"autoreset_mode": AutoresetMode.SAME_STEP, **dict(kwargs.get("vector_kwargs") or {})}
    env = SB3VecEnv(gym.make_vec(env_id, num_envs=num_envs, **kwargs))
    env.seed(seed)
    return env


def ppo_env_share(env_id: str, num_envs: int, timesteps: int) -> tuple[float, float, float, float]:
    """PPO training on the native vector env through this adapter, measured two ways (the speed
    benchmark's last table, ``python -m tether_gym.bench``).

    Returns ``(seconds with the env, seconds with a zero-cost env of the same spaces, seconds
    spent inside the env's reset/step during the first run, env share)``, where the share is
    the time inside the env over the training time of the first run.  The difference of the two
    runs is the issue's definition, but on a busy 2-core machine it is within the timing noise
    (it can come out negative), so the time inside the env is measured directly too.  PPO uses
    SB3's default hyperparameters (batch 64, 10 epochs) but for a rollout of 128 steps per env."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecEnvWrapper

    class ZeroCostVecEnv(VecEnv):
        """Same spaces, no work: what PPO costs by itself."""

        def __init__(self, like: VecEnv) -> None:
            super().__init__(like.num_envs, like.observation_space, like.action_space)
            self._obs = np.zeros((like.num_envs,) + tuple(like.observation_space.shape or ()), dtype=np.float32)
            self._rewards = np.zeros(like.num_envs, dtype=np.float32)
            self._dones = np.zeros(like.num_envs, dtype=bool)

        def reset(self) -> np.ndarray:
            return self._obs.copy()

        def step_async(self, actions: np.ndarray) -> None:
            pass

        def step_wait(self) -> tuple:
            return self._obs.copy(), self._rewards.copy(), self._dones.copy(), [{} for _ in range(self.num_envs)]

        def close(self) -> None:
            pass

        def get_attr(self, attr_name: str, indices: object = None) -> list:
            return [None] * self.num_envs

        def set_attr(self, attr_name: str, value: object, indices: object = None) -> None:
            pass

        def env_method(self, method_name: str, *args: object, indices: object = None, **kwargs: object) -> list:
            return [None] * self.num_envs

        def env_is_wrapped(self, wrapper_class: type, indices: object = None) -> list:
            return [False] * self.num_envs

    class TimedVecEnv(VecEnvWrapper):
        """Accumulates the wall time spent inside the wrapped env's reset and step."""

        def __init__(self, venv: VecEnv) -> None:
            super().__init__(venv)
            self.seconds = 0.0

        def reset(self) -> Any:
            start = time.perf_counter()
            observation = self.venv.reset()
            self.seconds += time.perf_counter() - start
            return observation

        def step_wait(self) -> tuple:
            start = time.perf_counter()
            result = self.venv.step_wait()
            self.seconds += time.perf_counter() - start
            return result

    real = TimedVecEnv(make_sb3_vec_env(env_id, num_envs, seed=0))
    times = []
    inside = 0.0
    for venv in (real, ZeroCostVecEnv(real)):
        model = PPO("MlpPolicy", venv, n_steps=128, seed=0, device="cpu")
        model.learn(total_timesteps=num_envs * 128)  # warm-up (compilation, torch)
        real.seconds = 0.0
        start = time.perf_counter()
        model.learn(total_timesteps=timesteps, reset_num_timesteps=False)
        times.append(time.perf_counter() - start)
        if venv is real:
            inside = real.seconds
    real.close()
    return times[0], times[1], inside, inside / times[0]
