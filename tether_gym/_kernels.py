"""Compiled kernels of the physics core: the only place where the dynamics is written.

Every kernel works on one cluster at a time and is driven over a batch by a serial or a
parallel loop.  Clusters never share data inside a kernel, so a cluster integrated in a batch
follows exactly the same floating-point operations as the same cluster integrated alone
(bit-identical results, whatever the batch size or the number of threads).

**The tables.**  The kernels read and write the simulator's state through a few tables, one per
kind of entity, whose columns are named below and nowhere else:

* the node table ``(B, n, NODE_COLUMNS)`` float64, one row per satellite;
* the cable table ``(B, m, CABLE_COLUMNS)`` float64, one row per cable;
* the cluster table ``(B, CLUSTER_COLUMNS)`` float64 and the counter table
  ``(B, COUNTER_COLUMNS)`` int64, one row per cluster;
* the topology ``(m, 2)`` int64 (the node indices of each cable, shared by the batch), and the
  settings ``(SETTINGS,)`` float64 (shared too).

Each table holds its entity's parameters, its state and what the last advance measured, so a
kernel takes a handful of arrays however many physical quantities there are, and a new quantity
is a new column, not a new argument in every signature.  (numba charges about 0.2 us per array
argument on every call: the 40 arguments the integrator once took were most of a single env's
step.)  Vector quantities take three consecutive columns (x, y, z), starting at the named one.

Conventions (SI units throughout): per cable ``stiffness = EA / L0`` in N/m, the rest length
``L0`` in m, the pretension ``N0`` in N, ``inv_split_mass_sum = 1/m_i^e + 1/m_j^e`` in 1/kg, where
the node masses are split equally among the cables meeting at the node (so that the element
masses sum to the assembled mass and the Irons-Treharne bound holds).  The internal force
``f_int`` is the restoring force of the equation of motion ``M a + C v + f_int = p``: a taut
cable contributes ``-N e`` at node i and ``+N e`` at node j, with ``e`` the unit vector from i to
j.
"""

from __future__ import annotations

import hashlib
import math
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numba
import numpy as np
from numba import config, njit, prange
from numpy.typing import ArrayLike

from tether_gym import _compilation  # noqa: F401 - announces each kernel group as it compiles

# The OpenMP layer scheduled the batched kernels 1.5-2x faster than numba's default
# "workqueue" layer on a busy 2-core machine (N = 1024 vector env: ~0.8 M against 0.4-0.58 M
# env steps/s); results are the same bits either way.  Users keep control through numba's own
# environment variables.
if "NUMBA_THREADING_LAYER" not in os.environ and "NUMBA_THREADING_LAYER_PRIORITY" not in os.environ:
    numba.config.THREADING_LAYER_PRIORITY = ["omp", "tbb", "workqueue"]  # type: ignore[attr-defined]
# OpenMP threads spin while they wait for work (libgomp: 300 000 spins by default). When other
# jobs share the cores (training next to an evaluation, a benchmark next to the tests), the
# spinning threads starve each other. Measured on this 2-core machine, native vector env at
# N = 64 (and N = 1024), env steps/s:
#   spin count             quiet machine        under load (two other busy processes)
#   default (300 000)      477-523 k (1.20 M)   2.0 k
#   100 000                499 k (1.17 M)       3.0 k
#   1 000                  397 k (1.13 M)       71 k
#   passive waiting        214-263 k (0.8-1.0 M) 105 k
# 1 000 keeps most of the quiet speed and avoids the collapse under load. It costs the quiet
# machine's second thread 25-50 us per parallel region, when the worker has gone to sleep during
# the Python between two steps: 30 000 spins ran 1.0-1.3x faster at N = 1 024 quiet, and up to
# 4.5x slower at N = 64 beside two busy processes (docs/speed.md, "Two threads"). libgomp reads it when
# numba first loads it (at the first parallel call), so setting it here takes effect; a user's
# own OMP_WAIT_POLICY or GOMP_SPINCOUNT wins.
if "OMP_WAIT_POLICY" not in os.environ:
    os.environ.setdefault("GOMP_SPINCOUNT", "1000")

# ---------------------------------------------------------------------------------------------
# The node table, (B, n, NODE_COLUMNS): one row per satellite.
MASS = 0  # kg
DAMPING = 1  # N*s/m, the satellite's diagonal (absolute) damping
REFERENCE = 2  # m, 3 columns: the position the linearised elongation is measured from
POSITION = 5  # m, 3 columns, in the cluster's frame
HALF_STEP_VELOCITY = 8  # m/s, 3 columns: v_{n-1/2}, the velocity the cables' axial damping sees (v_0 after a reset)
VELOCITY = 11  # m/s, 3 columns: v_n, at the current time
INTERNAL_FORCE = 14  # N, 3 columns: f_int at the current positions
PREVIOUS_FORCE = 17  # N, 3 columns: the applied force of the last interval (for exact impulses)
APPLIED_FORCE = 20  # N, 3 columns: the external force p held over the coming interval
NODE_COLUMNS = 23

# The cable table, (B, m, CABLE_COLUMNS): one row per cable.
STIFFNESS = 0  # N/m, EA / L0
REST_LENGTH = 1  # m, L0
PRETENSION = 2  # N, N0
INV_SPLIT_MASS_SUM = 3  # 1/kg
BREAKING_LOAD = 4  # N
AXIAL_DAMPING = 5  # N*s/m, Kelvin-Voigt
TENSION = 6  # N, at the current positions (0 when slack or broken)
INTACT = 7  # 1.0 intact, 0.0 broken (a float, so that the whole cable lives in one table)
PEAK_TENSION = 8  # N, the largest tension during the last advance (the tension itself after a reset)
CABLE_COLUMNS = 9

# The cluster table, (B, CLUSTER_COLUMNS): one row per cluster.
FRAME_RATE = 0  # rad/s, the frame's rotation rate about z
FRAME_TIDAL = 1  # 1/s^2, 3 columns: the diagonal of the frame's centrifugal and tidal term
TIME = 4  # s since the reset
LAST_STEP = 5  # s, the last sub-step (0 right after a reset: the next one starts uniformly accelerated)
OMEGA2 = 6  # (rad/s)^2, the step-limiting frequency estimate at the current positions
WORK = 7  # J, external work since the reset
DISSIPATED = 8  # J, damping and broken cables since the reset
INITIAL_ENERGY = 9  # J, at the reset
STEP_MIN = 10  # s, the smallest sub-step of the last advance (inf if it took none)
STEP_MAX = 11  # s, the largest sub-step of the last advance (0 if it took none)
ENERGY_SCALE = 12  # J, the largest energy scale of the books since the reset (see _energy_runaway)
CLUSTER_COLUMNS = 13

# The counter table, (B, COUNTER_COLUMNS) int64: one row per cluster.
STATUS = 0  # a STATUS_* code; a cluster that is not STATUS_OK is frozen until reset
SUBSTEPS = 1  # sub-steps of the last advance
COUNTER_COLUMNS = 2

# The settings, (SETTINGS,) float64: one per batch.
SAFETY_FACTOR = 0  # the sub-step as a fraction of the estimated critical step
MAX_STEP = 1  # s, an upper bound on the sub-step
MAX_SUBSTEPS = 2  # sub-steps one advance may take per cluster (a whole number, exact in float64)
LINEARISED = 3  # 1.0: the paper's linearised elongation (eq. 11), 0.0: the exact one
ENERGY_TOLERANCE_SETTING = 4  # the runaway guard's relative tolerance (inf: no guard); see _energy_runaway
SETTINGS = 5

#: Every column number above, in one tuple: the kernels of other modules that read these tables
#: hold it in their closure, which numba's cache hashes, so that a change here recompiles them
#: (the cache watches only the file a kernel is written in).
LAYOUT = (
    (MASS, DAMPING, REFERENCE, POSITION, HALF_STEP_VELOCITY, VELOCITY, INTERNAL_FORCE, PREVIOUS_FORCE),
    (APPLIED_FORCE, NODE_COLUMNS),
    (STIFFNESS, REST_LENGTH, PRETENSION, INV_SPLIT_MASS_SUM, BREAKING_LOAD, AXIAL_DAMPING, TENSION, INTACT),
    (PEAK_TENSION, CABLE_COLUMNS),
    (FRAME_RATE, FRAME_TIDAL, TIME, LAST_STEP, OMEGA2, WORK, DISSIPATED, INITIAL_ENERGY, STEP_MIN, STEP_MAX),
    (ENERGY_SCALE,),
    (CLUSTER_COLUMNS, STATUS, SUBSTEPS, COUNTER_COLUMNS),
    (SAFETY_FACTOR, MAX_STEP, MAX_SUBSTEPS, LINEARISED, ENERGY_TOLERANCE_SETTING, SETTINGS),
)
#: SHA-256 of this file: kernels of other modules that compile these into their own cached code
#: key their cache on it (numba keys a cache only on the file of the kernel itself).
SOURCE_SHA256 = hashlib.sha256((Path(__file__).resolve().parent / "_kernels.py").read_bytes()).hexdigest()

# Status codes of a cluster in a batch.  STATUS_NON_FINITE and STATUS_ENERGY_RUNAWAY freeze the
# cluster until reset; STATUS_TOO_MANY_SUBSTEPS refuses one interval and puts the cluster back at
# its start, so that the cluster may try again over shorter intervals.
STATUS_OK = 0
STATUS_NON_FINITE = 1  # a non-finite state, or a cable of zero length
STATUS_TOO_MANY_SUBSTEPS = 2  # the interval needed more than MAX_SUBSTEPS sub-steps: refused, rolled back
STATUS_ENERGY_RUNAWAY = 3  # the energy left its books (see _energy_runaway)
#: Every status code, for checks of states from outside (a restored state).
STATUS_CODES = (STATUS_OK, STATUS_NON_FINITE, STATUS_TOO_MANY_SUBSTEPS, STATUS_ENERGY_RUNAWAY)

#: The energy balance's largest relative residual before a cluster is flagged STATUS_ENERGY_RUNAWAY,
#: by default (the batch's ENERGY_TOLERANCE_SETTING):
#: ``|kinetic + strain + frame potential - initial + dissipated - work|`` over the largest of
#: ``kinetic + strain + |frame potential|`` with the kinetic energy taken relative to the centre
#: of mass (a uniform drift carries no error), ``|work|``, ``dissipated`` and a round-off floor
#: of the drift energy, at the reset and the end of any interval since (the largest so far: a
#: cluster pushed and brought back to rest holds round-off of the energy it once had, not of
#: zero).  The
#: residual of the exact solution is zero, and the integrator's is O(h^2); chosen from data
#: (docs/verification.md, "The runaway guard").
ENERGY_TOLERANCE = 0.25

#: The fraction of the drift energy (the centre of mass's kinetic energy) that the runaway
#: guard's scale keeps as its floor: the residual's round-off is about 1e-16 of the drift per
#: operation, 1e-13 after a million sub-steps, far below it, and a vibration that grows past
#: a quarter of it (2.5e-10 of the drift) is still flagged.
DRIFT_ROUND_OFF = 1e-9

