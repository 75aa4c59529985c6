"""The vibration-damping task, batched over clusters: actions, observations, rewards, episode ends.

:class:`DampingTask` sits on one :class:`~tether_gym.BatchSimulator` and turns it into the task
every environment shares: the single :class:`~tether_gym.envs.TetherClusterEnv` is a batch of
one, and a vector env is a batch of many.  Nothing here integrates dynamics; it only maps
actions to forces, and states to observations, rewards and end flags.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike

from tether_gym.cluster import Cluster
from tether_gym.envs import _task_kernels
from tether_gym.simulator import DEFAULT_SAFETY_FACTOR, PARALLEL_MIN_BATCH, AdvanceStats, BatchSimulator

__all__ = ["END_REASONS", "OBSERVATION_LIMIT", "SCALARS", "DampingTask", "TaskConfig", "task_from_arguments"]

ThrustLimit = Literal["per_axis", "magnitude"]
CableFailure = Literal["terminate", "continue"]

#: ``end_reason`` codes reported in ``info`` (index into this tuple).
END_REASONS = ("running", "formation_lost", "cable_broken", "numerics_diverged")

RANDOMISABLE = ("masses", "EA", "damping", "N0", "axial_damping")

#: Per-cluster quantities the task kernel writes after each step, in this column order.
SCALARS = ("reward", "reward_vibration", "reward_propellant", "reward_slack", "reward_failure",
           "vibration_energy", "max_deviation", "slack_fraction", "kinetic_energy", "strain_energy",
           "frame_potential")
_COLUMN = {name: k for k, name in enumerate(SCALARS)}

OBSERVATION_LIMIT = _task_kernels.OBSERVATION_LIMIT


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
            frame ends the episode (formation lost), m; None: 30 % of the shortest cable.
        observe_tensions: append cable tensions / breaking load to the observation.
        observation_noise: std of Gaussian noise added to the observation (its own units).
        observed_satellites: satellites whose displacements and velocities are observed (None:
            all).
        randomize: relative spread of domain randomisation per reset, e.g. ``{"masses": 0.2}``
            draws every mass uniformly within +-20 % of nominal; keys among masses, EA, damping,
            N0, axial_damping.
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

    def validate(self, cluster: Cluster) -> None:
        """Raise ``ValueError`` naming any setting that does not fit ``cluster``."""
        n = cluster.num_nodes
        if not (math.isfinite(self.control_interval) and self.control_interval > 0):
            raise ValueError(f"control_interval must be a finite number of seconds > 0; got {self.control_interval!r}")
        for name, indices in (("thrusters", self.thrusters), ("observed_satellites", self.observed_satellites)):
            if indices is None:
                continue
            if len(indices) == 0:
                raise ValueError(f"{name} must name at least one satellite (or be None for all)")
            bad = [i for i in indices if not (isinstance(i, (int, np.integer)) and 0 <= i < n)]
            if bad:
                raise ValueError(f"{name} {bad} are not satellites of this {n}-satellite cluster (valid: 0..{n - 1})")
            if len(set(indices)) != len(indices):
                raise ValueError(f"{name} lists a satellite twice: {list(indices)}")
        count = n if self.thrusters is None else len(self.thrusters)
        thrust = np.asarray(self.max_thrust, dtype=float)
        if thrust.ndim > 1 or (thrust.ndim == 1 and thrust.shape[0] != count):
            raise ValueError(f"max_thrust must be a scalar or one value per thruster ({count}); got {self.max_thrust!r}")
        if not np.all(np.isfinite(thrust)) or np.any(thrust <= 0):
            raise ValueError(f"max_thrust must be finite and > 0 N; got {self.max_thrust!r}")
        if self.thrust_limit not in ("per_axis", "magnitude"):
            raise ValueError(f"thrust_limit must be 'per_axis' or 'magnitude'; got {self.thrust_limit!r}")
        for name in ("initial_displacement", "initial_velocity", "vibration_weight", "propellant_weight",
                     "slack_weight", "failure_penalty", "observation_noise", "impulse_magnitude", "impulse_rate",
                     "periodic_amplitude", "thrust_noise"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be a finite number >= 0; got {value!r}")
        if self.max_deviation is not None and not (self.max_deviation > 0):
            raise ValueError(f"max_deviation must be > 0 m (or None); got {self.max_deviation!r}")
        unknown = set(self.randomize) - set(RANDOMISABLE)
        if unknown:
            raise ValueError(f"randomize keys {sorted(unknown)} are unknown; use some of {list(RANDOMISABLE)}")
        for key, spread in self.randomize.items():
            if not (0 <= spread < 1):
                raise ValueError(f"randomize[{key!r}] must be a relative spread in [0, 1); got {spread!r}")
        if not (math.isfinite(self.periodic_period) and self.periodic_period > 0):
            raise ValueError(f"periodic_period must be a finite number of seconds > 0; got {self.periodic_period!r}")
        if not (isinstance(self.thrust_delay, (int, np.integer)) and 0 <= self.thrust_delay <= 1000):
            raise ValueError(f"thrust_delay must be a whole number of control intervals in 0..1000; got {self.thrust_delay!r}")
        if not (0.0 <= self.thruster_failure_probability <= 1.0):
            raise ValueError(
                f"thruster_failure_probability must be a probability in [0, 1]; got {self.thruster_failure_probability!r}"
            )
        window = tuple(self.thruster_failure_window)
        if len(window) != 2 or not all(math.isfinite(t) for t in window) or not (0 <= window[0] <= window[1]):
            raise ValueError(
                "thruster_failure_window must be (start, end) in s with 0 <= start <= end; "
                f"got {self.thruster_failure_window!r}"
            )
        if self.cable_failure not in ("terminate", "continue"):
            raise ValueError(f"cable_failure must be 'terminate' or 'continue'; got {self.cable_failure!r}")
        check_difficulty(self.difficulty)


def check_difficulty(difficulty: float) -> float:
    """``difficulty`` as a float, or a ``ValueError`` if it is not a number in [0, 1]."""
    if not (isinstance(difficulty, (int, float, np.floating)) and 0.0 <= difficulty <= 1.0):
        raise ValueError(f"difficulty must be a number in [0, 1] (1: the configured task); got {difficulty!r}")
    return float(difficulty)


def task_from_arguments(
    num_clusters: int,
    preset: str = "tetrahedron",
    preset_kwargs: Mapping[str, Any] | None = None,
    cluster: Cluster | None = None,
    **task: Any,
) -> DampingTask:
    """A :class:`DampingTask` from the environments' keyword arguments (see the env docstring):
    a preset name with overrides, or a cluster, plus :class:`TaskConfig` fields."""
    from tether_gym.presets import make_cluster

    if cluster is None:
        cluster = make_cluster(preset, **dict(preset_kwargs or {}))
    elif not isinstance(cluster, Cluster):
        raise TypeError(f"cluster must be a tether_gym.Cluster; got {type(cluster).__name__}")
    fields = set(TaskConfig.__dataclass_fields__)
    unknown = sorted(set(task) - fields)
    if unknown:
        raise TypeError(f"unknown argument(s) {unknown}; task arguments are {sorted(fields)}")
    for key in ("thrusters", "observed_satellites", "thruster_failure_window"):
        if task.get(key) is not None:
            task[key] = tuple(task[key])
    if isinstance(task.get("max_thrust"), Sequence):
        task["max_thrust"] = tuple(float(v) for v in task["max_thrust"])
    return DampingTask(cluster, num_clusters, TaskConfig(**task))


class DampingTask:
    """The damping task over a batch of B clusters of one topology.

    After every :meth:`reset` or :meth:`step` the results sit in preallocated arrays:
    ``observation`` (B, observation_size) float64 (before noise), ``scalars`` (B, len(SCALARS))
    (reward and its terms, vibration energy in J, largest deviation in m, slack fraction, kinetic
    and strain energy in J) and ``end_reason`` (B,) (index into ``END_REASONS``; > 0 means
    terminated).  Read them before the next call.

    Args:
        cluster: the nominal cluster (its positions are the nominal shape).
        num_clusters: B.
        config: the :class:`TaskConfig`.
    """

    def __init__(self, cluster: Cluster, num_clusters: int, config: TaskConfig) -> None:
        config.validate(cluster)
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
        self.observation_size = 6 * self.observed.size + m + (m if config.observe_tensions else 0)
        self.nominal = np.broadcast_to(cluster.positions, (B, n, 3)).copy()
        self.bias = np.zeros((B, n, 3))
        self.nominal_strain_energy = np.zeros(B)
        for b in range(B):
            self._set_nominal(b, cluster)
        self.full_impulse = float(self.max_thrust.sum()) * config.control_interval * (
            math.sqrt(3.0) if config.thrust_limit == "per_axis" else 1.0
        )
        self.weights = np.array([config.vibration_weight, config.propellant_weight / self.full_impulse,
                                 config.slack_weight, config.failure_penalty])
        self.energy_scale = self._energy_scale()
        self.weights[0] = config.vibration_weight / self.energy_scale
        self.difficulty = config.difficulty
        self.force = np.zeros((B, n, 3))
        self.thrust = np.zeros((B, n, 3))
        self.impulse = np.zeros(B)
        self.propellant = np.zeros(B)
        # Disturbances and faults: what each cluster's episode holds, drawn at its reset.
        self.disturbance = np.zeros((B, n, 3))
        self.thruster_ok = np.ones((B, self.thrusters.size), dtype=np.bool_)
        self.failure_time = np.full(B, np.inf)
        self.failing_thruster = np.zeros(B, dtype=np.int64)
        self.periodic_direction = np.zeros((B, n, 3))
        self.periodic_phase = np.zeros((B, n))
        self.action_queue = np.zeros((B, config.thrust_delay, self.action_size))
        self._perturbed = bool(
            config.impulse_magnitude or config.periodic_amplitude or config.thrust_noise
            or config.thruster_failure_probability
        )
        self.stats = AdvanceStats(
            substeps=np.zeros(B, dtype=np.int64), step_min=np.full(B, np.inf), step_max=np.zeros(B),
            status=np.zeros(B, dtype=np.int64), step_sizes=np.zeros((B, 0)), peak_tension=np.zeros((B, m)),
        )
        self.observation = np.zeros((B, self.observation_size))
        self.scalars = np.zeros((B, len(SCALARS)))
        self.end_reason = np.zeros(B, dtype=np.int64)
        self._all = np.ones(B, dtype=np.bool_)
        self._evaluate()

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
        shape = (count,) + self.cluster.positions.shape
        scalars = np.zeros((count, len(SCALARS)))
        self._evaluate_batch(
            probe, np.ascontiguousarray(np.broadcast_to(self.bias[0], shape)),
            np.ascontiguousarray(np.broadcast_to(self.cluster.positions, shape)),
            np.full(count, self.nominal_strain_energy[0]), np.zeros(count, dtype=np.int64), probe.tension,
            np.zeros(count), np.zeros((count, self.observation_size)), scalars, np.zeros(count, dtype=np.int64),
        )
        scale = float(np.mean(scalars[:, _COLUMN["vibration_energy"]]))
        return scale if scale > 0 else 1.0

    def _evaluate_batch(
        self, sim: BatchSimulator, bias: np.ndarray, nominal: np.ndarray, nominal_strain_energy: np.ndarray,
        status: np.ndarray, peak_tension: np.ndarray, impulse: np.ndarray, observation: np.ndarray,
        scalars: np.ndarray, end_reason: np.ndarray,
    ) -> None:
        kernel = _task_kernels.evaluate_parallel if sim.num_clusters >= PARALLEL_MIN_BATCH else _task_kernels.evaluate_serial
        kernel(
            sim.positions_, sim.velocities_, sim.masses, sim.tension, sim.stiffness, sim.L0, sim.N0, sim.intact,
            sim.frame_tidal, sim.breaking_load, bias, nominal, nominal_strain_energy, sim.cables, self.observed,
            self.length_scale, self.speed_scale, self.config.observe_tensions, status, peak_tension, impulse,
            self.max_deviation, self.config.cable_failure == "terminate", self.weights, observation, scalars,
            end_reason,
        )

    def _evaluate(self) -> None:
        self._evaluate_batch(
            self.sim, self.bias, self.nominal, self.nominal_strain_energy, self.stats.status,
            self.stats.peak_tension, self.impulse, self.observation, self.scalars, self.end_reason,
        )

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
        _task_kernels.remove_rigid_velocity(x0, velocity, np.ascontiguousarray(np.broadcast_to(self.cluster.masses, (count, n))))
        return x0, velocity

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
        reset in a batch matches the same cluster reset alone."""
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
        if self._perturbed:
            for rng, b in zip(rngs, indices):
                self._draw_episode_faults(rng, int(b))
        self.stats.status[indices] = self.sim.status[indices]
        self.stats.peak_tension[indices] = self.sim.tension[indices]
        self.stats.substeps[indices] = 0
        self._evaluate()

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
                actions = (actions.reshape(self.num_clusters, -1, 3) * self.thruster_ok[:, :, None]).reshape(actions.shape)
        _task_kernels.command_forces(
            np.ascontiguousarray(actions), self.thrusters, self.max_thrust, config.thrust_limit == "magnitude",
            self.bias, interval, mask, self.force, self.thrust, self.impulse,
        )
        if self._perturbed:
            if rngs is None:
                raise ValueError("this task draws disturbances or thrust noise: pass step(..., rngs=[one per cluster])")
            self._disturb(mask, rngs)
        self.sim.advance_unchecked(interval, self.force, mask, self.stats)
        self.propellant[mask] += self.impulse[mask]
        self._evaluate()

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
        column = self.scalars.T
        kinetic, strain = column[_COLUMN["kinetic_energy"]], column[_COLUMN["strain_energy"]]
        arrays: dict[str, np.ndarray] = {
            "time": sim.time,
            "vibration_energy": column[_COLUMN["vibration_energy"]],
            "kinetic_energy": kinetic,
            "strain_energy": strain,
            "dissipated_energy": sim._dissipated,
            "external_work": sim._work,
            "frame_potential": column[_COLUMN["frame_potential"]],
            "energy_residual": kinetic + strain + column[_COLUMN["frame_potential"]] - sim._energy0 + sim._dissipated
            - sim._work,
            "tensions": sim.tension,
            "slack_count": np.rint(column[_COLUMN["slack_fraction"]] * self.cluster.num_cables).astype(np.int64),
            "max_deviation": column[_COLUMN["max_deviation"]],
            "propellant_used": self.propellant,
            "thrust": self.thrust,
            "disturbance": self.disturbance,
            "thruster_ok": self.thruster_ok,
            "broken_cables": ~sim.intact,
        }
        if stepped:
            arrays.update(
                substeps=self.stats.substeps, step_min=self.stats.step_min, step_max=self.stats.step_max,
                peak_tension=self.stats.peak_tension,
                **{key: column[_COLUMN[key]] for key in ("reward_vibration", "reward_propellant", "reward_slack",
                                                          "reward_failure")},
                end_reason=self.end_reason,
            )
        return arrays

    def info(self, index: int, stepped: bool = True) -> dict[str, Any]:
        """The ``info`` dict of cluster ``index``: the values of :meth:`info_arrays` at that index
        as Python scalars and array copies, with ``end_reason`` as its name.  Built directly
        (not through info_arrays) because the single env's step rate depends on it; a test keeps
        the two identical."""
        sim = self.sim
        row = self.scalars[index].tolist()
        kinetic, strain = row[_COLUMN["kinetic_energy"]], row[_COLUMN["strain_energy"]]
        frame_potential = row[_COLUMN["frame_potential"]]
        dissipated, work = float(sim._dissipated[index]), float(sim._work[index])
        info: dict[str, Any] = {
            "time": float(sim.time[index]),
            "vibration_energy": row[_COLUMN["vibration_energy"]],
            "kinetic_energy": kinetic,
            "strain_energy": strain,
            "dissipated_energy": dissipated,
            "external_work": work,
            "frame_potential": frame_potential,
            "energy_residual": kinetic + strain + frame_potential - float(sim._energy0[index]) + dissipated - work,
            "tensions": sim.tension[index].copy(),
            "slack_count": round(row[_COLUMN["slack_fraction"]] * self.cluster.num_cables),
            "max_deviation": row[_COLUMN["max_deviation"]],
            "propellant_used": float(self.propellant[index]),
            "thrust": self.thrust[index].copy(),
            "disturbance": self.disturbance[index].copy(),
            "thruster_ok": self.thruster_ok[index].copy(),
            "broken_cables": ~sim.intact[index],
        }
        if stepped:
            stats = self.stats
            info["substeps"] = int(stats.substeps[index])
            info["step_min"] = float(stats.step_min[index])
            info["step_max"] = float(stats.step_max[index])
            info["peak_tension"] = stats.peak_tension[index].copy()
            for key in ("reward_vibration", "reward_propellant", "reward_slack", "reward_failure"):
                info[key] = row[_COLUMN[key]]
            info["end_reason"] = END_REASONS[int(self.end_reason[index])]
        return info
