"""Compiled measurements of the damping task: commanded forces, rigid motion, vibration energy,
observation, reward and end reason.

Like the physics kernels they work one cluster at a time, so a cluster measured in a batch gives
the same bits as measured alone.  They read the simulator's tables (columns named in
:mod:`tether_gym._kernels`) and the task's own, named here:

* the task's node table ``(B, n, TASK_NODE_COLUMNS)``, one row per satellite;
* the task's cluster table ``(B, TASK_CLUSTER_COLUMNS + observation size)``, one row per
  cluster: what the kernels read of the cluster's episode, the scalar results of the last
  evaluation (reward terms, energies, ...) and its observation vector;
* the task settings ``(TASK_SETTINGS,)`` float64, shared by the batch.

The scalar results follow :class:`~tether_gym.envs.contract.Scalar`, the end reasons
:class:`~tether_gym.envs.contract.EndReason` and the observation the offsets of the task's
:class:`~tether_gym.envs.contract.ObservationLayout`, all defined in
:mod:`tether_gym.envs.contract`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
from numba import njit, prange

from tether_gym import _kernels
from tether_gym._kernels import (
    APPLIED_FORCE,
    BREAKING_LOAD,
    FRAME_TIDAL,
    INTACT,
    MASS,
    PARALLEL_CHUNKS,
    PEAK_TENSION,
    POSITION,
    PRETENSION,
    REST_LENGTH,
    STATUS,
    STIFFNESS,
    TENSION,
    VELOCITY,
)
from tether_gym.envs.contract import EndReason, Scalar

# ---------------------------------------------------------------------------------------------
# The task's node table, (B, n, TASK_NODE_COLUMNS).
BIAS = 0  # N, 3 columns: the constant thrust holding the nominal shape
NOMINAL = 3  # m, 3 columns: the nominal position
THRUST = 6  # N, 3 columns: the agent's thrust of the interval, as commanded
TASK_NODE_COLUMNS = 9

# The task's cluster table, (B, TASK_CLUSTER_COLUMNS + observation size).
NOMINAL_STRAIN_ENERGY = 0  # J, the cables' strain energy at the nominal shape
IMPULSE = 1  # N*s, the thrust impulse of the last interval, sum_j |F_j| dt
SCALAR_COLUMNS = 2  # the first of the scalar results, in the order of contract.Scalar
NUM_SCALARS = len(Scalar)
OBSERVATION_COLUMNS = SCALAR_COLUMNS + NUM_SCALARS  # the observation vector fills the rest of the row
TASK_CLUSTER_COLUMNS = OBSERVATION_COLUMNS

# The scalar columns and end reasons of the contract (tether_gym.envs.contract), as the plain ints
# the compiled code reads: an IntEnum member in numba code makes every load of the cache take
# seconds.
REWARD = int(Scalar.REWARD)
REWARD_VIBRATION = int(Scalar.REWARD_VIBRATION)
REWARD_PROPELLANT = int(Scalar.REWARD_PROPELLANT)
REWARD_SLACK = int(Scalar.REWARD_SLACK)
REWARD_FAILURE = int(Scalar.REWARD_FAILURE)
VIBRATION_ENERGY = int(Scalar.VIBRATION_ENERGY)
MAX_DEVIATION = int(Scalar.MAX_DEVIATION)
SLACK_FRACTION = int(Scalar.SLACK_FRACTION)
KINETIC_ENERGY = int(Scalar.KINETIC_ENERGY)
STRAIN_ENERGY = int(Scalar.STRAIN_ENERGY)
FRAME_POTENTIAL = int(Scalar.FRAME_POTENTIAL)
RUNNING = int(EndReason.RUNNING)
FORMATION_LOST = int(EndReason.FORMATION_LOST)
CABLE_BROKEN = int(EndReason.CABLE_BROKEN)
NUMERICS_DIVERGED = int(EndReason.NUMERICS_DIVERGED)

# The task settings, (TASK_SETTINGS,).
CONTROL_INTERVAL = 0  # s
MAGNITUDE_LIMIT = 1  # 1.0: a command longer than 1 is scaled back (thrust_limit="magnitude")
LENGTH_SCALE = 2  # m, the unit of displacements and elongations in the observation
SPEED_SCALE = 3  # m/s, the unit of velocities in the observation
DEVIATION_LIMIT = 4  # m, a satellite farther from its nominal place loses the formation
TERMINATE_ON_BREAK = 5  # 1.0: a cable past its breaking load ends the episode
VIBRATION_WEIGHT = 6  # 1/J: the vibration weight over the energy scale
PROPELLANT_WEIGHT = 7  # 1/(N*s): the propellant weight over the full impulse
SLACK_WEIGHT = 8  # per fraction of slack cables
FAILURE_PENALTY = 9  # the one-off cost of a failure
# Where the parts of the observation vector start (from the task's contract.ObservationLayout).
DISPLACEMENT_AT = 10
VELOCITY_AT = 11
ELONGATION_AT = 12
TENSION_RATIO_AT = 13  # -1 when the tension ratios are not observed
# The leading nodes that are satellites (the rest are tether beads): only a satellite beyond the
# deviation limit loses the formation, since a bead's whip is the vibration being damped.
SATELLITES = 14
# The leading cables observed one by one (the rest are tether segments, observed per tether).
OBSERVED_CABLES = 15
ON_OFF = 16  # 1.0: each command component fires its axis at full thrust or not at all (thrust_mode="on_off")
TASK_SETTINGS = 17
#: With on/off thrust, a command component at or beyond this (in magnitude) fires its axis.
ON_OFF_THRESHOLD = 0.5

#: Observations are clipped to +-this (it is reached only far beyond a lost formation).
OBSERVATION_LIMIT = 1e4

#: A step whose |reward| would exceed this (or be NaN) ends as ``numerics_diverged`` with a finite
#: reward.  No accepted setting gets near it unless the state has run away, and it keeps every
#: reward finite also in float32 (max 3.4e38), as Stable-Baselines3 stores them.
REWARD_LIMIT = 1e30


@njit(inline="always", error_model="numpy")
def _rigid_motion(x: np.ndarray, v: np.ndarray, masses: np.ndarray, out: np.ndarray) -> None:
    """Centre of mass, its velocity and the rigid angular velocity of one cluster, into ``out``
    (3, 3) rows: com (m), v_com (m/s), omega (rad/s), with ``I omega = angular momentum``; ``x, v``
    (n, 3) in m and m/s, ``masses`` (n,) kg."""
    n = x.shape[0]
    total = 0.0
    for d in range(3):
        out[0, d] = 0.0
        out[1, d] = 0.0
    for i in range(n):
        total += masses[i]
        for d in range(3):
            out[0, d] += masses[i] * x[i, d]
            out[1, d] += masses[i] * v[i, d]
    for d in range(3):
        out[0, d] /= total
        out[1, d] /= total
    i00 = i11 = i22 = i01 = i02 = i12 = 0.0
    l0 = l1 = l2 = 0.0
    r2_total = 0.0
    for i in range(n):
        rx, ry, rz = x[i, 0] - out[0, 0], x[i, 1] - out[0, 1], x[i, 2] - out[0, 2]
        ux, uy, uz = v[i, 0] - out[1, 0], v[i, 1] - out[1, 1], v[i, 2] - out[1, 2]
        m = masses[i]
        l0 += m * (ry * uz - rz * uy)
        l1 += m * (rz * ux - rx * uz)
        l2 += m * (rx * uy - ry * ux)
        r2 = rx * rx + ry * ry + rz * rz
        r2_total += m * r2
        i00 += m * (r2 - rx * rx)
        i11 += m * (r2 - ry * ry)
        i22 += m * (r2 - rz * rz)
        i01 -= m * rx * ry
        i02 -= m * rx * rz
        i12 -= m * ry * rz
    # A collinear cluster has no inertia about its axis; the small regularisation keeps the solve
    # defined and leaves the other axes untouched.
    a = i00 + 1e-9 * r2_total
    e = i11 + 1e-9 * r2_total
    i_ = i22 + 1e-9 * r2_total
    b, c, f = i01, i02, i12
    c00 = e * i_ - f * f
    c01 = c * f - b * i_
    c02 = b * f - c * e
    c11 = a * i_ - c * c
    c12 = b * c - a * f
    c22 = a * e - b * b
    det = a * c00 + b * c01 + c * c02
    if det > 0.0:
        out[2, 0] = (c00 * l0 + c01 * l1 + c02 * l2) / det
        out[2, 1] = (c01 * l0 + c11 * l1 + c12 * l2) / det
        out[2, 2] = (c02 * l0 + c12 * l1 + c22 * l2) / det
    else:
        out[2, :] = 0.0


@njit(cache=True, nogil=True, error_model="numpy")
def remove_rigid_velocity(x: np.ndarray, v: np.ndarray, masses: np.ndarray) -> None:
    """Subtract from ``v`` (B, n, 3) m/s, in place, each cluster's rigid translation and rotation
    at the positions ``x`` (B, n, 3) m, with the ``masses`` (B, n) kg."""
    motion = np.empty((3, 3))
    for b in range(x.shape[0]):
        _rigid_motion(x[b], v[b], masses[b], motion)
        for i in range(x.shape[1]):
            rx = x[b, i, 0] - motion[0, 0]
            ry = x[b, i, 1] - motion[0, 1]
            rz = x[b, i, 2] - motion[0, 2]
            v[b, i, 0] -= motion[1, 0] + motion[2, 1] * rz - motion[2, 2] * ry
            v[b, i, 1] -= motion[1, 1] + motion[2, 2] * rx - motion[2, 0] * rz
            v[b, i, 2] -= motion[1, 2] + motion[2, 0] * ry - motion[2, 1] * rx


@njit(inline="always", error_model="numpy")
def _bounded(value: float) -> float:
    """An observation entry: NaN as 0, clipped to +-OBSERVATION_LIMIT."""
    if value != value:
        return 0.0
    return min(max(value, -OBSERVATION_LIMIT), OBSERVATION_LIMIT)


@njit(inline="always", error_model="numpy")
def _pulse(command: float) -> float:
    """An on/off thruster axis: full thrust along the command's sign (+-1) where the command
    reaches :data:`ON_OFF_THRESHOLD` in magnitude, else off (0)."""
    if command >= ON_OFF_THRESHOLD:
        return 1.0
    if command <= -ON_OFF_THRESHOLD:
        return -1.0
    return 0.0


@njit(inline="always", error_model="numpy")
def _command_cluster(
    settings: np.ndarray,
    actions: np.ndarray,
    thrusters: np.ndarray,
    max_thrust: np.ndarray,
    task_nodes: np.ndarray,
    nodes: np.ndarray,
    row: np.ndarray,
) -> None:
    """One cluster's thrust (``THRUST``), applied force ``BIAS + THRUST`` (the simulator's
    ``APPLIED_FORCE``) and thrust impulse (``IMPULSE``) from its normalised actions (3k,)."""
    magnitude_limit = settings[MAGNITUDE_LIMIT] != 0.0
    on_off = settings[ON_OFF] != 0.0
    for i in range(task_nodes.shape[0]):
        for d in range(3):
            task_nodes[i, THRUST + d] = 0.0
    total = 0.0
    for k in range(thrusters.shape[0]):
        a0 = min(max(actions[3 * k], -1.0), 1.0)
        a1 = min(max(actions[3 * k + 1], -1.0), 1.0)
        a2 = min(max(actions[3 * k + 2], -1.0), 1.0)
        if on_off:
            a0, a1, a2 = _pulse(a0), _pulse(a1), _pulse(a2)
        norm = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
        scale = max_thrust[k]
        if magnitude_limit and norm > 1.0:
            scale /= norm
        i = thrusters[k]
        task_nodes[i, THRUST] = a0 * scale
        task_nodes[i, THRUST + 1] = a1 * scale
        task_nodes[i, THRUST + 2] = a2 * scale
        total += norm * scale
    row[IMPULSE] = total * settings[CONTROL_INTERVAL]
    for i in range(nodes.shape[0]):
        for d in range(3):
            nodes[i, APPLIED_FORCE + d] = task_nodes[i, BIAS + d] + task_nodes[i, THRUST + d]


@njit(inline="always", error_model="numpy")
def _nominal_centre(task_nodes: np.ndarray, nodes: np.ndarray, out: np.ndarray) -> None:
    """The centre of mass of the nominal shape, m, into ``out`` (3,)."""
    total = 0.0
    out[:] = 0.0
    for i in range(nodes.shape[0]):
        total += nodes[i, MASS]
        for d in range(3):
            out[d] += nodes[i, MASS] * task_nodes[i, NOMINAL + d]
    out /= total


@njit(inline="always", error_model="numpy")
def _deviation(
    task_nodes: np.ndarray, nodes: np.ndarray, motion: np.ndarray, centre: np.ndarray, i: int, d: int
) -> float:
    """Satellite ``i``'s displacement from its nominal place along ``d`` in the cluster frame
    (both about their centres of mass), m."""
    return (nodes[i, POSITION + d] - motion[0, d]) - (task_nodes[i, NOMINAL + d] - centre[d])


@njit(inline="always", error_model="numpy")
def _node_energies(
    task_nodes: np.ndarray,
    nodes: np.ndarray,
    cluster: np.ndarray,
    motion: np.ndarray,
    centre: np.ndarray,
    satellites: int,
) -> tuple[float, float, float, float, float, float]:
    """``(kinetic_deformation, kinetic, bias_potential, frame_potential, shape_potential,
    worst_deviation)`` of one cluster, J (the last in m, over the first ``satellites`` nodes;
    the energies sum every node, beads included): see :func:`evaluate_serial`."""
    kinetic_deformation = 0.0
    kinetic = 0.0
    bias_potential = 0.0
    frame_potential = 0.0
    shape_potential = 0.0
    worst = 0.0
    t0, t1, t2 = cluster[FRAME_TIDAL], cluster[FRAME_TIDAL + 1], cluster[FRAME_TIDAL + 2]
    for i in range(nodes.shape[0]):
        m = nodes[i, MASS]
        x0, x1, x2 = nodes[i, POSITION], nodes[i, POSITION + 1], nodes[i, POSITION + 2]
        v0, v1, v2 = nodes[i, VELOCITY], nodes[i, VELOCITY + 1], nodes[i, VELOCITY + 2]
        rx = x0 - motion[0, 0]
        ry = x1 - motion[0, 1]
        rz = x2 - motion[0, 2]
        if t0 != 0.0 or t1 != 0.0 or t2 != 0.0:
            nx = task_nodes[i, NOMINAL] - centre[0]
            ny = task_nodes[i, NOMINAL + 1] - centre[1]
            nz = task_nodes[i, NOMINAL + 2] - centre[2]
            shape_potential -= (
                0.5 * m * (t0 * (rx * rx - nx * nx) + t1 * (ry * ry - ny * ny) + t2 * (rz * rz - nz * nz))
            )
            frame_potential -= 0.5 * m * (t0 * x0 * x0 + t1 * x1 * x1 + t2 * x2 * x2)
        ux = v0 - motion[1, 0] - (motion[2, 1] * rz - motion[2, 2] * ry)
        uy = v1 - motion[1, 1] - (motion[2, 2] * rx - motion[2, 0] * rz)
        uz = v2 - motion[1, 2] - (motion[2, 0] * ry - motion[2, 1] * rx)
        kinetic_deformation += 0.5 * m * (ux * ux + uy * uy + uz * uz)
        kinetic += 0.5 * m * (v0 * v0 + v1 * v1 + v2 * v2)
        deviation2 = 0.0
        for d in range(3):
            bias_potential -= task_nodes[i, BIAS + d] * (nodes[i, POSITION + d] - task_nodes[i, NOMINAL + d])
            deviation = _deviation(task_nodes, nodes, motion, centre, i, d)
            deviation2 += deviation * deviation
        deviation_norm = math.sqrt(deviation2)
        if i < satellites and (deviation_norm > worst or not math.isfinite(deviation_norm)):
            worst = deviation_norm
    return kinetic_deformation, kinetic, bias_potential, frame_potential, shape_potential, worst


@njit(inline="always", error_model="numpy")
def _observe_satellites(
    settings: np.ndarray,
    observed: np.ndarray,
    task_nodes: np.ndarray,
    nodes: np.ndarray,
    motion: np.ndarray,
    centre: np.ndarray,
    observation: np.ndarray,
) -> None:
    """The observed satellites' displacements and velocities (about the centre of mass), in units
    of the length and speed scales, into ``observation``."""
    displacement_at = np.int64(settings[DISPLACEMENT_AT])
    velocity_at = np.int64(settings[VELOCITY_AT])
    for k in range(observed.shape[0]):
        i = observed[k]
        for d in range(3):
            deviation = _deviation(task_nodes, nodes, motion, centre, i, d)
            observation[displacement_at + 3 * k + d] = _bounded(deviation / settings[LENGTH_SCALE])
            observation[velocity_at + 3 * k + d] = _bounded(
                (nodes[i, VELOCITY + d] - motion[1, d]) / settings[SPEED_SCALE]
            )


@njit(inline="always", error_model="numpy")
def _cable_terms(
    settings: np.ndarray, topology: np.ndarray, nodes: np.ndarray, cables: np.ndarray, observation: np.ndarray
) -> tuple[float, int, bool]:
    """``(strain, slack, broken)``: the cables' elastic strain energy ``N_el^2 / 2k`` (intact
    cables), J, the number of slack cables, and whether a cable passed its breaking load during
    the interval (counted only when that ends the episode); observes each cable's elongation (and
    tension ratio)."""
    strain = 0.0
    slack = 0
    broken = False
    terminate_on_break = settings[TERMINATE_ON_BREAK] != 0.0
    elongation_at = np.int64(settings[ELONGATION_AT])
    tension_ratio_at = np.int64(settings[TENSION_RATIO_AT])
    observed_cables = np.int64(settings[OBSERVED_CABLES])
    for c in range(topology.shape[0]):
        cable = cables[c]
        i, j = topology[c, 0], topology[c, 1]
        dx = nodes[j, POSITION] - nodes[i, POSITION]
        dy = nodes[j, POSITION + 1] - nodes[i, POSITION + 1]
        dz = nodes[j, POSITION + 2] - nodes[i, POSITION + 2]
        elongation = math.sqrt(dx * dx + dy * dy + dz * dz) - cable[REST_LENGTH]
        if c < observed_cables:
            observation[elongation_at + c] = _bounded(elongation / settings[LENGTH_SCALE])
        elastic = cable[PRETENSION] + cable[STIFFNESS] * elongation
        if cable[INTACT] != 0.0 and elastic > 0.0:
            strain += 0.5 * elastic * elastic / cable[STIFFNESS]
        if cable[TENSION] <= 0.0:
            slack += 1
        if terminate_on_break and cable[PEAK_TENSION] > cable[BREAKING_LOAD]:
            broken = True
        if tension_ratio_at >= 0 and c < observed_cables:
            observation[tension_ratio_at + c] = _bounded(cable[TENSION] / cable[BREAKING_LOAD])
    return strain, slack, broken


@njit(inline="always", error_model="numpy")
def _reward(
    settings: np.ndarray,
    status: int,
    broken: bool,
    worst: float,
    energies: tuple[float, float, float, float],
    slack_fraction: float,
    impulse: float,
    scalars: np.ndarray,
) -> int:
    """The end reason and the scalar results (reward and its terms, the energies) of one cluster,
    from its ``energies = (vibration, kinetic, strain, frame_potential)``, J; see
    :func:`evaluate_serial`."""
    vibration, kinetic, strain, frame_potential = energies
    if status != _kernels.STATUS_OK:
        reason = NUMERICS_DIVERGED
        vibration = 0.0
    elif broken:
        reason = CABLE_BROKEN
    elif not worst <= settings[DEVIATION_LIMIT]:
        reason = FORMATION_LOST
    else:
        reason = RUNNING
    terms_vibration = -settings[VIBRATION_WEIGHT] * vibration
    terms_propellant = -settings[PROPELLANT_WEIGHT] * impulse
    terms_slack = -settings[SLACK_WEIGHT] * slack_fraction
    running_reward = terms_vibration + terms_propellant + terms_slack
    if not (
        abs(running_reward) <= REWARD_LIMIT
        and math.isfinite(kinetic)
        and math.isfinite(strain)
        and math.isfinite(frame_potential)
    ):
        # A state beyond the reward's arithmetic (an energy or a weighted term that overflows or
        # passes REWARD_LIMIT; NaN fails the comparison too) is a divergence: the episode ends
        # there with a finite reward, the vibration term dropped as for a frozen cluster, never a
        # NaN or -inf while it runs on.
        reason = NUMERICS_DIVERGED
        vibration = 0.0
        terms_vibration = 0.0
        if not math.isfinite(terms_propellant):
            terms_propellant = 0.0
        if not math.isfinite(terms_slack):
            terms_slack = 0.0
    terms_failure = -settings[FAILURE_PENALTY] if reason != RUNNING else 0.0
    scalars[REWARD] = terms_vibration + terms_propellant + terms_slack + terms_failure
    scalars[REWARD_VIBRATION] = terms_vibration
    scalars[REWARD_PROPELLANT] = terms_propellant
    scalars[REWARD_SLACK] = terms_slack
    scalars[REWARD_FAILURE] = terms_failure
    scalars[VIBRATION_ENERGY] = vibration
    scalars[MAX_DEVIATION] = worst
    scalars[SLACK_FRACTION] = slack_fraction
    scalars[KINETIC_ENERGY] = kinetic
    scalars[STRAIN_ENERGY] = strain
    scalars[FRAME_POTENTIAL] = frame_potential
    return reason


# Inlined into the driver: called, it compiled 0.3 s faster (1.8 s against 2.1 s of CPU time),
# but the N = 1 024 vector env ran about 3 % slower (1.17-1.25 M against 1.21-1.32 M env steps/s
# in alternating quiet rounds).
@njit(inline="always", error_model="numpy")
def _evaluate_cluster(
    settings: np.ndarray,
    topology: np.ndarray,
    observed: np.ndarray,
    nodes: np.ndarray,
    cables: np.ndarray,
    cluster: np.ndarray,
    status: int,
    task_nodes: np.ndarray,
    row: np.ndarray,
    scratch: np.ndarray,
) -> int:
    """Observation, scalar results and end reason (returned) of one cluster; ``scratch`` (4, 3)."""
    motion = scratch[:3]
    centre = scratch[3]
    _rigid_motion(nodes[:, POSITION : POSITION + 3], nodes[:, VELOCITY : VELOCITY + 3], nodes[:, MASS], motion)
    _nominal_centre(task_nodes, nodes, centre)
    kinetic_deformation, kinetic, bias_potential, frame_potential, shape_potential, worst = _node_energies(
        task_nodes, nodes, cluster, motion, centre, np.int64(settings[SATELLITES])
    )
    observation = row[OBSERVATION_COLUMNS:]
    _observe_satellites(settings, observed, task_nodes, nodes, motion, centre, observation)
    strain, slack, broken = _cable_terms(settings, topology, nodes, cables, observation)
    vibration = kinetic_deformation + strain - row[NOMINAL_STRAIN_ENERGY] + bias_potential + shape_potential
    return _reward(
        settings,
        status,
        broken,
        worst,
        (vibration, kinetic, strain, frame_potential),
        slack / topology.shape[0],
        row[IMPULSE],
        row[SCALAR_COLUMNS:OBSERVATION_COLUMNS],
    )


#: The numbers of other files the kernels below are compiled with (see :func:`_compile_command_forces`),
#: and the physics kernels' source: the fused step compiles the integrator into its own cached
#: code, and numba's cache keys only on this file's contents, so an edit of ``_kernels.py`` alone
#: would otherwise leave the old integrator in the cached step.
FOREIGN_LAYOUT = (
    _kernels.SOURCE_SHA256,
    _kernels.LAYOUT,
    PARALLEL_CHUNKS,
    _kernels.PARALLEL_MIN_CHUNKS,
    _kernels.STATUS_OK,
    tuple((column.name, int(column)) for column in Scalar),
    tuple((reason.name, int(reason)) for reason in EndReason),
)


def _compile_cluster_evaluation(foreign_layout: tuple) -> Callable[..., Any]:  # a numba dispatcher
    """Compile the evaluation of every cluster of some tables: the one-thread driver, which the
    parallel one calls on chunks (inlined into it, it made that take seconds longer to compile;
    a call per cluster cost as much as the evaluation itself).
    ``foreign_layout`` is part of its cache key (see :func:`_compile_command_forces`)."""

    @njit(cache=True, nogil=True, error_model="numpy")
    def evaluate_clusters(
        settings: np.ndarray,
        topology: np.ndarray,
        observed: np.ndarray,
        nodes: np.ndarray,
        cables: np.ndarray,
        clusters: np.ndarray,
        counters: np.ndarray,
        task_nodes: np.ndarray,
        task_clusters: np.ndarray,
        end_reason: np.ndarray,
    ) -> None:
        """Everything the task reads off each cluster of the given tables (a batch, or a chunk of one)
        after a step (or a reset); the one-thread driver, which the parallel one calls on chunks.

        Writes the observation (NaN as 0, clipped to +-OBSERVATION_LIMIT; see
        :class:`~tether_gym.envs.TetherClusterEnv`), ``end_reason`` and the scalar results:
        the reward and its terms, with the weights of the settings, the vibration energy (J), the
        largest deviation (m), the slack fraction, and the kinetic, strain and frame energies (J).
        A cable past its breaking load ends the episode only with ``TERMINATE_ON_BREAK``.  A
        cluster whose reward would pass ``REWARD_LIMIT`` (or be NaN), or whose energies would not
        be finite, ends as numerics diverged, with the vibration term (and any non-finite term)
        set to 0: the reward is always finite.

        The strain energy is the elastic part ``N_el^2 / 2k`` of the intact cables (the tension
        may hold a viscous part).  In a turning frame (``FRAME_TIDAL``, 1/s^2) the vibration energy
        also holds the change of the frame potential of the shape about its centre of mass,
        ``-1/2 sum_i m_i (r_i.T r_i - R_i.T R_i)`` (``r``, ``R``: current and nominal positions
        about the centre of mass), so that it measures the deformation against the frame's
        effective potential and is zero at the nominal equilibrium.
        """
        foreign_layout  # noqa: B018 - part of the cache key
        scratch = np.empty((4, 3))
        for b in range(nodes.shape[0]):
            end_reason[b] = _evaluate_cluster(
                settings,
                topology,
                observed,
                nodes[b],
                cables[b],
                clusters[b],
                counters[b, STATUS],
                task_nodes[b],
                task_clusters[b],
                scratch,
            )

    return evaluate_clusters


_evaluate_clusters = _compile_cluster_evaluation(FOREIGN_LAYOUT)


def _compile_command_forces(foreign_layout: tuple) -> Callable[..., Any]:  # a numba dispatcher
    """Compile :func:`command_forces`.  It writes the simulator's table, whose columns are named in
    another file: numba's cache watches only this one, so the kernel holds those numbers
    (``foreign_layout``) in its closure, which numba hashes into the cache key; an edit there then
    recompiles it instead of loading stale code.  (Nothing else may be in such a closure: numba
    pickles it into the key, and a compiled function pickles differently in every process.)"""

    @njit(cache=True, nogil=True, error_model="numpy")
    def command_forces(
        settings: np.ndarray,
        actions: np.ndarray,
        thrusters: np.ndarray,
        max_thrust: np.ndarray,
        active: np.ndarray,
        task_nodes: np.ndarray,
        nodes: np.ndarray,
        task_clusters: np.ndarray,
        propellant: np.ndarray,
    ) -> None:
        """Thruster forces from normalised actions (B, 3k): each command clipped to [-1, 1] (and,
        with the magnitude limit, scaled back to unit length when longer), times ``max_thrust``
        (k,) N on the satellites ``thrusters`` (k,).  Writes the thrust, the simulator's applied
        force ``bias + thrust`` and the interval's thrust impulse ``sum_j |F_j| dt``, N*s, and
        adds the impulse to the episode's ``propellant`` (B,) N*s, of the active clusters only
        (here rather than in Python: a masked numpy update cost the single env 1 us a step)."""
        foreign_layout  # noqa: B018 - part of the cache key
        for b in range(actions.shape[0]):
            if active[b]:
                _command_cluster(settings, actions[b], thrusters, max_thrust, task_nodes[b], nodes[b], task_clusters[b])
                propellant[b] += task_clusters[b, IMPULSE]

    return command_forces


def _compile_step(foreign_layout: tuple, in_lanes: bool) -> Callable[..., Any]:  # a numba dispatcher
    """Compile one whole task step of every cluster of some tables: the thrust commands, the
    advance and the evaluation, on one thread (the parallel driver calls it on chunks).  The same
    bits as the three kernels called one after the other (each cluster's arithmetic is unchanged
    and clusters do not interact), in one call, while a chunk's tables are in cache: on one
    thread it ran an N = 1 024 step in 1.56 ms against 1.94 ms for the three kernels.
    ``foreign_layout`` as for :func:`_compile_command_forces`; ``in_lanes`` advances with
    :func:`~tether_gym._kernels._advance_clusters_in_lanes` (the parallel driver's chunks) rather
    than :func:`~tether_gym._kernels._advance_clusters` (the single env's step, which then does
    not compile the lanes).  A constant of the closure: numba compiles only the branch it picks."""

    def step_clusters(
        duration: float,
        actions: np.ndarray,
        active: np.ndarray,
        settings: tuple,
        indices: tuple,
        simulator_tables: tuple,
        task_tables: tuple,
        step_record: np.ndarray,
    ) -> None:
        """Step clusters by ``duration`` s under ``actions`` (B, 3k): ``settings`` is (the
        simulator's kernel settings, the task settings), ``indices`` (the cable topology (m, 2),
        the thrusters (k,), their ``max_thrust`` (k,) N, the observed satellites),
        ``simulator_tables`` (node, cable, cluster and counter tables), ``task_tables`` (task node
        table, task cluster table, propellant (B,) N*s, end reasons (B,)), ``step_record``
        (B, R) as for :func:`~tether_gym._kernels.advance_serial`."""
        foreign_layout  # noqa: B018 - part of the cache key
        simulator_settings, task_settings = settings
        topology, thrusters, max_thrust, observed = indices
        nodes, cables, clusters, counters = simulator_tables
        task_nodes, task_clusters, propellant, end_reason = task_tables
        command_forces(
            task_settings, actions, thrusters, max_thrust, active, task_nodes, nodes, task_clusters, propellant
        )
        if in_lanes:
            _kernels._advance_clusters_in_lanes(
                duration, active, simulator_settings, topology, nodes, cables, clusters, counters, step_record
            )
        else:
            _kernels._advance_clusters(
                duration, active, simulator_settings, topology, nodes, cables, clusters, counters, step_record
            )
        _evaluate_clusters(
            task_settings, topology, observed, nodes, cables, clusters, counters, task_nodes, task_clusters, end_reason
        )

    if in_lanes:  # called only within the parallel kernel, which caches it in its own code
        step_clusters.__qualname__ += "_in_lanes"
        return njit(nogil=True, error_model="numpy")(step_clusters)
    return njit(cache=True, nogil=True, error_model="numpy")(step_clusters)


def _compile_parallel_task(foreign_layout: tuple, in_lanes: bool) -> Callable[..., Any]:  # a numba dispatcher
    """Compile the task's kernel on all threads, a chunk of clusters each (the same bits): the
    whole step of :data:`step_serial` (one parallel region per step, where separate command,
    advance and evaluation kernels made two), or with ``evaluate_only`` the evaluation of
    :data:`evaluate_serial` alone.  One parallel kernel for both: numba's parallel passes cost
    each parallel kernel about a second of compilation of its own, and the flag, read once per
    chunk, costs nothing.  Each region wakes the worker threads, which tether-gym's
    ``GOMP_SPINCOUNT`` lets sleep between regions so that they do not starve other jobs.
    ``foreign_layout`` as for :func:`_compile_command_forces`; ``in_lanes`` steps chunks of
    :func:`~tether_gym._kernels.parallel_chunks` with :data:`step_in_lanes` (for batches of
    ``LANE_MIN_BATCH`` or more), otherwise :data:`PARALLEL_CHUNKS` chunks with :data:`step_serial`."""

    def parallel_task(
        evaluate_only: bool,
        duration: float,
        actions: np.ndarray,
        active: np.ndarray,
        settings: tuple,
        indices: tuple,
        simulator_tables: tuple,
        task_tables: tuple,
        step_record: np.ndarray,
    ) -> None:  # pragma: no cover - compiled
        """:data:`step_serial` (or with ``evaluate_only``, :data:`evaluate_serial`) on all
        threads, a chunk of clusters each (the same bits); the arguments as for :data:`step_serial`."""
        foreign_layout  # noqa: B018 - part of the cache key
        nodes, cables, clusters, counters = simulator_tables
        task_nodes, task_clusters, propellant, end_reason = task_tables
        batch = nodes.shape[0]
        chunks = _kernels.parallel_chunks(batch) if in_lanes else min(batch, PARALLEL_CHUNKS)
        for k in prange(chunks):
            lo, hi = k * batch // chunks, (k + 1) * batch // chunks
            if evaluate_only:
                _evaluate_clusters(
                    settings[1],
                    indices[0],
                    indices[3],
                    nodes[lo:hi],
                    cables[lo:hi],
                    clusters[lo:hi],
                    counters[lo:hi],
                    task_nodes[lo:hi],
                    task_clusters[lo:hi],
                    end_reason[lo:hi],
                )
            else:
                chunk = (nodes[lo:hi], cables[lo:hi], clusters[lo:hi], counters[lo:hi])
                task_chunk = (task_nodes[lo:hi], task_clusters[lo:hi], propellant[lo:hi], end_reason[lo:hi])
                arguments = (
                    duration,
                    actions[lo:hi],
                    active[lo:hi],
                    settings,
                    indices,
                    chunk,
                    task_chunk,
                    step_record[lo:hi],
                )
                # A branch on a constant of the closure, not a dispatcher held in it: numba could
                # not find a kernel that holds a dispatcher in its cache again.
                if in_lanes:
                    step_in_lanes(*arguments)
                else:
                    step_serial(*arguments)

    if in_lanes:
        parallel_task.__qualname__ += "_in_lanes"
    return njit(cache=True, nogil=True, error_model="numpy", parallel=True)(parallel_task)


#: The task's thrust commands, on one thread: a parallel version measured slower at N = 1024, as
#: each parallel region wakes the worker threads, which the default GOMP_SPINCOUNT lets sleep.
command_forces = _compile_command_forces(FOREIGN_LAYOUT)
#: A whole task step (commands, advance, evaluation) without disturbances, on one thread.
step_serial = _compile_step(FOREIGN_LAYOUT, in_lanes=False)
#: The same step with the clusters in SIMD lanes where a chunk has enough: the parallel driver's.
step_in_lanes = _compile_step(FOREIGN_LAYOUT, in_lanes=True)
#: The task's evaluation on one thread, for small batches (its start-up cost is lower).
evaluate_serial = _evaluate_clusters
#: The task's step and evaluation on all threads, behind :func:`step_parallel` and
#: :func:`evaluate_parallel`.
parallel_task = _compile_parallel_task(FOREIGN_LAYOUT, in_lanes=False)
#: The task's step on all threads in SIMD lanes, for batches of ``LANE_MIN_BATCH`` or more.
parallel_task_in_lanes = _compile_parallel_task(FOREIGN_LAYOUT, in_lanes=True)

# What the evaluation passes for the step's arguments it does not read: empty, writable and of
# the step's types, so that both share the one compiled variant of ``parallel_task``.
_NO_ACTIONS = np.zeros((0, 0))
_NO_CLUSTERS = np.zeros(0, dtype=np.bool_)
_NO_THRUSTERS = np.zeros(0, dtype=np.int64)
_NO_VALUES = np.zeros(0)
_NO_RECORD = np.zeros((0, 0))


def step_parallel(
    duration: float,
    actions: np.ndarray,
    active: np.ndarray,
    settings: tuple[np.ndarray, np.ndarray],
    indices: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    simulator_tables: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    task_tables: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    step_record: np.ndarray,
) -> None:
    """:data:`step_serial` on all threads, one parallel region per step (the same bits), in SIMD
    lanes for ``LANE_MIN_BATCH`` clusters or more; the arguments as for :data:`step_serial`."""
    kernel = parallel_task_in_lanes if actions.shape[0] >= _kernels.LANE_MIN_BATCH else parallel_task
    kernel(False, duration, actions, active, settings, indices, simulator_tables, task_tables, step_record)


def evaluate_parallel(
    settings: np.ndarray,
    topology: np.ndarray,
    observed: np.ndarray,
    nodes: np.ndarray,
    cables: np.ndarray,
    clusters: np.ndarray,
    counters: np.ndarray,
    task_nodes: np.ndarray,
    task_clusters: np.ndarray,
    end_reason: np.ndarray,
) -> None:
    """:data:`evaluate_serial` on all threads (the same bits); the arguments as for it."""
    parallel_task(
        True,
        0.0,
        _NO_ACTIONS,
        _NO_CLUSTERS,
        (settings, settings),
        (topology, _NO_THRUSTERS, _NO_VALUES, observed),
        (nodes, cables, clusters, counters),
        (task_nodes, task_clusters, _NO_VALUES, end_reason),
        _NO_RECORD,
    )
