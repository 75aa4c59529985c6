"""The vibration-damping task, batched over clusters: actions, observations, rewards, episode ends.

:class:`DampingTask` sits on one :class:`~tether_gym.BatchSimulator` and turns it into the task
every environment shares: the single :class:`~tether_gym.envs.TetherClusterEnv` is a batch of
one, and a vector env is a batch of many.  Nothing here integrates dynamics; it only maps
actions to forces, and states to observations, rewards and end flags.

The task's parts live in their own modules: its settings in :mod:`tether_gym.envs.config`, the
ranges of every argument and their checks in :mod:`tether_gym.envs.arguments`, disturbances and
faults in :mod:`tether_gym.envs.disturbances`, the names of its results in
:mod:`tether_gym.envs.contract`, and its compiled measurements in
:mod:`tether_gym.envs._task_kernels`.  Their public names are importable from here too.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from tether_gym import _kernels
from tether_gym.cluster import Cluster
from tether_gym.envs import _task_kernels
from tether_gym.envs.arguments import (
    CONTROL_INTERVAL_RANGE,
    MAX_DELAY_LINE,
    MAX_DISPLACEMENT_FRACTION,
    MAX_IMPULSE,
    MAX_IMPULSE_RATE,
    MAX_NUM_ENVS,
    MAX_OBSERVATION_NOISE,
    MAX_PERIODIC_AMPLITUDE,
    MAX_RENDER_EXAGGERATION,
    MAX_RESET_DEVIATION_CABLES,
    MAX_SPREAD,
    MAX_THRUST_DELAY,
    MAX_THRUST_NOISE,
    MAX_TIME,
    MAX_WEIGHT,
    MIN_CABLE_LENGTH_FRACTION,
    MIN_INITIAL_FRACTION,
    OBSERVATION_LIMIT,
    RESET_SPEED_FACTOR,
    REWARD_LIMIT,
    SUBSTEP_HEADROOM,
    THRUST_RANGE,
    EnvArgumentError,
    as_real_array,
    check_bool,
    check_choice,
    check_difficulty,
    check_number,
    check_satellites,
    check_seed,
    check_whole,
)
from tether_gym.envs.config import (
    RANDOMISABLE,
    ClusterScales,
    DisturbanceConfig,
    FaultConfig,
    InitialStateConfig,
    RewardConfig,
    TaskConfig,
    env_simulator,
)
from tether_gym.envs.contract import (
    END_REASONS,
    REWARD_TERM_KEYS,
    SCALARS,
    EndReason,
    ObservationLayout,
    RewardWeights,
    Scalar,
)
from tether_gym.envs.disturbances import Disturbances
from tether_gym.envs.tethered import nominal_cluster, tether_features, tether_modes_noise
from tether_gym.limits import MAX_COORDINATE, MAX_FORCE, MAX_SPEED, short_repr
from tether_gym.simulator import (
    PARALLEL_MIN_BATCH,
    AdvanceStats,
    BatchSimulator,
    SimulatorState,
    TableColumns,
    check_distinct,
    checked_indices,
    read_only_rows,
)

__all__ = [
    "CONTROL_INTERVAL_RANGE",
    "END_REASONS",
    "MAX_DELAY_LINE",
    "MAX_DISPLACEMENT_FRACTION",
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
    "RANDOMISABLE",
    "RESET_OPTION_KEYS",
    "RESET_SPEED_FACTOR",
    "REWARD_LIMIT",
    "SCALARS",
    "SUBSTEP_HEADROOM",
    "TASK_STATE_FIELDS",
    "THRUST_RANGE",
    "ClusterScales",
    "DampingTask",
    "DisturbanceConfig",
    "EndReason",
    "EnvArgumentError",
    "FaultConfig",
    "InitialStateConfig",
    "ObservationLayout",
    "RewardConfig",
    "RewardWeights",
    "Scalar",
    "TaskConfig",
    "TaskState",
    "as_real_array",
    "check_bool",
    "check_choice",
    "check_difficulty",
    "check_number",
    "check_satellites",
    "check_seed",
    "check_whole",
    "task_from_arguments",
]

#: Keys of ``reset(options=...)``: an exact initial state.
RESET_OPTION_KEYS = ("positions", "velocities")


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

    fields = {field.name for field in dataclasses.fields(TaskConfig)}
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


#: The task node table's thrust columns, as a list index (see :meth:`DampingTask.info_arrays`).
_THRUST_COLUMNS = [_task_kernels.THRUST + d for d in range(3)]


class _EpisodeArray:
    """An array of the task's :class:`~tether_gym.envs.disturbances.Disturbances`, under the
    same name on the task (see :class:`~tether_gym.envs.disturbances.Disturbances` for each)."""

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name
        self.__doc__ = f"``disturbances.{name}``: see :class:`~tether_gym.envs.disturbances.Disturbances`."

    def __get__(self, task: DampingTask | None, owner: type | None = None) -> Any:
        return self if task is None else getattr(task.disturbances, self.name)


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
    *Disturbances.STATE,
    "observation",
    "scalars",
    "end_reason",
    "stats.substeps",
    "stats.step_min",
    "stats.step_max",
    "stats.status",
    "stats.peak_tension",
)


#: What :meth:`DampingTask.restore` accepts in the task arrays beyond their dtype and shape:
#: every float array must be finite, but for the fields of :data:`_TASK_INFINITE` (where +inf
#: means "none": no failing thruster, no sub-step taken); the fields here must also lie in
#: [lowest, highest].
_TASK_RANGES: dict[str, tuple[float, float]] = {
    "bias": (-MAX_FORCE, MAX_FORCE),
    "nominal": (-MAX_COORDINATE, MAX_COORDINATE),
    "nominal_strain_energy": (0.0, math.inf),
    "force": (-MAX_FORCE, MAX_FORCE),
    "thrust": (-MAX_FORCE, MAX_FORCE),
    "impulse": (0.0, math.inf),
    "propellant": (0.0, math.inf),
    "disturbance": (-MAX_FORCE, MAX_FORCE),
    "failure_time": (0.0, math.inf),
    "end_reason": (0, len(END_REASONS) - 1),
    "stats.substeps": (0, math.inf),
    "stats.step_min": (0.0, math.inf),
    "stats.step_max": (0.0, math.inf),
    "stats.peak_tension": (0.0, math.inf),
}
_TASK_INFINITE = frozenset({"failure_time", "stats.step_min"})


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
        """The state of clusters ``rows`` of this state, in that order: whole numbers, which may
        repeat (one restore then fills a planning batch with n copies of each cluster), or a (k,)
        boolean mask; anything else raises ``ValueError`` naming ``rows``."""
        rows = checked_indices("rows", rows, self.num_clusters)
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
    def perturbed(self) -> bool:
        """Whether the task draws disturbances, thrust noise or faults (``step`` then needs one
        generator per cluster)."""
        return self.disturbances.draws

    # The episodes' disturbances and faults: the arrays of :attr:`disturbances`.
    disturbance = _EpisodeArray()
    thruster_ok = _EpisodeArray()
    failure_time = _EpisodeArray()
    failing_thruster = _EpisodeArray()
    periodic_direction = _EpisodeArray()
    periodic_phase = _EpisodeArray()
    action_queue = _EpisodeArray()

    @property
    def reward_weights(self) -> RewardWeights:
        """The reward's weights as the kernels apply them (a copy of :attr:`weights`, named)."""
        return RewardWeights(*(float(w) for w in self.weights))

    def terminated(self) -> np.ndarray:
        """(B,) bool: clusters whose last step ended their episode (``end_reason`` is not
        ``RUNNING``)."""
        return self.end_reason != _task_kernels.RUNNING  # EndReason.RUNNING, as an int: compared every step

    def rewards(self) -> np.ndarray:
        """(B,) the rewards of the last step (a copy of ``scalars[:, Scalar.REWARD]``)."""
        return self.task_cluster_table[:, _task_kernels.SCALAR_COLUMNS + _task_kernels.REWARD].copy()

    def __init__(self, cluster: Cluster, num_clusters: int, config: TaskConfig) -> None:
        if not isinstance(cluster, Cluster):
            raise TypeError(f"cluster must be a tether_gym.Cluster; got {type(cluster).__name__}")
        if not isinstance(config, TaskConfig):
            raise TypeError(f"config must be a TaskConfig; got {type(config).__name__}")
        num_clusters = check_whole("num_clusters", num_clusters, 1, MAX_NUM_ENVS)
        cluster = nominal_cluster(cluster)
        self.scales = config.validate(cluster)
        S = cluster.num_satellites
        action_size = 3 * (S if config.thrusters is None else len(config.thrusters))
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
        self.sim = env_simulator(cluster, B, config.safety_factor, config.allow_unstable_safety_factor)
        self.thrusters = np.arange(S) if config.thrusters is None else np.array(config.thrusters, dtype=np.int64)
        self.observed = np.arange(S) if config.observed_satellites is None else np.array(config.observed_satellites)
        self.max_thrust = np.broadcast_to(np.asarray(config.max_thrust, dtype=float), self.thrusters.shape).copy()
        self.action_size = 3 * self.thrusters.size
        self.max_deviation = (
            0.3 * self.scales.shortest_cable if config.max_deviation is None else float(config.max_deviation)
        )
        # Observation scales: displacements and elongations in units of the initial displacement,
        # velocities in units of the initial velocity; a zero scale (exact resets only) falls back
        # to 0.1 % of the shortest cable (or tether) and 1 mm/s.
        self.length_scale = config.initial_displacement or 1e-3 * self.scales.shortest_cable
        self.speed_scale = config.initial_velocity or 1e-3
        # A tether's segments are observed per tether (the last block), not one by one.
        self.observed_cables = m - sum(spec.segments for spec in cluster.tethers)
        self.observation_layout = layout = ObservationLayout(
            self.observed.size,
            self.observed_cables,
            config.observe_tensions,
            cluster.num_tethers,
            config.thrust_delay * action_size if config.observe_commands else 0,
        )
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
            (tk.ON_OFF, config.thrust_mode == "on_off"),
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
            (tk.SATELLITES, S),
            (tk.OBSERVED_CABLES, self.observed_cables),
        ):
            self.task_settings[column] = value
        self.energy_scale = self._energy_scale()
        self.task_settings[tk.VIBRATION_WEIGHT] = config.vibration_weight / self.energy_scale
        self.difficulty = config.difficulty
        self.propellant = np.zeros(B)
        # Disturbances and faults: what each cluster's episode holds, drawn at its reset.
        self.disturbances = Disturbances(
            config.disturbances, config.faults, B, n, self.thrusters, self.max_thrust, config.control_interval, S
        )
        self.end_reason = np.zeros(B, dtype=np.int64)
        self._all = np.ones(B, dtype=np.bool_)
        self._num_cables = m  # a Cluster property costs 0.4 us, read on every step's info
        self._no_record = np.zeros((B, 0))  # the fused step records no sub-step sizes
        self.evaluate()

    # ------------------------------------------------------------------ nominal state
    def _set_nominal(self, index: int, cluster: Cluster) -> None:
        """Cluster ``index`` gets ``cluster``'s parameters, and the bias thrust holding its shape
        at rest in its frame (zero, to round-off, for shapes held by spin or gravity gradient)."""
        self.sim.set_cluster(index, cluster, reset=False)
        bias = self.sim.equilibrium_force(cluster.positions[None], indices=[index])[0]
        # Beads carry no thrusters: at the nominal (equilibrium) shape their force is round-off.
        bias[cluster.num_satellites :] = 0.0
        self.bias[index] = bias
        tension = np.maximum(cluster.N0, 0.0)
        self.nominal_strain_energy[index] = float((0.5 * tension**2 / cluster.stiffness).sum())

    def _energy_scale(self) -> float:
        """Vibration-energy normaliser, J: the mean vibration energy of 64 reset states of the
        nominal cluster drawn with a fixed seed (so it is the same for every env instance)."""
        count = 64
        x0, v0 = self.sample_initial_state(np.random.default_rng(0), count, difficulty=1.0)
        probe = env_simulator(self.cluster, count, self.config.safety_factor, self.config.allow_unstable_safety_factor)
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
        self._observe_extra_blocks()

    def _observe_extra_blocks(self) -> None:
        """Write the observation blocks the compiled kernels do not: each tether's and the
        commands in flight, when the layout has them."""
        layout = self.observation_layout
        if layout.tethers:
            self._observe_tethers()
        if layout.commands:
            start = _task_kernels.OBSERVATION_COLUMNS + layout.command.start
            # The queue holds the commands as given; the thrusters act on them clipped to [-1, 1].
            commands = np.clip(self.disturbances.action_queue.reshape(self.num_clusters, -1), -1.0, 1.0)
            self.task_cluster_table[:, start : start + layout.commands] = commands

    def _observe_tethers(self) -> None:
        """Write each tether's observation block (see :data:`~tether_gym.envs.contract.TETHER_FEATURES`)
        into the observation of every cluster, from the simulator's current state."""
        sim, cluster = self.sim, self.cluster
        features = tether_features(cluster, sim.positions, sim.tension, sim.broken, self.length_scale)
        start = _task_kernels.OBSERVATION_COLUMNS + self.observation_layout.tether.start
        block = np.clip(features.reshape(self.num_clusters, -1), -OBSERVATION_LIMIT, OBSERVATION_LIMIT)
        self.task_cluster_table[:, start : start + block.shape[1]] = block

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
        if not isinstance(state.simulator, SimulatorState):
            raise TypeError(f"state.simulator must be a SimulatorState; got {type(state.simulator).__name__}")
        self._check_task_arrays(state)
        idx = np.arange(state.num_clusters) if indices is None else self.sim.cluster_indices(indices)
        self.sim.restore(state.simulator, idx)  # checks the rest before it writes anything
        source = np.zeros(idx.size, dtype=np.int64) if state.num_clusters == 1 else np.arange(idx.size)
        for name in TASK_STATE_FIELDS:
            self._state_array(name)[idx] = state.arrays[name][source]

    def _check_task_arrays(self, state: TaskState) -> None:
        """Refuse, naming the array, task arrays of ``state`` that this task could not hold: not
        exactly the names of :data:`TASK_STATE_FIELDS`, not numpy arrays of this task's dtypes,
        not of shape (k, ...) with this task's trailing axes, holding NaN or an infinity (but +inf
        where it means none, :data:`_TASK_INFINITE`), or values outside their ranges
        (:data:`_TASK_RANGES`, the status codes, the thruster indices)."""
        arrays = state.arrays
        if not isinstance(arrays, dict) or set(arrays) != set(TASK_STATE_FIELDS):
            given = sorted(arrays) if isinstance(arrays, dict) else type(arrays).__name__
            raise ValueError(f"state.arrays must hold exactly the task arrays {list(TASK_STATE_FIELDS)}; got {given}")
        k = len(state.simulator.clusters) if isinstance(state.simulator.clusters, tuple) else -1
        # Clusters frozen for a non-finite state hold what they diverged to (the simulator's
        # restore checks its status array): their task arrays need not be finite either.
        status = state.simulator.arrays.get("status") if isinstance(state.simulator.arrays, dict) else None
        frozen = (
            status == _kernels.STATUS_NON_FINITE
            if isinstance(status, np.ndarray) and status.shape == (k,)
            else np.zeros(max(k, 0), dtype=np.bool_)
        )
        for name in TASK_STATE_FIELDS:
            value, own = arrays[name], self._state_array(name)
            if not isinstance(value, np.ndarray) or value.dtype != own.dtype:
                got = f"dtype {value.dtype}" if isinstance(value, np.ndarray) else type(value).__name__
                raise TypeError(f"state.arrays[{name!r}] must be a numpy array of dtype {own.dtype}; got {got}")
            if value.shape != (k, *own.shape[1:]):
                raise ValueError(f"state.arrays[{name!r}] must have shape {(k, *own.shape[1:])}; got {value.shape}")
            value = value[~frozen]
            if value.dtype.kind == "f":
                finite = np.isfinite(value) | ((value == math.inf) & (name in _TASK_INFINITE))
                if not finite.all():
                    raise ValueError(
                        f"state.arrays[{name!r}] must be finite"
                        + (" (or +inf for none)" if name in _TASK_INFINITE else "")
                        + f"; it holds {short_repr(value[~finite][:3].tolist())}"
                    )
            if name == "stats.status":
                if not np.isin(value, _kernels.STATUS_CODES).all():
                    raise ValueError(
                        f"state.arrays['stats.status'] must hold status codes {list(_kernels.STATUS_CODES)}; "
                        f"got {short_repr(value.tolist())}"
                    )
                continue
            if name == "failing_thruster":
                low, high = 0.0, float(max(self.disturbances.thrusters.size - 1, 0))
            elif name in _TASK_RANGES:
                low, high = _TASK_RANGES[name]
            else:
                continue
            outside = (value < low) | (value > high)
            if outside.any():
                raise ValueError(
                    f"state.arrays[{name!r}] must lie in [{low:g}, {high:g}]; it holds "
                    f"{short_repr(value[outside][:3].tolist())}"
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
        if self.cluster.num_beads:
            displacement, velocity = tether_modes_noise(
                self.cluster,
                rng,
                count,
                scale * self.config.initial_displacement,
                scale * self.config.initial_velocity,
            )
        else:
            displacement = scale * self.config.initial_displacement * rng.standard_normal(shape)
            velocity = scale * self.config.initial_velocity * rng.standard_normal(shape)
        masses = self.cluster.masses[None, :, None]
        displacement -= (masses * displacement).sum(axis=1, keepdims=True) / masses.sum(axis=1, keepdims=True)
        x0 = self.cluster.positions[None] + displacement
        _task_kernels.remove_rigid_velocity(x0, velocity, np.repeat(self.cluster.masses[None], count, axis=0))
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
                "options must be a dict such as {'positions': X0, 'velocities': V0} or None; "
                f"got {short_repr(options)}"
            )
        unknown = sorted(set(options) - set(RESET_OPTION_KEYS), key=repr)
        if unknown:
            raise EnvArgumentError(f"unknown reset option(s) {unknown}; accepted options are {list(RESET_OPTION_KEYS)}")
        n = self.cluster.num_nodes
        arrays: dict[str, np.ndarray | None] = {}
        for key, unit in zip(RESET_OPTION_KEYS, ("m", "m/s"), strict=True):
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
        for key, values, limit, unit in (
            ("positions", positions, MAX_COORDINATE, "m"),
            ("velocities", velocities, MAX_SPEED, "m/s"),
        ):
            if values is not None and not np.abs(values).max() <= limit:
                raise EnvArgumentError(
                    f"reset option {key!r} must have every entry within +-{limit:g} {unit} (the simulator's range); "
                    f"got {float(np.abs(values).max()):.3g} {unit}"
                )
        if positions is not None:
            distances = np.linalg.norm(positions - self.cluster.positions, axis=-1)
            deviation = float(distances.max())
            if not deviation <= scales.deviation_limit:
                node = int(np.nanargmax(np.where(np.isnan(distances), np.inf, distances)) % n)
                what = "a satellite" if not self.cluster.num_beads else self.cluster.node_label(node)
                raise EnvArgumentError(
                    f"reset option 'positions' puts {what} {deviation:.3g} m from its nominal place; the "
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
                    f"reset option 'positions' puts {' and '.join(map(self.cluster.node_label, cables[c].tolist()))}, "
                    f"the ends of cable "
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
        :meth:`check_reset_state` (the envs call it before they reseed anything).  Indices
        outside the batch or naming a cluster twice are refused before any generator draws."""
        check_distinct("indices", self.sim.cluster_indices(indices))
        for rng, b in zip(rngs, indices, strict=True):
            if self.config.randomize:
                self._set_nominal(int(b), self.config.initial_state.randomised(self.cluster, rng, self.difficulty))
            elif self.sim.clusters[b] is not self.cluster:
                self._set_nominal(int(b), self.cluster)
        x0: ArrayLike
        v0: ArrayLike | None
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
        self.disturbances.reset(rngs, indices)
        self.evaluate()

    def set_difficulty(self, difficulty: float) -> None:
        """Scale initial conditions, randomisation and disturbances by ``difficulty`` in [0, 1]
        from the next reset on (see :class:`TaskConfig`)."""
        self.difficulty = check_difficulty(difficulty)

    # ------------------------------------------------------------------ step
    def step(
        self,
        actions: np.ndarray,
        active: np.ndarray | None = None,
        rngs: Sequence[np.random.Generator] | None = None,
    ) -> None:
        """Apply (B, action_size) float64 actions for one control interval (bias thrust added) to
        the ``active`` clusters (default all), then evaluate observation, reward and end flags.

        Commands are clipped to [-1, 1]; with on/off thrust each component becomes -1, 0 or +1
        (off below 0.5 in magnitude); with the magnitude limit a command longer than 1 is scaled
        back to length 1; then they are multiplied by each thruster's ``max_thrust``.
        With a thrust delay the actions applied are those given ``thrust_delay`` steps earlier.
        Disturbances and thrust noise of cluster b draw from ``rngs[b]`` (needed only when they
        are configured).
        """
        mask = self._all if active is None else active
        disturbances = self.disturbances
        if disturbances.alters_actions:
            actions = disturbances.acting_actions(actions, mask, self.sim.time)
        actions = _kernels.kernel_operand(actions, np.float64)
        sim = self.sim
        if not disturbances.draws:
            # The whole step in one compiled call (one parallel region for a large batch).
            kernel = (
                _task_kernels.step_parallel if self.num_clusters >= PARALLEL_MIN_BATCH else _task_kernels.step_serial
            )
            kernel(
                self.config.control_interval,
                actions,
                mask,
                (sim.kernel_settings, self.task_settings),
                (sim.cables, self.thrusters, self.max_thrust, self.observed),
                (sim.node_table, sim.cable_table, sim.cluster_table, sim.counter_table),
                (self.task_node_table, self.task_cluster_table, self.propellant, self.end_reason),
                self._no_record,
            )
            self._observe_extra_blocks()
            return
        if rngs is None:
            raise ValueError("this task draws disturbances or thrust noise: pass step(..., rngs=[one per cluster])")
        _task_kernels.command_forces(
            self.task_settings,
            actions,
            self.thrusters,
            self.max_thrust,
            mask,
            self.task_node_table,
            sim.node_table,
            self.task_cluster_table,
            self.propellant,
        )
        disturbances.apply(mask, rngs, sim.time, self.difficulty, self.force, self.thrust)
        sim.advance_unchecked(self.config.control_interval, mask)
        self.evaluate()

    # ------------------------------------------------------------------ results
    def observe(self, rngs: Sequence[np.random.Generator], indices: np.ndarray | None = None) -> np.ndarray:
        """(k, observation_size) float32 observation of clusters ``indices`` (default all B);
        with noise configured, the noise of ``indices[k]`` comes from ``rngs[k]``."""
        # The table itself, not the ``observation`` descriptor: a view fewer on every step.
        start = _task_kernels.OBSERVATION_COLUMNS
        table = self.task_cluster_table
        observation = table[:, start:] if indices is None else table[indices, start:]
        if self.config.observation_noise == 0:
            return observation.astype(np.float32)
        noise = np.stack([rng.standard_normal(self.observation_size) for rng in rngs])
        # The commands in flight are the controller's own numbers, not a measurement.
        noise[:, self.observation_layout.command] = 0.0
        noisy = observation + self.config.observation_noise * noise
        return np.clip(noisy, -OBSERVATION_LIMIT, OBSERVATION_LIMIT).astype(np.float32)

    def info_arrays(self, stepped: bool = True, copy: bool = False) -> dict[str, np.ndarray]:
        """Every ``info`` quantity for the whole batch: (B,) or (B, ...) arrays.  ``stepped=False``
        (after a reset) leaves out the per-step quantities.  ``end_reason`` is the code; see
        ``END_REASONS``.

        ``copy=False``: some arrays are views of the task's buffers (copy what you keep).
        ``copy=True``: every array is a new one, the caller's to keep; the scalar results share
        one copy of their block (an N=1024 vector step spends a tenth of its time on infos, so
        they are copied in as few operations as possible)."""
        k, tk = _kernels, _task_kernels
        sim, episode = self.sim, self.disturbances
        clusters, cables = sim.cluster_table, sim.cable_table

        def kept(array: np.ndarray) -> np.ndarray:
            return array.copy() if copy else array

        scalars = kept(self.task_cluster_table[:, tk.SCALAR_COLUMNS : tk.OBSERVATION_COLUMNS])
        values = dict(zip(SCALARS, scalars.T, strict=True))
        kinetic, strain, frame_potential = values["kinetic_energy"], values["strain_energy"], values["frame_potential"]
        dissipated, work = sim.dissipated, sim.work  # read-only views
        arrays: dict[str, np.ndarray] = {
            "time": kept(clusters[:, k.TIME]),
            "vibration_energy": values["vibration_energy"],
            "kinetic_energy": kinetic,
            "strain_energy": strain,
            "dissipated_energy": kept(dissipated),
            "external_work": kept(work),
            "frame_potential": frame_potential,
            "energy_residual": kinetic + strain + frame_potential - clusters[:, k.INITIAL_ENERGY] + dissipated - work,
            "tensions": kept(cables[:, :, k.TENSION]),
            "slack_count": np.rint(values["slack_fraction"] * self._num_cables).astype(np.int64),
            "max_deviation": values["max_deviation"],
            "propellant_used": kept(self.propellant),
            # A list index copies the three strided columns in half the time of a view's copy().
            "thrust": self.task_node_table[:, :, _THRUST_COLUMNS] if copy else self.thrust,
            "disturbance": kept(episode.disturbance),
            "thruster_ok": kept(episode.thruster_ok),
            "broken_cables": cables[:, :, k.INTACT] == 0.0,
        }
        if stepped:
            arrays.update(
                substeps=kept(sim.counter_table[:, k.SUBSTEPS]),
                step_min=kept(clusters[:, k.STEP_MIN]),
                step_max=kept(clusters[:, k.STEP_MAX]),
                simulator_status=kept(sim.counter_table[:, k.STATUS]),
                peak_tension=kept(cables[:, :, k.PEAK_TENSION]),
                **{key: values[key] for key in REWARD_TERM_KEYS},
                end_reason=kept(self.end_reason),
            )
        return arrays

    def info(self, index: int, stepped: bool = True) -> dict[str, Any]:
        """The ``info`` dict of cluster ``index``: the values of :meth:`info_arrays` at that index
        as Python scalars and array copies, with ``end_reason`` as its name.  Built directly
        (not through info_arrays) because the single env's step rate depends on it; a test keeps
        the two identical."""
        return self._info(index, stepped)[2]

    def outcome(self, index: int) -> tuple[float, bool, dict[str, Any]]:
        """``(reward, terminated, info)`` of cluster ``index`` after a step: what a single env's
        ``step`` returns beside the observation, read from the tables in one pass (the same
        values as ``rewards()[index]``, ``terminated()[index]`` and ``info(index)``)."""
        return self._info(index, stepped=True)

    def _info(self, index: int, stepped: bool) -> tuple[float, bool, dict[str, Any]]:
        """``(reward, terminated, info)`` of cluster ``index``; see :meth:`info`."""
        sim = self.sim
        k = _kernels
        tk = _task_kernels
        episode = self.disturbances  # once: each task attribute of it is a descriptor lookup
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
            "slack_count": round(values["slack_fraction"] * self._num_cables),
            "max_deviation": values["max_deviation"],
            "propellant_used": float(self.propellant[index]),
            "thrust": self.task_node_table[index, :, tk.THRUST : tk.THRUST + 3].copy(),
            "disturbance": episode.disturbance[index].copy(),
            "thruster_ok": episode.thruster_ok[index].copy(),
            "broken_cables": cables[:, k.INTACT] == 0.0,
        }
        reason = self.end_reason[index].item()
        if stepped:
            info["substeps"] = int(sim.counter_table[index, k.SUBSTEPS])
            info["step_min"] = cluster[k.STEP_MIN]
            info["step_max"] = cluster[k.STEP_MAX]
            # Why a numerics_diverged end happened (tether_gym.simulator.STATUS_NAMES): a
            # non-finite state, an interval refused for its sub-step budget, an energy runaway.
            info["simulator_status"] = int(sim.counter_table[index, k.STATUS])
            info["peak_tension"] = cables[:, k.PEAK_TENSION].copy()
            for key in REWARD_TERM_KEYS:
                info[key] = values[key]
            info["end_reason"] = END_REASONS[reason]
        return values["reward"], reason != _task_kernels.RUNNING, info
