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
  ``get_attr`` reads the adapter's attributes (``observation_space`` is one sub-env's, as SB3
  gives it), then the vector env's, ``set_attr``/``env_method`` act on the vector env itself
  (see :class:`BatchVecEnv` for what they accept), and
  ``env_is_wrapped`` is False everywhere (no per-env ``gym.Wrapper``).
* **Rendering** is not supported: ``render()`` warns and returns None. Render a single
  :class:`~tether_gym.envs.TetherClusterEnv` with ``render_mode="rgb_array"`` instead.
"""

from __future__ import annotations

import inspect
import time
import warnings
from abc import abstractmethod
from collections.abc import Callable, Mapping, Sequence
from copy import deepcopy
from types import MappingProxyType
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv

from tether_gym._optional import needs_extra

with needs_extra("train", "the Stable-Baselines3 adapter (tether_gym.sb3)"):
    from stable_baselines3.common.vec_env import VecEnv
    from stable_baselines3.common.vec_env.base_vec_env import VecEnvIndices, VecEnvObs, VecEnvStepReturn

from tether_gym.envs.arguments import (
    EnvArgumentError,
    check_actions,
    check_difficulty,
    check_indices,
    check_max_episode_steps,
    check_seed,
)
from tether_gym.limits import short_repr

__all__ = ["BatchVecEnv", "SB3VecEnv", "float32_rewards", "make_sb3_vec_env", "ppo_env_share"]

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


def float32_rewards(rewards: Any) -> np.ndarray:
    """(N,) rewards as float32, or a ``ValueError`` naming the rows whose reward is not finite in
    float32 (SB3 would silently train on NaN or inf)."""
    with np.errstate(over="ignore"):  # a float64 reward beyond float32's range: reported below
        rewards32 = np.asarray(rewards, dtype=np.float32)
    if not np.isfinite(rewards32).all():
        bad = np.flatnonzero(~np.isfinite(rewards32))
        raise ValueError(
            f"the env returned rewards that are not finite in float32 for rows {bad.tolist()} "
            f"({np.asarray(rewards)[bad].tolist()}); SB3 would train on NaN or inf. tether-gym envs end such a "
            "step as numerics_diverged with a finite reward; for other envs, fix the reward or wrap the env in "
            "SB3's VecCheckNan to find where it comes from"
        )
    return rewards32


def _set_difficulty_arguments(difficulty: float) -> None:
    """The arguments ``env_method("set_difficulty", ...)`` passes on, checked: one difficulty in [0, 1]."""
    check_difficulty(difficulty)


#: Where :meth:`BatchVecEnv.get_attr` found no attribute.
_MISSING = object()


class BatchVecEnv(VecEnv):
    """The SB3 ``VecEnv`` contract of tether-gym's adapters, implemented once.

    :class:`SB3VecEnv` (a single-agent vector env) and
    :class:`~tether_gym.multiagent.sb3.AgentVecEnv` (agents x clusters) are both this class: every
    argument either of them takes is checked here, by the same code, so that both refuse the same
    inputs with the same errors. A subclass provides only how its batch resets and steps and which
    objects its attributes and methods live on.

    The contract, for N rows:

    * ``seed(s)``: s is None (a random base seed, as SB3 draws it) or a whole number >= 0;
      scheduled for the next :meth:`reset` only.
    * ``set_options(o)``: None, one dict for the whole batch, or a list of N dicts; the options
      themselves are checked by the env at :meth:`reset` (for tether-gym, ``positions`` and
      ``velocities`` as (n_clusters, n, 3) arrays), before anything changes.
    * ``step_async(actions)``: an (N, *action_shape) array of real, finite numbers, checked at
      once; values outside the action space's bounds are clipped by the env, as in the
      single-agent env. A second ``step_async`` before ``step_wait`` is refused, and so is a
      ``step_wait`` with no pending ``step_async``.
    * ``get_attr(name)``: a public attribute (no leading underscore) of the adapter, or else of
      the batch, or else of its batched task;
      ``AttributeError`` for a private or missing one (so ``has_attr`` is False for them).
    * ``set_attr(name, value)``: only the names of :attr:`SETTABLE`, each value checked by the
      same function the env's own setter runs, for the whole batch (``indices`` None or all N).
    * ``env_method(name, *args)``: only the methods of :attr:`CALLABLE`, called once for the
      batch, with the arguments checked against the method's signature and values first.
    * ``indices``: None, an int, or a list/tuple/range/1-D int array of distinct rows in
      0..N-1; not a boolean mask, not floats (:func:`~tether_gym.envs.arguments.check_indices`).
    * After :meth:`close` (which may be called again), every other call raises ``RuntimeError``.

    Bad values raise :class:`~tether_gym.envs.EnvArgumentError` (a ``ValueError``) naming the
    argument; a name that is not a string raises ``TypeError``, and one that is not readable,
    settable or callable ``AttributeError``. A refused call changes nothing.

    Args:
        num_envs: N, the rows.
        observation_space, action_space: one row's spaces.
        action_axes: what the axes of the (N, *action_shape) action array are, for its errors.
    """

    #: The attributes ``set_attr`` may set, each with the check of its value (the one the env's
    #: setter runs too). Every other setting is fixed when the env is made.
    SETTABLE: ClassVar[Mapping[str, Callable[[Any], Any]]] = MappingProxyType(
        {"max_episode_steps": check_max_episode_steps}
    )
    #: The methods ``env_method`` may call on the whole batch, each with a function of the same
    #: signature that checks its arguments. Other public methods (``reset``, ``step``, ...) would
    #: change the batch behind the adapter's back.
    CALLABLE: ClassVar[Mapping[str, Callable[..., None]]] = MappingProxyType(
        {"set_difficulty": _set_difficulty_arguments}
    )

    def __init__(self, num_envs: int, observation_space: gym.Space, action_space: gym.Space, action_axes: str) -> None:
        # Set first: SB3's __init__ calls get_attr("render_mode").
        self._closed = False
        self._actions: np.ndarray | None = None
        self._action_axes = action_axes
        super().__init__(num_envs, observation_space, action_space)

    # ------------------------------------------------------------------ what a subclass provides
    @abstractmethod
    def _reset_batch(self, seeds: list[int | None], options: dict[str, Any] | None) -> VecEnvObs:
        """Reset every row with the checked per-row ``seeds`` and batch ``options``; fill
        ``reset_infos``; return the (N, *obs_shape) observations."""
        raise NotImplementedError

    @abstractmethod
    def _step_batch(self, actions: np.ndarray) -> VecEnvStepReturn:
        """Step the batch with checked (N, *action_shape) float64 actions."""
        raise NotImplementedError

    def _row_seeds(self, seed: int) -> list[int | None]:
        """The N row seeds that the base seed ``seed`` schedules."""
        return [seed + row for row in range(self.num_envs)]

    @abstractmethod
    def _attribute_owners(self) -> tuple[object, ...]:
        """The objects ``get_attr`` reads, in order (the first that has the attribute wins)."""
        raise NotImplementedError

    @abstractmethod
    def _setting_owner(self) -> object:
        """The object ``set_attr`` sets."""
        raise NotImplementedError

    @abstractmethod
    def _method_owner(self) -> object:
        """The object whose method ``env_method`` calls."""
        raise NotImplementedError

    def _release(self) -> None:
        """Release what the batch holds (called once, by the first :meth:`close`)."""

    # ------------------------------------------------------------------ checks
    def _check_open(self, call: str) -> None:
        if self._closed:
            raise RuntimeError(f"{type(self).__name__} is closed, so {call}() cannot run; make a new env")

    def _get_indices(self, indices: VecEnvIndices) -> list[int]:
        """The rows ``indices`` addresses, checked (see :func:`~tether_gym.envs.arguments.check_indices`)."""
        return check_indices("indices", indices, self.num_envs)

    @staticmethod
    def _public_name(call: str, argument: str, name: Any) -> str:
        """``name`` if it is a public attribute name; ``TypeError`` or ``AttributeError`` naming it."""
        if not isinstance(name, str):
            raise TypeError(f"{call}: {argument} must be a str naming an attribute; got {short_repr(name)}")
        if not name.isidentifier() or name.startswith("_"):
            raise AttributeError(
                f"{call}: {argument} {name!r} is not a public attribute name; the adapter reaches public "
                "attributes only (no leading underscore)"
            )
        return name

    # ------------------------------------------------------------------ reset / step
    def seed(self, seed: int | None = None) -> Sequence[int | None]:
        """Schedule the row seeds of ``seed`` (see :meth:`_row_seeds`) for the next :meth:`reset`
        (None: a random base seed, as SB3 draws it); returns them.

        Raises:
            EnvArgumentError: ``seed`` is not None or a whole number >= 0 (nothing is scheduled).
        """
        self._check_open("seed")
        base = check_seed("seed", seed)
        if base is None:
            base = int(np.random.randint(0, np.iinfo(np.uint32).max, dtype=np.uint32))
        self._seeds = self._row_seeds(base)
        return self._seeds

    def set_options(self, options: list[dict] | dict | None = None) -> None:
        """Schedule reset options for the next :meth:`reset`: None (none), one dict for the whole
        batch, or a list of N dicts, which must then be the same (a Gymnasium vector env takes
        one options dict). Their keys and values are checked by the env at :meth:`reset`.

        Raises:
            EnvArgumentError: ``options`` is none of these (nothing is scheduled).
        """
        self._check_open("set_options")
        if options is None:
            rows: list[dict[str, Any]] = [{}] * self.num_envs
        elif isinstance(options, Mapping):
            rows = [dict(options)] * self.num_envs
        elif (
            isinstance(options, (list, tuple))
            and len(options) == self.num_envs
            and all(isinstance(row, Mapping) for row in options)
        ):
            rows = [dict(row) for row in options]
        else:
            raise EnvArgumentError(
                f"options must be None, one dict for the whole batch, or a list of {self.num_envs} dicts (one per "
                f"row, all the same); got {short_repr(options)}"
            )
        # Copied, as SB3 does, so that later changes to the caller's arrays do not leak in.
        self._options = deepcopy(rows)

    def _batch_options(self) -> dict[str, Any] | None:
        """The scheduled per-row options as the one options dict of the whole batch's reset."""
        options = list(self._options)
        if not any(options):
            return None
        if len(options) != self.num_envs or not _same_options(options):
            raise EnvArgumentError(
                f"a Gymnasium vector env takes one options dict for the whole batch, so {type(self).__name__} needs "
                "the same options for every row: call set_options(dict) with batch-level values (for "
                "tether-gym, 'positions'/'velocities' as (clusters, n, 3) arrays), not a list of different "
                "per-row dicts"
            )
        return dict(options[0])

    def reset(self) -> VecEnvObs:
        """Reset every row; returns the (N, *obs_shape) observation batch.

        Uses the seeds scheduled by :meth:`seed` (none scheduled: the generators continue) and the
        options scheduled by :meth:`set_options`, then forgets both, and drops a pending
        ``step_async``. Fills ``reset_infos`` with N dicts of scalar info entries.

        Raises:
            EnvArgumentError: the scheduled options differ between rows, or the env refuses them
                (the batch is left as it was, and the seeds and options stay scheduled).
        """
        self._check_open("reset")
        try:
            options = self._batch_options()
            observations = self._reset_batch(list(self._seeds), options)
        except EnvArgumentError as error:
            if not any(self._options):
                raise
            # The refused options stay scheduled (the caller may want to inspect or mend them), so
            # every later reset would fail the same way: say how to get out.
            raise EnvArgumentError(
                f"{error} (the refused reset options stay scheduled: call set_options(...) with corrected "
                "options, or set_options(None) to drop them)"
            ) from error
        self._reset_seeds()
        self._reset_options()
        self._actions = None
        return observations

    def step_async(self, actions: np.ndarray) -> None:
        """Check and store the (N, *action_shape) action batch for :meth:`step_wait` (the step is
        synchronous).

        Raises:
            EnvArgumentError: not an array of real numbers, the wrong shape, or NaN or inf.
            RuntimeError: a step is already pending (call :meth:`step_wait` first).
        """
        self._check_open("step_async")
        if self._actions is not None:
            raise RuntimeError("step_async() called twice: call step_wait() for the pending step first")
        if isinstance(self.action_space, gym.spaces.Box):
            shape = (self.num_envs, *self.action_space.shape)
            self._actions = check_actions("actions", actions, shape, self._action_axes)
        else:  # another vector env's discrete or composite actions: its own step checks them
            self._actions = actions

    def step_wait(self) -> VecEnvStepReturn:
        """Step the batch with the actions of the pending :meth:`step_async`.

        Returns:
            obs: (N, *obs_shape) observations; an ended row's is its new episode's first one.
            rewards: (N,) float32.
            dones: (N,) bool, ``terminated | truncated``.
            infos: N dicts: empty for rows that did not end; for those that ended,
                ``terminal_observation``, ``TimeLimit.truncated`` and the scalar entries of the
                final info.

        Raises:
            RuntimeError: no ``step_async`` is pending.
        """
        self._check_open("step_wait")
        if self._actions is None:
            raise RuntimeError("step_wait() called without a pending step_async(actions)")
        actions, self._actions = self._actions, None
        return self._step_batch(actions)

    # ------------------------------------------------------------------ the batch as one object
    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """The batch's public attribute ``attr_name``, once per requested row (the same object:
        the batch is one object, so e.g. ``get_attr("task")`` gives the shared batched task).

        Raises:
            TypeError: ``attr_name`` is not a str.
            AttributeError: it is private or missing (``has_attr`` relies on it).
            EnvArgumentError: bad ``indices``.
        """
        self._check_open("get_attr")
        name = self._public_name("get_attr", "attr_name", attr_name)
        rows = self._get_indices(indices)
        for owner in self._attribute_owners():
            value = getattr(owner, name, _MISSING)
            if value is not _MISSING:
                return [value for _ in rows]
        raise AttributeError(f"get_attr: {type(self).__name__} has no attribute {name!r}")

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        """Set ``attr_name``, one of :attr:`SETTABLE`, once for the whole batch: the value is
        **shared** by every row (e.g. ``set_attr("max_episode_steps", 100)``), so ``indices``
        must be None or cover all N. The value is checked first.

        Raises:
            TypeError: ``attr_name`` is not a str.
            AttributeError: it is not one of :attr:`SETTABLE`, or the env has no such attribute.
            EnvArgumentError: a bad value, or ``indices`` naming only some rows.
        """
        self._check_open("set_attr")
        name = self._public_name("set_attr", "attr_name", attr_name)
        check = self.SETTABLE.get(name)
        if check is None:
            raise AttributeError(
                f"set_attr cannot set {name!r}: it sets only {sorted(self.SETTABLE)}; every other setting is "
                "fixed when the env is made (make a new env), and the difficulty is env_method('set_difficulty', d)"
            )
        rows = self._get_indices(indices)
        if len(rows) != self.num_envs:
            raise EnvArgumentError(
                f"set_attr({name!r}) acts on the whole batch (one object shared by all {self.num_envs} rows); "
                f"indices cannot name only the rows {rows}: pass indices=None"
            )
        checked = check(value)
        owner = self._setting_owner()
        if not hasattr(owner, name):
            raise AttributeError(f"set_attr: {type(owner).__name__} has no attribute {name!r} to set")
        setattr(owner, name, checked)

    def env_method(
        self, method_name: str, *method_args: Any, indices: VecEnvIndices = None, **method_kwargs: Any
    ) -> list[Any]:
        """Call ``method_name``, one of :attr:`CALLABLE`, **once** for the batch (it acts on the
        whole batch, so calling it once per row would repeat its effect N times) and return its
        result once per requested row (the same object). The arguments are checked first; no
        call is made if no row is requested.

        Raises:
            TypeError: ``method_name`` is not a str.
            AttributeError: it is not one of :attr:`CALLABLE`, or the env has no such method.
            EnvArgumentError: arguments that do not fit the method or are out of range, or bad
                ``indices``.
        """
        self._check_open("env_method")
        name = self._public_name("env_method", "method_name", method_name)
        check = self.CALLABLE.get(name)
        if check is None:
            raise AttributeError(
                f"env_method cannot call {name!r}: it calls only {sorted(self.CALLABLE)} on the whole batch "
                "(reset and step go through the adapter itself)"
            )
        signature = inspect.signature(check)
        try:
            signature.bind(*method_args, **method_kwargs)
        except TypeError as error:
            raise EnvArgumentError(
                f"env_method({name!r}) takes {name}({', '.join(signature.parameters)}): {error}; got arguments "
                f"{short_repr(method_args)} and keywords {short_repr(method_kwargs)}"
            ) from None
        check(*method_args, **method_kwargs)
        rows = self._get_indices(indices)
        method = getattr(self._method_owner(), name, None)
        if not callable(method):
            raise AttributeError(f"env_method: {type(self._method_owner()).__name__} has no method {name!r}")
        if not rows:
            return []
        result = method(*method_args, **method_kwargs)
        return [result for _ in rows]

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None) -> list[bool]:
        """False for each requested row: the rows of a batch are not ``gym.Wrapper`` chains (a
        Monitor cannot wrap them; use SB3's VecMonitor on top of the adapter)."""
        self._check_open("env_is_wrapped")
        return [False for _ in self._get_indices(indices)]

    # ------------------------------------------------------------------ rendering / closing
    def render(self, mode: str | None = None) -> np.ndarray | None:
        """Not supported: warns and returns None (no image)."""
        self._check_open("render")
        warnings.warn(
            f"{type(self).__name__} does not render (asked for mode={mode!r}); render a single env instead, e.g. "
            "gym.make('TetherTetrahedron-v0', render_mode='rgb_array').",
            stacklevel=2,
        )
        return None

    def get_images(self) -> Sequence[np.ndarray | None]:
        """Not supported: warns and returns N Nones."""
        self._check_open("get_images")
        warnings.warn(f"{type(self).__name__} does not render; get_images() returns no images", stacklevel=2)
        return [None] * self.num_envs

    def close(self) -> None:
        """Release the batch; later calls (but ``close``) raise ``RuntimeError``."""
        if self._closed:
            return
        self._closed = True
        self._actions = None
        self._release()