#: Node columns saved at the start of each interval, from POSITION on (positions, half-step
#: velocities, velocities, internal forces): with each cable's TENSION and INTACT and the cluster's
#: OMEGA2, all that sub-steps overwrite before the interval ends.  An interval refused for its
#: sub-step budget puts them back.
SAVED_NODE_COLUMNS = INTERNAL_FORCE + 3 - POSITION

#: Chunks the parallel drivers split a batch into: enough to even out clusters that sub-step more
#: over any likely number of threads, few enough that the per-chunk call costs nothing.
PARALLEL_CHUNKS = 64
#: The fewest chunks the lane drivers split a batch into (see :func:`parallel_chunks`): two
#: per thread that numba may run, to even out chunks that sub-step more.  Read once, at import, and
#: compiled in as a constant: it only sets how the work is shared, never the bits.
PARALLEL_MIN_CHUNKS = 2 * int(config.NUMBA_NUM_THREADS)  # type: ignore[attr-defined]  # set at import by numba


def kernel_operand(values: ArrayLike, dtype: type | None = None) -> np.ndarray:
    """``values`` as the kernels' one compiled variant takes an array: C-contiguous and writable
    (and of ``dtype`` if given), copied only when it is not so already.  Three flag checks cost
    about 0.2 us against about 3 us for ``np.require``, which matters on the single env's step."""
    array = np.asarray(values)
    if (dtype is None or array.dtype == dtype) and array.flags.c_contiguous and array.flags.writeable:
        return array
    return np.array(array, dtype=dtype, order="C")


@njit(cache=True, nogil=True)
def all_finite(values: np.ndarray) -> bool:
    """Whether every entry of the float64 array ``values`` (any shape) is finite.  Compiled
    because the single env checks every action: about 0.2 us against 1.3 us for
    ``np.isfinite(values).all()`` on a 12-number action."""
    for value in values.flat:
        if not math.isfinite(value):
            return False
    return True


@njit(cache=True, nogil=True)
def all_within(values: np.ndarray, limit: float) -> bool:
    """Whether every entry of the float64 array ``values`` (any shape) is finite with magnitude
    at most ``limit``: one compiled pass where numpy's checks of a batch's force took about ten
    (NaN, infinities, the magnitude, each a pass and an array), some 40 us at 1 024 clusters."""
    for value in values.flat:
        if not (math.isfinite(value) and abs(value) <= limit):
            return False
    return True


# ---------------------------------------------------------------------------------------------
# Cable forces
def _make_cable_forces(viscous: bool) -> Callable[..., Any]:  # a numba dispatcher
    """Compile :func:`cable_forces` with the Kelvin-Voigt term (``viscous=True``: the general
    kernel) or without it.  ``viscous`` is frozen into the compiled code: merely having the
    viscous term in the loop made the common, undamped case 30 % slower, even when skipped."""

    @njit(cache=True, nogil=True, error_model="numpy")
    def cable_forces(
        nodes: np.ndarray,
        cables: np.ndarray,
        topology: np.ndarray,
        linearised: bool,
        taut_branch: bool,
        may_break: bool,
    ) -> tuple[float, bool, float, float]:
        """Restoring forces and cable tensions of one cluster, plus its largest element frequency.

        Reads the cluster's node table ``nodes`` (n, NODE_COLUMNS) and cable table ``cables``
        (m, CABLE_COLUMNS); writes ``INTERNAL_FORCE`` of every node and ``TENSION`` of every
        cable (0 for slack and broken ones), and raises ``PEAK_TENSION`` to any larger tension.  A
        taut cable carries ``N = max(0, N0 + EA/L0 dL + c_ax dL')``, its stretching rate ``dL'``
        taken from the ``HALF_STEP_VELOCITY`` columns: in the integrator these are ``v_{n-1/2}``,
        the usual explicit (lagged) treatment of a velocity-dependent internal force.  With
        ``may_break``, a cable whose tension passes its breaking load is marked broken
        (``INTACT`` 0) and carries nothing from then on.

        Returns ``(omega2_max, finite, viscous_power, released_energy)``:

        * ``omega2_max``: the largest squared element frequency in (rad/s)^2, taken on the taut branch
          ``max(EA/L0, N_taut/L) * (1/m_i^e + 1/m_j^e)`` so that a slack cable that can snap taut
          within the next step still limits the step.  Axial damping with lagged velocity lowers the
          stable step of an element from ``2/omega`` to ``(2/omega)(sqrt(1 + xi^2) - xi)``, with
          ``xi = c_ax (1/m_i^e + 1/m_j^e) / (2 omega)``; the returned value is the frequency that
          gives that step, ``omega^2 (sqrt(1 + xi^2) + xi)^2``.
        * ``finite``: every intact cable length was finite and non-zero (two tethered satellites
          meeting is a collision the model cannot represent).
        * ``viscous_power``: power dissipated by the cables' axial damping, W.
        * ``released_energy``: elastic energy of the cables that broke in this call, J.

        ``linearised`` measures the elongation as the paper's eq. (11) (end displacements from the
        ``REFERENCE`` positions projected on the current direction).  ``taut_branch=True`` drops
        the tension-only cut-off (``N`` may go negative): the smooth law that the
        finite-difference critical-step estimate perturbs.
        """
        for i in range(nodes.shape[0]):
            for d in range(3):
                nodes[i, INTERNAL_FORCE + d] = 0.0
        omega2_max = 0.0
        length_sum = 0.0
        shortest = math.inf
        viscous_power = 0.0
        released = 0.0
        for c in range(topology.shape[0]):
            cable = cables[c]
            if cable[INTACT] == 0.0:
                cable[TENSION] = 0.0
                continue
            i = topology[c, 0]
            j = topology[c, 1]
            dx = nodes[j, POSITION] - nodes[i, POSITION]
            dy = nodes[j, POSITION + 1] - nodes[i, POSITION + 1]
            dz = nodes[j, POSITION + 2] - nodes[i, POSITION + 2]
            length = math.sqrt(dx * dx + dy * dy + dz * dz)
            length_sum += length
            if length < shortest:
                shortest = length
            inverse_length = 1.0 / length
            ex = dx * inverse_length
            ey = dy * inverse_length
            ez = dz * inverse_length
            if linearised:
                # The paper's eq. (11): end displacements projected on the current direction.
                elongation = (
                    (dx - (nodes[j, REFERENCE] - nodes[i, REFERENCE])) * ex
                    + (dy - (nodes[j, REFERENCE + 1] - nodes[i, REFERENCE + 1])) * ey
                    + (dz - (nodes[j, REFERENCE + 2] - nodes[i, REFERENCE + 2])) * ez
                )
            else:
                elongation = length - cable[REST_LENGTH]
            stiffness = cable[STIFFNESS]
            n_taut = cable[PRETENSION] + stiffness * elongation
            n_cable = n_taut if (n_taut > 0.0 or taut_branch) else 0.0
            damping_c = cable[AXIAL_DAMPING]
            if viscous and damping_c > 0.0 and n_cable != 0.0:
                rate = (
                    (nodes[j, HALF_STEP_VELOCITY] - nodes[i, HALF_STEP_VELOCITY]) * ex
                    + (nodes[j, HALF_STEP_VELOCITY + 1] - nodes[i, HALF_STEP_VELOCITY + 1]) * ey
                    + (nodes[j, HALF_STEP_VELOCITY + 2] - nodes[i, HALF_STEP_VELOCITY + 2]) * ez
                )
                n_cable = n_taut + damping_c * rate
                if n_cable < 0.0 and not taut_branch:
                    n_cable = 0.0
                viscous_power += (n_cable - n_taut) * rate
            geometric = n_cable * inverse_length
            k_max = stiffness if stiffness >= geometric else geometric
            omega2 = k_max * cable[INV_SPLIT_MASS_SUM]
            if damping_c > 0.0:
                xi = 0.5 * damping_c * cable[INV_SPLIT_MASS_SUM] / math.sqrt(omega2)
                factor = math.sqrt(1.0 + xi * xi) + xi
                omega2 *= factor * factor
            if omega2 > omega2_max:
                omega2_max = omega2
            if n_cable > cable[PEAK_TENSION]:
                cable[PEAK_TENSION] = n_cable
            if may_break and n_cable > cable[BREAKING_LOAD]:
                cable[INTACT] = 0.0
                elastic = n_taut if n_taut > 0.0 else 0.0
                released += 0.5 * elastic * elastic / stiffness
                n_cable = 0.0
            cable[TENSION] = n_cable
            if n_cable != 0.0:
                fx = n_cable * ex
                fy = n_cable * ey
                fz = n_cable * ez
                nodes[i, INTERNAL_FORCE] -= fx
                nodes[i, INTERNAL_FORCE + 1] -= fy
                nodes[i, INTERNAL_FORCE + 2] -= fz
                nodes[j, INTERNAL_FORCE] += fx
                nodes[j, INTERNAL_FORCE + 1] += fy
                nodes[j, INTERNAL_FORCE + 2] += fz
        finite = math.isfinite(length_sum) and shortest > 0.0
        return omega2_max, finite, viscous_power, released

    return cable_forces


#: The general kernel (any axial damping).
cable_forces = _make_cable_forces(True)
#: The same for clusters without axial damping: the integrator's hot path.
_cable_forces_undamped = _make_cable_forces(False)


# ---------------------------------------------------------------------------------------------
# The integrator's pieces.  ``nodes`` and ``cables`` are one cluster's node and cable tables,
# ``cluster`` its row of the cluster table.
#
# Inlined or called, chosen by measurement (first-use compilation and sub-steps/s, this 2-core
# machine).  Pieces marked ``inline="always"`` are copied into their caller by numba: the
# sub-step and what it runs on every sub-step, so that the two clusters of :func:`_advance_pair`
# keep their chains in one loop body (calling :func:`_substep` instead cost 20-25 % of the
# sub-steps/s).  The others are compiled once and called: numba copies an inlined function's IR
# at every call site, at a cost that grows faster than its size, and the sub-step was inlined
# twice into a pair inlined once more into the driver: compiling the integrator took 10-20 s.
# Calling the kicks away from a fresh state or in a turning frame, the velocity synchronisation
# and the pair itself cut that to about 4 s (CPU time), at the same sub-steps/s or slightly more.
# The per-interval start and end stay inlined: called, they cost the N = 1 024 vector env 3-7 %
# (its intervals are about 9 sub-steps), for 0.4 s less compilation.  The arithmetic is the same
# either way, so are the bits.


@njit(inline="always", error_model="numpy")
def _largest_tidal(cluster: np.ndarray) -> float:
    """``max |T_d|`` of a frame's tidal diagonal, 1/s^2: the frame's share of omega_max^2."""
    return max(abs(cluster[FRAME_TIDAL]), abs(cluster[FRAME_TIDAL + 1]), abs(cluster[FRAME_TIDAL + 2]))


