"""The vibration-damping task, batched over clusters: actions, observations, rewards, episode ends.

:class:`DampingTask` sits on one :class:`~tether_gym.BatchSimulator` and turns it into the task
every environment shares: the single :class:`~tether_gym.envs.TetherClusterEnv` is a batch of
one, and a vector env is a batch of many.  Nothing here integrates dynamics; it only maps
actions to forces, and states to observations, rewards and end flags.

Every argument a user can give the environments (task settings, seeds, reset options, actions,
difficulty) is checked here, by one helper per kind of value, before any state is built or
changed; a bad one raises :class:`EnvArgumentError` naming it, what is allowed and the fix.  The
ranges of the settings are the named constants below.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike

from tether_gym import _kernels
from tether_gym.cluster import Cluster
from tether_gym.envs import _task_kernels
from tether_gym.envs.contract import (
    END_REASONS,
    REWARD_TERMS,
    SCALARS,
    EndReason,
    ObservationLayout,
    RewardWeights,
    Scalar,
)
from tether_gym.limits import (
    MAX_COORDINATE,
    MAX_SPEED,
    is_real_number,
    is_whole_number,
    real_array,
    short_repr,
    to_float,
)
from tether_gym.simulator import (
    DEFAULT_SAFETY_FACTOR,
    PARALLEL_MIN_BATCH,
    AdvanceStats,
    BatchSimulator,
    SimulatorState,
    TableColumns,
    read_only_rows,
)

__all__ = [
    "END_REASONS",
    "OBSERVATION_LIMIT",
    "SCALARS",
    "TASK_STATE_FIELDS",
    "ClusterScales",
    "DampingTask",
    "EndReason",
    "EnvArgumentError",
    "ObservationLayout",
    "RewardWeights",
    "Scalar",
    "TaskConfig",
    "TaskState",
    "task_from_arguments",
]

ThrustLimit = Literal["per_axis", "magnitude"]
CableFailure = Literal["terminate", "continue"]

RANDOMISABLE = ("masses", "EA", "damping", "N0", "axial_damping")

#: Keys of ``reset(options=...)``: an exact initial state.
RESET_OPTION_KEYS = ("positions", "velocities")

OBSERVATION_LIMIT = _task_kernels.OBSERVATION_LIMIT

# ---------------------------------------------------------------------------------------------
# Ranges of the settings.  Each limit is far beyond any physical tether cluster or thruster; the
# limits only keep the arithmetic finite (energies, rewards, sub-step counts, float32 outputs) and
# the task meaningful.  Limits that depend on the cluster are fractions of its scales
# (:class:`ClusterScales`).

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
#: (:attr:`ClusterScales.speed_limit`): the speed of the stiffest cable mode swinging with that
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

#: A step whose |reward| exceeds this (or is NaN) ends as ``numerics_diverged`` with a finite
#: reward (checked in the task kernel, where it is defined).
REWARD_LIMIT = _task_kernels.REWARD_LIMIT

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


def _real(value: Any) -> float | None:
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
    number = _real(value)
    above = number is not None and (number > low if low_open else number >= low)
    if above and math.isfinite(number) and number <= high:  # type: ignore[arg-type]
        return number  # type: ignore[return-value]
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


def _items(name: str, value: Any, what: str) -> list[Any]:
    """The elements of a list, tuple, range or 1-D array, or an error naming ``name``."""
    if isinstance(value, np.ndarray) and value.ndim == 1:
        return value.tolist()
    if isinstance(value, (list, tuple, range)):
        return list(value)
    raise EnvArgumentError(f"{name} must be {what} (a list or tuple); got {short_repr(value)}")


def check_satellites(name: str, value: Any) -> tuple[int, ...] | None:
    """None, or ``value`` as a non-empty tuple of distinct satellite indices >= 0 (the upper
    bound depends on the cluster: see :meth:`TaskConfig.validate`)."""
    if value is None:
        return None
    items = _items(name, value, "satellite indices, or None for all")
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


def check_difficulty(difficulty: Any) -> float:
    """``difficulty`` as a float in [0, 1], or an :class:`EnvArgumentError`."""
    return check_number(
        "difficulty", difficulty, 0.0, 1.0, fix="1 is the configured task, 0 the nominal cluster at rest"
    )


# ---------------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class ClusterScales:
    """The scales of a cluster that bound the task settings (SI units).

    Attributes:
        shortest_cable, longest_cable: reference lengths L0 of the shortest and longest cable, m.
        critical_step: the simulator's estimated critical step at the nominal state at rest, s.
        damping_step: ``2 m / c`` of the most heavily damped satellite, s (inf without diagonal
            damping); the sub-step also respects it.
        max_substeps: sub-steps the simulator allows in one advance.
    """

    shortest_cable: float
    longest_cable: float
    critical_step: float
    damping_step: float
    max_substeps: int

    @classmethod
    def of(cls, cluster: Cluster, safety_factor: float = DEFAULT_SAFETY_FACTOR) -> ClusterScales:
        """The scales of ``cluster``, from a one-cluster simulator at its nominal state."""
        probe = BatchSimulator(cluster, 1, safety_factor=safety_factor)
        damped = cluster.damping > 0
        damping_step = math.inf
        if damped.any():
            damping_step = float((2.0 * cluster.masses[damped] / cluster.damping[damped]).min())
        return cls(
            shortest_cable=float(cluster.L0.min()),
            longest_cable=float(cluster.L0.max()),
            critical_step=float(probe.critical_time_step()[0]),
            damping_step=damping_step,
            max_substeps=probe.max_substeps,
        )

    @property
    def omega_max(self) -> float:
        """The fastest cable frequency at the nominal state, rad/s."""
        return 2.0 / self.critical_step

    @property
    def displacement_limit(self) -> float:
        """Largest initial-displacement std, m (see ``MAX_DISPLACEMENT_FRACTION``)."""
        return MAX_DISPLACEMENT_FRACTION * self.shortest_cable

    @property
    def speed_limit(self) -> float:
        """Largest initial-velocity std, m/s (see ``MAX_DISPLACEMENT_FRACTION``), and at most
        ``MAX_SPEED / RESET_SPEED_FACTOR`` so that draws and exact resets stay within the
        simulator's speed range."""
        return min(self.displacement_limit * self.omega_max, MAX_SPEED / RESET_SPEED_FACTOR)

    @property
    def deviation_limit(self) -> float:
        """Farthest an exact reset position may lie from its nominal place, m."""
        return MAX_RESET_DEVIATION_CABLES * self.longest_cable