class SB3VecEnv(BatchVecEnv):
    """A Gymnasium same-step-autoreset :class:`~gymnasium.vector.VectorEnv` as an SB3 ``VecEnv``.

    See the module docstring for the mapping between the two APIs, and :class:`BatchVecEnv` for
    the checks of every argument. Works with VecNormalize, VecMonitor and the other SB3
    ``VecEnvWrapper`` classes on top. ``get_attr`` reads the adapter's attributes (its one-row
    spaces), then the vector env's, then its task's; ``set_attr`` and ``env_method`` act on the
    vector env itself.

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
        super().__init__(
            int(venv.num_envs), venv.single_observation_space, venv.single_action_space, "num_envs, action entries"
        )
        self._all = np.arange(self.num_envs)
        # SB3's base class replaces metadata by its render modes; keep the vector env's entries too.
        self.metadata = {**dict(getattr(venv, "metadata", {}) or {}), **self.metadata}

    # ------------------------------------------------------------------ the batch
    def _reset_batch(self, seeds: list[int | None], options: dict[str, Any] | None) -> VecEnvObs:
        # Gymnasium declares one seed for a whole VectorEnv; the native and the sync vector envs
        # take one per sub-env.
        scheduled = None if all(s is None for s in seeds) else seeds
        obs, infos = self.venv.reset(seed=scheduled, options=options)  # type: ignore[arg-type]
        self.vector_infos = infos
        self.reset_infos = _scalar_rows(infos, self._all, self.num_envs, skip=_FINAL_KEYS)
        return obs

    def _step_batch(self, actions: np.ndarray) -> VecEnvStepReturn:
        obs, rewards, terminated, truncated, infos = self.venv.step(actions)
        self.vector_infos = infos
        rewards32 = float32_rewards(rewards)
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

    def _attribute_owners(self) -> tuple[object, ...]:
        # As AgentVecEnv: the adapter (its spaces are one row's, as SB3's get_attr gives them),
        # the batch, then the batched task (where env_method's methods live) if there is one.
        task = getattr(self.venv, "task", None)
        return (self, self.venv) if task is None else (self, self.venv, task)

    def _setting_owner(self) -> object:
        return self.venv

    def _method_owner(self) -> object:
        return self.venv

    def _release(self) -> None:
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