@njit(inline="always", error_model="numpy")
def _solve_gyroscopic(lhs: float, gyro: float, rx: float, ry: float) -> tuple[float, float]:
    """Solve ``lhs vx - gyro vy = rx, lhs vy + gyro vx = ry``: the in-plane part of a velocity
    update whose Coriolis term is taken at the centred velocity (a Cayley rotation, which, like
    the exact Coriolis force, does no work)."""
    det = lhs * lhs + gyro * gyro
    return (lhs * rx + gyro * ry) / det, (lhs * ry - gyro * rx) / det


@njit(inline="always", error_model="numpy")
def _frame_force(nodes: np.ndarray, cluster: np.ndarray, i: int, d: int) -> float:
    """The frame's centrifugal and tidal force on node ``i`` along axis ``d``, ``m T_d x_d``, N."""
    return nodes[i, MASS] * cluster[FRAME_TIDAL + d] * nodes[i, POSITION + d]


@njit(inline="always", error_model="numpy")
def _damping_step(nodes: np.ndarray, safety_factor: float) -> float:
    """``safety_factor * min 2 m / c`` over the damped satellites, s (inf without damping).

    The centred damping update scales v by (m/h - c/2) / (m/h + c/2): stable for any h, but past
    h = 2 m/c it reverses the velocity, which free damped motion never does.  So the step also
    respects the damping time scale, with the same safety factor; it binds only where no cable
    limits the step more (all cables broken, or very heavy damping)."""
    h_damping = math.inf
    for i in range(nodes.shape[0]):
        mass, damping = nodes[i, MASS], nodes[i, DAMPING]
        if damping > 0.0 and 2.0 * mass / damping < h_damping:
            h_damping = 2.0 * mass / damping
    return h_damping * safety_factor


@njit(inline="always", error_model="numpy")
def _step_size(
    omega2: float, h_damping: float, settings: np.ndarray, remaining: float, taken: int
) -> tuple[float, bool]:
    """``(h, last)``: the next sub-step, s, for the ``remaining`` seconds of the interval after
    ``taken`` sub-steps, and whether it ends the interval; ``h = 0`` when the rest of the interval
    would need more sub-steps than the budget allows.

    The stable step is ``min(safety_factor * 2 / omega_est, h_damping, max_step)``; what remains
    is spread evenly over the fewest steps no longer than that: equal steps within an interval,
    and no sliver step before its end."""
    max_substeps = np.int64(settings[MAX_SUBSTEPS])
    h_stable = settings[SAFETY_FACTOR] * 2.0 / math.sqrt(omega2) if omega2 > 0.0 else math.inf
    if h_stable > h_damping:
        h_stable = h_damping
    if h_stable > settings[MAX_STEP]:
        h_stable = settings[MAX_STEP]
    # The step count is compared as a float before it becomes an integer: a duration far beyond
    # the budget would overflow the integer, and the cluster is flagged before it takes steps it
    # could not finish.
    steps_wanted = remaining / h_stable - 1e-9
    if taken >= max_substeps or steps_wanted > max_substeps - taken:
        return 0.0, False
    steps_left = math.ceil(steps_wanted)
    if steps_left <= 1:
        return remaining, True
    return remaining / steps_left, False


@njit(error_model="numpy")  # called, not inlined: see above
def _kick_from_rest(nodes: np.ndarray, cluster: np.ndarray, h: float) -> None:
    """The first half step after a reset, ``v_{1/2} = v_0 + h/2 a_0`` (uniformly accelerated
    motion, paper section 2), with the frame's terms at the initial state."""
    rate = cluster[FRAME_RATE]
    for i in range(nodes.shape[0]):
        mass, damping = nodes[i, MASS], nodes[i, DAMPING]
        v0, v1, v2 = nodes[i, HALF_STEP_VELOCITY], nodes[i, HALF_STEP_VELOCITY + 1], nodes[i, HALF_STEP_VELOCITY + 2]
        ax = (
            nodes[i, APPLIED_FORCE] - nodes[i, INTERNAL_FORCE] - damping * v0 + _frame_force(nodes, cluster, i, 0)
        ) / mass + 2.0 * rate * v1
        ay = (
            nodes[i, APPLIED_FORCE + 1]
            - nodes[i, INTERNAL_FORCE + 1]
            - damping * v1
            + _frame_force(nodes, cluster, i, 1)
        ) / mass - 2.0 * rate * v0
        az = (
            nodes[i, APPLIED_FORCE + 2]
            - nodes[i, INTERNAL_FORCE + 2]
            - damping * v2
            + _frame_force(nodes, cluster, i, 2)
        ) / mass
        nodes[i, HALF_STEP_VELOCITY] = v0 + 0.5 * h * ax
        nodes[i, HALF_STEP_VELOCITY + 1] = v1 + 0.5 * h * ay
        nodes[i, HALF_STEP_VELOCITY + 2] = v2 + 0.5 * h * az


@njit(inline="always", error_model="numpy")
def _dual_force(nodes: np.ndarray, i: int, d: int, blend: float) -> float:
    """The applied force over the velocity update's span, N: ``blend`` of it under the previous
    interval's force and the rest under the new one (exact impulses at force switches)."""
    applied = nodes[i, APPLIED_FORCE + d]
    return applied + blend * (nodes[i, PREVIOUS_FORCE + d] - applied)


@njit(inline="always", error_model="numpy")
def _kick(nodes: np.ndarray, h_mid: float, blend: float) -> None:
    """The velocity update ``v_{n+1/2} = [(M/h_n - C/2) v_{n-1/2} + p - f_int] / (M/h_n + C/2)``
    of the inertial frame, kept free of the frame terms: it is the hot loop."""
    inverse_h_mid = 1.0 / h_mid
    for i in range(nodes.shape[0]):
        inertia = nodes[i, MASS] * inverse_h_mid
        inverse_lhs = 1.0 / (inertia + 0.5 * nodes[i, DAMPING])
        rhs_factor = inertia - 0.5 * nodes[i, DAMPING]
        for d in range(3):
            p_dual = _dual_force(nodes, i, d, blend)
            nodes[i, HALF_STEP_VELOCITY + d] = (
                rhs_factor * nodes[i, HALF_STEP_VELOCITY + d] + p_dual - nodes[i, INTERNAL_FORCE + d]
            ) * inverse_lhs


@njit(error_model="numpy")  # called, not inlined: see above
def _kick_turning(nodes: np.ndarray, cluster: np.ndarray, h_mid: float, blend: float) -> None:
    """:func:`_kick` in a turning frame: with the frame's force ``M T u_n`` and the Coriolis force
    taken at the centred velocity (a 2x2 solve per satellite)."""
    inverse_h_mid = 1.0 / h_mid
    rate = cluster[FRAME_RATE]
    for i in range(nodes.shape[0]):
        mass, damping = nodes[i, MASS], nodes[i, DAMPING]
        inertia = mass * inverse_h_mid
        lhs = inertia + 0.5 * damping
        rhs_factor = inertia - 0.5 * damping
        gyro = mass * rate
        v0, v1, v2 = nodes[i, HALF_STEP_VELOCITY], nodes[i, HALF_STEP_VELOCITY + 1], nodes[i, HALF_STEP_VELOCITY + 2]
        r0 = rhs_factor * v0 + gyro * v1
        r1 = rhs_factor * v1 - gyro * v0
        r2 = rhs_factor * v2
        r0 += _dual_force(nodes, i, 0, blend) - nodes[i, INTERNAL_FORCE] + _frame_force(nodes, cluster, i, 0)
        r1 += _dual_force(nodes, i, 1, blend) - nodes[i, INTERNAL_FORCE + 1] + _frame_force(nodes, cluster, i, 1)
        r2 += _dual_force(nodes, i, 2, blend) - nodes[i, INTERNAL_FORCE + 2] + _frame_force(nodes, cluster, i, 2)
        nodes[i, HALF_STEP_VELOCITY], nodes[i, HALF_STEP_VELOCITY + 1] = _solve_gyroscopic(lhs, gyro, r0, r1)
        nodes[i, HALF_STEP_VELOCITY + 2] = r2 / lhs


@njit(inline="always", error_model="numpy")
def _drift(nodes: np.ndarray, h: float, work: float, dissipated: float) -> tuple[float, float]:
    """``u_{n+1} = u_n + h v_{n+1/2}``, adding the step's external work and diagonal-damping loss to
    the running totals ``work`` and ``dissipated`` (J), which it returns."""
    for i in range(nodes.shape[0]):
        speed2 = 0.0
        for d in range(3):
            velocity = nodes[i, HALF_STEP_VELOCITY + d]
            dx = h * velocity
            work += nodes[i, APPLIED_FORCE + d] * dx
            speed2 += velocity * velocity
            nodes[i, POSITION + d] += dx
        dissipated += h * nodes[i, DAMPING] * speed2
    return work, dissipated


@njit(error_model="numpy")  # called, not inlined: see above
def _synchronise_velocity(nodes: np.ndarray, cluster: np.ndarray, h_last: float) -> None:
    """The velocity at the end of the interval, consistent with the force just applied:
    ``(M + h/2 C) v_n + h M Omega x v_n = M v_{n-1/2} + h/2 (p - f_int(u_n) + M T u_n)``."""
    half = 0.5 * h_last
    rate = cluster[FRAME_RATE]
    for i in range(nodes.shape[0]):
        mass = nodes[i, MASS]
        denominator = mass + half * nodes[i, DAMPING]
        r0 = mass * nodes[i, HALF_STEP_VELOCITY] + half * (
            nodes[i, APPLIED_FORCE] - nodes[i, INTERNAL_FORCE] + _frame_force(nodes, cluster, i, 0)
        )
        r1 = mass * nodes[i, HALF_STEP_VELOCITY + 1] + half * (
            nodes[i, APPLIED_FORCE + 1] - nodes[i, INTERNAL_FORCE + 1] + _frame_force(nodes, cluster, i, 1)
        )
        r2 = mass * nodes[i, HALF_STEP_VELOCITY + 2] + half * (
            nodes[i, APPLIED_FORCE + 2] - nodes[i, INTERNAL_FORCE + 2] + _frame_force(nodes, cluster, i, 2)
        )
        if rate == 0.0:
            nodes[i, VELOCITY] = r0 / denominator
            nodes[i, VELOCITY + 1] = r1 / denominator
        else:
            nodes[i, VELOCITY], nodes[i, VELOCITY + 1] = _solve_gyroscopic(denominator, h_last * mass * rate, r0, r1)
        nodes[i, VELOCITY + 2] = r2 / denominator


@njit(inline="always", error_model="numpy")
def _update_forces(
    nodes: np.ndarray, cables: np.ndarray, topology: np.ndarray, linearised: bool, viscous: bool
) -> tuple[float, bool, float, float]:
    """:func:`cable_forces` at the new positions, breaking overloaded cables; the undamped variant
    when no cable of the cluster has axial damping."""
    if viscous:
        return cable_forces(nodes, cables, topology, linearised, False, True)
    return _cable_forces_undamped(nodes, cables, topology, linearised, False, True)