@dataclasses.dataclass(frozen=True)
class TaskConfig:
    """Settings of the damping task (SI units).  Frozen: build a new one to change anything.

    Attributes:
        control_interval: time between actions, s; the simulator sub-steps inside it.
        thrusters: indices of the satellites that carry a thruster (None: all).
        max_thrust: largest thruster force, N; a scalar or one value per thruster.
        thrust_limit: ``"per_axis"`` (each component within +-max_thrust) or ``"magnitude"`` (the
            force vector's norm within max_thrust; a longer command is scaled back).
        initial_displacement: std of the random initial displacement per component, m.
        initial_velocity: std of the random initial velocity per component, m/s.
        vibration_weight: weight of the normalised vibration energy in the cost.
        propellant_weight: weight of the normalised thrust impulse in the cost.
        slack_weight: weight of the fraction of slack cables in the cost.
        failure_penalty: one-off cost when the episode terminates on a failure.
        max_deviation: a satellite farther than this from its nominal place in the cluster
            frame ends the episode (formation lost), m; None: 30 % of the shortest cable; inf:
            never.
        observe_tensions: append cable tensions / breaking load to the observation.
        observation_noise: std of Gaussian noise added to the observation (its own units).
        observed_satellites: satellites whose displacements and velocities are observed (None:
            all).
        randomize: relative spread of domain randomisation per reset, e.g. ``{"masses": 0.2}``
            draws every mass uniformly within +-20 % of nominal; keys among masses, EA, damping,
            N0, axial_damping; spreads in [0, ``MAX_SPREAD``].
        safety_factor: the simulator's sub-step as a fraction of the critical step.
        impulse_magnitude: size of random impulsive kicks, N*s (0: none).  Kicks arrive as a
            Poisson process of rate ``impulse_rate``; each hits one random satellite in a random
            direction, as a force held over one control interval.
        impulse_rate: mean number of kicks per second.
        periodic_amplitude: amplitude of a periodic external force on every satellite, N (0:
            none), ``A d_i sin(2 pi t / periodic_period + phi_i)`` with a random unit direction
            ``d_i`` and phase ``phi_i`` per satellite and episode.
        periodic_period: its period, s.
        thrust_noise: std of Gaussian noise added to each delivered thrust component, as a
            fraction of the thruster's ``max_thrust``.
        thrust_delay: actuation delay in control intervals: an action acts this many steps
            after it is given (zero thrust before).
        thruster_failure_probability: chance that one random thruster fails in an episode; it
            then delivers no thrust from a time drawn uniformly in ``thruster_failure_window``.
        thruster_failure_window: (start, end) of that time, s.
        cable_failure: a cable past its breaking load breaks (and stays broken until reset);
            ``"terminate"`` ends the episode there, ``"continue"`` lets the cluster go on
            without it.
        difficulty: in [0, 1], scales the initial displacement and velocity, the randomisation
            spreads and the disturbances (impulses, periodic force, thrust noise) together, for
            curriculum training; change it between episodes with ``set_difficulty``.  The
            observation units and the reward's energy scale stay those of difficulty 1.

    Every field is checked on construction (type and range; ranges are the module's named
    constants, e.g. ``CONTROL_INTERVAL_RANGE``, ``THRUST_RANGE``, ``MAX_WEIGHT``), and against a
    cluster by :meth:`validate`; a bad value raises :class:`EnvArgumentError` naming the field.
    Sequences are stored as tuples and numbers as Python floats and ints.
    """

    control_interval: float = 0.1
    thrusters: tuple[int, ...] | None = None
    max_thrust: float | tuple[float, ...] = 1.0
    thrust_limit: ThrustLimit = "per_axis"
    initial_displacement: float = 0.05
    initial_velocity: float = 0.1
    vibration_weight: float = 1.0
    propellant_weight: float = 0.1
    slack_weight: float = 0.0
    failure_penalty: float = 100.0
    max_deviation: float | None = None
    observe_tensions: bool = False
    observation_noise: float = 0.0
    observed_satellites: tuple[int, ...] | None = None
    randomize: Mapping[str, float] = dataclasses.field(default_factory=dict)
    safety_factor: float = DEFAULT_SAFETY_FACTOR
    impulse_magnitude: float = 0.0
    impulse_rate: float = 0.05
    periodic_amplitude: float = 0.0
    periodic_period: float = 20.0
    thrust_noise: float = 0.0
    thrust_delay: int = 0
    thruster_failure_probability: float = 0.0
    thruster_failure_window: tuple[float, float] = (0.0, 30.0)
    cable_failure: CableFailure = "terminate"
    difficulty: float = 1.0

    def __post_init__(self) -> None:
        """Check every field on its own and normalise it to plain Python values (tuples, floats,
        ints); the checks against a cluster are in :meth:`validate`."""
        number = check_number
        low, high = CONTROL_INTERVAL_RANGE
        fields: dict[str, Any] = {
            "control_interval": number("control_interval", self.control_interval, low, high, "s"),
            "thrusters": check_satellites("thrusters", self.thrusters),
            "max_thrust": self._checked_thrust(),
            "thrust_limit": check_choice("thrust_limit", self.thrust_limit, ("per_axis", "magnitude")),
            "initial_displacement": number("initial_displacement", self.initial_displacement, 0.0, math.inf, "m"),
            "initial_velocity": number("initial_velocity", self.initial_velocity, 0.0, math.inf, "m/s"),
            "observe_tensions": check_bool("observe_tensions", self.observe_tensions),
            "observation_noise": number("observation_noise", self.observation_noise, 0.0, MAX_OBSERVATION_NOISE),
            "observed_satellites": check_satellites("observed_satellites", self.observed_satellites),
            "randomize": self._checked_randomize(),
            "safety_factor": number(
                "safety_factor", self.safety_factor, 0.0, 1.0, low_open=True, fix="a fraction of the critical step"
            ),
            "impulse_magnitude": number("impulse_magnitude", self.impulse_magnitude, 0.0, MAX_IMPULSE, "N*s"),
            "impulse_rate": number("impulse_rate", self.impulse_rate, 0.0, MAX_IMPULSE_RATE, "1/s"),
            "periodic_amplitude": number(
                "periodic_amplitude", self.periodic_amplitude, 0.0, MAX_PERIODIC_AMPLITUDE, "N"
            ),
            "periodic_period": number("periodic_period", self.periodic_period, 0.0, MAX_TIME, "s", low_open=True),
            "thrust_noise": number(
                "thrust_noise", self.thrust_noise, 0.0, MAX_THRUST_NOISE, fix="a multiple of max_thrust"
            ),
            "thrust_delay": check_whole("thrust_delay", self.thrust_delay, 0, MAX_THRUST_DELAY, "control intervals"),
            "thruster_failure_probability": number(
                "thruster_failure_probability", self.thruster_failure_probability, 0.0, 1.0, fix="a probability"
            ),
            "thruster_failure_window": self._checked_window(),
            "cable_failure": check_choice("cable_failure", self.cable_failure, ("terminate", "continue")),
            "difficulty": check_difficulty(self.difficulty),
        }
        for name in ("vibration_weight", "propellant_weight", "slack_weight", "failure_penalty"):
            fields[name] = number(name, getattr(self, name), 0.0, MAX_WEIGHT)
        if self.max_deviation is not None and _real(self.max_deviation) != math.inf:
            fields["max_deviation"] = number(
                "max_deviation",
                self.max_deviation,
                0.0,
                math.inf,
                "m",
                low_open=True,
                fix="inf never ends an episode on it, None is 30 % of the shortest cable",
            )
        elif self.max_deviation is not None:
            fields["max_deviation"] = math.inf
        if fields["periodic_amplitude"] and fields["periodic_period"] < 2.0 * fields["control_interval"]:
            raise EnvArgumentError(
                f"periodic_period ({fields['periodic_period']:g} s) must be at least two control intervals "
                f"(2 x {fields['control_interval']:g} s): the periodic force is sampled once per interval, so a "
                "shorter period aliases; raise periodic_period or lower control_interval"
            )
        for name, value in fields.items():
            object.__setattr__(self, name, value)

    def _checked_thrust(self) -> float | tuple[float, ...]:
        """``max_thrust`` as a float or a tuple of floats, each within ``THRUST_RANGE``."""
        value = self.max_thrust
        if isinstance(value, np.ndarray) and value.ndim == 0:
            value = value.item()
        scalar = _real(value) is not None
        items = [value] if scalar else _items("max_thrust", value, "a number of N or one number per thruster")
        low, high = THRUST_RANGE
        thrusts = []
        for item in items:
            thrust = _real(item)
            if thrust is None or not (math.isfinite(thrust) and low <= thrust <= high):
                raise EnvArgumentError(
                    f"max_thrust must be finite and > 0 N, in [{low:g}, {high:g}] N per thruster; "
                    f"got {short_repr(self.max_thrust)}"
                )
            thrusts.append(thrust)
        return thrusts[0] if scalar else tuple(thrusts)

    def _checked_randomize(self) -> dict[str, float]:
        """``randomize`` as a dict of known keys to spreads within [0, MAX_SPREAD]."""
        if not isinstance(self.randomize, Mapping):
            raise EnvArgumentError(
                f"randomize must be a dict of relative spreads, e.g. {{'masses': 0.2}}; got {short_repr(self.randomize)}"
            )
        unknown = [key for key in self.randomize if key not in RANDOMISABLE]
        if unknown:
            raise EnvArgumentError(
                f"randomize keys {sorted(map(repr, unknown))} are unknown; use some of {list(RANDOMISABLE)}"
            )
        return {
            key: check_number(f"randomize[{key!r}]", spread, 0.0, MAX_SPREAD, fix="a relative spread (0.2: +-20 %)")
            for key, spread in self.randomize.items()
        }

    def _checked_window(self) -> tuple[float, float]:
        """``thruster_failure_window`` as (start, end) with 0 <= start <= end <= MAX_TIME."""
        usage = f"thruster_failure_window must be (start, end) in s with 0 <= start <= end <= {MAX_TIME:g}"
        items = _items("thruster_failure_window", self.thruster_failure_window, "(start, end) in s")
        times = [_real(item) for item in items]
        if len(times) != 2 or any(t is None or not math.isfinite(t) for t in times):
            raise EnvArgumentError(f"{usage}; got {short_repr(self.thruster_failure_window)}")
        start, end = times
        if not (0.0 <= start <= end <= MAX_TIME):  # type: ignore[operator]
            raise EnvArgumentError(f"{usage}; got {short_repr(self.thruster_failure_window)}")
        return (start, end)  # type: ignore[return-value]

    def validate(self, cluster: Cluster) -> ClusterScales:
        """Check the settings against ``cluster`` and return its :class:`ClusterScales`.

        Raises:
            EnvArgumentError: naming a setting that does not fit the cluster: satellite indices
                beyond it, one ``max_thrust`` per thruster, initial conditions beyond the
                cluster's scales, or a control interval needing more sub-steps than the
                simulator allows.
        """
        if not isinstance(cluster, Cluster):
            raise TypeError(f"cluster must be a tether_gym.Cluster; got {type(cluster).__name__}")
        n = cluster.num_nodes
        for name, indices in (("thrusters", self.thrusters), ("observed_satellites", self.observed_satellites)):
            bad = [i for i in indices or () if i >= n]
            if bad:
                raise EnvArgumentError(
                    f"{name} {bad} are not satellites of this {n}-satellite cluster (valid: 0..{n - 1})"
                )
        count = n if self.thrusters is None else len(self.thrusters)
        if isinstance(self.max_thrust, tuple) and len(self.max_thrust) != count:
            raise EnvArgumentError(
                f"max_thrust must be a scalar or one value per thruster ({count}); got {len(self.max_thrust)} values"
            )
        scales = ClusterScales.of(cluster, self.safety_factor)
        for name, limit, unit in (
            ("initial_displacement", scales.displacement_limit, "m"),
            ("initial_velocity", scales.speed_limit, "m/s"),
        ):
            value = getattr(self, name)
            if value and not (MIN_INITIAL_FRACTION * limit <= value <= limit):
                raise EnvArgumentError(
                    f"{name} must be 0 or in [{MIN_INITIAL_FRACTION * limit:.3g}, {limit:.3g}] {unit} for this cluster; "
                    f"got {value!r}.  The upper limit is a deformation of {MAX_DISPLACEMENT_FRACTION:.0%} of the "
                    f"shortest cable ({scales.shortest_cable:.3g} m)"
                    + (" swinging at the fastest cable frequency" if unit == "m/s" else "")
                    + "; beyond it the cluster folds instead of vibrating.  The lower limit keeps the reward's energy "
                    f"scale (the mean energy at reset) meaningful.  Pass {name} within the range (the default, "
                    f"{TaskConfig.__dataclass_fields__[name].default:g} {unit}, suits the presets' scales)"
                )
        self._check_substeps(scales)
        return scales

    def _check_substeps(self, scales: ClusterScales) -> None:
        """Raise if one control interval needs more sub-steps than the simulator allows, with
        ``SUBSTEP_HEADROOM``, at the smallest sub-step the randomisation can give."""
        spread = self.randomize.get
        # The critical step scales as sqrt(m / EA) and the damping step as m / c: the worst draw is
        # the lightest, stiffest, most damped cluster.
        critical = scales.critical_step * math.sqrt((1.0 - spread("masses", 0.0)) / (1.0 + spread("EA", 0.0)))
        damping = scales.damping_step * (1.0 - spread("masses", 0.0)) / (1.0 + spread("damping", 0.0))
        substep = self.safety_factor * min(critical, damping)
        allowed = scales.max_substeps // SUBSTEP_HEADROOM
        needed = self.control_interval / substep if substep > 0 else math.inf
        if needed <= allowed:
            return
        longest = allowed * substep
        advice = (
            f"lower control_interval to at most {longest:.3g} s, or raise safety_factor"
            if longest >= CONTROL_INTERVAL_RANGE[0]
            else "this cluster is too stiff or too light for the simulator: use softer cables (EA), heavier "
            "satellites (masses) or longer cables (L0), or smaller randomize spreads"
        )
        raise EnvArgumentError(
            f"control_interval={self.control_interval:g} s needs about {needed:.3g} sub-steps of {substep:.3g} s "
            f"(safety_factor {self.safety_factor:g} x this cluster's smallest critical or damping step), more than "
            f"the {allowed} allowed per interval (the simulator's max_substeps={scales.max_substeps} over a "
            f"headroom of {SUBSTEP_HEADROOM} for stretched cables); {advice}"
        )


