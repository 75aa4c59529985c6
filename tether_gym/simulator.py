"""The physics core: explicit central-difference integration of tether clusters, batched.

:class:`BatchSimulator` integrates B clusters of the same topology at once, arrays shaped
``(B, n, 3)``; each cluster sub-steps at its own estimated critical step, and a cluster that
diverges is frozen and flagged without disturbing the others.  :class:`Simulator` is the same core
seen as a single cluster, with ``(n, 3)`` arrays.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike

from tether_gym import _kernels
from tether_gym.cluster import Cluster
from tether_gym.limits import (
    MAX_COORDINATE,
    MAX_FORCE,
    MAX_SPEED,
    check_range,
    check_real,
    is_real_number,
    is_whole_number,
    real_array,
    short_repr,
    to_float,
)

__all__ = [
    "DEFAULT_SAFETY_FACTOR",
    "ENERGY_RUNAWAY_TOLERANCE",
    "MAX_STABLE_SAFETY_FACTOR",
    "UnstableSafetyFactorWarning",
    "AdvanceStats",
    "BatchSimulator",
    "EnergyReport",
    "STATE_FIELDS",
    "STATUS_NAMES",
    "SimulationDiverged",
    "SimulatorState",
    "Simulator",
]

#: Fraction of the estimated critical step ``2 / omega_max`` used as the sub-step.  Chosen from data:
#: at 0.1 the position error against a DOP853 reference stays below 1 % of the displacement scale
#: over 5 s of repeated slack-snap vibration (tests/test_reference.py), and the energy drift of
#: undamped, constantly snapping clusters is about 1 % per 100 s (``python
#: benchmarks/safety_factor.py``); at 0.2 both are 3-6x larger.  Each snap adds a small energy
#: error of random sign, so over very long undamped runs use 0.025-0.05.
DEFAULT_SAFETY_FACTOR = 0.1

#: The largest safety factor accepted without ``allow_unstable_safety_factor=True``.  Through
#: slack and snap the linear stability limit (1.0) means nothing: the energy drift of undamped,
#: snapping clusters grows without bound from about 0.5 on, and from 0.3 on strongly
#: pretensioned snapping pairs leave their energy books by more than the runaway guard's
#: tolerance within 10 s; up to 0.2 no measured case does (docs/verification.md, "Choosing the
#: safety factor", ``python benchmarks/energy_guard.py``).
MAX_STABLE_SAFETY_FACTOR = 0.2

#: The default ``energy_tolerance``: a cluster whose energy balance (the :class:`EnergyReport`
#: residual) exceeds this fraction of its energy scale after an advance is flagged as diverged
#: (status 3); see :data:`tether_gym._kernels.ENERGY_TOLERANCE`.  Chosen from data: the eight
#: default ids at the default safety factor, with random or saturated thrust, every disturbance
#: and breaking cables, reach at most 0.086 (``python benchmarks/energy_guard.py``).
ENERGY_RUNAWAY_TOLERANCE = _kernels.ENERGY_TOLERANCE

#: Batches at least this large are integrated by the multi-threaded kernel; smaller ones by the
#: serial kernel, whose start-up cost is lower.  Both give bit-identical results.
PARALLEL_MIN_BATCH = 16

#: Largest batch: 10^7 clusters of a tetrahedron already hold about 10 GB of state.
MAX_BATCH = 10_000_000
#: Largest ``max_substeps``: sub-step counts are int64 in the kernels, and 10^12 sub-steps of a
#: cluster already take days.
MAX_SUBSTEPS_LIMIT = 10**12
#: Smallest ``energy_tolerance``.  The books of a healthy cluster are off by the integrator's own
#: O(h^2) error: 4.7e-4 of the energy for a triangle settling under its pretension at the default
#: step, up to 0.086 on the ids (docs/verification.md).  A tighter tolerance would flag clusters
#: that are integrating correctly.
MIN_ENERGY_TOLERANCE = 1e-3
#: Largest ``record_steps`` (the record is a (B, R) float64 array).
MAX_RECORDED_STEPS = 10**6

Elongation = Literal["exact", "linearised"]
CriticalStepMethod = Literal["closed-form", "finite-difference"]


#: Each status code of :attr:`AdvanceStats.status` by name: what the environments report as
#: ``info["simulator_status"]``, so that an episode ended as ``numerics_diverged`` says why.
STATUS_NAMES: dict[int, str] = {
    _kernels.STATUS_OK: "ok",
    _kernels.STATUS_NON_FINITE: "non_finite",
    _kernels.STATUS_TOO_MANY_SUBSTEPS: "too_many_substeps",
    _kernels.STATUS_ENERGY_RUNAWAY: "energy_runaway",
}


class SimulationDiverged(FloatingPointError):
    """The integration produced a non-finite state, its energy left its books, or an interval
    needed too many sub-steps."""


class UnstableSafetyFactorWarning(UserWarning):
    """A safety factor above :data:`MAX_STABLE_SAFETY_FACTOR` was asked for explicitly."""


@dataclass(frozen=True)
class AdvanceStats:
    """What one :meth:`BatchSimulator.advance` call did, per cluster.

    Attributes:
        substeps: (B,) number of sub-steps taken (0 for inactive or frozen clusters).
        step_min: (B,) smallest sub-step, s (inf where none was taken).
        step_max: (B,) largest sub-step, s.
        status: (B,) 0 ok; 1 non-finite state and 3 energy runaway (the cluster is frozen until
            reset); 2 sub-step limit reached (the interval was refused and the cluster put back
            at its start: it may advance again over shorter intervals).
        step_sizes: (B, R) the first R sub-step sizes, s, when ``record_steps=R`` was asked
            (NaN-padded), else shape (B, 0).
        peak_tension: (B, m) each cable's largest tension over the interval (sub-step ends), N.
    """

    substeps: np.ndarray
    step_min: np.ndarray
    step_max: np.ndarray
    status: np.ndarray
    step_sizes: np.ndarray
    peak_tension: np.ndarray

    @property
    def diverged(self) -> np.ndarray:
        """(B,) bool: clusters whose integration failed (or whose interval was refused)."""
        return self.status != _kernels.STATUS_OK


@dataclass(frozen=True)
class EnergyReport:
    """Energy accounting since the last reset, J; arrays of shape (B,) (scalars for a Simulator).

    ``kinetic`` is taken with the velocities relative to the cluster's frame, ``strain`` is the
    elastic energy of the intact cables, and ``frame_potential`` the potential of the frame's
    centrifugal and tidal forces (zero in an inertial frame; the Coriolis force does no work).
    ``dissipated`` counts diagonal and axial damping and the elastic energy of cables that broke.
    ``residual = total - initial + dissipated - work`` is zero for the exact solution; for the
    integrator it is O(h^2) and bounded.
    """

    kinetic: np.ndarray
    strain: np.ndarray
    frame_potential: np.ndarray
    dissipated: np.ndarray
    work: np.ndarray
    initial: np.ndarray
    residual: np.ndarray

    @property
    def total(self) -> np.ndarray:
        """Mechanical energy kinetic + strain + frame potential, J (the Jacobi integral in a
        turning frame)."""
        return self.kinetic + self.strain + self.frame_potential

    @property
    def relative_residual(self) -> np.ndarray:
        """``|residual|`` over the books' largest entry (the initial energy, the current kinetic +
        strain + |frame potential|, ``|work|``, ``dissipated``); 0 where all are 0.  A
        dimensionless measure of the integration's energy error for tables and studies; the
        runaway guard uses its own scale (see :meth:`BatchSimulator.advance`)."""
        scale = np.maximum.reduce(
            [
                np.abs(self.initial),
                self.kinetic + self.strain + np.abs(self.frame_potential),
                np.abs(self.work),
                self.dissipated,
            ]
        )
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(scale > 0, np.abs(self.residual) / scale, 0.0)


#: The state of a cluster in a batch: public name -> BatchSimulator attribute.  Together with the
#: cluster's parameters these are everything the integration reads, so a cluster restored from
#: them continues bit-identically.
STATE_FIELDS: dict[str, str] = {
    "positions": "positions_",  # (k, n, 3) m
    "half_step_velocities": "_v_half",  # (k, n, 3) m/s, v_{n-1/2} (v_0 right after a reset)
    "velocities": "velocities_",  # (k, n, 3) m/s at the current time
    "internal_forces": "_f_int",  # (k, n, 3) N, f_int at the current positions
    "tension": "tension",  # (k, m) N
    "intact": "intact",  # (k, m) bool
    "last_step": "_h_prev",  # (k,) s, 0 right after a reset (the next step starts uniformly accelerated)
    "omega2": "_omega2",  # (k,) (rad/s)^2, the step-limiting estimate at the current positions
    "previous_force": "_previous_force",  # (k, n, 3) N, the force of the last interval (exact impulses)
    "time": "time",  # (k,) s since the reset
    "work": "_work",  # (k,) J, external work since the reset
    "dissipated": "_dissipated",  # (k,) J
    "initial_energy": "_energy0",  # (k,) J
    "status": "status",  # (k,) STATUS_* code
    "energy_scale": "_energy_scale",  # (k,) J, the largest energy of the books since the reset (the runaway guard's)
}


def check_safety_factor(
    safety_factor: object, allow_unstable: object, *, error: type[Exception] = ValueError, warn: bool = True
) -> float:
    """``safety_factor`` as a float in (0, :data:`MAX_STABLE_SAFETY_FACTOR`], or in (0, 1] with
    ``allow_unstable`` (then a value above the stable range warns with
    :class:`UnstableSafetyFactorWarning` unless ``warn`` is False); anything else, NaN included,
    raises ``error`` naming ``safety_factor`` or ``allow_unstable_safety_factor``."""
    if not isinstance(allow_unstable, (bool, np.bool_)):
        raise error(f"allow_unstable_safety_factor must be True or False; got {short_repr(allow_unstable)}")
    try:
        value = check_real("safety_factor (a fraction of the critical step)", safety_factor, 0.0, 1.0, "")
    except ValueError as exc:
        raise error(str(exc)) from None
    if value > MAX_STABLE_SAFETY_FACTOR:
        risk = (
            f"safety_factor {value:g} is above {MAX_STABLE_SAFETY_FACTOR:g}, where the energy of clusters whose "
            "cables go slack and snap taut grows without bound (see 'Choosing the safety factor' in "
            "docs/verification.md)"
        )
        if not allow_unstable:
            raise error(
                f"{risk}; use at most {MAX_STABLE_SAFETY_FACTOR:g} (the default is {DEFAULT_SAFETY_FACTOR:g}), "
                "or pass allow_unstable_safety_factor=True to accept it"
            )
        if warn:
            warnings.warn(
                f"{risk}; accepted because allow_unstable_safety_factor=True", UnstableSafetyFactorWarning, stacklevel=3
            )
    return value


def checked_indices(name: str, indices: object, count: int) -> np.ndarray:
    """``indices`` of ``count`` clusters as a (k,) int64 array: a 1-D sequence or array of whole
    numbers in 0..count-1 (repeats allowed, in any order), or a (count,) boolean mask.  Anything
    else (floats, booleans mixed with numbers, nested or ragged sequences, scalars) raises a
    ``ValueError`` naming ``name``: nothing is truncated, wrapped around or read as a mask by
    accident."""
    try:
        idx = np.asarray(indices)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a 1-D sequence of cluster indices; got {short_repr(indices)}") from None
    if idx.dtype == np.bool_:
        if idx.shape != (count,):
            raise ValueError(
                f"{name} given as a boolean mask must have shape ({count},), one flag per cluster; "
                f"got shape {idx.shape}"
            )
        return np.flatnonzero(idx)
    if idx.shape == (0,) and isinstance(indices, (list, tuple, range, np.ndarray)):
        return np.zeros(0, dtype=np.int64)  # numpy types an empty list float64: still no index
    if idx.ndim != 1 or not np.issubdtype(idx.dtype, np.integer):
        raise ValueError(
            f"{name} must be a 1-D sequence of whole cluster indices in 0..{count - 1} or a ({count},) boolean "
            f"mask; got {short_repr(indices)}"
        )
    if isinstance(indices, (list, tuple)) and any(isinstance(item, (bool, np.bool_)) for item in indices):
        raise ValueError(
            f"{name} mixes booleans with indices; give whole numbers or a boolean mask: {short_repr(indices)}"
        )
    if idx.size and (idx.min() < 0 or idx.max() >= count):
        raise ValueError(f"{name}: cluster indices must be in 0..{count - 1}; got {short_repr(idx.tolist())}")
    if idx.size > MAX_BATCH:
        # A selection is copied row by row (a state of 10^8 tetrahedra is 100 GB), and no batch
        # could take more than MAX_BATCH clusters back.
        raise ValueError(f"{name} selects {idx.size} clusters; at most {MAX_BATCH} (the largest batch) may be selected")
    return idx.astype(np.int64)


def check_distinct(name: str, idx: np.ndarray) -> None:
    """Refuse (``ValueError`` naming ``name``) cluster indices ``idx`` that name a cluster twice:
    a reset or restore writes one state per cluster, and a repeat would silently keep the last."""
    if np.unique(idx).size != idx.size:
        raise ValueError(
            f"{name} must name each cluster at most once (two states cannot go into one cluster); "
            f"got {short_repr(idx.tolist())}"
        )


def read_only_rows(arrays: dict[str, np.ndarray], rows: np.ndarray) -> dict[str, np.ndarray]:
    """Read-only copies of rows ``rows`` (fancy indexing, so repeats are allowed) of every array."""
    selected = {}
    for name, array in arrays.items():
        copy = array[rows]
        copy.flags.writeable = False
        selected[name] = copy
    return selected


@dataclass(frozen=True, eq=False)
class SimulatorState:
    """An exact copy of the state of k clusters of a :class:`BatchSimulator`, from
    :meth:`BatchSimulator.snapshot`; :meth:`BatchSimulator.restore` puts it back, into the same
    clusters or into others (of this or another batch of the same topology and settings), and
    the restored clusters continue bit-identically to the originals.

    Attributes:
        clusters: the k clusters' parameters (randomised clusters included).
        arrays: every entry of :data:`STATE_FIELDS`, each of shape (k, ...), read-only copies.
        settings: the batch settings the continuation depends on (safety factor, elongation,
            largest step, sub-step budget); a batch with other settings refuses the state.
    """

    clusters: tuple[Cluster, ...]
    arrays: dict[str, np.ndarray]
    settings: tuple[float, str, float, int]

    @property
    def num_clusters(self) -> int:
        """k, the number of clusters held."""
        return len(self.clusters)

    def select(self, rows: Sequence[int] | np.ndarray) -> SimulatorState:
        """The state of clusters ``rows`` of this state, in that order: whole numbers in 0..k-1,
        which may repeat (e.g. ``np.repeat(np.arange(k), n)`` makes n copies of each cluster for
        planning), or a (k,) boolean mask.  Anything else raises ``ValueError`` naming ``rows``."""
        rows = checked_indices("rows", rows, self.num_clusters)
        return SimulatorState(
            tuple(self.clusters[int(r)] for r in rows), read_only_rows(self.arrays, rows), self.settings
        )

    def __getattr__(self, name: str) -> np.ndarray:
        if name in STATE_FIELDS:
            return self.arrays[name]
        raise AttributeError(f"SimulatorState has no attribute {name!r}; its arrays are {list(STATE_FIELDS)}")


#: What :meth:`BatchSimulator.restore` accepts in each array of a state: (shape, with "k", "n", "m"
#: for the clusters, satellites and cables; dtype; lowest and highest value; unit).
_STATE_CHECKS: dict[str, tuple[tuple[int | str, ...], type, float, float, str]] = {
    "positions": (("k", "n", 3), np.float64, -MAX_COORDINATE, MAX_COORDINATE, "m"),
    "half_step_velocities": (("k", "n", 3), np.float64, -MAX_SPEED, MAX_SPEED, "m/s"),
    "velocities": (("k", "n", 3), np.float64, -MAX_SPEED, MAX_SPEED, "m/s"),
    "internal_forces": (("k", "n", 3), np.float64, -math.inf, math.inf, "N"),
    "tension": (("k", "m"), np.float64, 0.0, math.inf, "N"),
    "intact": (("k", "m"), np.bool_, 0.0, 1.0, ""),
    "last_step": (("k",), np.float64, 0.0, math.inf, "s"),
    "omega2": (("k",), np.float64, 0.0, math.inf, "(rad/s)^2"),
    "previous_force": (("k", "n", 3), np.float64, -MAX_FORCE, MAX_FORCE, "N"),
    "time": (("k",), np.float64, 0.0, math.inf, "s"),
    "work": (("k",), np.float64, -math.inf, math.inf, "J"),
    "dissipated": (("k",), np.float64, 0.0, math.inf, "J"),
    "initial_energy": (("k",), np.float64, -math.inf, math.inf, "J"),
    "status": (("k",), np.int64, 0.0, 0.0, ""),
    "energy_scale": (("k",), np.float64, 0.0, math.inf, "J"),
}


#: Relative round-off allowed when :meth:`BatchSimulator.restore` recomputes what a state's
#: arrays imply (forces, tensions, omega^2, the energy books): a snapshot agrees to the bit, a
#: state computed with numpy to about 1e-15; parameters or positions edited by hand are off by
#: far more.
_CONSISTENCY = 1e-9
#: The absolute floor of that comparison (N, (rad/s)^2 or J): values that small are round-off.
_CONSISTENCY_FLOOR = 1e-300


def _check_array(name: str, value: ArrayLike, shape: tuple[int, ...], unit: str, limit: float = math.inf) -> np.ndarray:
    """A float64 C-contiguous copy of ``value`` with exactly ``shape`` and finite entries of
    magnitude at most ``limit`` (see :mod:`tether_gym.limits`)."""
    if isinstance(value, np.ndarray) and value.dtype == np.float64 and value.shape == shape:
        # The common case, checked in one compiled pass over the copy (C-contiguous and writable:
        # one compiled variant per dimension); the checks below name what is wrong.
        array = np.array(value, order="C")
        if _kernels.all_within(array, limit):
            return array
    array = np.ascontiguousarray(real_array(name, value), dtype=np.float64)
    if array.shape != shape:
        raise ValueError(f"{name} must have shape {shape} ({unit}); got shape {array.shape}")
    check_range(name, np.abs(array), 0.0, limit, f"{unit} (absolute value)")
    return array


def _check_duration(duration: float) -> float:
    """``duration`` as a float, > 0 and finite (its sub-step count is checked by the kernel)."""
    value = to_float(duration) if is_real_number(duration) else math.nan
    if not (math.isfinite(value) and value > 0.0):
        raise ValueError(f"duration must be a finite number of seconds > 0; got {duration!r}")
    return value


class TableColumns:
    """A named view of columns of one of an object's tables (see :mod:`tether_gym._kernels`):
    column ``column`` alone (``width`` 1), ``width`` columns from it, or every column from it to
    the end (``width`` None).

    A descriptor, not an attribute holding a view: a view kept in the instance would come apart
    from its table in a copy or a pickle.  Each access builds a fresh view (writable unless
    ``read_only``), so hot loops read the tables themselves."""

    def __init__(self, table: str, column: int, width: int | None, doc: str, *, read_only: bool = False) -> None:
        self.table = table
        self.columns: int | slice = column if width == 1 else slice(column, None if width is None else column + width)
        self.read_only = read_only
        self.__doc__ = doc

    def __get__(self, owner: object, owner_type: type | None = None) -> Any:
        if owner is None:
            return self
        view = getattr(owner, self.table)[..., self.columns]
        if self.read_only:
            view.flags.writeable = False
        return view


def _node(column: int, doc: str, width: int = 1, **kwargs: Any) -> TableColumns:
    return TableColumns("node_table", column, width, doc, **kwargs)


def _cable(column: int, doc: str, **kwargs: Any) -> TableColumns:
    return TableColumns("cable_table", column, 1, doc, **kwargs)


def _cluster(column: int, doc: str, width: int = 1, **kwargs: Any) -> TableColumns:
    return TableColumns("cluster_table", column, width, doc, **kwargs)


class BatchSimulator:
    """B tether clusters of one topology, integrated together by explicit central differences.

    Args:
        clusters: one :class:`Cluster` (replicated ``num_clusters`` times) or a sequence of clusters
            sharing the same number of satellites and the same cable list (their masses, damping,
            EA, L0, N0 may differ: domain randomisation).
        num_clusters: B when a single cluster is given.
        safety_factor: sub-step as a fraction of the estimated critical step ``2 / omega_max``;
            in (0, :data:`MAX_STABLE_SAFETY_FACTOR`] = (0, 0.2], or (0, 1] with
            ``allow_unstable_safety_factor``.
        elongation: ``"exact"`` (``|x_j - x_i| - L0``, default) or ``"linearised"`` (the paper's
            eq. 11: end displacements from the cluster's positions projected on the current cable
            direction; it strains cables under large rigid rotations).
        max_step: an upper bound on the sub-step, s (default: none).
        max_substeps: sub-steps allowed in one :meth:`advance` per cluster: an interval that
            needs more is refused (status 2) and the cluster put back at its start.
        allow_unstable_safety_factor: accept a ``safety_factor`` above
            :data:`MAX_STABLE_SAFETY_FACTOR` (up to 1), with an :class:`UnstableSafetyFactorWarning`.
        energy_tolerance: the runaway guard's relative tolerance (default
            :data:`ENERGY_RUNAWAY_TOLERANCE`): after each advance a cluster whose energy-balance
            residual exceeds this fraction of the largest energy of its books since the reset is
            flagged (status 3) and frozen.  ``math.inf`` turns the guard off, for studies of the
            integrator's own drift.  It changes no bit of a trajectory it does not stop.

    The state after construction is every cluster at rest at its nominal positions.

    Everything the integration reads and writes lives in four tables, the kernels' contract (their
    columns are named in :mod:`tether_gym._kernels`): ``node_table`` (B, n, NODE_COLUMNS),
    ``cable_table`` (B, m, CABLE_COLUMNS), ``cluster_table`` (B, CLUSTER_COLUMNS) and
    ``counter_table`` (B, COUNTER_COLUMNS) int64, plus the topology ``cables`` (m, 2) and the
    ``kernel_settings``.  The named attributes below (``masses``, ``tension``, ``time``, ...) are
    views of their columns.
    """

    # Parameters.
    masses = _node(_kernels.MASS, "(B, n) node masses (satellites, then beads), kg.")
    damping = _node(_kernels.DAMPING, "(B, n) diagonal damping of each node, N*s/m.")
    reference = _node(_kernels.REFERENCE, "(B, n, 3) nominal positions (the linearised elongation's reference), m.", 3)
    stiffness = _cable(_kernels.STIFFNESS, "(B, m) axial stiffness EA / L0 of each cable, N/m.")
    L0 = _cable(_kernels.REST_LENGTH, "(B, m) rest lengths, m.")
    N0 = _cable(_kernels.PRETENSION, "(B, m) pretensions, N.")
    inv_split_mass_sum = _cable(_kernels.INV_SPLIT_MASS_SUM, "(B, m) 1/m_i^e + 1/m_j^e of each cable, 1/kg.")
    breaking_load = _cable(_kernels.BREAKING_LOAD, "(B, m) breaking loads, N.")
    axial_damping = _cable(_kernels.AXIAL_DAMPING, "(B, m) Kelvin-Voigt damping of each cable, N*s/m.")
    frame_rate = _cluster(_kernels.FRAME_RATE, "(B,) rotation rate of each cluster's frame about z, rad/s.")
    frame_tidal = _cluster(
        _kernels.FRAME_TIDAL, "(B, 3) diagonal of each frame's centrifugal and tidal term, 1/s^2.", 3
    )
    # State (writable views; the public, read-only ones are the properties further down).
    positions_ = _node(_kernels.POSITION, "(B, n, 3) node positions, m (writable).", 3)
    _v_half = _node(_kernels.HALF_STEP_VELOCITY, "(B, n, 3) half-step velocities v_{n-1/2}, m/s.", 3)
    velocities_ = _node(_kernels.VELOCITY, "(B, n, 3) velocities at the current time, m/s (writable).", 3)
    _f_int = _node(_kernels.INTERNAL_FORCE, "(B, n, 3) internal forces at the current positions, N.", 3)
    _previous_force = _node(_kernels.PREVIOUS_FORCE, "(B, n, 3) applied force of the last interval, N.", 3)
    applied_force = _node(_kernels.APPLIED_FORCE, "(B, n, 3) external force of the coming interval, N (writable).", 3)
    tension = _cable(_kernels.TENSION, "(B, m) cable tensions at the current positions, N.")
    time = _cluster(_kernels.TIME, "(B,) time since each cluster's reset, s.")
    _h_prev = _cluster(_kernels.LAST_STEP, "(B,) last sub-step, s (0 right after a reset).")
    _omega2 = _cluster(_kernels.OMEGA2, "(B,) step-limiting frequency estimate, (rad/s)^2.")
    _work = _cluster(_kernels.WORK, "(B,) external work since the reset, J.")
    _dissipated = _cluster(_kernels.DISSIPATED, "(B,) energy dissipated since the reset, J.")
    _energy0 = _cluster(_kernels.INITIAL_ENERGY, "(B,) mechanical energy at the reset, J.")
    _energy_scale = _cluster(_kernels.ENERGY_SCALE, "(B,) largest energy of the books since the reset, J.")
    status = TableColumns("counter_table", _kernels.STATUS, 1, "(B,) status code of each cluster (0: healthy).")
    positions = _node(_kernels.POSITION, "(B, n, 3) current node positions, m (a read-only view).", 3, read_only=True)
    velocities = _node(
        _kernels.VELOCITY, "(B, n, 3) node velocities at the current time, m/s (a read-only view).", 3, read_only=True
    )
    work = _cluster(_kernels.WORK, "(B,) external work since each cluster's reset, J (read-only).", read_only=True)
    dissipated = _cluster(
        _kernels.DISSIPATED,
        "(B,) energy dissipated since each cluster's reset (damping, broken cables), J (read-only).",
        read_only=True,
    )
    initial_energy = _cluster(
        _kernels.INITIAL_ENERGY, "(B,) mechanical energy at each cluster's reset, J (read-only).", read_only=True
    )

    def __init__(
        self,
        clusters: Cluster | Sequence[Cluster],
        num_clusters: int | None = None,
        *,
        safety_factor: float = DEFAULT_SAFETY_FACTOR,
        elongation: Elongation = "exact",
        max_step: float = math.inf,
        max_substeps: int = 10_000_000,
        allow_unstable_safety_factor: bool = False,
        energy_tolerance: float = ENERGY_RUNAWAY_TOLERANCE,
    ) -> None:
        if isinstance(clusters, Cluster):
            count = 1 if num_clusters is None else num_clusters
            if not is_whole_number(count) or not 1 <= count <= MAX_BATCH:
                raise ValueError(f"num_clusters must be a whole number in 1..{MAX_BATCH}; got {num_clusters!r}")
            cluster_list = [clusters] * int(count)
        else:
            cluster_list = list(clusters)
            if not cluster_list or not all(isinstance(c, Cluster) for c in cluster_list):
                raise TypeError("clusters must be a Cluster or a non-empty sequence of Cluster objects")
            if num_clusters is not None and num_clusters != len(cluster_list):
                raise ValueError(f"num_clusters={num_clusters} disagrees with the {len(cluster_list)} clusters given")
        self.safety_factor = check_safety_factor(safety_factor, allow_unstable_safety_factor)
        if not isinstance(elongation, str) or elongation not in ("exact", "linearised"):
            raise ValueError(f"elongation must be 'exact' or 'linearised'; got {elongation!r}")
        self.elongation: Elongation = elongation
        self.max_step = check_real("max_step", max_step, 0.0, math.inf, "s")
        self.energy_tolerance = check_real(
            "energy_tolerance (a fraction of the energy scale; inf: no runaway guard)",
            energy_tolerance,
            MIN_ENERGY_TOLERANCE,
            math.inf,
            "",
            low_inclusive=True,
        )
        if not is_whole_number(max_substeps) or not 1 <= max_substeps <= MAX_SUBSTEPS_LIMIT:
            raise ValueError(
                f"max_substeps must be a whole number in 1..{MAX_SUBSTEPS_LIMIT:.0e}; got {max_substeps!r}"
            )
        self.max_substeps = int(max_substeps)

        template = cluster_list[0]
        self.template = template
        self.num_clusters = len(cluster_list)
        self.num_nodes = template.num_nodes
        self.num_cables = template.num_cables
        # Read-only, as every topology the kernels get: numba compiles a variant per writability.
        self.cables = np.array(template.cables, dtype=np.int64)
        self.cables.flags.writeable = False
        B, n, m = self.num_clusters, self.num_nodes, self.num_cables
        self.kernel_settings = np.zeros(_kernels.SETTINGS)
        self.kernel_settings[_kernels.SAFETY_FACTOR] = self.safety_factor
        self.kernel_settings[_kernels.MAX_STEP] = self.max_step
        self.kernel_settings[_kernels.MAX_SUBSTEPS] = self.max_substeps  # exact: at most 1e12 < 2^53
        self.kernel_settings[_kernels.LINEARISED] = 1.0 if elongation == "linearised" else 0.0
        self.kernel_settings[_kernels.ENERGY_TOLERANCE_SETTING] = self.energy_tolerance
        self.node_table = np.zeros((B, n, _kernels.NODE_COLUMNS))
        self.cable_table = np.zeros((B, m, _kernels.CABLE_COLUMNS))
        self.cluster_table = np.zeros((B, _kernels.CLUSTER_COLUMNS))
        self.counter_table = np.zeros((B, _kernels.COUNTER_COLUMNS), dtype=np.int64)
        self.clusters: list[Cluster] = [template] * B
        for b, cluster in enumerate(cluster_list):
            self.set_cluster(b, cluster, reset=False)
        self._all_active = np.ones(B, dtype=np.bool_)
        self._no_record = np.zeros((B, 0))
        self.reset(self.reference)

    # ------------------------------------------------------------------ parameters
    def set_cluster(self, index: int, cluster: Cluster, *, reset: bool = True) -> None:
        """Give cluster ``index`` new physical parameters (same topology), e.g. for randomisation.

        With ``reset=True`` (default) it is also put at rest at its nominal positions.  Nothing
        changes when the arguments are refused.
        """
        if not is_whole_number(index) or not 0 <= index < len(self.clusters):
            raise ValueError(f"index must be a cluster index in 0..{len(self.clusters) - 1}; got {index!r}")
        if not isinstance(cluster, Cluster):
            raise TypeError(f"cluster must be a tether_gym.Cluster; got {type(cluster).__name__}")
        if cluster.num_nodes != self.num_nodes or not np.array_equal(cluster.cables, self.cables):
            raise ValueError(
                f"cluster {cluster.name!r} has a different topology ({cluster.num_nodes} nodes, "
                f"{cluster.num_cables} cables) from the batch's ({self.num_nodes} nodes, "
                f"{self.num_cables} cables, same cable list required)"
            )
        self.clusters[index] = cluster
        nodes, cables, row = self.node_table[index], self.cable_table[index], self.cluster_table[index]
        nodes[:, _kernels.MASS] = cluster.masses
        nodes[:, _kernels.DAMPING] = cluster.damping
        nodes[:, _kernels.REFERENCE : _kernels.REFERENCE + 3] = cluster.positions
        cables[:, _kernels.STIFFNESS] = cluster.stiffness
        cables[:, _kernels.REST_LENGTH] = cluster.L0
        cables[:, _kernels.PRETENSION] = cluster.N0
        cables[:, _kernels.INV_SPLIT_MASS_SUM] = cluster.inv_split_mass_sum
        cables[:, _kernels.BREAKING_LOAD] = cluster.breaking_load
        cables[:, _kernels.AXIAL_DAMPING] = cluster.axial_damping
        row[_kernels.FRAME_RATE] = cluster.frame.rate
        row[_kernels.FRAME_TIDAL : _kernels.FRAME_TIDAL + 3] = cluster.frame.tidal
        if reset:
            self.reset(cluster.positions[None], indices=[index])

    # ------------------------------------------------------------------ state
    @property
    def intact(self) -> np.ndarray:
        """(B, m) bool: cables that have not broken since the cluster's last reset (a copy)."""
        return self.cable_table[:, :, _kernels.INTACT] != 0.0

    @property
    def slack(self) -> np.ndarray:
        """(B, m) bool: cables carrying no tension at the current positions (broken ones too)."""
        return self.cable_table[:, :, _kernels.TENSION] <= 0.0

    @property
    def broken(self) -> np.ndarray:
        """(B, m) bool: cables that broke since the cluster's last reset (they stay broken)."""
        return self.cable_table[:, :, _kernels.INTACT] == 0.0

    @property
    def last_advance(self) -> AdvanceStats:
        """What the last :meth:`advance` (or :meth:`advance_unchecked`) did, per cluster, as views
        of the tables (the next advance overwrites them; :meth:`advance` returns copies).  After a
        reset: no sub-step, and each cable's peak tension is its tension."""
        return AdvanceStats(
            substeps=self.counter_table[:, _kernels.SUBSTEPS],
            step_min=self.cluster_table[:, _kernels.STEP_MIN],
            step_max=self.cluster_table[:, _kernels.STEP_MAX],
            status=self.counter_table[:, _kernels.STATUS],
            step_sizes=self._no_record,
            peak_tension=self.cable_table[:, :, _kernels.PEAK_TENSION],
        )

    def cluster_indices(self, indices: Sequence[int] | np.ndarray | None) -> np.ndarray:
        """``indices`` checked and as an int array: None (every cluster, in order), a sequence of
        cluster indices in 0..B-1, or a (B,) boolean mask.  Raises ``ValueError`` naming the
        problem."""
        if indices is None:
            return np.arange(self.num_clusters)
        return checked_indices("indices", indices, self.num_clusters)

    def reset(
        self,
        positions: ArrayLike,
        velocities: ArrayLike | None = None,
        indices: Sequence[int] | np.ndarray | None = None,
    ) -> None:
        """Set the state of some clusters (all by default) and restart their energy accounting.

        Args:
            positions: (k, n, 3) node positions in the cluster's frame, m, for the k selected clusters.
            velocities: (k, n, 3) node velocities relative to that frame, m/s (default: at rest).
            indices: the k clusters to reset (default: all B, in order), each at most once.

        Every cable is intact again.  The next :meth:`advance` of these clusters starts with
        uniformly accelerated motion.
        """
        idx = self.cluster_indices(indices)
        check_distinct("indices", idx)
        shape = (idx.size, self.num_nodes, 3)
        x0 = _check_array("positions", positions, shape, "m", MAX_COORDINATE)
        v0 = np.zeros(shape) if velocities is None else _check_array("velocities", velocities, shape, "m/s", MAX_SPEED)
        # Everything that can refuse the state is computed before any of it is stored.
        nodes, cables, clusters, finite = self.evaluate_at(x0, idx, velocities=v0, intact=True)
        if not finite.all():
            raise ValueError(
                f"positions of cluster(s) {idx[~finite].tolist()} give a zero-length cable: "
                f"{self._coincident_cable(x0[int(np.argmin(finite))])}; "
                "two connected nodes may not occupy the same point"
            )
        k = _kernels
        self.node_table[idx, :, k.POSITION : k.POSITION + 3] = x0
        self.node_table[idx, :, k.HALF_STEP_VELOCITY : k.HALF_STEP_VELOCITY + 3] = v0
        self.node_table[idx, :, k.VELOCITY : k.VELOCITY + 3] = v0
        self.node_table[idx, :, k.INTERNAL_FORCE : k.INTERNAL_FORCE + 3] = nodes[
            :, :, k.INTERNAL_FORCE : k.INTERNAL_FORCE + 3
        ]
        self.cable_table[idx, :, k.TENSION] = cables[:, :, k.TENSION]
        self.cable_table[idx, :, k.PEAK_TENSION] = cables[:, :, k.TENSION]
        self.cable_table[idx, :, k.INTACT] = 1.0
        self.cluster_table[idx, k.OMEGA2] = clusters[:, k.OMEGA2]
        for column, value in ((k.LAST_STEP, 0.0), (k.TIME, 0.0), (k.WORK, 0.0), (k.DISSIPATED, 0.0)):
            self.cluster_table[idx, column] = value
        self.cluster_table[idx, k.STEP_MIN] = math.inf
        self.cluster_table[idx, k.STEP_MAX] = 0.0
        self.counter_table[idx, k.STATUS] = k.STATUS_OK
        self.counter_table[idx, k.SUBSTEPS] = 0
        report = self.energy()
        self.cluster_table[idx, k.INITIAL_ENERGY] = report.total[idx]
        self.cluster_table[idx, k.ENERGY_SCALE] = self._guard_books(report, idx)

    def _guard_books(self, report: EnergyReport, idx: np.ndarray) -> np.ndarray:
        """(k,) the runaway guard's energy scale of clusters ``idx`` at their current state, J,
        as the kernel measures it (:func:`tether_gym._kernels._energy_runaway`): the largest of
        internal kinetic + strain + |frame potential|, |work|, dissipated, and
        ``DRIFT_ROUND_OFF`` times the drift energy; the kinetic energy of the centre of mass is
        left out (a uniform drift carries no integration error)."""
        masses = self.masses[idx]
        velocities = self.velocities_[idx]
        total_mass = masses.sum(axis=1)
        centre = np.einsum("bn,bnd->bd", masses, velocities) / total_mass[:, None]
        drift = 0.5 * total_mass * (centre**2).sum(axis=1)
        internal = 0.5 * np.einsum("bn,bnd->b", masses, (velocities - centre[:, None, :]) ** 2)
        return np.maximum.reduce(
            [
                internal + report.strain[idx] + np.abs(report.frame_potential[idx]),
                np.abs(report.work[idx]),
                report.dissipated[idx],
                _kernels.DRIFT_ROUND_OFF * drift,
            ]
        )

    # ------------------------------------------------------------------ snapshots
    @property
    def settings(self) -> tuple[float, str, float, int]:
        """``(safety_factor, elongation, max_step, max_substeps)``: what a restored state needs
        to be the same for a bit-identical continuation."""
        return (self.safety_factor, self.elongation, self.max_step, self.max_substeps)

    def snapshot(self, indices: Sequence[int] | np.ndarray | None = None) -> SimulatorState:
        """An exact copy of the state of clusters ``indices`` (default all, in order): see
        :class:`SimulatorState`.  For planning and search: snapshot, try something, restore."""
        idx = self.cluster_indices(indices)
        arrays = read_only_rows({name: getattr(self, attribute) for name, attribute in STATE_FIELDS.items()}, idx)
        return SimulatorState(tuple(self.clusters[int(b)] for b in idx), arrays, self.settings)

    def restore(self, state: SimulatorState, indices: Sequence[int] | np.ndarray | None = None) -> None:
        """Put ``state`` (k clusters) into clusters ``indices`` (default: the first k, in order),
        parameters included; a state of one cluster may be restored into any number of clusters
        (cloning, e.g. for sampling-based planning).  Each restored cluster then continues
        bit-identically to the cluster the state was taken from.  The state must come from a
        batch of the same topology and :attr:`settings`.  A state may also be built by hand: each
        of its arrays is checked (shape, dtype, finiteness, range, status codes) before anything
        is written, and nothing changes when it is refused."""
        if not isinstance(state, SimulatorState):
            raise TypeError(f"state must be a SimulatorState from BatchSimulator.snapshot; got {type(state).__name__}")
        arrays = self._checked_state(state)
        count = len(state.clusters)
        idx = np.arange(count) if indices is None else self.cluster_indices(indices)
        if count not in (1, idx.size):
            raise ValueError(
                f"state holds {count} clusters and cannot fill the {idx.size} clusters of indices; "
                "give one index per cluster of the state, or a state of one cluster to clone"
            )
        if idx.size and (idx.max() >= self.num_clusters):
            raise ValueError(f"indices must be in 0..{self.num_clusters - 1}; got {idx.tolist()}")
        check_distinct("indices", idx)
        # Whether the arrays agree with each other and with the clusters' parameters is measured
        # on the restored rows themselves, by the kernels that made them; a refusal puts the rows
        # (and their cluster objects) back as they were.
        saved = tuple(table[idx].copy() for table in self._tables()) + ([self.clusters[int(b)] for b in idx],)
        source = np.zeros(idx.size, dtype=np.int64) if count == 1 else np.arange(idx.size)
        for k, b in zip(source, idx, strict=True):
            cluster = state.clusters[int(k)]
            if self.clusters[int(b)] is not cluster:
                self.set_cluster(int(b), cluster, reset=False)
        for name, attribute in STATE_FIELDS.items():
            if name == "intact":  # a flag column: the attribute is a bool copy
                self.cable_table[idx, :, _kernels.INTACT] = arrays[name][source]
            else:
                getattr(self, attribute)[idx] = arrays[name][source]
        try:
            self._check_consistent(idx)
        except ValueError:
            for table, rows in zip(self._tables(), saved, strict=False):
                table[idx] = rows
            for b, cluster in zip(idx, saved[-1], strict=True):
                self.clusters[int(b)] = cluster
            raise

    def _tables(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The four tables of the kernels' contract, in the order ``restore`` saves them."""
        return (self.node_table, self.cable_table, self.cluster_table, self.counter_table)

    def _check_consistent(self, idx: np.ndarray) -> None:
        """Refuse (``ValueError``) restored clusters ``idx`` whose arrays contradict each other
        or their parameters, as only a state built or edited by hand can: the internal forces,
        tensions (zero for broken cables) and omega^2 must be what the kernels compute from the
        positions, half-step velocities and intact flags with the clusters' parameters, and the
        energy books must balance within ``energy_tolerance`` of an energy scale no smaller than
        the books' largest entry.  Clusters that are not healthy (status other than 0) are frozen
        until reset and are not measured."""
        rows = idx[self.counter_table[idx, _kernels.STATUS] == _kernels.STATUS_OK]
        if not rows.size:
            return
        k = _kernels
        nodes, cables, clusters, finite = self.evaluate_at(
            self.positions_[rows], rows, velocities=self._v_half[rows], intact=None
        )
        cause = (
            "state.arrays['positions'], state.arrays['half_step_velocities'], state.arrays['intact'] and the "
            "parameters of state.clusters"
        )
        if not finite.all():
            raise ValueError(
                f"state.arrays['positions'] of cluster(s) {rows[~finite].tolist()} give a zero-length cable: "
                f"{self._coincident_cable(self.positions_[rows][int(np.argmin(finite))])}; "
                "two connected nodes may not occupy the same point"
            )
        tension = cables[:, :, k.TENSION]
        # Forces are compared on the scale of the cluster's tensions: at an equilibrium they
        # cancel to round-off of the tensions, not of zero.
        force_scale = np.maximum(np.abs(tension).max(axis=1, initial=0.0), self.tension[rows].max(axis=1, initial=0.0))
        for name, computed, stored, scale in (
            ("internal_forces", nodes[:, :, k.INTERNAL_FORCE : k.INTERNAL_FORCE + 3], self._f_int[rows], force_scale),
            ("tension", tension, self.tension[rows], force_scale),
            ("omega2", clusters[:, k.OMEGA2], self._omega2[rows], np.abs(clusters[:, k.OMEGA2])),
        ):
            difference = np.abs(computed - stored).reshape(rows.size, -1).max(axis=1)
            bad = ~(difference <= _CONSISTENCY * scale + _CONSISTENCY_FLOOR)
            if bad.any():
                raise ValueError(
                    f"state.arrays[{name!r}] of cluster(s) {rows[bad].tolist()} does not follow from {cause} "
                    f"(off by up to {difference[bad].max():.3g}); restore takes states from "
                    "BatchSimulator.snapshot, or states whose arrays agree as a snapshot's do"
                )
        report = self.energy()
        books = self._guard_books(report, rows)
        scale = self._energy_scale[rows]
        books_text = (
            "state.arrays['positions'], state.arrays['velocities'], state.arrays['initial_energy'], "
            "state.arrays['work'], state.arrays['dissipated'] and state.arrays['energy_scale']"
        )
        small = ~(scale >= books * (1.0 - _CONSISTENCY))
        if small.any():
            raise ValueError(
                f"state.arrays['energy_scale'] of cluster(s) {rows[small].tolist()} is below the largest entry of "
                f"its energy books ({books[small].max():.6g} J), which a snapshot's never is; check {books_text}"
            )
        residual = np.abs(report.residual[rows])
        unbalanced = ~(residual <= self.energy_tolerance * scale * (1.0 + _CONSISTENCY) + _CONSISTENCY_FLOOR)
        if unbalanced.any():
            raise ValueError(
                f"the energy books of healthy cluster(s) {rows[unbalanced].tolist()} do not balance: a residual of "
                f"{residual[unbalanced].max():.3g} J, more than energy_tolerance={self.energy_tolerance:g} of "
                f"the energy scale; check {books_text} (a cluster whose books are out has status 3)"
            )

    def _checked_state(self, state: SimulatorState) -> dict[str, np.ndarray]:
        """The arrays of ``state`` once every part of it is checked against this batch: its
        clusters (a tuple of :class:`Cluster` of this topology), its settings, and each
        array of :data:`STATE_FIELDS` (the exact set of names; numpy arrays of shape (k, ...)
        exactly, no broadcasting; dtype float64, bool for ``intact``, int64 for ``status``;
        a known status code; finite and within the ranges of :mod:`tether_gym.limits` and of
        physics, but in clusters frozen for a non-finite state: positions within MAX_COORDINATE,
        velocities within MAX_SPEED, non-negative time, last step, omega^2, tensions and
        dissipated energy).  A ``ValueError`` or ``TypeError``
        names the first bad part."""
        clusters = state.clusters
        if not isinstance(clusters, tuple) or not all(isinstance(c, Cluster) for c in clusters):
            raise TypeError("state.clusters must be a tuple of tether_gym.Cluster objects")
        checked: set[int] = set()  # a snapshot of a batch of one cluster object holds it k times
        for position, cluster in enumerate(clusters):
            if id(cluster) in checked:
                continue
            checked.add(id(cluster))
            if cluster.num_nodes != self.num_nodes or not np.array_equal(cluster.cables, self.cables):
                raise ValueError(
                    f"state.clusters[{position}] has a different topology ({cluster.num_nodes} nodes, "
                    f"{cluster.num_cables} cables) from this batch ({self.num_nodes} nodes, "
                    f"{self.num_cables} cables, same cable list required)"
                )
        if state.settings != self.settings:
            raise ValueError(
                "state was taken with settings (safety_factor, elongation, max_step, max_substeps) = "
                f"{short_repr(state.settings)}, this batch has {self.settings}; a restored cluster would not "
                "continue the same way"
            )
        arrays = state.arrays
        if not isinstance(arrays, dict) or set(arrays) != set(STATE_FIELDS):
            given = sorted(arrays) if isinstance(arrays, dict) else type(arrays).__name__
            raise ValueError(f"state.arrays must hold exactly the arrays {list(STATE_FIELDS)}; got {given}")
        k, n, m = len(clusters), self.num_nodes, self.num_cables
        for name, value in arrays.items():
            shape, dtype, low, high, unit = _STATE_CHECKS[name]
            sizes = {"k": k, "n": n, "m": m}
            full = tuple(sizes[axis] if isinstance(axis, str) else axis for axis in shape)
            if not isinstance(value, np.ndarray) or value.dtype != dtype:
                got = f"dtype {value.dtype}" if isinstance(value, np.ndarray) else type(value).__name__
                raise TypeError(f"state.arrays[{name!r}] must be a numpy array of dtype {np.dtype(dtype)}; got {got}")
            if value.shape != full:
                raise ValueError(
                    f"state.arrays[{name!r}] must have shape {full} (k={k} clusters, n={n} nodes, m={m} "
                    f"cables); got shape {value.shape}"
                )
        status = arrays["status"]
        if not np.isin(status, _kernels.STATUS_CODES).all():
            raise ValueError(
                f"state.arrays['status'] must hold status codes {list(_kernels.STATUS_CODES)}; "
                f"got {short_repr(status.tolist())}"
            )
        # A cluster frozen for a non-finite state (status 1) holds what it diverged to, and is
        # never integrated again before a reset: its arrays need not be finite, so that a
        # snapshot of a batch with such a cluster restores.
        measured = status != _kernels.STATUS_NON_FINITE
        for name, value in arrays.items():
            if value.dtype != np.float64:
                continue
            _, _, low, high, unit = _STATE_CHECKS[name]
            rows = value[measured]
            if not np.isfinite(rows).all():
                raise ValueError(
                    f"state.arrays[{name!r}] must be finite (but in clusters of status 1); it holds NaN or an infinity"
                )
            check_range(f"state.arrays[{name!r}]", rows, low, high, unit)
        return arrays

    def evaluate_at(
        self,
        x: np.ndarray,
        idx: np.ndarray,
        taut_branch: bool = False,
        velocities: np.ndarray | None = None,
        intact: np.ndarray | bool | None = None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Forces, tensions and the step-limiting omega^2 of clusters ``idx`` (k,) at positions
        ``x`` (k, n, 3) m, with the cables' axial damping acting on ``velocities`` (k, n, 3) m/s
        (default: at rest) and the cables ``intact`` (k, m) (default: each cluster's current
        state; True: all), on the taut branch with ``taut_branch`` (see
        :func:`tether_gym._kernels.cable_forces`).  Unchecked: the inputs are used as they are.

        Computed on scratch copies of the clusters' rows of the tables, which it returns with
        ``finite`` (k,) bool, whether every cable length was finite and non-zero: ``(nodes,
        cables, clusters, finite)``, the ``INTERNAL_FORCE``, ``TENSION`` and ``OMEGA2`` columns
        filled in.  The state is not touched."""
        k = _kernels
        nodes = self.node_table[idx]
        nodes[:, :, k.POSITION : k.POSITION + 3] = x
        nodes[:, :, k.HALF_STEP_VELOCITY : k.HALF_STEP_VELOCITY + 3] = 0.0 if velocities is None else velocities
        cables = self.cable_table[idx]
        if intact is not None:
            cables[:, :, k.INTACT] = intact
        clusters = self.cluster_table[idx]
        finite = np.empty(idx.size, dtype=np.bool_)
        with np.errstate(divide="ignore", invalid="ignore"):
            k.evaluate_forces(self.kernel_settings, taut_branch, self.cables, nodes, cables, clusters, finite)
        return nodes, cables, clusters, finite

    # ------------------------------------------------------------------ integration
    def advance(
        self,
        duration: float,
        force: ArrayLike | None = None,
        *,
        active: ArrayLike | None = None,
        record_steps: int = 0,
    ) -> AdvanceStats:
        """Integrate every active cluster over ``duration`` seconds with the external force held.

        Args:
            duration: interval length, s, > 0.  Each cluster lands exactly on its end.
            force: (B, n, 3) external force p on each node (thrust and bias on satellites), N; default zero.
            active: (B,) bool mask of clusters to integrate (default all); others are left as
                they are, and so are clusters already flagged as diverged.
            record_steps: record the first R sub-step sizes of each cluster in the result.

        Returns:
            :class:`AdvanceStats`.  A cluster whose state became non-finite or that needed more than
            ``max_substeps`` sub-steps is flagged in ``status`` and frozen until reset.
        """
        duration = _check_duration(duration)
        shape = (self.num_clusters, self.num_nodes, 3)
        p = np.zeros(shape) if force is None else _check_array("force", force, shape, "N", MAX_FORCE)
        if not is_whole_number(record_steps) or not 0 <= record_steps <= MAX_RECORDED_STEPS:
            raise ValueError(f"record_steps must be a whole number in 0..{MAX_RECORDED_STEPS}; got {record_steps!r}")
        if active is None:
            mask = self._all_active
        else:
            mask = _kernels.kernel_operand(active)
            if mask.shape != (self.num_clusters,) or mask.dtype != np.bool_:
                raise ValueError(f"active must be a boolean array of shape ({self.num_clusters},); got {active!r}")
        self.applied_force[...] = p
        step_sizes = np.full((self.num_clusters, int(record_steps)), np.nan)
        self.advance_unchecked(duration, mask, step_sizes)
        last = self.last_advance
        return AdvanceStats(
            substeps=last.substeps.copy(),
            step_min=last.step_min.copy(),
            step_max=last.step_max.copy(),
            status=last.status.copy(),
            step_sizes=step_sizes,
            peak_tension=last.peak_tension.copy(),
        )

    def advance_unchecked(self, duration: float, active: np.ndarray, step_sizes: np.ndarray | None = None) -> None:
        """:meth:`advance` without argument checks, with the force already in :attr:`applied_force`;
        the results are in :attr:`last_advance`.

        For callers that validated their inputs (the environments): ``duration`` > 0, the
        applied force finite, ``active`` a (B,) bool array, ``step_sizes`` None or a (B, R)
        float64 array that receives the first R sub-steps.
        """
        if self.num_clusters >= _kernels.LANE_MIN_BATCH:
            kernel = _kernels.advance_parallel_in_lanes
        elif self.num_clusters >= PARALLEL_MIN_BATCH:
            kernel = _kernels.advance_parallel
        else:
            kernel = _kernels.advance_serial
        kernel(
            duration,
            active,
            self.kernel_settings,
            self.cables,
            self.node_table,
            self.cable_table,
            self.cluster_table,
            self.counter_table,
            self._no_record if step_sizes is None else step_sizes,
        )

    # ------------------------------------------------------------------ queries
    def internal_forces(self, positions: ArrayLike, indices: Sequence[int] | np.ndarray | None = None) -> np.ndarray:
        """(k, n, 3) elastic restoring forces f_int, N, at ``positions`` (k, n, 3), m, of clusters
        ``indices`` (default all B, in order), with each cluster's own cable parameters and its
        broken cables left out.

        ``f_int`` is the term of ``M a + C v + f_int = p``.  In an inertial frame a satellite held
        at rest at ``positions`` needs the external force ``p = f_int`` to stay there; see
        :meth:`equilibrium_force` for turning frames.
        """
        return self._forces_at(positions, indices)[2]

    def _coincident_cable(self, positions: np.ndarray) -> str:
        """Which cable of one cluster's (n, 3) ``positions`` has zero length, named by its nodes."""
        lengths = np.linalg.norm(positions[self.cables[:, 1]] - positions[self.cables[:, 0]], axis=1)
        cable = int(np.argmin(np.where(np.isfinite(lengths), lengths, 0.0)))
        i, j = (self.template.node_label(int(node)) for node in self.cables[cable])
        return f"cable {cable} joins {i} and {j}, which coincide"

    def _forces_at(
        self, positions: ArrayLike, indices: Sequence[int] | np.ndarray | None, intact: bool | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(idx, x, f_int)``: the checked cluster indices and (k, n, 3) positions, and the elastic
        forces there, with every cable intact when ``intact`` is True (default: each cluster's
        current state)."""
        idx = self.cluster_indices(indices)
        x = _check_array("positions", positions, (idx.size, self.num_nodes, 3), "m")
        nodes, _, _, finite = self.evaluate_at(x, idx, intact=intact)
        if not finite.all():
            raise ValueError(
                f"positions of cluster(s) {idx[~finite].tolist()} give a zero-length cable: "
                f"{self._coincident_cable(x[int(np.argmin(finite))])}; two connected nodes may not coincide"
            )
        column = _kernels.INTERNAL_FORCE
        return idx, x, nodes[:, :, column : column + 3]

    def equilibrium_force(self, positions: ArrayLike, indices: Sequence[int] | np.ndarray | None = None) -> np.ndarray:
        """(k, n, 3) external force, N, that holds clusters ``indices`` at rest in their frame at
        ``positions`` (k, n, 3), m, with every cable intact: ``f_int(x) - M diag(T) x``.

        It is zero (to round-off) for a cluster whose shape is an equilibrium of its frame, such as
        a radial chain in the Hill frame or a spinning formation in its rotating frame.
        """
        idx, x, f_int = self._forces_at(positions, indices, intact=True)
        return f_int - self.masses[idx][:, :, None] * self.frame_tidal[idx][:, None, :] * x

    def critical_time_step(self, method: CriticalStepMethod = "closed-form") -> np.ndarray:
        """(B,) estimated critical step ``2 / omega_max`` at the current positions, s.

        ``omega_max`` is bounded by the largest element frequency (Irons-Treharne), with node masses
        split equally among cables and every cable on its taut branch.  ``"closed-form"`` uses the
        exact element eigenvalue ``max(EA/L0, N/L) (1/m_i^e + 1/m_j^e)``, the integrator's fast
        path; ``"finite-difference"`` is the paper's reference method (section 4): the element
        stiffness is built column by column from central differences of the element force (eq. 21)
        and bounded by its largest mass-scaled column L1 norm (eqs. 19-20).  The reference is never
        larger than the closed form's step.  The sub-step actually taken is
        ``safety_factor`` times this.
        """
        if method == "closed-form":
            omega2 = self._omega2
        elif method == "finite-difference":
            omega2 = self.element_omega2_finite_difference().max(axis=1)
        else:
            raise ValueError(f"method must be 'closed-form' or 'finite-difference'; got {method!r}")
        with np.errstate(divide="ignore"):
            return 2.0 / np.sqrt(omega2)

    def element_omega2_finite_difference(self, relative_perturbation: float = 1e-6) -> np.ndarray:
        """(B, m) the paper's finite-difference column-L1 bound on each cable's squared frequency,
        (rad/s)^2: see :func:`tether_gym.analysis.element_omega2_finite_difference`."""
        from tether_gym.analysis import element_omega2_finite_difference

        return element_omega2_finite_difference(self, relative_perturbation)

    def energy(self) -> EnergyReport:
        """Energy accounting of every cluster since its last reset (see :class:`EnergyReport`)."""
        # Contiguous copies: einsum's summation order (and so its last bits) depends on the layout.
        masses = np.ascontiguousarray(self.masses)
        velocities = np.ascontiguousarray(self.velocities_)
        kinetic = 0.5 * np.einsum("bn,bnd,bnd->b", masses, velocities, velocities)
        # With axial damping the tension holds a viscous part; the strain energy is elastic only.
        elastic = (
            self.tension
            if not self.axial_damping.any()
            else self.evaluate_at(self.positions_, np.arange(self.num_clusters))[1][:, :, _kernels.TENSION]
        )
        strain = (0.5 * elastic**2 / self.stiffness).sum(axis=1)
        tidal = np.ascontiguousarray(self.frame_tidal)
        frame_potential = -0.5 * np.einsum("bn,bnd,bd->b", masses, self.positions_**2, tidal)
        row = self.cluster_table
        initial, dissipated, work = (
            row[:, c].copy() for c in (_kernels.INITIAL_ENERGY, _kernels.DISSIPATED, _kernels.WORK)
        )
        residual = kinetic + strain + frame_potential - initial + dissipated - work
        return EnergyReport(
            kinetic=kinetic,
            strain=strain,
            frame_potential=frame_potential,
            dissipated=dissipated,
            work=work,
            initial=initial,
            residual=residual,
        )


class Simulator:
    """One tether cluster, integrated by the batched core (a batch of one); arrays are (n, 3).

    Args:
        cluster: the :class:`Cluster` to simulate.
        **options: ``safety_factor``, ``elongation``, ``max_step``, ``max_substeps``,
            ``allow_unstable_safety_factor``, ``energy_tolerance`` as in :class:`BatchSimulator`.

    Unlike the batch, a single simulator raises :class:`SimulationDiverged` when the integration
    fails, since there is no other cluster to carry on with.
    """

    def __init__(self, cluster: Cluster, **options: object) -> None:
        if not isinstance(cluster, Cluster):
            raise TypeError(f"Simulator takes a Cluster (see tether_gym.make_cluster); got {type(cluster).__name__}")
        self.cluster = cluster
        self.batch = BatchSimulator(cluster, 1, **options)  # type: ignore[arg-type]

    @property
    def positions(self) -> np.ndarray:
        """(n, 3) current positions, m."""
        return self.batch.positions[0]

    @property
    def velocities(self) -> np.ndarray:
        """(n, 3) current velocities, m/s."""
        return self.batch.velocities[0]

    @property
    def time(self) -> float:
        """Time since the last reset, s."""
        return float(self.batch.time[0])

    @property
    def tension(self) -> np.ndarray:
        """(m,) cable tensions at the current positions, N."""
        return self.batch.tension[0].copy()

    @property
    def slack(self) -> np.ndarray:
        """(m,) bool: slack cables at the current positions."""
        return self.batch.slack[0]

    def reset(self, positions: ArrayLike | None = None, velocities: ArrayLike | None = None) -> None:
        """Set the state: positions (n, 3) in m (default nominal), velocities (n, 3) in m/s (default 0)."""
        n = self.cluster.num_nodes
        x0 = (
            self.cluster.positions
            if positions is None
            else _check_array("positions", positions, (n, 3), "m", MAX_COORDINATE)
        )
        v0 = None if velocities is None else _check_array("velocities", velocities, (n, 3), "m/s", MAX_SPEED)[None]
        self.batch.reset(x0[None], v0)

    def advance(self, duration: float, force: ArrayLike | None = None, *, record_steps: int = 0) -> AdvanceStats:
        """Integrate over ``duration`` s with the external force (n, 3), N, held constant.

        Returns the :class:`AdvanceStats` of the batch of one (arrays of shape (1,)).  Raises
        :class:`SimulationDiverged` if the state became non-finite or its energy left its books
        (then only :meth:`reset` revives it), or if the interval needed more than ``max_substeps``
        sub-steps (then the cluster is back where it was before the call, and may advance again
        over shorter intervals).
        """
        p = None if force is None else _check_array("force", force, (self.cluster.num_nodes, 3), "N", MAX_FORCE)[None]
        stats = self.batch.advance(duration, p, record_steps=record_steps)
        if stats.status[0] == _kernels.STATUS_NON_FINITE:
            raise SimulationDiverged(
                "the state became non-finite (a cable reached zero length or the motion blew up); "
                "reduce safety_factor or the initial conditions, then reset()"
            )
        if stats.status[0] == _kernels.STATUS_ENERGY_RUNAWAY:
            report = self.energy()
            raise SimulationDiverged(
                f"the energy left its books: residual {report.residual:.3g} J against initial {report.initial:.3g} J, "
                f"work {report.work:.3g} J, dissipated {report.dissipated:.3g} J (more than "
                f"{self.batch.energy_tolerance:g} of its scale); the integration is unstable: reduce safety_factor "
                f"(now {self.batch.safety_factor:g}) or max_step, then reset()"
            )
        if stats.status[0] == _kernels.STATUS_TOO_MANY_SUBSTEPS:
            raise SimulationDiverged(
                f"more than max_substeps={self.batch.max_substeps} sub-steps were needed for {to_float(duration):g} s; "
                "the simulator is back where it was before this call: advance over shorter intervals or raise "
                "max_substeps"
            )
        return stats

    def internal_forces(self, positions: ArrayLike) -> np.ndarray:
        """(n, 3) restoring forces f_int at ``positions`` (n, 3), N (see BatchSimulator)."""
        x = _check_array("positions", positions, (self.cluster.num_nodes, 3), "m")
        return self.batch.internal_forces(x[None])[0]

    def critical_time_step(self, method: CriticalStepMethod = "closed-form") -> float:
        """Estimated critical step at the current state, s (see BatchSimulator.critical_time_step)."""
        return float(self.batch.critical_time_step(method)[0])

    def energy(self) -> EnergyReport:
        """Energy accounting since the last reset, as floats (see :class:`EnergyReport`)."""
        report = self.batch.energy()
        values = {k: float(getattr(report, k)[0]) for k in report.__dataclass_fields__}
        return EnergyReport(**values)  # type: ignore[arg-type]  # a single cluster's report holds floats