@njit(inline="always", error_model="numpy")
def _hold_cluster(cables: np.ndarray, cluster: np.ndarray, counters: np.ndarray) -> None:
    """The measurements of a cluster that takes no step (inactive, or frozen by its status)."""
    counters[SUBSTEPS] = 0
    cluster[STEP_MIN] = math.inf
    cluster[STEP_MAX] = 0.0
    for c in range(cables.shape[0]):
        cables[c, PEAK_TENSION] = cables[c, TENSION]


@njit(inline="always", error_model="numpy")
def _begin_advance(
    settings: np.ndarray,
    nodes: np.ndarray,
    cables: np.ndarray,
    cluster: np.ndarray,
    saved: np.ndarray,
) -> tuple:
    """What stays fixed over one cluster's interval, ``(tidal_max, turning, viscous, h_damping,
    omega2, saved)``, and the running values its sub-steps carry, ``(elapsed, count, h_lo, h_hi,
    work, dissipated, h_last)``; also starts each cable's ``PEAK_TENSION`` at its tension, and
    saves what the sub-steps overwrite for :func:`_roll_back`: in ``saved`` (n + m,
    SAVED_NODE_COLUMNS) each node's columns from POSITION on, then each cable's TENSION and
    INTACT; ``omega2`` in ``fixed``."""
    n = nodes.shape[0]
    tidal_max = _largest_tidal(cluster)
    turning = cluster[FRAME_RATE] != 0.0 or tidal_max != 0.0
    viscous = False
    for c in range(cables.shape[0]):
        viscous = viscous or cables[c, AXIAL_DAMPING] > 0.0
        cables[c, PEAK_TENSION] = cables[c, TENSION]
        saved[n + c, 0] = cables[c, TENSION]
        saved[n + c, 1] = cables[c, INTACT]
    for i in range(n):
        for column in range(SAVED_NODE_COLUMNS):
            saved[i, column] = nodes[i, POSITION + column]
    h_damping = _damping_step(nodes, settings[SAFETY_FACTOR])
    fixed = (tidal_max, turning, viscous, h_damping, cluster[OMEGA2], saved)
    running = (0.0, 0, math.inf, 0.0, cluster[WORK], cluster[DISSIPATED], cluster[LAST_STEP])
    return fixed, running


@njit(inline="always", error_model="numpy")
def _next_step(duration: float, settings: np.ndarray, cluster: np.ndarray, fixed: tuple, running: tuple) -> tuple:
    """:func:`_step_size` of the cluster's next sub-step, ``(h, last)``."""
    return _step_size(cluster[OMEGA2], fixed[3], settings, duration - running[0], running[1])


@njit(inline="always", error_model="numpy")
def _substep(
    step: tuple[float, bool],
    settings: np.ndarray,
    topology: np.ndarray,
    nodes: np.ndarray,
    cables: np.ndarray,
    cluster: np.ndarray,
    counters: np.ndarray,
    step_record: np.ndarray,
    fixed: tuple,
    running: tuple,
) -> tuple:
    """One sub-step ``step = (h, last)`` of :func:`_next_step` (kick, drift, forces at the new
    positions): ``(done, running)``, ``done`` when the interval ends (``last``) or the cluster is
    flagged."""
    h, last = step
    tidal_max, turning, viscous, _, _, _ = fixed
    elapsed, count, h_lo, h_hi, work, dissipated, h_last = running
    if h == 0.0:
        counters[STATUS] = STATUS_TOO_MANY_SUBSTEPS
        return True, running
    if h_last == 0.0:
        _kick_from_rest(nodes, cluster, h)
    else:
        blend = h_last / (h_last + h) if count == 0 else 0.0
        if turning:
            _kick_turning(nodes, cluster, 0.5 * (h_last + h), blend)
        else:
            _kick(nodes, 0.5 * (h_last + h), blend)
    work, dissipated = _drift(nodes, h, work, dissipated)
    if count < step_record.shape[0]:
        step_record[count] = h
    count += 1
    h_last = h
    h_lo = min(h_lo, h)
    h_hi = max(h_hi, h)
    omega2_cables, finite, viscous_power, released = _update_forces(
        nodes, cables, topology, settings[LINEARISED] != 0.0, viscous
    )
    cluster[OMEGA2] = omega2_cables + tidal_max
    dissipated += h * viscous_power + released
    done = True
    if not finite:
        counters[STATUS] = STATUS_NON_FINITE
    elif not last:
        elapsed += h
        done = False
    return done, (elapsed, count, h_lo, h_hi, work, dissipated, h_last)


@njit(error_model="numpy")  # called, not inlined: it runs once per interval, on a refusal only
def _roll_back(
    nodes: np.ndarray,
    cables: np.ndarray,
    cluster: np.ndarray,
    counters: np.ndarray,
    saved: np.ndarray,
    omega2: float,
) -> None:
    """Put a cluster back at the start of an interval refused for its sub-step budget, from what
    :func:`_begin_advance` saved: its state is then bit for bit what it was before the advance
    (the running totals were never stored), and it measures as a cluster that took no step."""
    n = nodes.shape[0]
    for i in range(n):
        for column in range(SAVED_NODE_COLUMNS):
            nodes[i, POSITION + column] = saved[i, column]
    for c in range(cables.shape[0]):
        cables[c, TENSION] = saved[n + c, 0]
        cables[c, INTACT] = saved[n + c, 1]
    cluster[OMEGA2] = omega2
    _hold_cluster(cables, cluster, counters)


@njit(error_model="numpy")  # called, not inlined: once per interval, next to its sub-steps
def _energy_runaway(
    nodes: np.ndarray,
    cables: np.ndarray,
    cluster: np.ndarray,
    topology: np.ndarray,
    linearised: bool,
    viscous: bool,
    tolerance: float,
) -> bool:
    """Whether a cluster's energy has left its books: the balance ``kinetic + strain + frame
    potential - initial + dissipated - work`` (the residual of
    :class:`~tether_gym.simulator.EnergyReport`, J) exceeds ``tolerance`` times the
    largest of ``internal kinetic + strain + |frame potential|``, ``|work|``, ``dissipated`` and
    ``DRIFT_ROUND_OFF`` times the drift energy since the reset, which it keeps in
    ``ENERGY_SCALE`` (see :func:`_drift_and_internal`).  A NaN residual counts as a runaway.
    Reads the velocities at the end of the interval; changes nothing else."""
    kinetic = 0.0
    frame_potential = 0.0
    for i in range(nodes.shape[0]):
        mass = nodes[i, MASS]
        for d in range(3):
            velocity = nodes[i, VELOCITY + d]
            position = nodes[i, POSITION + d]
            kinetic += mass * velocity * velocity
            frame_potential -= mass * cluster[FRAME_TIDAL + d] * position * position
    kinetic *= 0.5
    frame_potential *= 0.5
    drift, internal = _drift_and_internal(nodes)
    strain = 0.0
    for c in range(cables.shape[0]):
        cable = cables[c]
        if cable[INTACT] == 0.0:
            continue
        # With axial damping the tension holds a viscous part; the strain energy is elastic only.
        elastic = (
            _elastic_tension(nodes, cable, topology[c, 0], topology[c, 1], linearised) if viscous else cable[TENSION]
        )
        strain += 0.5 * elastic * elastic / cable[STIFFNESS]
    scale, runaway = _energy_verdict(
        kinetic,
        strain,
        frame_potential,
        internal,
        drift,
        cluster[INITIAL_ENERGY],
        cluster[WORK],
        cluster[DISSIPATED],
        cluster[ENERGY_SCALE],
        tolerance,
    )
    cluster[ENERGY_SCALE] = scale
    return runaway


@njit(inline="always", error_model="numpy")
def _energy_verdict(
    kinetic: float,
    strain: float,
    frame_potential: float,
    internal: float,
    drift: float,
    initial: float,
    work: float,
    dissipated: float,
    scale: float,
    tolerance: float,
) -> tuple[float, bool]:
    """The runaway guard's verdict on one cluster from its energies, J (see
    :func:`_energy_runaway`): the new energy scale, and whether the balance's residual exceeds
    ``tolerance`` times it (a NaN residual does).  The lanes call it per lane, so that both
    paths keep the same bits."""
    residual = kinetic + strain + frame_potential - initial + dissipated - work
    # max()'s reduction as numba compiles it (each argument replaces the running value when
    # greater), written out because the lanes' loop vectorises this form.
    largest = scale
    for candidate in (internal + strain + abs(frame_potential), abs(work), dissipated, DRIFT_ROUND_OFF * drift):
        largest = candidate if candidate > largest else largest
    return largest, not abs(residual) <= tolerance * largest


@njit(inline="always", error_model="numpy")
def _drift_and_internal(nodes: np.ndarray) -> tuple[float, float]:
    """``(drift, internal)``: the kinetic energy of a cluster's centre of mass, J, and the rest
    of its kinetic energy (relative to the centre of mass), J, at its current velocities.

    The runaway guard leaves the drift out of its energy scale: the integrator carries a
    uniform drift without error (internal forces cancel in the momentum), so a cluster reset
    with a large common velocity has no larger energy error to forgive, and a scale that counted
    it hid the runaway of its vibration (a snapping pair at 300 m/s was never flagged)."""
    internal = 0.0
    drift = 0.0
    for d in range(3):
        total_mass = 0.0
        momentum = 0.0
        for i in range(nodes.shape[0]):
            total_mass += nodes[i, MASS]
            momentum += nodes[i, MASS] * nodes[i, VELOCITY + d]
        centre = momentum / total_mass
        drift += 0.5 * total_mass * centre * centre
        for i in range(nodes.shape[0]):
            relative = nodes[i, VELOCITY + d] - centre
            internal += 0.5 * nodes[i, MASS] * relative * relative
    return drift, internal


@njit(inline="always", error_model="numpy")
def _elastic_tension(nodes: np.ndarray, cable: np.ndarray, i: int, j: int, linearised: bool) -> float:
    """The elastic part ``max(0, N0 + EA/L0 dL)`` of an intact cable's tension at the current
    positions, N (as :func:`cable_forces` measures the elongation)."""
    dx = nodes[j, POSITION] - nodes[i, POSITION]
    dy = nodes[j, POSITION + 1] - nodes[i, POSITION + 1]
    dz = nodes[j, POSITION + 2] - nodes[i, POSITION + 2]
    length = math.sqrt(dx * dx + dy * dy + dz * dz)
    if linearised:
        elongation = (
            (dx - (nodes[j, REFERENCE] - nodes[i, REFERENCE])) * dx
            + (dy - (nodes[j, REFERENCE + 1] - nodes[i, REFERENCE + 1])) * dy
            + (dz - (nodes[j, REFERENCE + 2] - nodes[i, REFERENCE + 2])) * dz
        ) / length
    else:
        elongation = length - cable[REST_LENGTH]
    tension = cable[PRETENSION] + cable[STIFFNESS] * elongation
    return tension if tension > 0.0 else 0.0