def task_from_arguments(
    num_clusters: int,
    preset: str = "tetrahedron",
    preset_kwargs: Mapping[str, Any] | None = None,
    cluster: Cluster | None = None,
    **task: Any,
) -> DampingTask:
    """A :class:`DampingTask` from the environments' keyword arguments (see the env docstring):
    a preset name with overrides, or a cluster, plus :class:`TaskConfig` fields.

    Every argument is checked before anything is built: the task settings first (on their own),
    then the cluster, then the settings against the cluster.
    """
    from tether_gym.presets import make_cluster, preset_names

    fields = set(TaskConfig.__dataclass_fields__)
    unknown = sorted(set(task) - fields)
    if unknown:
        raise TypeError(f"unknown argument(s) {unknown}; task arguments are {sorted(fields)}")
    config = TaskConfig(**task)
    if preset_kwargs is not None and not isinstance(preset_kwargs, Mapping):
        raise EnvArgumentError(
            "preset_kwargs must be a dict of the preset's parameters, e.g. {'N0': 1.0}, or None; "
            f"got {short_repr(preset_kwargs)}"
        )
    if cluster is None:
        if not isinstance(preset, str):
            raise EnvArgumentError(f"preset must be a preset name, one of {preset_names()}; got {short_repr(preset)}")
        keys = [key for key in preset_kwargs or {} if not isinstance(key, str)]
        if keys:
            raise EnvArgumentError(f"preset_kwargs keys must be parameter names (strings); got {short_repr(keys)}")
        cluster = make_cluster(preset, **dict(preset_kwargs or {}))
    elif not isinstance(cluster, Cluster):
        raise TypeError(f"cluster must be a tether_gym.Cluster; got {type(cluster).__name__}")
    elif preset_kwargs:
        raise EnvArgumentError(
            "preset_kwargs change a preset, but a cluster was given: build the cluster with the values you want "
            "(Cluster.replace) and pass no preset_kwargs"
        )
    return DampingTask(cluster, num_clusters, config)


