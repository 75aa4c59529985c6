"""The settings of the damping task: :class:`TaskConfig`, grouped into reward, initial state,
disturbances and faults, and the scales of a cluster that bound them.

A :class:`TaskConfig` is built from the flat keyword arguments the environments take
(``gym.make(id, vibration_weight=2.0, thrust_noise=0.1)``) or from its groups
(:meth:`TaskConfig.from_groups`); either way every value is checked on construction, and against
a cluster by :meth:`TaskConfig.validate`.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Mapping
from typing import Any, Literal

import numpy as np

from tether_gym.cluster import Cluster
from tether_gym.envs.arguments import (
    CONTROL_INTERVAL_RANGE,
    MAX_DISPLACEMENT_FRACTION,
    MAX_OBSERVATION_NOISE,
    MAX_RESET_DEVIATION_CABLES,
    MAX_SPREAD,
    MAX_WEIGHT,
    MIN_INITIAL_FRACTION,
    RESET_SPEED_FACTOR,
    SUBSTEP_HEADROOM,
    THRUST_RANGE,
    EnvArgumentError,
    check_bool,
    check_choice,
    check_difficulty,
    check_number,
    check_satellites,
    items_of,
    real_or_none,
)
from tether_gym.envs.disturbances import CableFailure, DisturbanceConfig, FaultConfig
from tether_gym.limits import MAX_SPEED, short_repr
from tether_gym.simulator import (
    DEFAULT_SAFETY_FACTOR,
    BatchSimulator,
    UnstableSafetyFactorWarning,
    check_safety_factor,
)

__all__ = [
    "RANDOMISABLE",
    "TASK_CONFIG_GROUPS",
    "ClusterScales",
    "DisturbanceConfig",
    "FaultConfig",
    "InitialStateConfig",
    "RewardConfig",
    "TaskConfig",
    "ThrustLimit",
    "ThrustMode",
]

ThrustLimit = Literal["per_axis", "magnitude"]
ThrustMode = Literal["continuous", "on_off"]

#: The cluster parameters domain randomisation may draw.
RANDOMISABLE = ("masses", "EA", "damping", "N0", "axial_damping")


def env_simulator(
    cluster: Cluster, count: int, safety_factor: float, allow_unstable_safety_factor: bool
) -> BatchSimulator:
    """A :class:`BatchSimulator` of ``count`` copies of ``cluster`` for a task whose config has
    already checked (and warned about) its safety factor: the config's one warning is enough."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UnstableSafetyFactorWarning)
        return BatchSimulator(
            cluster, count, safety_factor=safety_factor, allow_unstable_safety_factor=allow_unstable_safety_factor
        )