@njit(inline="always", error_model="numpy")
def _record_interval(cluster: np.ndarray, counters: np.ndarray, running: tuple) -> None:
    """Store the measurements of a cluster's interval that was not refused: its last sub-step,
    the work and dissipation books, the sub-step count and the smallest and largest sub-step."""
    _, count, h_lo, h_hi, work, dissipated, h_last = running
    cluster[LAST_STEP] = h_last
    cluster[WORK] = work
    cluster[DISSIPATED] = dissipated
    counters[SUBSTEPS] = count
    cluster[STEP_MIN] = h_lo
    cluster[STEP_MAX] = h_hi


@njit(inline="always", error_model="numpy")
def _end_advance(
    duration: float,
    settings: np.ndarray,
    topology: np.ndarray,
    nodes: np.ndarray,
    cables: np.ndarray,
    cluster: np.ndarray,
    counters: np.ndarray,
    fixed: tuple,
    running: tuple,
) -> None:
    """Store a cluster's measurements of the interval, and its velocity at the end of it; or,
    for an interval refused for its sub-step budget, put the cluster back at its start.  A
    cluster that stays healthy has ``duration`` added to its ``TIME`` and its energy balance
    checked (:func:`_energy_runaway`)."""
    count, h_last = running[1], running[6]
    if counters[STATUS] == STATUS_TOO_MANY_SUBSTEPS:
        if count > 0:
            _roll_back(nodes, cables, cluster, counters, fixed[5], fixed[4])
        else:  # refused before its first step: the state is exactly as it was
            _hold_cluster(cables, cluster, counters)
        return
    _record_interval(cluster, counters, running)
    if count == 0:  # refused before its first step: the state is left exactly as it was
        return
    for i in range(nodes.shape[0]):
        for d in range(3):
            nodes[i, PREVIOUS_FORCE + d] = nodes[i, APPLIED_FORCE + d]
    _synchronise_velocity(nodes, cluster, h_last)
    if counters[STATUS] == STATUS_OK:
        cluster[TIME] += duration
        tolerance = settings[ENERGY_TOLERANCE_SETTING]
        if tolerance < math.inf and _energy_runaway(
            nodes, cables, cluster, topology, settings[LINEARISED] != 0.0, fixed[2], tolerance
        ):
            counters[STATUS] = STATUS_ENERGY_RUNAWAY


@njit(error_model="numpy")  # called, not inlined: see above
def _advance_pair(
    duration: float,
    settings: np.ndarray,
    topology: np.ndarray,
    nodes: np.ndarray,
    cables: np.ndarray,
    clusters: np.ndarray,
    counters: np.ndarray,
    step_record: np.ndarray,
    a: int,
    b: int,
) -> None:
    """Integrate healthy clusters ``a`` and ``b`` of the tables (``b < 0``: ``a`` alone) over
    ``duration`` seconds, each with its ``APPLIED_FORCE`` held.

    Their sub-steps are taken in turn: each sub-step is a chain of dependent square roots and
    divisions (step size, kick, cable lengths), and two independent chains in one loop let the
    processor overlap them.  Each cluster goes through exactly its own operations, so the bits
    are those of a cluster integrated alone.  (The sub-step appears twice; a separate loop for a
    lone cluster, or for the one left when the other ends first, made the first compilation
    seconds longer.)

    Central differences in half-step (leapfrog) form, valid for variable steps::

        h_n        = (h_{n-1/2} + h_{n+1/2}) / 2
        v_{n+1/2}  = [(M/h_n - C/2) v_{n-1/2} + p - f_int(u_n)] / (M/h_n + C/2)
        u_{n+1}    = u_n + h_{n+1/2} v_{n+1/2}

    which at constant step is the paper's three-level scheme (eqs. 7-9).  ``LAST_STEP == 0`` marks
    a fresh state (just reset): the half-step velocity then holds the initial velocity and the
    first interval assumes uniformly accelerated motion, ``v_{1/2} = v_0 + h/2 a_0`` (paper,
    section 2).

    In a turning frame (``FRAME_RATE`` Omega about z, tidal diagonal ``FRAME_TIDAL``, 1/s^2) the
    force gains ``M diag(T) u_n`` and the Coriolis force ``-2 M Omega x v``, which is taken at the
    centred velocity ``(v_{n-1/2} + v_{n+1/2}) / 2`` like the diagonal damping: the update stays
    explicit (a 2x2 solve per satellite), unconditionally stable in the Coriolis term and free of
    spurious Coriolis work.

    The force is piecewise constant and switches at the start of the interval.  The first velocity
    update spans ``[t_n - h_{n-1/2}/2, t_n + h_{n+1/2}/2]``, half under the previous interval's force
    (``PREVIOUS_FORCE``) and half under the new one, so it uses their time-weighted mean: the
    impulse of every force switch is then exact, instead of half a sub-step early.

    Each sub-step is ``min(safety_factor * 2 / omega_est, safety_factor * 2 min(m/c), max_step)``,
    re-estimated at every configuration, then shortened so that the rest of the interval splits
    into equal steps; the interval ends exactly at ``duration``.  A cluster whose remaining
    sub-steps at the current step size would exceed the settings' ``MAX_SUBSTEPS`` is flagged
    ``STATUS_TOO_MANY_SUBSTEPS`` without taking them, and put back at the start of the interval
    (:func:`_roll_back`), from where it may advance again.  ``omega_est^2`` is the largest element value
    of :func:`cable_forces` plus ``max |T|``.  Cables whose tension passes their breaking load
    break and the cluster goes on without them.  The cable table's ``PEAK_TENSION`` receives each
    cable's largest tension over the interval, N; ``step_record`` (R,) the first R sub-steps, s.
    A cluster that stays healthy has ``duration`` added to its ``TIME``; one whose energy then
    leaves its books is flagged ``STATUS_ENERGY_RUNAWAY`` (:func:`_energy_runaway`).
    """
    alone = b < 0
    if alone:
        b = a  # read, never stepped, so both chains have values of one type (its peaks restart at the same tensions)
    # The start states, for a refusal (see _roll_back); an allocation per pair and interval costs
    # about 0.1 us, little next to the sub-steps, and keeps the kernels' signatures short.
    saved = np.empty((2, nodes.shape[1] + cables.shape[1], SAVED_NODE_COLUMNS))
    fixed_a, running_a = _begin_advance(settings, nodes[a], cables[a], clusters[a], saved[0])
    fixed_b, running_b = _begin_advance(settings, nodes[b], cables[b], clusters[b], saved[1])
    done_a = False
    done_b = alone
    while not (done_a and done_b):
        # Both step sizes first (each only reads its cluster): their chains overlap.
        step_a = _next_step(duration, settings, clusters[a], fixed_a, running_a)
        step_b = _next_step(duration, settings, clusters[b], fixed_b, running_b)
        if not done_a:
            done_a, running_a = _substep(
                step_a,
                settings,
                topology,
                nodes[a],
                cables[a],
                clusters[a],
                counters[a],
                step_record[a],
                fixed_a,
                running_a,
            )
        if not done_b:
            done_b, running_b = _substep(
                step_b,
                settings,
                topology,
                nodes[b],
                cables[b],
                clusters[b],
                counters[b],
                step_record[b],
                fixed_b,
                running_b,
            )
    _end_advance(
        duration,
        settings,
        topology,
        nodes[a],
        cables[a],
        clusters[a],
        counters[a],
        fixed_a,
        running_a,
    )
    if not alone:
        _end_advance(
            duration,
            settings,
            topology,
            nodes[b],
            cables[b],
            clusters[b],
            counters[b],
            fixed_b,
            running_b,
        )


# ---------------------------------------------------------------------------------------------
# The same integrator over blocks of clusters in SIMD lanes.  The tables keep a cluster's numbers
# together (a cluster per row), so each block is gathered into arrays with the block's clusters
# innermost (``[node, axis, lane]``), sub-stepped there with every loop over nodes, axes and
# cables branch-free across the lanes, so that one vector instruction updates several clusters,
# and scattered back.  Each lane keeps its own step; a lane that has finished its interval (or
# was flagged) takes a zero step and every write it would make is a select that keeps the old
# value, so a cluster goes through exactly the operations of :func:`_advance_pair`: the same bits,
# whatever block it shares.  The velocity at the interval's end and the energy books run in the
# lanes too (about 7 % of the default id's interval when they ran per cluster); a refused
# interval needs no roll-back copy, as the tables keep its start until the scatter.

#: Clusters per block of :func:`_advance_lanes`: on the tetrahedron at N = 1 024 (one thread, 0.1 s
#: intervals) blocks of 64 and 32 ran alike, 128 about 10 % slower, and 16 at the pairs' rate (the
#: vector loops, 8 lanes of AVX-512 with 4 loops interleaved, need 32 iterations to run at all).
LANE_WIDTH = 64
#: The fewest lane-ready clusters a call integrates in lanes; fewer go in pairs, which have no
#: gather and scatter to pay (from 8 to 31 the lanes run their loops' scalar remainder, at about
#: the pairs' rate).
LANE_MIN_CLUSTERS = 8
#: The smallest batch the simulator and the vector env advance in lanes (with
#: :func:`advance_parallel_in_lanes`): chunks of at least 32 clusters on two threads, which fill the
#: vector loops (AVX-512 runs 8 lanes, 4 loops interleaved); smaller batches gain little.
LANE_MIN_BATCH = 128

# The block's numbers live in three arrays (per node, per cable, per lane), a row of LANE_WIDTH
# lanes per number, and the loops read them through 1-D views of those rows, indexed by the lane
# alone.  Two layouts measured slower: one flat array indexed by computed offsets (numba's check
# for negative indices on each access kept LLVM from vectorising), and an array per number with
# `and` in the selects (the cable loop stayed scalar; its selects now combine with `&`).
# A node's rows: position (3), half-step velocity (3), internal force (3), applied force (3),
# the previous interval's applied force (3), mass, damping.
_L_POSITION, _L_VELOCITY, _L_FORCE, _L_APPLIED, _L_PREVIOUS, _L_MASS, _L_DAMPING = 0, 3, 6, 9, 12, 15, 16
_L_NODE_ROWS = 17
# A cable's rows.
_L_STIFFNESS, _L_REST, _L_PRETENSION, _L_INVERSE_MASS, _L_BREAKING, _L_INTACT, _L_TENSION, _L_PEAK = range(8)
_L_CABLE_ROWS = 8
# The lanes' own rows: the sub-step and its books, and the cable loop's per-lane results.
_L_H, _L_H_LAST, _L_H_DAMPING, _L_ELAPSED, _L_BLEND, _L_INVERSE_H_MID, _L_OMEGA2 = range(7)
_L_WORK, _L_DISSIPATED, _L_H_LO, _L_H_HI, _L_INVERSE_LHS, _L_RHS_FACTOR, _L_SPEED2, _L_OMEGA2_MAX = range(7, 15)
_L_RELEASED, _L_LENGTH_SUM, _L_SHORTEST, _L_PULL, _L_FROM_REST = 15, 16, 17, 18, 21  # _L_PULL: 3 rows
_L_KICK, _L_BROKEN, _L_NON_FINITE = 22, 23, 24
# The interval's end: the frame's tidal diagonal (3 rows), the energy books and their results.
_L_TIDAL, _L_INITIAL, _L_SCALE, _L_KINETIC, _L_FRAME_POTENTIAL, _L_DRIFT, _L_INTERNAL = 25, 28, 29, 30, 31, 32, 33
_L_STRAIN, _L_TOTAL_MASS, _L_MOMENTUM, _L_CENTRE, _L_RUNAWAY = 34, 35, 36, 37, 38
_L_LANE_ROWS = 39