#: A cluster's task state beyond the simulator's: what its next step reads (bias, nominal shape,
#: delay line, faults and disturbances of the episode) and what the last step wrote (forces,
#: books, observation, reward terms, end reason, sub-step statistics).  ``stats.*`` name the
#: arrays of the task's :class:`~tether_gym.simulator.AdvanceStats`.
TASK_STATE_FIELDS = (
    "bias",
    "nominal",
    "nominal_strain_energy",
    "force",
    "thrust",
    "impulse",
    "propellant",
    "disturbance",
    "thruster_ok",
    "failure_time",
    "failing_thruster",
    "periodic_direction",
    "periodic_phase",
    "action_queue",
    "observation",
    "scalars",
    "end_reason",
    "stats.substeps",
    "stats.step_min",
    "stats.step_max",
    "stats.status",
    "stats.peak_tension",
)


@dataclasses.dataclass(frozen=True, eq=False)
class TaskState:
    """An exact copy of the state of k clusters of a :class:`DampingTask`, from
    :meth:`DampingTask.snapshot`; :meth:`DampingTask.restore` puts it back into any clusters of a
    task built from the same cluster and :class:`TaskConfig`, which then continue bit-identically
    (given the same actions, and the same generators where disturbances or noise draw).

    Attributes:
        simulator: the clusters' :class:`~tether_gym.simulator.SimulatorState`.
        arrays: every entry of :data:`TASK_STATE_FIELDS`, each of shape (k, ...), read-only copies.
        config: the task's settings; ``cluster``: its nominal cluster; ``difficulty``: its
            difficulty when the state was taken.
    """

    simulator: SimulatorState
    arrays: dict[str, np.ndarray]
    config: TaskConfig
    cluster: Cluster
    difficulty: float

    @property
    def num_clusters(self) -> int:
        """k, the number of clusters held."""
        return self.simulator.num_clusters

    def select(self, rows: Sequence[int] | np.ndarray) -> TaskState:
        """The state of clusters ``rows`` of this state, in that order; rows may repeat (one
        restore then fills a planning batch with n copies of each cluster)."""
        rows = np.asarray(rows, dtype=np.int64)
        return TaskState(
            self.simulator.select(rows), read_only_rows(self.arrays, rows), self.config, self.cluster, self.difficulty
        )


