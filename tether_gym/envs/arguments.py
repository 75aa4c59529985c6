"""The arguments of the environments: the ranges of every setting, and one check per kind of value.

Every argument a user can give the environments (task settings, seeds, reset options, actions,
difficulty) is checked by these helpers before any state is built or changed; a bad one raises
:class:`EnvArgumentError` naming it, what is allowed and the fix.  The ranges are the named
constants below.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from tether_gym._kernels import all_finite
from tether_gym.envs._task_kernels import OBSERVATION_LIMIT, REWARD_LIMIT
from tether_gym.limits import is_real_number, is_whole_number, real_array, short_repr, to_float

__all__ = [
    "CONTROL_INTERVAL_RANGE",
    "MAX_DELAY_LINE",
    "MAX_DISPLACEMENT_FRACTION",
    "MAX_EPISODE_STEPS",
    "MAX_IMPULSE",
    "MAX_IMPULSE_RATE",
    "MAX_NUM_ENVS",
    "MAX_OBSERVATION_NOISE",
    "MAX_PERIODIC_AMPLITUDE",
    "MAX_RENDER_EXAGGERATION",
    "MAX_RESET_DEVIATION_CABLES",
    "MAX_SPREAD",
    "MAX_THRUST_DELAY",
    "MAX_THRUST_NOISE",
    "MAX_TIME",
    "MAX_WEIGHT",
    "MIN_CABLE_LENGTH_FRACTION",
    "MIN_INITIAL_FRACTION",
    "OBSERVATION_LIMIT",
    "RESET_SPEED_FACTOR",
    "REWARD_LIMIT",
    "SUBSTEP_HEADROOM",
    "THRUST_RANGE",
    "EnvArgumentError",
    "as_real_array",
    "check_actions",
    "check_bool",
    "check_choice",
    "check_difficulty",
    "check_indices",
    "check_max_episode_steps",
    "check_no_render",
    "check_num_envs",
    "check_number",
    "check_satellites",
    "check_seed",
    "check_whole",
    "items_of",
    "real_or_none",
]

# ---------------------------------------------------------------------------------------------
# Ranges of the settings.  Each limit is far beyond any physical tether cluster or thruster; the
# limits only keep the arithmetic finite (energies, rewards, sub-step counts, float32 outputs) and
# the task meaningful.  Limits that depend on the cluster are fractions of its scales
# (:class:`~tether_gym.envs.config.ClusterScales`).

#: Control interval range, s.  Below 0.1 ms (10 kHz) no thruster valve responds, and the
#: propellant normaliser ``max_thrust * control_interval`` and the force of a kick held over one
#: interval (``impulse_magnitude / control_interval``) lose their scale.  Above an hour a
#: controller cannot act on vibrations of periods of seconds to minutes.
CONTROL_INTERVAL_RANGE = (1e-4, 3600.0)

#: Sub-step headroom.  At construction one control interval may need at most
#: ``max_substeps / SUBSTEP_HEADROOM`` sub-steps at the cluster's nominal sub-step (for the
#: worst case of the randomisation), because stretched cables and fast motion shorten the
#: critical step mid-episode, and a cluster that needs ``max_substeps`` ends as
#: ``numerics_diverged``.
SUBSTEP_HEADROOM = 10

#: Thrust range of each thruster, N: from nano-newton electric thrusters to a 1 MN rocket engine.
#: Below 1 nN the propellant normaliser ``max_thrust * control_interval`` leaves the normal floats.
THRUST_RANGE = (1e-9, 1e6)

#: Largest reward weight and failure penalty.  The rewards of RL tasks are O(1) to O(1e3) per
#: step; at 1e6 the reward of any state the formation check lets through stays far inside
#: ``REWARD_LIMIT``.
MAX_WEIGHT = 1e6

#: Largest initial-displacement std, as a fraction of the shortest cable.  A 10 % deformation
#: already stretches cables far past any breaking load; beyond it the draws fold the cluster
#: (cables through zero length) instead of making it vibrate.  The initial-velocity std is
#: limited likewise to ``MAX_DISPLACEMENT_FRACTION * shortest cable * omega_max``
#: (:attr:`~tether_gym.envs.config.ClusterScales.speed_limit`): the speed of the stiffest cable mode swinging with that
#: displacement.
MAX_DISPLACEMENT_FRACTION = 0.1

#: Smallest non-zero initial-displacement and initial-velocity std, as fractions of their upper
#: limits.  The reward's energy scale is the mean energy at reset: a smaller one would make
#: every later vibration reward astronomically large.  (0 is allowed: no displacement, or no
#: velocity.)
MIN_INITIAL_FRACTION = 1e-8

#: How far an exact reset position (reset option) may lie from its nominal place, in
#: longest-cable lengths: farther out the satellites are no longer a formation.
MAX_RESET_DEVIATION_CABLES = 10.0

#: Exact reset velocities (reset options) may reach this multiple of the initial-velocity limit.
RESET_SPEED_FACTOR = 10.0

#: A cable shorter than this fraction of its reference length in an exact reset state has its
#: satellites on top of each other: its direction, and so its force, is undefined.
MIN_CABLE_LENGTH_FRACTION = 1e-6

#: Largest randomisation spread.  A parameter drawn at 10 % of nominal is another cluster, and as
#: the spread nears 1 the drawn masses, and with them the sub-step, shrink without bound.
MAX_SPREAD = 0.9

#: Largest observation-noise std, in observation units (the observation is clipped at +-this).
MAX_OBSERVATION_NOISE = OBSERVATION_LIMIT

#: Largest thrust-noise std, as a multiple of the thruster's ``max_thrust``.
MAX_THRUST_NOISE = 10.0

#: Largest kick, N*s (1 MN for a second), and the largest kick rate, 1/s (a thousand kicks per
#: second are already a continuous force).
MAX_IMPULSE = 1e6
MAX_IMPULSE_RATE = 1e3

#: Largest periodic-force amplitude, N (as large as the largest thrust).
MAX_PERIODIC_AMPLITUDE = THRUST_RANGE[1]

#: Longest period and latest thruster-failure time, s: about four months, beyond any episode.
MAX_TIME = 1e7

#: Longest actuation delay, control intervals (each cluster holds its delay line).
MAX_THRUST_DELAY = 1000

#: Most numbers the delay lines of a whole batch may hold (``num_envs * thrust_delay *
#: action size``): 1e8 float64 are 800 MB, beyond which the delay alone outgrows memory.
MAX_DELAY_LINE = 10**8

#: Most sub-envs of one vector env.  Each cluster holds some kB of state; beyond this one batch
#: outgrows a process's memory and a step's latency: run several processes instead.
MAX_NUM_ENVS = 100_000

#: Largest render exaggeration (displacements drawn this many times larger leave any figure).
MAX_RENDER_EXAGGERATION = 1e6


class EnvArgumentError(ValueError):
    """A bad argument to a tether-gym environment or task: a setting, a seed, a reset option, an
    action or a difficulty.  The message names the argument, what is allowed and the fix."""


# ---------------------------------------------------------------------------------------------
# One check per kind of value.  Each returns the value normalised (Python float, int, bool, str
# or tuple) or raises EnvArgumentError naming ``name``.


def real_or_none(value: Any) -> float | None:
    """``value`` as a float if it is a real number (not a bool, not a string), else None; an int
    beyond the float range becomes +-inf, so that the range checks refuse it by name."""
    return to_float(value) if is_real_number(value) else None


def _interval(low: float, high: float, low_open: bool, unit: str) -> str:
    """``"in [low, high] unit"``, or ``">= low unit"`` when there is no upper bound."""
    if math.isinf(high):
        text = f"{'>' if low_open else '>='} {low:g}"
    else:
        text = f"in {'(' if low_open else '['}{low:g}, {high:g}]"
    return f"{text} {unit}" if unit else text


def check_number(
    name: str, value: Any, low: float, high: float, unit: str = "", *, low_open: bool = False, fix: str = ""
) -> float:
    """``value`` as a float in [low, high] (``(low, high]`` with ``low_open``), or an
    :class:`EnvArgumentError` naming ``name``; bools, strings and NaN/inf are rejected."""
    number = real_or_none(value)
    if (
        number is not None
        and math.isfinite(number)
        and (number > low if low_open else number >= low)
        and number <= high
    ):
        return number
    kind = "" if number is not None else f" (a {type(value).__name__})"
    raise EnvArgumentError(
        f"{name} must be a finite number {_interval(low, high, low_open, unit)}; got {short_repr(value)}{kind}"
        + (f"; {fix}" if fix else "")
    )


def check_whole(name: str, value: Any, low: int, high: int, unit: str = "") -> int:
    """``value`` as an int in [low, high], or an :class:`EnvArgumentError` naming ``name``; bools
    and floats (even 2.0) are rejected."""
    if is_whole_number(value) and low <= value <= high:
        return int(value)
    raise EnvArgumentError(
        f"{name} must be a whole number (an int) in {low}..{high}{' ' + unit if unit else ''}; "
        f"got {short_repr(value)} (a {type(value).__name__})"
    )


def check_bool(name: str, value: Any) -> bool:
    """``value`` as a bool (True/False only), or an :class:`EnvArgumentError` naming ``name``."""
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    raise EnvArgumentError(f"{name} must be True or False; got {short_repr(value)}")


def check_choice(name: str, value: Any, choices: Sequence[str]) -> str:
    """``value`` if it is one of the strings ``choices``, or an :class:`EnvArgumentError` naming ``name``."""
    if isinstance(value, str) and value in choices:
        return value
    raise EnvArgumentError(f"{name} must be one of {' or '.join(repr(c) for c in choices)}; got {short_repr(value)}")


def items_of(name: str, value: Any, what: str) -> list[Any]:
    """The elements of a list, tuple, range or 1-D array, or an error naming ``name``."""
    if isinstance(value, np.ndarray) and value.ndim == 1:
        return value.tolist()
    if isinstance(value, (list, tuple, range)):
        return list(value)
    raise EnvArgumentError(f"{name} must be {what} (a list or tuple); got {short_repr(value)}")


def check_satellites(name: str, value: Any) -> tuple[int, ...] | None:
    """None, or ``value`` as a non-empty tuple of distinct satellite indices >= 0 (the upper
    bound depends on the cluster: see :meth:`~tether_gym.envs.config.TaskConfig.validate`)."""
    if value is None:
        return None
    items = items_of(name, value, "satellite indices, or None for all")
    indices = tuple(check_whole(f"{name}[{k}]", item, 0, 2**31 - 1) for k, item in enumerate(items))
    if not indices:
        raise EnvArgumentError(f"{name} must name at least one satellite (or be None for all)")
    if len(set(indices)) != len(indices):
        raise EnvArgumentError(f"{name} lists a satellite twice: {list(indices)}; list each once")
    return indices


def check_seed(name: str, value: Any) -> int | None:
    """None, or ``value`` as an int >= 0 (a seed for ``numpy.random.default_rng``)."""
    if value is None:
        return None
    if is_whole_number(value) and value >= 0:
        return int(value)
    raise EnvArgumentError(f"{name} must be a whole number >= 0 (an int) or None; got {short_repr(value)}")


#: Longest episode limit, steps: beyond any run, and far inside an int64 step counter.
MAX_EPISODE_STEPS = 2**62


def check_max_episode_steps(value: Any) -> int | None:
    """``max_episode_steps``, the truncation limit of an episode, checked wherever it is set (a
    vector env, the multi-agent engine, an SB3 adapter's ``set_attr``): a whole number of steps
    >= 1, or None or -1 (``gym.make``'s spelling) for no limit, which gives None; anything else
    raises an :class:`EnvArgumentError` naming it."""
    if value is None or (is_whole_number(value) and value == -1):
        return None
    return check_whole("max_episode_steps", value, 1, MAX_EPISODE_STEPS, "steps (or None or -1 for no limit)")


def check_num_envs(value: Any) -> int:
    """``num_envs``, the clusters of one batch (a vector env, the multi-agent engine), as an int
    in ``1..MAX_NUM_ENVS``, or an :class:`EnvArgumentError` naming it."""
    if is_whole_number(value) and 1 <= value <= MAX_NUM_ENVS:
        return int(value)
    raise EnvArgumentError(
        f"num_envs must be a whole number (an int) in 1..{MAX_NUM_ENVS} (run several processes for more); "
        f"got {short_repr(value)} (a {type(value).__name__})"
    )


def check_no_render(render_mode: Any, surface: str, fix: str) -> None:
    """Refuse a ``render_mode`` other than None on a ``surface`` that does not render (a vector
    env, a multi-agent env), with an :class:`EnvArgumentError` naming it and the ``fix``."""
    if render_mode is not None:
        raise EnvArgumentError(
            f"render_mode must be None: {surface} does not render (got {short_repr(render_mode)}); {fix}"
        )


def check_indices(name: str, value: Any, count: int) -> list[int]:
    """``value``, the rows a batch call addresses, as a list of ints in ``0..count - 1``: None
    (every row), one whole number, or a list, tuple, range or 1-D integer array of distinct ones
    (in the order given). Bools and boolean masks, floats, negative, out-of-range or repeated
    indices, strings and anything else raise an :class:`EnvArgumentError` naming ``name``."""
    if value is None:
        return list(range(count))
    allowed = f"None (every row), an int or a list of ints in 0..{count - 1}"
    if is_whole_number(value):
        items = [value]
    elif isinstance(value, (list, tuple, range)) or (
        isinstance(value, np.ndarray) and value.ndim == 1 and value.dtype.kind in "iu"
    ):
        # Distinct rows are at most count: a longer list is refused before it is copied.
        if len(value) > count:
            raise EnvArgumentError(f"{name} must list each of the {count} rows at most once; got {len(value)} indices")
        items = value.tolist() if isinstance(value, np.ndarray) else list(value)
    else:
        kind = " (a boolean mask)" if isinstance(value, np.ndarray) and value.dtype.kind == "b" else ""
        raise EnvArgumentError(f"{name} must be {allowed}; got {short_repr(value)}{kind}")
    bad = [item for item in items if not (is_whole_number(item) and 0 <= item < count)]
    if bad:
        raise EnvArgumentError(f"{name} must be {allowed}; got {short_repr(value)}, with {short_repr(bad[0])}")
    rows = [int(item) for item in items]
    if len(set(rows)) != len(rows):
        raise EnvArgumentError(f"{name} must list each row at most once; got {short_repr(value)}")
    return rows


def as_real_array(name: str, value: Any, what: str) -> np.ndarray:
    """``value`` as a float64 array (any shape; the caller checks the shape and that it is
    finite), or an :class:`EnvArgumentError` naming ``name`` if it is not made of real numbers:
    bools, complex numbers, strings, None, dicts and ragged lists are refused (by
    :func:`tether_gym.limits.real_array`, which also refuses NaN in anything but an array)."""
    if isinstance(value, np.ndarray) and value.dtype.kind in "iuf":  # the hot path of every step
        if value.dtype.itemsize <= 8:  # float16/32/64 and integers: no overflow, no errstate needed
            return np.asarray(value, dtype=np.float64)
        # A longdouble beyond float64 becomes inf, which the caller refuses.
        with np.errstate(over="ignore", invalid="ignore"):
            return value.astype(np.float64, copy=False)
    if isinstance(value, (str, bytes, Mapping)):
        raise EnvArgumentError(f"{name} must be {what}; got {short_repr(value)}")
    return real_array(name, value, EnvArgumentError, allow_inf=True)


def check_actions(name: str, value: Any, shape: tuple[int, ...], axes: str) -> np.ndarray:
    """``value``, the thrust commands of an env step, as a float64 array of ``shape``, or an
    :class:`EnvArgumentError` naming ``name``: not real numbers, a shape other than ``shape``
    (whose ``axes`` the message spells out), or NaN or inf."""
    array = as_real_array(name, value, f"a {shape} array of thrust commands in [-1, 1]")
    if array.shape != shape:
        raise EnvArgumentError(f"{name} must have shape {shape} ({axes}); got shape {array.shape}")
    # The compiled loop wins on one env's action (0.2 us against 1.3 us); numpy's vectorised test
    # on a batch (3.4 us against 4.2 us at 1024 x 12).
    if not (all_finite(array) if array.size <= 256 else np.isfinite(array).all()):
        verb = "contain" if name.endswith("s") else "contains"
        raise EnvArgumentError(f"{name} {verb} NaN or inf; thrust commands must be finite numbers in [-1, 1]")
    return array


def check_difficulty(difficulty: Any) -> float:
    """``difficulty`` as a float in [0, 1], or an :class:`EnvArgumentError`."""
    return check_number(
        "difficulty", difficulty, 0.0, 1.0, fix="1 is the configured task, 0 the nominal cluster at rest"
    )