@njit(inline="always", error_model="numpy")
def _lane_ready(cables: np.ndarray, cluster: np.ndarray) -> bool:
    """Whether :func:`_advance_lanes` integrates this cluster: an inertial frame and no axial
    damping (the lanes carry neither the frame's terms nor the Kelvin-Voigt force)."""
    if cluster[FRAME_RATE] != 0.0 or _largest_tidal(cluster) != 0.0:
        return False
    for c in range(cables.shape[0]):
        if cables[c, AXIAL_DAMPING] > 0.0:
            return False
    return True


@njit(inline="always")
def parallel_chunks(batch: int) -> int:
    """How many chunks the parallel drivers split ``batch`` clusters into: chunks of
    :data:`LANE_WIDTH` clusters where the batch has enough, so that each fills its SIMD lanes
    (chunks of 16, from a fixed 64 chunks at N = 1 024, ran their lanes at the scalar rate), and
    at least :data:`PARALLEL_MIN_CHUNKS`."""
    return min(batch, max(batch // LANE_WIDTH, PARALLEL_MIN_CHUNKS))


# Cached, as the pairs' driver is: a kernel that calls a cached kernel links the code numba loads
# from its cache, while an uncached callee is compiled again in each process and optimised again
# inside each caller (the lanes kernels then took about 28 s each to compile; cached, 10-20 s).
@njit(cache=True, nogil=True, error_model="numpy")
def _advance_lanes(  # noqa: C901 - the kernel: one loop body per stage, as the pair has
    duration: float,
    settings: np.ndarray,
    topology: np.ndarray,
    nodes: np.ndarray,
    cables: np.ndarray,
    clusters: np.ndarray,
    counters: np.ndarray,
    step_record: np.ndarray,
    members: np.ndarray,
) -> None:
    """:func:`_advance_pair` for the clusters ``members`` (K,) int64 of the tables, every one
    healthy, active and :func:`_lane_ready` (exact elongation), in blocks of :data:`LANE_WIDTH`
    SIMD lanes: bit for bit the same results, every table and ``step_record`` included."""
    n, m, w = nodes.shape[1], cables.shape[1], LANE_WIDTH
    node_lanes = np.zeros((n, _L_NODE_ROWS, w))
    cable_lanes = np.zeros((m, _L_CABLE_ROWS, w))
    lane = np.zeros((_L_LANE_ROWS, w))
    count = np.zeros(w, dtype=np.int64)
    running = np.zeros(w, dtype=np.bool_)
    last = np.zeros(w, dtype=np.bool_)
    recorded = step_record.shape[1]
    # The lanes' own rows, as 1-D views: the loops index them by the lane alone.
    h_row, h_last_row, h_damping_row, elapsed_row = lane[_L_H], lane[_L_H_LAST], lane[_L_H_DAMPING], lane[_L_ELAPSED]
    blend_row, inverse_h_mid_row, omega2_row = lane[_L_BLEND], lane[_L_INVERSE_H_MID], lane[_L_OMEGA2]
    work_row, dissipated_row = lane[_L_WORK], lane[_L_DISSIPATED]
    h_lo_row, h_hi_row, inverse_lhs_row, rhs_factor_row = (
        lane[_L_H_LO],
        lane[_L_H_HI],
        lane[_L_INVERSE_LHS],
        lane[_L_RHS_FACTOR],
    )
    speed2_row, omega2_max_row, released_row = lane[_L_SPEED2], lane[_L_OMEGA2_MAX], lane[_L_RELEASED]
    length_sum_row, shortest_row, from_rest_row = lane[_L_LENGTH_SUM], lane[_L_SHORTEST], lane[_L_FROM_REST]
    pull_x, pull_y, pull_z = lane[_L_PULL], lane[_L_PULL + 1], lane[_L_PULL + 2]
    kick_row, broken_row, non_finite_row = lane[_L_KICK], lane[_L_BROKEN], lane[_L_NON_FINITE]
    safety_factor, max_step = settings[SAFETY_FACTOR], settings[MAX_STEP]
    max_substeps = np.int64(settings[MAX_SUBSTEPS])
    end_velocity = np.zeros((n, 3, w))
    tolerance = settings[ENERGY_TOLERANCE_SETTING]
    for start in range(0, members.shape[0], w):
        lanes = min(w, members.shape[0] - start)
        for k in range(lanes):
            b = members[start + k]
            # _begin_advance's values, without its copy for a roll-back: the tables keep the
            # interval's start until the scatter, which a refused interval skips.
            h_damping_row[k] = _damping_step(nodes[b], settings[SAFETY_FACTOR])
            omega2_row[k] = clusters[b, OMEGA2]
            elapsed_row[k], count[k], h_lo_row[k], h_hi_row[k] = 0.0, 0, math.inf, 0.0
            work_row[k], dissipated_row[k], h_last_row[k] = (
                clusters[b, WORK],
                clusters[b, DISSIPATED],
                clusters[b, LAST_STEP],
            )
            for d in range(3):
                lane[_L_TIDAL + d, k] = clusters[b, FRAME_TIDAL + d]
            lane[_L_INITIAL, k], lane[_L_SCALE, k] = clusters[b, INITIAL_ENERGY], clusters[b, ENERGY_SCALE]
            running[k] = True
            for i in range(n):
                node_lanes[i, _L_MASS, k], node_lanes[i, _L_DAMPING, k] = nodes[b, i, MASS], nodes[b, i, DAMPING]
                for d in range(3):
                    node_lanes[i, _L_POSITION + d, k] = nodes[b, i, POSITION + d]
                    node_lanes[i, _L_VELOCITY + d, k] = nodes[b, i, HALF_STEP_VELOCITY + d]
                    node_lanes[i, _L_FORCE + d, k] = nodes[b, i, INTERNAL_FORCE + d]
                    node_lanes[i, _L_APPLIED + d, k] = nodes[b, i, APPLIED_FORCE + d]
                    node_lanes[i, _L_PREVIOUS + d, k] = nodes[b, i, PREVIOUS_FORCE + d]
            for c in range(m):
                cable_lanes[c, _L_STIFFNESS, k] = cables[b, c, STIFFNESS]
                cable_lanes[c, _L_REST, k] = cables[b, c, REST_LENGTH]
                cable_lanes[c, _L_PRETENSION, k] = cables[b, c, PRETENSION]
                cable_lanes[c, _L_INVERSE_MASS, k] = cables[b, c, INV_SPLIT_MASS_SUM]
                cable_lanes[c, _L_BREAKING, k] = cables[b, c, BREAKING_LOAD]
                cable_lanes[c, _L_INTACT, k] = cables[b, c, INTACT]
                cable_lanes[c, _L_TENSION, k] = cables[b, c, TENSION]
                cable_lanes[c, _L_PEAK, k] = cables[b, c, TENSION]  # each peak starts at the tension
        active = lanes
        # Only the interval's first sub-step can start from rest (h_last = 0 after a reset) or
        # blend the previous interval's force in (count = 0): every lane of a block starts its
        # interval together, so later sub-steps skip the blend's division and the kick from rest
        # (four divisions per node), which the selects below would otherwise compute and discard.
        first = True
        while active > 0:
            # Step sizes, branch-free across the lanes (the scalar _step_size's operations, in its
            # order); h = 0 marks a lane that does not step.
            refused = 0
            for k in range(lanes):
                omega2, taken = omega2_row[k], count[k]
                h_stable = safety_factor * 2.0 / math.sqrt(omega2) if omega2 > 0.0 else math.inf
                h_stable = h_damping_row[k] if h_stable > h_damping_row[k] else h_stable
                h_stable = max_step if h_stable > max_step else h_stable
                remaining = duration - elapsed_row[k]
                steps_wanted = remaining / h_stable - 1e-9
                refuse = running[k] & ((taken >= max_substeps) | (steps_wanted > np.float64(max_substeps - taken)))
                steps_left = np.ceil(steps_wanted)
                ends = steps_left <= 1.0
                h = remaining if ends else remaining / steps_left
                h = h if running[k] & (not refuse) else 0.0
                h_row[k] = h
                last[k] = ends
                inverse_h_mid_row[k] = 1.0 / (0.5 * (h_last_row[k] + h))
                refused += refuse
            if refused > 0:  # rare: each refused lane is flagged and stops
                for k in range(lanes):
                    if running[k] and h_row[k] == 0.0:
                        counters[members[start + k], STATUS] = STATUS_TOO_MANY_SUBSTEPS
                        running[k] = False
                        active -= 1
            from_rest = False
            if first:
                from_rest_lanes = 0
                for k in range(lanes):
                    h_last, h = h_last_row[k], h_row[k]
                    from_rest_row[k] = 1.0 if h_last == 0.0 else 0.0
                    blend_row[k] = h_last / (h_last + h) if h > 0.0 else 0.0
                    from_rest_lanes += (h > 0.0) & (h_last == 0.0)
                from_rest = from_rest_lanes > 0
            # Kick and drift, node by node (each node's update reads that node only), with the
            # drift's work and damping losses; the internal forces are zeroed for the cables'.
            for i in range(n):
                mass_row, damping_row = node_lanes[i, _L_MASS], node_lanes[i, _L_DAMPING]
                for k in range(lanes):
                    inertia = mass_row[k] * inverse_h_mid_row[k]
                    inverse_lhs_row[k] = 1.0 / (inertia + 0.5 * damping_row[k])
                    rhs_factor_row[k] = inertia - 0.5 * damping_row[k]
                    speed2_row[k] = 0.0
                for d in range(3):
                    velocity, force = node_lanes[i, _L_VELOCITY + d], node_lanes[i, _L_FORCE + d]
                    applied, previous = node_lanes[i, _L_APPLIED + d], node_lanes[i, _L_PREVIOUS + d]
                    position = node_lanes[i, _L_POSITION + d]
                    if from_rest:  # the first half step from a fresh state: uniformly accelerated motion
                        for k in range(lanes):
                            h, v_old, f, p = h_row[k], velocity[k], force[k], applied[k]
                            accelerated = v_old + 0.5 * h * ((p - f - damping_row[k] * v_old) / mass_row[k])
                            kick_row[k] = accelerated if from_rest_row[k] != 0.0 else math.nan
                    for k in range(lanes):
                        h = h_row[k]
                        v_old, f, p = velocity[k], force[k], applied[k]
                        p_dual = p + blend_row[k] * (previous[k] - p)
                        kicked = (rhs_factor_row[k] * v_old + p_dual - f) * inverse_lhs_row[k]
                        kicked = kick_row[k] if from_rest and from_rest_row[k] != 0.0 else kicked
                        v_new = kicked if h > 0.0 else v_old
                        dx = h * v_new
                        velocity[k] = v_new
                        position[k] = position[k] + dx if h > 0.0 else position[k]
                        work_row[k] = work_row[k] + p * dx if h > 0.0 else work_row[k]
                        speed2_row[k] += v_new * v_new
                        force[k] = 0.0 if h > 0.0 else f
                for k in range(lanes):
                    lost = h_row[k] * damping_row[k] * speed2_row[k]
                    dissipated_row[k] = dissipated_row[k] + lost if h_row[k] > 0.0 else dissipated_row[k]
            if first:  # the blend belongs to the interval's first sub-step
                blend_row[:lanes] = 0.0
                first = False
            # Cable forces at the new positions (the undamped cable_forces, breaking included):
            # tensions and their books, then the forces on the cable's two nodes.
            breaking_lanes = 0
            for k in range(lanes):
                omega2_max_row[k] = 0.0
                released_row[k] = 0.0
                length_sum_row[k] = 0.0
                shortest_row[k] = math.inf
            for c in range(m):
                i, j = topology[c, 0], topology[c, 1]
                xi0, xi1, xi2 = (
                    node_lanes[i, _L_POSITION],
                    node_lanes[i, _L_POSITION + 1],
                    node_lanes[i, _L_POSITION + 2],
                )
                xj0, xj1, xj2 = (
                    node_lanes[j, _L_POSITION],
                    node_lanes[j, _L_POSITION + 1],
                    node_lanes[j, _L_POSITION + 2],
                )
                stiffness, rest, pretension = (
                    cable_lanes[c, _L_STIFFNESS],
                    cable_lanes[c, _L_REST],
                    cable_lanes[c, _L_PRETENSION],
                )
                inverse_mass, breaking = cable_lanes[c, _L_INVERSE_MASS], cable_lanes[c, _L_BREAKING]
                intact, tension, peak = cable_lanes[c, _L_INTACT], cable_lanes[c, _L_TENSION], cable_lanes[c, _L_PEAK]
                for k in range(lanes):
                    stepping = h_row[k] > 0.0
                    whole = intact[k] != 0.0
                    counted = stepping & whole
                    dx = xj0[k] - xi0[k]
                    dy = xj1[k] - xi1[k]
                    dz = xj2[k] - xi2[k]
                    length = math.sqrt(dx * dx + dy * dy + dz * dz)
                    length_sum_row[k] = length_sum_row[k] + length if counted else length_sum_row[k]
                    shortest_row[k] = length if counted & (length < shortest_row[k]) else shortest_row[k]
                    inverse_length = 1.0 / length
                    n_taut = pretension[k] + stiffness[k] * (length - rest[k])
                    n_cable = n_taut if (n_taut > 0.0) & whole else 0.0
                    geometric = n_cable * inverse_length
                    k_max = stiffness[k] if stiffness[k] >= geometric else geometric
                    w2 = k_max * inverse_mass[k]
                    omega2_max_row[k] = w2 if counted & (w2 > omega2_max_row[k]) else omega2_max_row[k]
                    peak[k] = n_cable if stepping & (n_cable > peak[k]) else peak[k]
                    breaks = counted & (n_cable > breaking[k])
                    # The strain energy a break frees is booked after the loop, for the lanes that
                    # broke: a division per cable that every other sub-step would discard.
                    broken_row[k] = n_taut if breaks else -1.0
                    breaking_lanes += breaks
                    intact[k] = 0.0 if breaks else intact[k]
                    n_cable = 0.0 if breaks else n_cable
                    tension[k] = n_cable if stepping else tension[k]
                    pulls = stepping & (n_cable != 0.0)
                    pull_x[k] = n_cable * (dx * inverse_length) if pulls else 0.0
                    pull_y[k] = n_cable * (dy * inverse_length) if pulls else 0.0
                    pull_z[k] = n_cable * (dz * inverse_length) if pulls else 0.0
                if breaking_lanes > 0:  # rare
                    for k in range(lanes):
                        n_taut = broken_row[k]
                        if n_taut >= 0.0:
                            elastic = n_taut if n_taut > 0.0 else 0.0
                            released_row[k] = released_row[k] + 0.5 * elastic * elastic / stiffness[k]
                    breaking_lanes = 0
                for d in range(3):
                    pull = lane[_L_PULL + d]
                    force_i, force_j = node_lanes[i, _L_FORCE + d], node_lanes[j, _L_FORCE + d]
                    for k in range(lanes):
                        pulls = (tension[k] != 0.0) & (h_row[k] > 0.0)
                        force_i[k] = force_i[k] - pull[k] if pulls else force_i[k]
                        force_j[k] = force_j[k] + pull[k] if pulls else force_j[k]
            # The sub-step's books (the scalar _substep's), branch-free across the lanes.
            if recorded > 0:
                for k in range(lanes):
                    if h_row[k] > 0.0 and count[k] < recorded:
                        step_record[members[start + k], count[k]] = h_row[k]
            finished, flagged = 0, 0
            for k in range(lanes):
                h = h_row[k]
                stepping = h > 0.0
                count[k] = count[k] + 1 if stepping else count[k]
                h_last_row[k] = h if stepping else h_last_row[k]
                h_lo_row[k] = min(h_lo_row[k], h) if stepping else h_lo_row[k]
                h_hi_row[k] = max(h_hi_row[k], h) if stepping else h_hi_row[k]
                omega2_row[k] = omega2_max_row[k] if stepping else omega2_row[k]
                # no viscous power in these lanes
                dissipated_row[k] = dissipated_row[k] + (h * 0.0 + released_row[k]) if stepping else dissipated_row[k]
                bad = stepping & (not ((abs(length_sum_row[k]) < math.inf) & (shortest_row[k] > 0.0)))
                ends = stepping & (bad | last[k])
                elapsed_row[k] = elapsed_row[k] + h if stepping & (not ends) else elapsed_row[k]
                running[k] = running[k] & (not ends)
                non_finite_row[k] = 1.0 if bad else 0.0
                finished += ends
                flagged += bad
            active -= finished
            if flagged > 0:  # rare
                for k in range(lanes):
                    if non_finite_row[k] != 0.0:
                        counters[members[start + k], STATUS] = STATUS_NON_FINITE
        _velocity_at_end_in_lanes(lanes, node_lanes, lane, end_velocity)
        if tolerance < math.inf:
            _energy_runaway_in_lanes(lanes, tolerance, node_lanes, cable_lanes, lane, end_velocity)
        for k in range(lanes):
            b = members[start + k]
            if counters[b, STATUS] == STATUS_TOO_MANY_SUBSTEPS:  # refused: the tables hold its start
                _hold_cluster(cables[b], clusters[b], counters[b])
                continue
            for i in range(n):
                for d in range(3):
                    nodes[b, i, POSITION + d] = node_lanes[i, _L_POSITION + d, k]
                    nodes[b, i, HALF_STEP_VELOCITY + d] = node_lanes[i, _L_VELOCITY + d, k]
                    nodes[b, i, INTERNAL_FORCE + d] = node_lanes[i, _L_FORCE + d, k]
            for c in range(m):
                cables[b, c, TENSION] = cable_lanes[c, _L_TENSION, k]
                cables[b, c, INTACT] = cable_lanes[c, _L_INTACT, k]
                cables[b, c, PEAK_TENSION] = cable_lanes[c, _L_PEAK, k]
            clusters[b, OMEGA2] = omega2_row[k]
            ended = (
                elapsed_row[k], count[k], h_lo_row[k], h_hi_row[k], work_row[k], dissipated_row[k], h_last_row[k],
            )  # fmt: skip
            # _end_advance's writes, with the velocity and the energy books from the lanes.
            _record_interval(clusters[b], counters[b], ended)
            if count[k] == 0:
                continue
            for i in range(n):
                for d in range(3):
                    nodes[b, i, PREVIOUS_FORCE + d] = nodes[b, i, APPLIED_FORCE + d]
                    nodes[b, i, VELOCITY + d] = end_velocity[i, d, k]
            if counters[b, STATUS] == STATUS_OK:
                clusters[b, TIME] += duration
                if tolerance < math.inf:
                    clusters[b, ENERGY_SCALE] = lane[_L_SCALE, k]
                    if lane[_L_RUNAWAY, k] != 0.0:
                        counters[b, STATUS] = STATUS_ENERGY_RUNAWAY


@njit(inline="always", error_model="numpy")
def _velocity_at_end_in_lanes(lanes: int, node_lanes: np.ndarray, lane: np.ndarray, end_velocity: np.ndarray) -> None:
    """:func:`_synchronise_velocity` for every lane of a block of :func:`_advance_lanes` (an
    inertial frame), its operations in their order: each node's velocity at the end of the
    interval into ``end_velocity`` (n, 3, lanes), m/s.  Lanes that took no step get values too,
    which the caller does not read."""
    h_last_row = lane[_L_H_LAST]
    for i in range(node_lanes.shape[0]):
        mass_row, damping_row = node_lanes[i, _L_MASS], node_lanes[i, _L_DAMPING]
        for d in range(3):
            velocity, applied = node_lanes[i, _L_VELOCITY + d], node_lanes[i, _L_APPLIED + d]
            force, position, tidal = node_lanes[i, _L_FORCE + d], node_lanes[i, _L_POSITION + d], lane[_L_TIDAL + d]
            ended = end_velocity[i, d]
            for k in range(lanes):
                half = 0.5 * h_last_row[k]
                mass = mass_row[k]
                denominator = mass + half * damping_row[k]
                frame_force = mass * tidal[k] * position[k]
                ended[k] = (mass * velocity[k] + half * (applied[k] - force[k] + frame_force)) / denominator


@njit(inline="always", error_model="numpy")
def _energy_runaway_in_lanes(
    lanes: int,
    tolerance: float,
    node_lanes: np.ndarray,
    cable_lanes: np.ndarray,
    lane: np.ndarray,
    end_velocity: np.ndarray,
) -> None:
    """:func:`_energy_runaway` for every lane of a block of :func:`_advance_lanes` (an inertial
    frame, no axial damping), its operations in their order, from the velocities at the end of the
    interval ``end_velocity`` (n, 3, lanes): each lane's energy scale into ``_L_SCALE`` and
    whether its energy left its books into ``_L_RUNAWAY`` (1.0 or 0.0).  Unhealthy lanes get
    values too, which the caller does not read."""
    n, m = node_lanes.shape[0], cable_lanes.shape[0]
    kinetic, frame_potential = lane[_L_KINETIC], lane[_L_FRAME_POTENTIAL]
    drift, internal, strain = lane[_L_DRIFT], lane[_L_INTERNAL], lane[_L_STRAIN]
    total_mass, momentum, centre = lane[_L_TOTAL_MASS], lane[_L_MOMENTUM], lane[_L_CENTRE]
    kinetic[:lanes] = 0.0
    frame_potential[:lanes] = 0.0
    drift[:lanes] = 0.0
    internal[:lanes] = 0.0
    strain[:lanes] = 0.0
    for i in range(n):
        mass_row = node_lanes[i, _L_MASS]
        for d in range(3):
            velocity, position, tidal = end_velocity[i, d], node_lanes[i, _L_POSITION + d], lane[_L_TIDAL + d]
            for k in range(lanes):
                kinetic[k] += mass_row[k] * velocity[k] * velocity[k]
                frame_potential[k] -= mass_row[k] * tidal[k] * position[k] * position[k]
    for k in range(lanes):
        kinetic[k] *= 0.5
        frame_potential[k] *= 0.5
    # _drift_and_internal's
    for d in range(3):
        total_mass[:lanes] = 0.0
        momentum[:lanes] = 0.0
        for i in range(n):
            mass_row, velocity = node_lanes[i, _L_MASS], end_velocity[i, d]
            for k in range(lanes):
                total_mass[k] += mass_row[k]
                momentum[k] += mass_row[k] * velocity[k]
        for k in range(lanes):
            centre[k] = momentum[k] / total_mass[k]
            drift[k] += 0.5 * total_mass[k] * centre[k] * centre[k]
        for i in range(n):
            mass_row, velocity = node_lanes[i, _L_MASS], end_velocity[i, d]
            for k in range(lanes):
                relative = velocity[k] - centre[k]
                internal[k] += 0.5 * mass_row[k] * relative * relative
    for c in range(m):
        intact, tension, stiffness = (
            cable_lanes[c, _L_INTACT],
            cable_lanes[c, _L_TENSION],
            cable_lanes[c, _L_STIFFNESS],
        )
        for k in range(lanes):
            stored = 0.5 * tension[k] * tension[k] / stiffness[k]
            strain[k] = strain[k] + stored if intact[k] != 0.0 else strain[k]
    initial, scale, runaway = lane[_L_INITIAL], lane[_L_SCALE], lane[_L_RUNAWAY]
    work, dissipated = lane[_L_WORK], lane[_L_DISSIPATED]
    for k in range(lanes):
        scale[k], runs_away = _energy_verdict(
            kinetic[k],
            strain[k],
            frame_potential[k],
            internal[k],
            drift[k],
            initial[k],
            work[k],
            dissipated[k],
            scale[k],
            tolerance,
        )
        runaway[k] = 1.0 if runs_away else 0.0


@njit(cache=True, nogil=True, error_model="numpy")
def _advance_clusters(
    duration: float,
    active: np.ndarray,
    settings: np.ndarray,
    topology: np.ndarray,
    nodes: np.ndarray,
    cables: np.ndarray,
    clusters: np.ndarray,
    counters: np.ndarray,
    step_record: np.ndarray,
) -> None:
    """Advance every cluster of the given tables (a batch, or a chunk of one) by ``duration`` s:
    those ``active`` and healthy (or whose last interval was refused for its sub-step budget) by
    :func:`_advance_pair`, two at a time, the others held.  ``step_record``
    (B, R) receives the first R sub-steps of each cluster.

    It is the one-thread driver, and :func:`advance_parallel` calls it on chunks: compiled once
    for both (inlined into the parallel driver, it made that take seconds longer to compile), and
    one call per chunk (a call per cluster cost more than a short interval's work)."""
    # One call site of the pair, whose two inlined sub-steps are most of the integrator's code.
    batch = nodes.shape[0]
    # np.int64 rather than the literal -1: numba types a literal as a type of its own until the
    # loop's values widen it, and would compile the called pair once more for that first guess.
    waiting = np.int64(-1)  # a healthy cluster waiting for a partner
    for b in range(batch + 1):
        if b < batch and active[b] and counters[b, STATUS] == STATUS_TOO_MANY_SUBSTEPS:
            counters[b, STATUS] = STATUS_OK  # its refused interval left it as it was: it may try again
        if b < batch and not (active[b] and counters[b, STATUS] == STATUS_OK):
            _hold_cluster(cables[b], clusters[b], counters[b])
        elif b < batch and waiting < 0:
            waiting = b
        elif waiting >= 0:  # a partner, or the end of the batch: the waiting cluster goes alone
            partner = b if b < batch else -1
            _advance_pair(
                duration,
                settings,
                topology,
                nodes,
                cables,
                clusters,
                counters,
                step_record,
                waiting,
                partner,
            )
            waiting = -1


@njit(cache=True, nogil=True, error_model="numpy")
def _advance_clusters_in_lanes(
    duration: float,
    active: np.ndarray,
    settings: np.ndarray,
    topology: np.ndarray,
    nodes: np.ndarray,
    cables: np.ndarray,
    clusters: np.ndarray,
    counters: np.ndarray,
    step_record: np.ndarray,
) -> None:
    """:func:`_advance_clusters`, with the clusters that are :func:`_lane_ready` (and the exact
    elongation) in SIMD lanes (:func:`_advance_lanes`) when they number at least
    :data:`LANE_MIN_CLUSTERS`, and the rest by :func:`_advance_clusters`: the same bits either
    way, so a cluster's trajectory does not depend on the batch it shares.  The parallel drivers
    run it on chunks.  Apart from :func:`_advance_clusters`, so that the single env, which never
    has a block to fill, does not compile the lanes."""
    batch = nodes.shape[0]
    exact = settings[LINEARISED] == 0.0
    in_lanes = np.empty(batch, dtype=np.int64)
    in_pairs = active.copy()
    lane_count = 0
    for b in range(batch):
        if active[b] and counters[b, STATUS] == STATUS_TOO_MANY_SUBSTEPS:
            counters[b, STATUS] = STATUS_OK  # its refused interval left it as it was: it may try again
        if active[b] and counters[b, STATUS] == STATUS_OK and exact and _lane_ready(cables[b], clusters[b]):
            in_lanes[lane_count] = b
            lane_count += 1
    if lane_count >= LANE_MIN_CLUSTERS:
        in_pairs[in_lanes[:lane_count]] = False
    # First the pairs, which hold every cluster they do not advance: the lanes then write all
    # that holding wrote (sub-step counts, step sizes, peak tensions) for theirs.  With every
    # cluster in the lanes there is nothing for the pairs to do (a pass that cost about 10 ns
    # per cluster and interval, a sixtieth of the lanes' interval).
    every_cluster_in_lanes = lane_count >= LANE_MIN_CLUSTERS and lane_count == batch
    if not every_cluster_in_lanes:
        _advance_clusters(duration, in_pairs, settings, topology, nodes, cables, clusters, counters, step_record)
    if lane_count >= LANE_MIN_CLUSTERS:
        _advance_lanes(
            duration, settings, topology, nodes, cables, clusters, counters, step_record, in_lanes[:lane_count]
        )


#: The integrator on one thread, for small batches (its start-up cost is lower).
advance_serial = _advance_clusters


def _compile_parallel_advance(in_lanes: bool) -> Callable[..., Any]:  # a numba dispatcher
    """Compile the integrator on all threads: :func:`advance_serial`'s driver on a chunk of
    clusters per thread, or with ``in_lanes`` :func:`_advance_clusters_in_lanes` on the chunks of
    :func:`parallel_chunks` (for batches of :data:`LANE_MIN_BATCH` or more: a kernel apart, so
    that smaller batches do not compile the lanes, 15-20 s once on a 2-core machine).  The same
    bits either way, whatever the chunks.  ``in_lanes`` is a constant of the closure: numba
    compiles only the driver it picks (a dispatcher held in the closure instead kept numba from
    finding the kernel in its cache again)."""

    def advance_parallel(
        duration: float,
        active: np.ndarray,
        settings: np.ndarray,
        topology: np.ndarray,
        nodes: np.ndarray,
        cables: np.ndarray,
        clusters: np.ndarray,
        counters: np.ndarray,
        step_record: np.ndarray,
    ) -> None:  # pragma: no cover - compiled
        """The integrator on all threads, a chunk of clusters each (the same bits as
        :func:`advance_serial`); the arguments as for it."""
        batch = nodes.shape[0]
        chunks = parallel_chunks(batch) if in_lanes else min(batch, PARALLEL_CHUNKS)
        for k in prange(chunks):
            lo, hi = k * batch // chunks, (k + 1) * batch // chunks
            tables = (nodes[lo:hi], cables[lo:hi], clusters[lo:hi], counters[lo:hi])
            if in_lanes:
                _advance_clusters_in_lanes(duration, active[lo:hi], settings, topology, *tables, step_record[lo:hi])
            else:
                _advance_clusters(duration, active[lo:hi], settings, topology, *tables, step_record[lo:hi])

    # Named for numba's cache files and the compilation log (tether_gym._compilation).
    advance_parallel.__qualname__ = advance_parallel.__name__ = (
        "advance_parallel_in_lanes" if in_lanes else "advance_parallel"
    )
    return njit(cache=True, nogil=True, error_model="numpy", parallel=True)(advance_parallel)


#: :func:`advance_serial` on all threads, a chunk of clusters each (the same bits).
advance_parallel = _compile_parallel_advance(in_lanes=False)
#: The same in SIMD lanes, for batches of :data:`LANE_MIN_BATCH` clusters or more.
advance_parallel_in_lanes = _compile_parallel_advance(in_lanes=True)


@njit(cache=True, nogil=True, error_model="numpy")
def evaluate_forces(
    settings: np.ndarray,
    taut_branch: bool,
    topology: np.ndarray,
    nodes: np.ndarray,
    cables: np.ndarray,
    clusters: np.ndarray,
    finite: np.ndarray,
) -> None:
    """:func:`cable_forces` for every cluster of a batch of tables, without breaking any cable:
    fills ``INTERNAL_FORCE``, ``TENSION`` and ``OMEGA2`` (the step-limiting value, tidal term
    included), and ``finite`` (B,) bool.  The axial damping acts on the ``HALF_STEP_VELOCITY``
    columns.  (The callers pass scratch copies of the tables: it also raises ``PEAK_TENSION``.)"""
    linearised = settings[LINEARISED] != 0.0
    for b in range(nodes.shape[0]):
        omega2_cables, finite[b], _, _ = cable_forces(nodes[b], cables[b], topology, linearised, taut_branch, False)
        clusters[b, OMEGA2] = omega2_cables + _largest_tidal(clusters[b])