class DampingTask:
    """The damping task over a batch of B clusters of one topology.

    After every :meth:`reset` or :meth:`step` the results sit in preallocated arrays:
    ``observation`` (B, observation_size) float64 (before noise; its parts are the slices of
    :attr:`observation_layout`), ``scalars`` (B, len(Scalar)) (the reward, its terms and the
    energies, ``scalars[:, Scalar.REWARD]`` and so on) and ``end_reason`` (B,) (an
    :class:`EndReason` code; anything but ``RUNNING`` means terminated).  Read them before the
    next call.

    The reward is always finite: a cluster whose reward comes out NaN, infinite or beyond
    ``REWARD_LIMIT`` ends as ``numerics_diverged`` with the reward ``-failure_penalty`` plus its
    (finite) propellant and slack terms.  The observation is always finite (NaN as 0, clipped to
    +-``OBSERVATION_LIMIT``).

    Args:
        cluster: the nominal cluster (its positions are the nominal shape).
        num_clusters: B.
        config: the :class:`TaskConfig`.

    Attributes:
        scales: the cluster's :class:`ClusterScales`, which bound the settings and reset states.
        observation_layout: the :class:`ObservationLayout` of the observation vector.
        perturbed: whether the task draws disturbances, thrust noise or faults (``step`` then
            needs one generator per cluster).

    What the task kernels read and write lives in two tables and a settings vector (their columns
    are named in :mod:`tether_gym.envs._task_kernels`): ``task_node_table`` (B, n, ...),
    ``task_cluster_table`` (B, ...) and ``task_settings``.  The named attributes below are views
    of their columns.
    """

    bias = TableColumns("task_node_table", _task_kernels.BIAS, 3, "(B, n, 3) bias thrust holding the nominal shape, N.")
    nominal = TableColumns("task_node_table", _task_kernels.NOMINAL, 3, "(B, n, 3) nominal positions, m.")
    thrust = TableColumns("task_node_table", _task_kernels.THRUST, 3, "(B, n, 3) the agent's thrust of the step, N.")
    nominal_strain_energy = TableColumns(
        "task_cluster_table", _task_kernels.NOMINAL_STRAIN_ENERGY, 1, "(B,) strain energy at the nominal shape, J."
    )
    impulse = TableColumns("task_cluster_table", _task_kernels.IMPULSE, 1, "(B,) thrust impulse of the step, N*s.")
    scalars = TableColumns(
        "task_cluster_table",
        _task_kernels.SCALAR_COLUMNS,
        _task_kernels.NUM_SCALARS,
        "(B, len(Scalar)) the scalar results of the last step, columns named by Scalar: reward, its terms, energies.",
    )
    observation = TableColumns(
        "task_cluster_table",
        _task_kernels.OBSERVATION_COLUMNS,
        None,
        "(B, observation_size) float64 observation of the last step, before noise.",
    )
    weights = TableColumns(
        "task_settings",
        _task_kernels.VIBRATION_WEIGHT,
        4,
        "(4,) the reward's weights as the kernel applies them: vibration per J, propellant per N*s, slack, "
        "failure penalty (writable).",
    )

    @property
    def force(self) -> np.ndarray:
        """(B, n, 3) external force of the step (bias, thrust, disturbances), N: the simulator's
        applied force."""
        return self.sim.applied_force

    @property
    def stats(self) -> AdvanceStats:
        """What the simulator's last advance did (views; see :attr:`BatchSimulator.last_advance`)."""
        return self.sim.last_advance

    @property
    def reward_weights(self) -> RewardWeights:
        """The reward's weights as the kernels apply them (a copy of :attr:`weights`, named)."""
        return RewardWeights(*(float(w) for w in self.weights))

    def terminated(self) -> np.ndarray:
        """(B,) bool: clusters whose last step ended their episode (``end_reason`` is not
        ``RUNNING``)."""
        return self.end_reason != EndReason.RUNNING

    def __init__(self, cluster: Cluster, num_clusters: int, config: TaskConfig) -> None:
        if not isinstance(cluster, Cluster):
            raise TypeError(f"cluster must be a tether_gym.Cluster; got {type(cluster).__name__}")
        if not isinstance(config, TaskConfig):
            raise TypeError(f"config must be a TaskConfig; got {type(config).__name__}")
        num_clusters = check_whole("num_clusters", num_clusters, 1, MAX_NUM_ENVS)
        self.scales = config.validate(cluster)
        action_size = 3 * (cluster.num_nodes if config.thrusters is None else len(config.thrusters))
        delay_line = num_clusters * config.thrust_delay * action_size
        if delay_line > MAX_DELAY_LINE:
            raise EnvArgumentError(
                f"thrust_delay={config.thrust_delay} with {num_clusters} clusters of {action_size} commands needs "
                f"a delay line of {delay_line:.3g} numbers, more than {MAX_DELAY_LINE:.0e} (800 MB); lower "
                "thrust_delay or num_envs"
            )
        self.cluster = cluster
        self.config = config
        self.num_clusters = B = num_clusters
        n, m = cluster.num_nodes, cluster.num_cables
        self.sim = BatchSimulator(cluster, B, safety_factor=config.safety_factor)
        self.thrusters = np.arange(n) if config.thrusters is None else np.array(config.thrusters, dtype=np.int64)
        self.observed = np.arange(n) if config.observed_satellites is None else np.array(config.observed_satellites)
        self.max_thrust = np.broadcast_to(np.asarray(config.max_thrust, dtype=float), self.thrusters.shape).copy()
        self.action_size = 3 * self.thrusters.size
        self.max_deviation = (
            0.3 * float(cluster.L0.min()) if config.max_deviation is None else float(config.max_deviation)
        )
        # Observation scales: displacements and elongations in units of the initial displacement,
        # velocities in units of the initial velocity; a zero scale (exact resets only) falls back
        # to 0.1 % of the shortest cable and 1 mm/s.
        self.length_scale = config.initial_displacement or 1e-3 * float(cluster.L0.min())
        self.speed_scale = config.initial_velocity or 1e-3
        self.observation_layout = layout = ObservationLayout(self.observed.size, m, config.observe_tensions)
        self.observation_size = layout.size
        tk = _task_kernels
        self.task_node_table = np.zeros((B, n, tk.TASK_NODE_COLUMNS))
        self.task_node_table[:, :, tk.NOMINAL : tk.NOMINAL + 3] = cluster.positions
        self.task_cluster_table = np.zeros((B, tk.TASK_CLUSTER_COLUMNS + self.observation_size))
        for b in range(B):
            self._set_nominal(b, cluster)
        self.full_impulse = (
            float(self.max_thrust.sum())
            * config.control_interval
            * (math.sqrt(3.0) if config.thrust_limit == "per_axis" else 1.0)
        )
        self.task_settings = np.zeros(tk.TASK_SETTINGS)
        for column, value in (
            (tk.CONTROL_INTERVAL, config.control_interval),
            (tk.MAGNITUDE_LIMIT, config.thrust_limit == "magnitude"),
            (tk.LENGTH_SCALE, self.length_scale),
            (tk.SPEED_SCALE, self.speed_scale),
            (tk.DEVIATION_LIMIT, self.max_deviation),
            (tk.TERMINATE_ON_BREAK, config.cable_failure == "terminate"),
            (tk.VIBRATION_WEIGHT, config.vibration_weight),
            (tk.PROPELLANT_WEIGHT, config.propellant_weight / self.full_impulse),
            (tk.SLACK_WEIGHT, config.slack_weight),
            (tk.FAILURE_PENALTY, config.failure_penalty),
            (tk.DISPLACEMENT_AT, layout.displacement.start),
            (tk.VELOCITY_AT, layout.velocity.start),
            (tk.ELONGATION_AT, layout.elongation.start),
            (tk.TENSION_RATIO_AT, layout.tension_ratio.start if layout.tensions else -1),
        ):
            self.task_settings[column] = value
        self.energy_scale = self._energy_scale()
        self.task_settings[tk.VIBRATION_WEIGHT] = config.vibration_weight / self.energy_scale
        self.difficulty = config.difficulty
        self.propellant = np.zeros(B)
        # Disturbances and faults: what each cluster's episode holds, drawn at its reset.
        self.disturbance = np.zeros((B, n, 3))
        self.thruster_ok = np.ones((B, self.thrusters.size), dtype=np.bool_)
        self.failure_time = np.full(B, np.inf)
        self.failing_thruster = np.zeros(B, dtype=np.int64)
        self.periodic_direction = np.zeros((B, n, 3))
        self.periodic_phase = np.zeros((B, n))
        self.action_queue = np.zeros((B, config.thrust_delay, self.action_size))
        self.perturbed = bool(
            config.impulse_magnitude
            or config.periodic_amplitude
            or config.thrust_noise
            or config.thruster_failure_probability
        )
        self.end_reason = np.zeros(B, dtype=np.int64)
        self._all = np.ones(B, dtype=np.bool_)
        self.evaluate()

    # ------------------------------------------------------------------ nominal state
    def _set_nominal(self, index: int, cluster: Cluster) -> None:
        """Cluster ``index`` gets ``cluster``'s parameters, and the bias thrust holding its shape
        at rest in its frame (zero, to round-off, for shapes held by spin or gravity gradient)."""
        self.sim.set_cluster(index, cluster, reset=False)
        self.bias[index] = self.sim.equilibrium_force(cluster.positions[None], indices=[index])[0]
        tension = np.maximum(cluster.N0, 0.0)
        self.nominal_strain_energy[index] = float((0.5 * tension**2 / cluster.stiffness).sum())

    def _energy_scale(self) -> float:
        """Vibration-energy normaliser, J: the mean vibration energy of 64 reset states of the
        nominal cluster drawn with a fixed seed (so it is the same for every env instance)."""
        count = 64
        x0, v0 = self.sample_initial_state(np.random.default_rng(0), count, difficulty=1.0)
        probe = BatchSimulator(self.cluster, count, safety_factor=self.config.safety_factor)
        probe.reset(x0, v0)
        tk = _task_kernels
        task_nodes = np.ascontiguousarray(
            np.broadcast_to(self.task_node_table[0], (count,) + self.task_node_table.shape[1:])
        )
        task_clusters = np.zeros((count, self.task_cluster_table.shape[1]))
        task_clusters[:, tk.NOMINAL_STRAIN_ENERGY] = self.task_cluster_table[0, tk.NOMINAL_STRAIN_ENERGY]
        # The serial kernel even for 64 clusters (the same bits): a single env then never compiles
        # the parallel one.
        self._evaluate_tables(probe, task_nodes, task_clusters, np.zeros(count, dtype=np.int64), parallel=False)
        scale = float(np.mean(task_clusters[:, tk.SCALAR_COLUMNS + Scalar.VIBRATION_ENERGY]))
        return scale if scale > 0 else 1.0

    def _evaluate_tables(
        self,
        sim: BatchSimulator,
        task_nodes: np.ndarray,
        task_clusters: np.ndarray,
        end_reason: np.ndarray,
        parallel: bool,
    ) -> None:
        kernel = _task_kernels.evaluate_parallel if parallel else _task_kernels.evaluate_serial
        kernel(
            self.task_settings,
            sim.cables,
            self.observed,
            sim.node_table,
            sim.cable_table,
            sim.cluster_table,
            sim.counter_table,
            task_nodes,
            task_clusters,
            end_reason,
        )

    def evaluate(self) -> None:
        """Recompute the observation, the scalar results and the end reason of every cluster from
        the current state (``step`` and ``reset`` do it; call it after changing the state or the
        weights directly)."""
        self._evaluate_tables(
            self.sim,
            self.task_node_table,
            self.task_cluster_table,
            self.end_reason,
            parallel=self.num_clusters >= PARALLEL_MIN_BATCH,
        )

    #: The name :meth:`evaluate` had before it was public (kept for existing callers).
    _evaluate = evaluate

    # ------------------------------------------------------------------ snapshots
    def _state_array(self, name: str) -> np.ndarray:
        owner, _, attribute = name.rpartition(".")
        return getattr(self.stats if owner == "stats" else self, attribute)

    def snapshot(self, indices: Sequence[int] | np.ndarray | None = None) -> TaskState:
        """An exact copy of the state of clusters ``indices`` (default all, in order): their
        simulator state and every task array of :data:`TASK_STATE_FIELDS`.  For planning and
        search: snapshot, step candidate actions, restore (see :class:`TaskState`)."""
        simulator = self.sim.snapshot(indices)
        idx = self.sim.cluster_indices(indices)
        arrays = read_only_rows({name: self._state_array(name) for name in TASK_STATE_FIELDS}, idx)
        return TaskState(simulator, arrays, self.config, self.cluster, self.difficulty)

    def restore(self, state: TaskState, indices: Sequence[int] | np.ndarray | None = None) -> None:
        """Put ``state`` (k clusters) into clusters ``indices`` (default: the first k); a state of
        one cluster may fill any number of clusters (cloning).  The state must come from a task
        with an equal cluster, :class:`TaskConfig` and difficulty; nothing changes when it is
        refused.  The restored clusters continue bit-identically to the originals."""
        if not isinstance(state, TaskState):
            raise TypeError(f"state must be a TaskState from DampingTask.snapshot; got {type(state).__name__}")
        if state.config != self.config or state.cluster != self.cluster:
            raise ValueError(
                "state was taken from a task with another cluster or TaskConfig; restore it into a task built "
                "from the same cluster and settings"
            )
        if state.difficulty != self.difficulty:
            raise ValueError(
                f"state was taken at difficulty {state.difficulty}, this task is at {self.difficulty}; call "
                f"set_difficulty({state.difficulty}) first"
            )
        idx = np.arange(state.num_clusters) if indices is None else self.sim.cluster_indices(indices)
        self.sim.restore(state.simulator, idx)  # validates the indices and the cluster count first
        source = np.zeros(idx.size, dtype=np.int64) if state.num_clusters == 1 else np.arange(idx.size)
        for name in TASK_STATE_FIELDS:
            self._state_array(name)[idx] = state.arrays[name][source]

    # ------------------------------------------------------------------ reset
    def sample_initial_state(
        self, rng: np.random.Generator, count: int, difficulty: float | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """(count, n, 3) positions and velocities: the nominal shape plus Gaussian displacements and
        velocities of the configured scales times ``difficulty`` (default: the task's), with the
        rigid part removed (centroid kept in place, zero linear and angular momentum relative to
        the frame), so that the motion is pure deformation."""
        n = self.cluster.num_nodes
        shape = (count, n, 3)
        scale = self.difficulty if difficulty is None else difficulty
        displacement = scale * self.config.initial_displacement * rng.standard_normal(shape)
        velocity = scale * self.config.initial_velocity * rng.standard_normal(shape)
        masses = self.cluster.masses[None, :, None]
        displacement -= (masses * displacement).sum(axis=1, keepdims=True) / masses.sum(axis=1, keepdims=True)
        x0 = self.cluster.positions[None] + displacement
        _task_kernels.remove_rigid_velocity(
            x0, velocity, np.ascontiguousarray(np.broadcast_to(self.cluster.masses, (count, n)))
        )
        return x0, velocity

    def check_reset_state(self, options: Any, shape: tuple[int, ...]) -> tuple[np.ndarray | None, np.ndarray | None]:
        """The exact initial state given as reset options, checked, without touching any state.

        Args:
            options: None or a dict with ``"positions"`` (m, in the cluster's frame) and/or
                ``"velocities"`` (m/s, relative to the frame), each None or an array of ``shape``:
                (n, 3) for one cluster or (k, n, 3) for k.

        Returns:
            ``(positions, velocities)``, each None or a (k, n, 3) float64 array.

        Raises:
            EnvArgumentError: naming the option: not a dict, an unknown key, not numbers, the
                wrong shape, NaN or inf, a satellite farther than ``scales.deviation_limit`` from
                its nominal place, a cable shorter than ``MIN_CABLE_LENGTH_FRACTION`` of its L0,
                or a speed beyond ``RESET_SPEED_FACTOR * scales.speed_limit``.
        """
        if options is None:
            return None, None
        if not isinstance(options, Mapping):
            raise EnvArgumentError(
                f"options must be a dict such as {{'positions': X0, 'velocities': V0}} or None; got {short_repr(options)}"
            )
        unknown = sorted(set(options) - set(RESET_OPTION_KEYS), key=repr)
        if unknown:
            raise EnvArgumentError(f"unknown reset option(s) {unknown}; accepted options are {list(RESET_OPTION_KEYS)}")
        n = self.cluster.num_nodes
        arrays: dict[str, np.ndarray | None] = {}
        for key, unit in zip(RESET_OPTION_KEYS, ("m", "m/s")):
            name = f"reset option {key!r}"
            if options.get(key) is None:
                arrays[key] = None
                continue
            array = as_real_array(name, options[key], f"an {shape} array in {unit}")
            if array.shape != shape:
                raise EnvArgumentError(f"{name} must be an {shape} array in {unit}; got shape {array.shape}")
            if not np.isfinite(array).all():
                raise EnvArgumentError(f"{name} contains NaN or inf; every entry must be a finite number ({unit})")
            arrays[key] = array.reshape(-1, n, 3)
        positions, velocities = arrays["positions"], arrays["velocities"]
        scales = self.scales
        for key, array, limit, unit in (
            ("positions", positions, MAX_COORDINATE, "m"),
            ("velocities", velocities, MAX_SPEED, "m/s"),
        ):
            if array is not None and not np.abs(array).max() <= limit:
                raise EnvArgumentError(
                    f"reset option {key!r} must have every entry within +-{limit:g} {unit} (the simulator's range); "
                    f"got {float(np.abs(array).max()):.3g} {unit}"
                )
        if positions is not None:
            deviation = float(np.linalg.norm(positions - self.cluster.positions, axis=-1).max())
            if not deviation <= scales.deviation_limit:
                raise EnvArgumentError(
                    f"reset option 'positions' puts a satellite {deviation:.3g} m from its nominal place; the "
                    f"limit is {scales.deviation_limit:.3g} m ({MAX_RESET_DEVIATION_CABLES:g} lengths of the "
                    "longest cable).  Positions are in the cluster's frame, m; the nominal shape is "
                    "env.unwrapped.cluster.positions"
                )
            cables = self.cluster.cables
            lengths = np.linalg.norm(positions[:, cables[:, 1]] - positions[:, cables[:, 0]], axis=-1)
            short = lengths < MIN_CABLE_LENGTH_FRACTION * self.cluster.L0
            if short.any():
                c = int(np.argwhere(short)[0, 1])
                raise EnvArgumentError(
                    f"reset option 'positions' puts satellites {tuple(cables[c].tolist())}, the ends of cable "
                    f"{c}, on top of each other ({float(lengths[short][0]):.3g} m apart); a cable's direction, and "
                    "so its force, needs distinct end positions"
                )
        if velocities is not None:
            speed = float(np.linalg.norm(velocities, axis=-1).max())
            limit = RESET_SPEED_FACTOR * scales.speed_limit
            if not speed <= limit:
                raise EnvArgumentError(
                    f"reset option 'velocities' gives a satellite {speed:.3g} m/s; the limit is {limit:.3g} "
                    f"m/s ({RESET_SPEED_FACTOR:g} x the initial_velocity limit of this cluster).  Velocities are "
                    "relative to the cluster's frame, m/s"
                )
        return positions, velocities

    def reset(
        self,
        rngs: Sequence[np.random.Generator],
        indices: np.ndarray,
        positions: ArrayLike | None = None,
        velocities: ArrayLike | None = None,
    ) -> None:
        """Start new episodes for clusters ``indices``, cluster ``indices[k]`` drawing from
        ``rngs[k]``: randomise its parameters (if configured), then draw its initial conditions,
        or use the given (k, n, 3) positions/velocities; then draw its episode's disturbances and
        faults (if configured).  Each cluster draws only from its own generator, so a cluster
        reset in a batch matches the same cluster reset alone.  Exact states must come from
        :meth:`check_reset_state` (the envs call it before they reseed anything)."""
        for rng, b in zip(rngs, indices):
            if self.config.randomize:
                self._set_nominal(int(b), self._randomised_cluster(rng))
            elif self.sim.clusters[b] is not self.cluster:
                self._set_nominal(int(b), self.cluster)
        if positions is None and velocities is None:
            states = [self.sample_initial_state(rng, 1) for rng in rngs]
            x0 = np.concatenate([x for x, _ in states])
            v0 = np.concatenate([v for _, v in states])
        else:
            x0 = self.nominal[indices] if positions is None else positions
            v0 = velocities
        self.sim.reset(x0, v0, indices=indices)
        self.propellant[indices] = 0.0
        self.thrust[indices] = 0.0
        self.impulse[indices] = 0.0
        self.disturbance[indices] = 0.0
        self.thruster_ok[indices] = True
        self.action_queue[indices] = 0.0
        if self.perturbed:
            for rng, b in zip(rngs, indices):
                self._draw_episode_faults(rng, int(b))
        self.evaluate()

    def _draw_episode_faults(self, rng: np.random.Generator, b: int) -> None:
        """Draw cluster ``b``'s periodic-force directions and phases and its thruster failure."""
        config = self.config
        n = self.cluster.num_nodes
        if config.periodic_amplitude:
            direction = rng.standard_normal((n, 3))
            self.periodic_direction[b] = direction / np.linalg.norm(direction, axis=1, keepdims=True)
            self.periodic_phase[b] = rng.uniform(0.0, 2.0 * math.pi, n)
        self.failure_time[b] = math.inf
        if config.thruster_failure_probability and rng.random() < config.thruster_failure_probability:
            self.failure_time[b] = rng.uniform(*config.thruster_failure_window)
            self.failing_thruster[b] = rng.integers(self.thrusters.size)

    def set_difficulty(self, difficulty: float) -> None:
        """Scale initial conditions, randomisation and disturbances by ``difficulty`` in [0, 1]
        from the next reset on (see :class:`TaskConfig`)."""
        self.difficulty = check_difficulty(difficulty)

    def _randomised_cluster(self, rng: np.random.Generator) -> Cluster:
        changes: dict[str, Any] = {}
        for key in RANDOMISABLE:  # fixed order: the draws do not depend on dict order
            spread = self.difficulty * self.config.randomize.get(key, 0.0)
            if spread:
                nominal = getattr(self.cluster, key)
                changes[key] = nominal * rng.uniform(1 - spread, 1 + spread, nominal.shape)
        if "EA" in changes:  # keep the nominal reference lengths
            changes["L0"] = self.cluster.L0
        return self.cluster.replace(**changes)

    # ------------------------------------------------------------------ step
    def step(
        self,
        actions: np.ndarray,
        active: np.ndarray | None = None,
        rngs: Sequence[np.random.Generator] | None = None,
    ) -> None:
        """Apply (B, action_size) float64 actions for one control interval (bias thrust added) to
        the ``active`` clusters (default all), then evaluate observation, reward and end flags.

        Commands are clipped to [-1, 1]; with the magnitude limit a command longer than 1 is
        scaled back to length 1; then they are multiplied by each thruster's ``max_thrust``.
        With a thrust delay the actions applied are those given ``thrust_delay`` steps earlier.
        Disturbances and thrust noise of cluster b draw from ``rngs[b]`` (needed only when they
        are configured).
        """
        mask = self._all if active is None else active
        config = self.config
        interval = config.control_interval
        if config.thrust_delay:
            given = actions
            actions = np.where(mask[:, None], self.action_queue[:, 0], 0.0)
            self.action_queue[mask] = np.concatenate([self.action_queue[mask, 1:], given[mask, None]], axis=1)
        if config.thruster_failure_probability:
            failing = np.flatnonzero(mask & (self.sim.time >= self.failure_time))
            self.thruster_ok[failing, self.failing_thruster[failing]] = False
            if not self.thruster_ok.all():
                actions = (actions.reshape(self.num_clusters, -1, 3) * self.thruster_ok[:, :, None]).reshape(
                    actions.shape
                )
        _task_kernels.command_forces(
            self.task_settings,
            np.ascontiguousarray(actions),
            self.thrusters,
            self.max_thrust,
            mask,
            self.task_node_table,
            self.sim.node_table,
            self.task_cluster_table,
        )
        if self.perturbed:
            if rngs is None:
                raise ValueError("this task draws disturbances or thrust noise: pass step(..., rngs=[one per cluster])")
            self._disturb(mask, rngs)
        self.sim.advance_unchecked(interval, mask)
        self.propellant[mask] += self.impulse[mask]
        self.evaluate()

    def _disturb(self, mask: np.ndarray, rngs: Sequence[np.random.Generator]) -> None:
        """Add this interval's disturbance force and thrust noise to the active clusters' force.

        Each cluster makes at most one draw per kind from its own generator (so it gets the same
        numbers in any batch); the rest is vectorised over the batch."""
        config = self.config
        interval = config.control_interval
        n = self.cluster.num_nodes
        active = np.flatnonzero(mask)
        scale = self.difficulty
        disturbance = np.zeros((active.size, n, 3))
        if config.periodic_amplitude:
            midpoint = self.sim.time[active] + 0.5 * interval
            wave = np.sin(2.0 * math.pi * midpoint[:, None] / config.periodic_period + self.periodic_phase[active])
            disturbance += scale * config.periodic_amplitude * wave[:, :, None] * self.periodic_direction[active]
        if config.impulse_magnitude:
            # Per cluster: whether a kick comes, which satellite, and a direction uniform on the sphere.
            draws = np.array([rngs[b].random(4) for b in active]).reshape(-1, 4)
            kicked = np.flatnonzero(draws[:, 0] < 1.0 - math.exp(-config.impulse_rate * interval))
            node = np.minimum((draws[kicked, 1] * n).astype(np.int64), n - 1)
            z = 2.0 * draws[kicked, 2] - 1.0
            azimuth = 2.0 * math.pi * draws[kicked, 3]
            radius = np.sqrt(1.0 - z * z)
            direction = np.stack([radius * np.cos(azimuth), radius * np.sin(azimuth), z], axis=1)
            disturbance[kicked, node] += scale * config.impulse_magnitude / interval * direction
        if config.thrust_noise:
            k = self.thrusters.size
            noise = np.array([rngs[b].standard_normal((k, 3)) for b in active]).reshape(-1, k, 3)
            noise *= (scale * config.thrust_noise * self.max_thrust[None, :] * self.thruster_ok[active])[:, :, None]
            self.thrust[active[:, None], self.thrusters[None, :]] += noise
            self.force[active[:, None], self.thrusters[None, :]] += noise
        self.disturbance[active] = disturbance
        self.force[active] += disturbance

    # ------------------------------------------------------------------ results
    def observe(self, rngs: Sequence[np.random.Generator], indices: np.ndarray | None = None) -> np.ndarray:
        """(k, observation_size) float32 observation of clusters ``indices`` (default all B);
        with noise configured, the noise of ``indices[k]`` comes from ``rngs[k]``."""
        observation = self.observation if indices is None else self.observation[indices]
        if self.config.observation_noise == 0:
            return observation.astype(np.float32)
        noise = np.stack([rng.standard_normal(self.observation_size) for rng in rngs])
        noisy = observation + self.config.observation_noise * noise
        return np.clip(noisy, -OBSERVATION_LIMIT, OBSERVATION_LIMIT).astype(np.float32)

    def info_arrays(self, stepped: bool = True) -> dict[str, np.ndarray]:
        """Every ``info`` quantity for the whole batch: (B,) or (B, ...) arrays, some of them views
        of the task's buffers (copy what you keep).  ``stepped=False`` (after a reset) leaves out
        the per-step quantities.  ``end_reason`` is the code; see ``END_REASONS``."""
        sim = self.sim
        values = dict(zip(SCALARS, self.scalars.T, strict=True))
        kinetic, strain, frame_potential = values["kinetic_energy"], values["strain_energy"], values["frame_potential"]
        arrays: dict[str, np.ndarray] = {
            "time": sim.time,
            "vibration_energy": values["vibration_energy"],
            "kinetic_energy": kinetic,
            "strain_energy": strain,
            "dissipated_energy": sim.dissipated,
            "external_work": sim.work,
            "frame_potential": frame_potential,
            "energy_residual": kinetic + strain + frame_potential - sim.initial_energy + sim.dissipated - sim.work,
            "tensions": sim.tension,
            "slack_count": np.rint(values["slack_fraction"] * self.cluster.num_cables).astype(np.int64),
            "max_deviation": values["max_deviation"],
            "propellant_used": self.propellant,
            "thrust": self.thrust,
            "disturbance": self.disturbance,
            "thruster_ok": self.thruster_ok,
            "broken_cables": sim.broken,
        }
        if stepped:
            stats = self.stats
            arrays.update(
                substeps=stats.substeps,
                step_min=stats.step_min,
                step_max=stats.step_max,
                peak_tension=stats.peak_tension,
                **{term.key: values[term.key] for term in REWARD_TERMS},
                end_reason=self.end_reason,
            )
        return arrays

    def info(self, index: int, stepped: bool = True) -> dict[str, Any]:
        """The ``info`` dict of cluster ``index``: the values of :meth:`info_arrays` at that index
        as Python scalars and array copies, with ``end_reason`` as its name.  Built directly
        (not through info_arrays) because the single env's step rate depends on it; a test keeps
        the two identical."""
        sim = self.sim
        k = _kernels
        tk = _task_kernels
        task_row = self.task_cluster_table[index]
        values = dict(zip(SCALARS, task_row[tk.SCALAR_COLUMNS : tk.OBSERVATION_COLUMNS].tolist(), strict=True))
        cluster = sim.cluster_table[index].tolist()
        cables = sim.cable_table[index]
        kinetic, strain, frame_potential = values["kinetic_energy"], values["strain_energy"], values["frame_potential"]
        dissipated, work = cluster[k.DISSIPATED], cluster[k.WORK]
        info: dict[str, Any] = {
            "time": cluster[k.TIME],
            "vibration_energy": values["vibration_energy"],
            "kinetic_energy": kinetic,
            "strain_energy": strain,
            "dissipated_energy": dissipated,
            "external_work": work,
            "frame_potential": frame_potential,
            "energy_residual": kinetic + strain + frame_potential - cluster[k.INITIAL_ENERGY] + dissipated - work,
            "tensions": cables[:, k.TENSION].copy(),
            "slack_count": round(values["slack_fraction"] * self.cluster.num_cables),
            "max_deviation": values["max_deviation"],
            "propellant_used": float(self.propellant[index]),
            "thrust": self.task_node_table[index, :, tk.THRUST : tk.THRUST + 3].copy(),
            "disturbance": self.disturbance[index].copy(),
            "thruster_ok": self.thruster_ok[index].copy(),
            "broken_cables": cables[:, k.INTACT] == 0.0,
        }
        if stepped:
            info["substeps"] = int(sim.counter_table[index, k.SUBSTEPS])
            info["step_min"] = cluster[k.STEP_MIN]
            info["step_max"] = cluster[k.STEP_MAX]
            info["peak_tension"] = cables[:, k.PEAK_TENSION].copy()
            for term in REWARD_TERMS:
                info[term.key] = values[term.key]
            info["end_reason"] = END_REASONS[self.end_reason[index]]
        return info