@dataclasses.dataclass(frozen=True)
class ClusterScales:
    """The scales of a cluster that bound the task settings (SI units).

    Attributes:
        shortest_cable, longest_cable: reference lengths L0 of the shortest and longest cable, m
            (a tether with beads counts as one cable of its whole length).
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
    def of(
        cls, cluster: Cluster, safety_factor: float = DEFAULT_SAFETY_FACTOR, allow_unstable_safety_factor: bool = False
    ) -> ClusterScales:
        """The scales of ``cluster``, from a one-cluster simulator at its nominal state."""
        probe = env_simulator(cluster, 1, safety_factor, allow_unstable_safety_factor)
        damped = cluster.damping > 0
        damping_step = math.inf
        if damped.any():
            damping_step = float((2.0 * cluster.masses[damped] / cluster.damping[damped]).min())
        # A tether with beads counts as one line of its whole length, not as its segments.
        lines = cluster.L0
        if cluster.tethers:
            plain = cluster.L0[: cluster.num_cables - sum(spec.segments for spec in cluster.tethers)]
            lines = np.concatenate([plain, [float(spec.L0 or 0.0) for spec in cluster.tethers]])
        return cls(
            shortest_cable=float(lines.min()),
            longest_cable=float(lines.max()),
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
class RewardConfig:
    """The reward's weights; see the env docstring's Rewards.

    Attributes:
        vibration_weight: weight of the normalised vibration energy in the cost.
        propellant_weight: weight of the normalised thrust impulse in the cost.
        slack_weight: weight of the fraction of slack cables in the cost.
        failure_penalty: one-off cost when the episode terminates on a failure.
    """

    vibration_weight: float = 1.0
    propellant_weight: float = 0.1
    slack_weight: float = 0.0
    failure_penalty: float = 100.0

    def __post_init__(self) -> None:
        for field in dataclasses.fields(self):
            object.__setattr__(self, field.name, check_number(field.name, getattr(self, field.name), 0.0, MAX_WEIGHT))


@dataclasses.dataclass(frozen=True)
class InitialStateConfig:
    """How each episode starts (SI units); see the env docstring's Starting State.

    Attributes:
        initial_displacement: std of the random initial displacement per component, m.
        initial_velocity: std of the random initial velocity per component, m/s.
        randomize: relative spread of domain randomisation per reset, e.g. ``{"masses": 0.2}``
            draws every mass uniformly within +-20 % of nominal; keys among masses, EA, damping,
            N0, axial_damping; spreads in [0, ``MAX_SPREAD``].
    """

    initial_displacement: float = 0.05
    initial_velocity: float = 0.1
    randomize: Mapping[str, float] = dataclasses.field(default_factory=dict)

    def __post_init__(self) -> None:
        number = check_number
        fields = {
            "initial_displacement": number("initial_displacement", self.initial_displacement, 0.0, math.inf, "m"),
            "initial_velocity": number("initial_velocity", self.initial_velocity, 0.0, math.inf, "m/s"),
            "randomize": self._checked_randomize(),
        }
        for name, value in fields.items():
            object.__setattr__(self, name, value)

    def _checked_randomize(self) -> dict[str, float]:
        """``randomize`` as a dict of known keys to spreads within [0, MAX_SPREAD]."""
        if not isinstance(self.randomize, Mapping):
            raise EnvArgumentError(
                "randomize must be a dict of relative spreads, e.g. {'masses': 0.2}; "
                f"got {short_repr(self.randomize)}"
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

    def randomised(self, cluster: Cluster, rng: np.random.Generator, difficulty: float) -> Cluster:
        """``cluster`` with its randomised parameters drawn from ``rng``, each within
        ``+-difficulty * spread`` of nominal (the reference lengths stay nominal)."""
        changes: dict[str, Any] = {}
        for key in RANDOMISABLE:  # fixed order: the draws do not depend on dict order
            spread = difficulty * self.randomize.get(key, 0.0)
            if spread:
                nominal = getattr(cluster, key)
                changes[key] = nominal * rng.uniform(1 - spread, 1 + spread, nominal.shape)
        if "EA" in changes:  # keep the nominal reference lengths
            changes["L0"] = cluster.L0
        return cluster.replace(**changes)


@dataclasses.dataclass(frozen=True)
class TaskConfig:
    """Settings of the damping task (SI units).  Frozen: build a new one to change anything.

    The fields are flat, as the environments take them as keyword arguments; the settings of the
    reward, the initial state, the disturbances and the faults are also available as groups,
    :attr:`reward` (:class:`RewardConfig`), :attr:`initial_state` (:class:`InitialStateConfig`),
    :attr:`disturbances` (:class:`~tether_gym.envs.disturbances.DisturbanceConfig`) and
    :attr:`faults` (:class:`~tether_gym.envs.disturbances.FaultConfig`), whose docstrings
    describe their fields; :meth:`from_groups` builds a config from them.

    Attributes:
        control_interval: time between actions, s; the simulator sub-steps inside it.
        thrusters: indices of the satellites that carry a thruster (None: all).
        max_thrust: largest thruster force, N; a scalar or one value per thruster.
        thrust_limit: ``"per_axis"`` (each component within +-max_thrust) or ``"magnitude"`` (the
            force vector's norm within max_thrust; a longer command is scaled back).
        thrust_mode: ``"continuous"`` (any thrust within the limit) or ``"on_off"``: each axis of
            a thruster fires at full thrust or not at all for the whole control interval, as
            cold-gas and resistojet thrusters do. A command component of 0.5 or more in
            magnitude fires that axis along its sign; the control interval is the shortest
            firing, so each axis's minimum impulse bit is ``max_thrust * control_interval``.
            The limit then applies to the fired vector (``"magnitude"``: scaled back to
            ``max_thrust``).
        max_deviation: a satellite farther than this from its nominal place in the cluster
            frame ends the episode (formation lost), m; None: 30 % of the shortest cable; inf:
            never.
        observe_tensions: append cable tensions / breaking load to the observation.
        observe_commands: append the commands given but not acting yet (the ``thrust_delay``
            line, oldest first), as a flight computer knows what it sent; needs
            ``thrust_delay`` > 0.  With it the delayed task's state is observed (a Markov
            observation), without it a controller has to remember its own commands.
        observation_noise: std of Gaussian noise added to the observation (its own units).
        observed_satellites: satellites whose displacements and velocities are observed (None:
            all).
        safety_factor: the simulator's sub-step as a fraction of the critical step, in (0, 0.2]
            (:data:`~tether_gym.simulator.MAX_STABLE_SAFETY_FACTOR`).
        allow_unstable_safety_factor: accept a safety_factor up to 1, above the range where the
            energy stays bounded through slack and snap, with an
            :class:`~tether_gym.simulator.UnstableSafetyFactorWarning`.
        difficulty: in [0, 1], scales the initial displacement and velocity, the randomisation
            spreads and the disturbances (impulses, periodic force, thrust noise) together, for
            curriculum training; change it between episodes with ``set_difficulty``.  The
            observation units and the reward's energy scale stay those of difficulty 1.
        vibration_weight, propellant_weight, slack_weight, failure_penalty: :class:`RewardConfig`.
        initial_displacement, initial_velocity, randomize: :class:`InitialStateConfig`.
        impulse_magnitude, impulse_rate, periodic_amplitude, periodic_period, thrust_noise,
            thrust_delay: :class:`~tether_gym.envs.disturbances.DisturbanceConfig`.
        thruster_failure_probability, thruster_failure_window, cable_failure:
            :class:`~tether_gym.envs.disturbances.FaultConfig`.

    Every field is checked on construction (type and range; ranges are the named constants of
    :mod:`tether_gym.envs.arguments`, e.g. ``CONTROL_INTERVAL_RANGE``, ``THRUST_RANGE``,
    ``MAX_WEIGHT``), and against a cluster by :meth:`validate`; a bad value raises
    :class:`~tether_gym.envs.EnvArgumentError` naming the field.  Sequences are stored as tuples
    and numbers as Python floats and ints.
    """

    control_interval: float = 0.1
    thrusters: tuple[int, ...] | None = None
    max_thrust: float | tuple[float, ...] = 1.0
    thrust_limit: ThrustLimit = "per_axis"
    thrust_mode: ThrustMode = "continuous"
    initial_displacement: float = InitialStateConfig.initial_displacement
    initial_velocity: float = InitialStateConfig.initial_velocity
    vibration_weight: float = RewardConfig.vibration_weight
    propellant_weight: float = RewardConfig.propellant_weight
    slack_weight: float = RewardConfig.slack_weight
    failure_penalty: float = RewardConfig.failure_penalty
    max_deviation: float | None = None
    observe_tensions: bool = False
    observe_commands: bool = False
    observation_noise: float = 0.0
    observed_satellites: tuple[int, ...] | None = None
    randomize: Mapping[str, float] = dataclasses.field(default_factory=dict)
    safety_factor: float = DEFAULT_SAFETY_FACTOR
    allow_unstable_safety_factor: bool = False
    impulse_magnitude: float = DisturbanceConfig.impulse_magnitude
    impulse_rate: float = DisturbanceConfig.impulse_rate
    periodic_amplitude: float = DisturbanceConfig.periodic_amplitude
    periodic_period: float = DisturbanceConfig.periodic_period
    thrust_noise: float = DisturbanceConfig.thrust_noise
    thrust_delay: int = DisturbanceConfig.thrust_delay
    thruster_failure_probability: float = FaultConfig.thruster_failure_probability
    thruster_failure_window: tuple[float, float] = FaultConfig.thruster_failure_window
    cable_failure: CableFailure = FaultConfig.cable_failure
    difficulty: float = 1.0

    def __post_init__(self) -> None:
        """Check every field on its own and normalise it to plain Python values (tuples, floats,
        ints), building the groups on the way; the checks against a cluster are in
        :meth:`validate`."""
        number = check_number
        low, high = CONTROL_INTERVAL_RANGE
        fields: dict[str, Any] = {
            "control_interval": number("control_interval", self.control_interval, low, high, "s"),
            "thrusters": check_satellites("thrusters", self.thrusters),
            "max_thrust": self._checked_thrust(),
            "thrust_limit": check_choice("thrust_limit", self.thrust_limit, ("per_axis", "magnitude")),
            "thrust_mode": check_choice("thrust_mode", self.thrust_mode, ("continuous", "on_off")),
            "observe_tensions": check_bool("observe_tensions", self.observe_tensions),
            "observe_commands": check_bool("observe_commands", self.observe_commands),
            "observation_noise": number("observation_noise", self.observation_noise, 0.0, MAX_OBSERVATION_NOISE),
            "observed_satellites": check_satellites("observed_satellites", self.observed_satellites),
            "safety_factor": number(
                "safety_factor", self.safety_factor, 0.0, 1.0, low_open=True, fix="a fraction of the critical step"
            ),
            "allow_unstable_safety_factor": check_bool(
                "allow_unstable_safety_factor", self.allow_unstable_safety_factor
            ),
            "difficulty": check_difficulty(self.difficulty),
        }
        if self.max_deviation is not None and real_or_none(self.max_deviation) != math.inf:
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
        for group_name, group_type in TASK_CONFIG_GROUPS.items():
            names = [field.name for field in dataclasses.fields(group_type)]
            group = group_type(**{name: getattr(self, name) for name in names})
            object.__setattr__(self, "_" + group_name, group)
            fields.update({name: getattr(group, name) for name in names})
        if fields["observe_commands"] and not fields["thrust_delay"]:
            raise EnvArgumentError(
                "observe_commands=True needs thrust_delay > 0: without a delay no command is in flight to "
                "observe; pass thrust_delay=k (control intervals) or drop observe_commands"
            )
        # The simulator's own bound on the safety factor, with its opt-in, named as env arguments.
        check_safety_factor(fields["safety_factor"], fields["allow_unstable_safety_factor"], error=EnvArgumentError)
        for name, value in fields.items():
            object.__setattr__(self, name, value)
        self.disturbances.check_sampling(self.control_interval)

    @classmethod
    def from_groups(
        cls,
        *,
        reward: RewardConfig | None = None,
        initial_state: InitialStateConfig | None = None,
        disturbances: DisturbanceConfig | None = None,
        faults: FaultConfig | None = None,
        **settings: Any,
    ) -> TaskConfig:
        """A config from its groups (None: the group's defaults) and the other, top-level fields
        (``control_interval``, ``thrusters``, ...).  A field given both in a group and flat is
        refused."""
        flat = dict(settings)
        for group_name, group in (
            ("reward", reward),
            ("initial_state", initial_state),
            ("disturbances", disturbances),
            ("faults", faults),
        ):
            if group is None:
                continue
            group_type = TASK_CONFIG_GROUPS[group_name]
            if not isinstance(group, group_type):
                raise TypeError(f"{group_name} must be a {group_type.__name__}; got {type(group).__name__}")
            for field in dataclasses.fields(group):
                if field.name in flat:
                    raise EnvArgumentError(
                        f"{field.name} is given twice, flat and in {group_name}; give it in one place"
                    )
                flat[field.name] = getattr(group, field.name)
        return cls(**flat)

    @property
    def reward(self) -> RewardConfig:
        """The reward's weights."""
        return self._reward  # type: ignore[attr-defined]

    @property
    def initial_state(self) -> InitialStateConfig:
        """The initial conditions and the domain randomisation."""
        return self._initial_state  # type: ignore[attr-defined]

    @property
    def disturbances(self) -> DisturbanceConfig:
        """The disturbances of every episode."""
        return self._disturbances  # type: ignore[attr-defined]

    @property
    def faults(self) -> FaultConfig:
        """The faults an episode may suffer."""
        return self._faults  # type: ignore[attr-defined]

    def _checked_thrust(self) -> float | tuple[float, ...]:
        """``max_thrust`` as a float or a tuple of floats, each within ``THRUST_RANGE``."""
        value = self.max_thrust
        if isinstance(value, np.ndarray) and value.ndim == 0:
            value = value.item()
        scalar = real_or_none(value) is not None
        items = [value] if scalar else items_of("max_thrust", value, "a number of N or one number per thruster")
        low, high = THRUST_RANGE
        thrusts = []
        for item in items:
            thrust = real_or_none(item)
            if thrust is None or not (math.isfinite(thrust) and low <= thrust <= high):
                raise EnvArgumentError(
                    f"max_thrust must be finite and > 0 N, in [{low:g}, {high:g}] N per thruster; "
                    f"got {short_repr(self.max_thrust)}"
                )
            thrusts.append(thrust)
        return thrusts[0] if scalar else tuple(thrusts)

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
        n, S = cluster.num_nodes, cluster.num_satellites
        for name, indices in (("thrusters", self.thrusters), ("observed_satellites", self.observed_satellites)):
            bad = [i for i in indices or () if i >= S]
            if bad and S < n:
                named = ", ".join(cluster.node_label(i) if i < n else f"node {i} (beyond the cluster)" for i in bad)
                raise EnvArgumentError(
                    f"{name} {bad} are not satellites of this {S}-satellite cluster ({named}); thrusters and "
                    f"observations sit on satellites only (valid: 0..{S - 1})"
                )
            if bad:
                raise EnvArgumentError(
                    f"{name} {bad} are not satellites of this {n}-satellite cluster (valid: 0..{n - 1})"
                )
        count = S if self.thrusters is None else len(self.thrusters)
        if isinstance(self.max_thrust, tuple) and len(self.max_thrust) != count:
            raise EnvArgumentError(
                f"max_thrust must be a scalar or one value per thruster ({count}); got {len(self.max_thrust)} values"
            )
        scales = ClusterScales.of(cluster, self.safety_factor, self.allow_unstable_safety_factor)
        for name, limit, unit in (
            ("initial_displacement", scales.displacement_limit, "m"),
            ("initial_velocity", scales.speed_limit, "m/s"),
        ):
            value = getattr(self, name)
            if value and not (MIN_INITIAL_FRACTION * limit <= value <= limit):
                raise EnvArgumentError(
                    f"{name} must be 0 or in [{MIN_INITIAL_FRACTION * limit:.3g}, {limit:.3g}] {unit} "
                    "for this cluster; "
                    f"got {value!r}.  The upper limit is a deformation of {MAX_DISPLACEMENT_FRACTION:.0%} of the "
                    f"shortest cable ({scales.shortest_cable:.3g} m)"
                    + (" swinging at the fastest cable frequency" if unit == "m/s" else "")
                    + "; beyond it the cluster folds instead of vibrating.  The lower limit keeps the reward's energy "
                    f"scale (the mean energy at reset) meaningful.  Pass {name} within the range (the default, "
                    f"{getattr(InitialStateConfig, name):g} {unit}, suits the presets' scales)"
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


#: The groups of :class:`TaskConfig`: attribute name -> settings class.  Every field of a group is
#: a field of TaskConfig of the same name.
TASK_CONFIG_GROUPS: dict[str, type] = {
    "reward": RewardConfig,
    "initial_state": InitialStateConfig,
    "disturbances": DisturbanceConfig,
    "faults": FaultConfig,
}
