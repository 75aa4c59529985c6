"""Analysis of a cluster: the paper's finite-difference reference, assembled tangent stiffness and
normal modes.

The integrator never assembles a stiffness matrix.  These functions do, for what needs one:
verifying the critical-step estimate against the true largest frequency and against the paper's
finite-difference bound (:func:`element_omega2_finite_difference`), and designing linear
controllers (LQR) about a nominal state.  The linear analysis uses the exact elongation
``|x_j - x_i| - L0``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from tether_gym import _kernels
from tether_gym.cluster import Cluster
from tether_gym.limits import check_real

if TYPE_CHECKING:
    from tether_gym.envs.task import DampingTask
    from tether_gym.simulator import BatchSimulator

#: The topology of a lone cable element: node 0 to node 1 (read-only, like every topology the
#: kernels get, so that they run the variant already compiled).
_ELEMENT_TOPOLOGY = np.array([[0, 1]], dtype=np.int64)
_ELEMENT_TOPOLOGY.flags.writeable = False

__all__ = [
    "CostBoundScopeError",
    "CostLowerBound",
    "axial_damping_matrix",
    "cost_lower_bound",
    "element_omega2_finite_difference",
    "frame_stiffness",
    "gyroscopic_matrix",
    "max_frequency",
    "normal_modes",
    "tangent_stiffness",
    "TetherModeErrors",
    "tether_mode_errors",
]


def tangent_stiffness(cluster: Cluster, positions: ArrayLike | None = None, *, taut_branch: bool = False) -> np.ndarray:
    """(3n, 3n) tangent stiffness ``K = d f_int / d x`` at ``positions`` (n, 3) m, in N/m.

    Each taut cable contributes ``EA/L0 e e^T + N/L (I - e e^T)`` (material plus geometric
    stiffness) to its 6x6 block pattern.  A slack cable contributes nothing, unless
    ``taut_branch=True``, where it counts as just taut (axial stiffness ``EA/L0``, geometric term
    ``max(N0 + EA/L0 dL, 0) / L``): the stiffest the cable can be within one step.
    Degrees of freedom are ordered node by node, ``[x0, y0, z0, x1, ...]``.
    """
    x = cluster.positions if positions is None else np.asarray(positions, dtype=np.float64)
    if x.shape != cluster.positions.shape:
        raise ValueError(f"positions must have shape {cluster.positions.shape}; got {x.shape}")
    n = cluster.num_nodes
    K = np.zeros((3 * n, 3 * n))
    i_nodes, j_nodes = cluster.cables[:, 0], cluster.cables[:, 1]
    delta = x[j_nodes] - x[i_nodes]
    lengths = np.linalg.norm(delta, axis=1)
    directions = delta / lengths[:, None]
    tension_taut = cluster.N0 + cluster.stiffness * (lengths - cluster.L0)
    for c in range(cluster.num_cables):
        taut = tension_taut[c] > 0.0
        if not (taut or taut_branch):
            continue
        e = directions[c]
        tension = max(tension_taut[c], 0.0)
        block = cluster.stiffness[c] * np.outer(e, e) + tension / lengths[c] * (np.eye(3) - np.outer(e, e))
        a = slice(3 * i_nodes[c], 3 * i_nodes[c] + 3)
        b = slice(3 * j_nodes[c], 3 * j_nodes[c] + 3)
        K[a, a] += block
        K[b, b] += block
        K[a, b] -= block
        K[b, a] -= block
    return K


def normal_modes(
    cluster: Cluster, positions: ArrayLike | None = None, *, taut_branch: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """Undamped normal modes of the cluster linearised at ``positions``.

    Returns ``(omega2, modes)``: (3n,) squared angular frequencies in (rad/s)^2, ascending, and
    (3n, 3n) mass-normalised mode shapes as columns (``modes.T @ M @ modes = I``).
    """
    K = tangent_stiffness(cluster, positions, taut_branch=taut_branch)
    inv_sqrt_mass = 1.0 / np.sqrt(np.repeat(cluster.masses, 3))
    scaled = K * inv_sqrt_mass[:, None] * inv_sqrt_mass[None, :]
    omega2, vectors = np.linalg.eigh(0.5 * (scaled + scaled.T))
    return omega2, vectors * inv_sqrt_mass[:, None]


def max_frequency(cluster: Cluster, positions: ArrayLike | None = None, *, taut_branch: bool = True) -> float:
    """Largest natural frequency ``omega_max`` of the tangent problem at ``positions``, rad/s.

    ``2 / omega_max`` is the linear stability limit of the central-difference method (paper eq. 13).
    """
    omega2, _ = normal_modes(cluster, positions, taut_branch=taut_branch)
    return float(np.sqrt(max(omega2[-1], 0.0)))


def _cable_blocks(cluster: Cluster, positions: np.ndarray, blocks: np.ndarray) -> np.ndarray:
    """(3n, 3n) assembly of one (3, 3) block per cable, ``blocks`` (m, 3, 3), in the pattern
    ``[[B, -B], [-B, B]]`` on the cable's two nodes."""
    n = cluster.num_nodes
    matrix = np.zeros((3 * n, 3 * n))
    for c, (i, j) in enumerate(cluster.cables):
        a = slice(3 * i, 3 * i + 3)
        b = slice(3 * j, 3 * j + 3)
        matrix[a, a] += blocks[c]
        matrix[b, b] += blocks[c]
        matrix[a, b] -= blocks[c]
        matrix[b, a] -= blocks[c]
    return matrix


def axial_damping_matrix(cluster: Cluster, positions: ArrayLike | None = None) -> np.ndarray:
    """(3n, 3n) damping matrix of the cables' Kelvin-Voigt damping at ``positions`` (n, 3), m,
    with every cable taut: ``c_ax e e^T`` per cable, N*s/m."""
    x = cluster.positions if positions is None else np.asarray(positions, dtype=np.float64)
    delta = x[cluster.cables[:, 1]] - x[cluster.cables[:, 0]]
    e = delta / np.linalg.norm(delta, axis=1, keepdims=True)
    return _cable_blocks(cluster, x, cluster.axial_damping[:, None, None] * e[:, :, None] * e[:, None, :])


def frame_stiffness(cluster: Cluster) -> np.ndarray:
    """(3n, 3n) stiffness of the frame's centrifugal and tidal forces, ``-M diag(T)``, N/m (zero in
    an inertial frame; negative entries push satellites away, as the gravity gradient does
    radially).  Add it to :func:`tangent_stiffness` for the linearised motion in the frame."""
    return -np.diag(np.repeat(cluster.masses, 3) * np.tile(cluster.frame.tidal, cluster.num_nodes))


def gyroscopic_matrix(cluster: Cluster) -> np.ndarray:
    """(3n, 3n) skew matrix ``G`` of the Coriolis force ``-G v = -2 M Omega x v`` in the cluster's
    frame, N*s/m (zero in an inertial frame)."""
    block = 2.0 * cluster.frame.rate * np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    return np.kron(np.diag(cluster.masses), block)


def element_omega2_finite_difference(batch: BatchSimulator, relative_perturbation: float = 1e-6) -> np.ndarray:
    """(B, m) the paper's finite-difference column-L1 bound on each cable's squared frequency, at
    the current positions of every cluster of ``batch``: the reference method of the
    critical-step estimate (paper section 4; ``batch.critical_time_step("finite-difference")``).

    Each cable is cut out as a two-node element with its split masses; each of its 6 degrees of
    freedom is perturbed by ``+-h`` (``h = relative_perturbation * L``) and the element force
    evaluated, giving the stiffness columns of eq. (21); the bound is the largest L1 norm of a
    column of ``M_e^-1/2 K_e M_e^-1/2``, in (rad/s)^2.  A slack cable is perturbed as if it
    were just taut at its current length (pretension shifted so that ``N = 0`` there): the
    stiffest it can be within a step, without the spurious compression of the linear law.
    """
    check_real("relative_perturbation", relative_perturbation, 0.0, 0.1, "(a fraction of the cable length)")
    k = _kernels
    B, m = batch.num_clusters, batch.num_cables
    x = batch.positions_
    ends = np.stack([x[:, batch.cables[:, 0]], x[:, batch.cables[:, 1]]], axis=2)  # (B, m, 2, 3)
    lengths = np.linalg.norm(ends[:, :, 1] - ends[:, :, 0], axis=-1)  # (B, m)
    h = relative_perturbation * lengths
    # 12 perturbed copies of each element: dof j = 0..5, sign +-.
    dof_shift = np.eye(6).reshape(6, 2, 3)
    perturbed = (
        ends[:, :, None, None]
        + np.array([1.0, -1.0])[None, None, None, :, None, None]
        * h[:, :, None, None, None, None]
        * dof_shift[None, None, :, None]
    )  # (B, m, 6, 2, 2, 3)
    E = B * m * 12
    ref = batch.reference
    ref_ends = np.stack([ref[:, batch.cables[:, 0]], ref[:, batch.cables[:, 1]]], axis=2)
    ref_elements = np.broadcast_to(ref_ends[:, :, None, None], perturbed.shape).reshape(E, 2, 3)

    def per_element(values: np.ndarray) -> np.ndarray:
        return np.broadcast_to(values[:, :, None, None], (B, m, 6, 2)).reshape(E)

    all_clusters = np.arange(B)
    tension_taut_branch = batch.evaluate_at(x, all_clusters, taut_branch=True)[1][:, :, k.TENSION]
    just_taut_N0 = batch.N0 - np.minimum(tension_taut_branch, 0.0)
    # Each element is a cluster of two nodes and one cable, at rest, intact, in an inertial frame.
    nodes = np.zeros((E, 2, k.NODE_COLUMNS))
    nodes[:, :, k.POSITION : k.POSITION + 3] = perturbed.reshape(E, 2, 3)
    nodes[:, :, k.REFERENCE : k.REFERENCE + 3] = ref_elements
    cables = np.zeros((E, 1, k.CABLE_COLUMNS))
    cables[:, 0, k.STIFFNESS] = per_element(batch.stiffness)
    cables[:, 0, k.REST_LENGTH] = per_element(batch.L0)
    cables[:, 0, k.PRETENSION] = per_element(just_taut_N0)
    cables[:, 0, k.INV_SPLIT_MASS_SUM] = per_element(batch.inv_split_mass_sum)
    cables[:, 0, k.INTACT] = 1.0
    k.evaluate_forces(
        batch.kernel_settings,
        True,
        _ELEMENT_TOPOLOGY,
        nodes,
        cables,
        np.zeros((E, k.CLUSTER_COLUMNS)),
        np.empty(E, dtype=np.bool_),
    )
    f = nodes[:, :, k.INTERNAL_FORCE : k.INTERNAL_FORCE + 3].reshape(B, m, 6, 2, 6)
    columns = (f[:, :, :, 0] - f[:, :, :, 1]) / (2.0 * h[:, :, None, None])  # (B, m, j, i)
    degree = np.bincount(batch.cables.ravel(), minlength=batch.num_nodes)
    split = batch.masses / degree  # (B, n)
    dof_mass = np.repeat(
        np.stack([split[:, batch.cables[:, 0]], split[:, batch.cables[:, 1]]], axis=2), 3, axis=2
    )  # (B, m, 6)
    scale = 1.0 / np.sqrt(dof_mass)
    scaled = np.abs(columns) * scale[:, :, :, None] * scale[:, :, None, :]
    omega2 = scaled.sum(axis=3).max(axis=2)
    # Axial damping with lagged velocity shortens the stable step (see _kernels.cable_forces).
    axial_damping, inv_split_mass_sum = batch.axial_damping, batch.inv_split_mass_sum
    with np.errstate(divide="ignore", invalid="ignore"):
        xi = np.where(axial_damping > 0.0, 0.5 * axial_damping * inv_split_mass_sum / np.sqrt(omega2), 0.0)
    omega2 = omega2 * (np.sqrt(1.0 + xi * xi) + xi) ** 2
    omega2 = omega2 + np.abs(batch.frame_tidal).max(axis=1)[:, None]
    return np.where(batch.intact, omega2, 0.0)


@dataclasses.dataclass(frozen=True)
class TetherModeErrors:
    """How far one beaded tether's lowest modes fall from the continuous line's closed forms.

    Attributes:
        tether: index of the tether in ``cluster.tethers``.
        segments: its segment count N.
        length: its reference length L0, m.
        line_density: its mass per reference length, kg/m.
        tension: its mean segment pretension, N.
        transverse_hz: (modes,) the taut string's ``f_k = k / (2 L0) sqrt(N0 / mu)``, Hz (zero
            without pretension).
        transverse_error: (modes,) the beaded line's relative error on them, satellites held
            (NaN without pretension).
        axial_hz: the first axial mode of a uniform bar between the two satellites' masses, Hz.
        axial_error: the beaded line's relative error on it, satellites free.
    """

    tether: int
    segments: int
    length: float
    line_density: float
    tension: float
    transverse_hz: np.ndarray
    transverse_error: np.ndarray
    axial_hz: float
    axial_error: float


def _bar_with_end_masses_wavenumber(length: float, line_density: float, mass_a: float, mass_b: float) -> float:
    """The first nonzero wavenumber k, 1/m, of axial vibration of a uniform bar of ``length`` m and
    ``line_density`` kg/m between free end masses ``mass_a`` and ``mass_b`` kg.

    With ``a = M_a k / mu`` and ``b = M_b k / mu`` the end conditions give
    ``sin(kL) (a b - 1) = (a + b) cos(kL)``; its first root lies in ``(0, pi / L)``, where the
    left side minus the right runs from ``-(a + b) < 0`` at ``k -> 0`` to ``a + b > 0`` at
    ``pi / L``, so bisection finds it to round-off.
    """

    def residual(k: float) -> float:
        a, b = mass_a * k / line_density, mass_b * k / line_density
        return math.sin(k * length) * (a * b - 1.0) - (a + b) * math.cos(k * length)

    low, high = 1e-12 / length, math.pi / length
    for _ in range(200):
        middle = 0.5 * (low + high)
        if residual(middle) < 0.0:
            low = middle
        else:
            high = middle
    return 0.5 * (low + high)


def tether_mode_errors(cluster: Cluster, modes: int = 3) -> list[TetherModeErrors]:
    """The discretisation error of each beaded tether of ``cluster``: its lowest transverse and
    axial frequencies as the lumped-mass line gives them, against the continuous line's closed forms.

    Each tether is taken alone: a straight line of its ``L0``, mass, ``EA``, mean pretension,
    segment count and lumping rule between its two satellites, with their own masses (the
    cluster's less every tether's lumped share), so that the closed forms do not move with N.
    Its frequencies are the eigenvalues of :func:`tangent_stiffness` over the lumped masses:
    transverse with the satellites held (the taut string, modes 1..``modes``), axial with them
    free (the bar between two end masses, mode 1).  Their errors are spatial, from the segment
    count; the central-difference step adds a phase error of about ``(omega h)^2 / 24``, far
    smaller at the safety factors in use.

    Args:
        cluster: a cluster with tethers (see :func:`tether_gym.tethers.build_cluster`).
        modes: number of transverse modes, >= 1 and < the segment count.

    Returns:
        One :class:`TetherModeErrors` per tether with beads, in the order of ``cluster.tethers``.
    """
    from tether_gym.tethers import Tether, build_cluster

    results = []
    for t, spec in enumerate(cluster.tethers):
        if spec.segments < 2:
            continue
        if not 1 <= modes < spec.segments:
            raise ValueError(f"modes must be in 1..{spec.segments - 1} for tether {t}'s {spec.segments} segments")
        if spec.L0 is None:  # a cluster's tethers carry their L0 (Cluster checks it)
            raise ValueError(f"tether {t} has no L0")
        length = float(spec.L0)
        density = spec.mass / length
        tension = float(np.mean(cluster.N0[cluster.tether_cables(t)]))
        ends = [
            cluster.masses[node] - sum(other.end_mass for other in cluster.tethers if node in other.ends)
            for node in spec.ends
        ]
        line = build_cluster(
            [[0.0, 0.0, 0.0], [length, 0.0, 0.0]],
            ends,
            [Tether((0, 1), EA=spec.EA, segments=spec.segments, mass=spec.mass, N0=tension, lumping=spec.lumping)],
        )
        stiffness = tangent_stiffness(line)

        def frequencies(axis: int, held: bool, line: Cluster = line, stiffness: np.ndarray = stiffness) -> np.ndarray:
            dofs = np.arange(line.num_nodes) * 3 + axis
            if held:
                dofs = dofs[line.is_bead]
            scale = 1.0 / np.sqrt(line.masses[dofs // 3])
            block = stiffness[np.ix_(dofs, dofs)] * scale[:, None] * scale[None, :]
            omega2 = np.linalg.eigvalsh(0.5 * (block + block.T))
            return np.sqrt(np.clip(omega2, 0.0, None)) / (2 * math.pi)

        k = np.arange(1, modes + 1)
        string = k / (2 * length) * math.sqrt(tension / density)
        with np.errstate(divide="ignore", invalid="ignore"):
            transverse_error = np.where(string > 0, frequencies(1, True)[:modes] / string - 1.0, np.nan)
        wavenumber = _bar_with_end_masses_wavenumber(length, density, ends[0], ends[1])
        bar = wavenumber * math.sqrt(spec.EA / density) / (2 * math.pi)
        # Mode 0 of the free line is its rigid translation.
        axial_error = float(frequencies(0, False)[1] / bar - 1.0)
        results.append(
            TetherModeErrors(t, spec.segments, length, density, tension, string, transverse_error, bar, axial_error)
        )
    return results


# ---------------------------------------------------------------------------------------------
# A lower bound on the task's cost: how fast can bounded thrust take vibration energy out?


class CostBoundScopeError(ValueError):
    """:func:`cost_lower_bound` was asked about a task outside the scope of its derivation (a
    turning frame, disturbances, damping that is not proportional to mass, ...); the message
    says which assumption fails and why the bound would not hold there."""


@dataclasses.dataclass(frozen=True)
class CostLowerBound:
    """Per-seed lower bounds on the cost (minus the return) of any controller on a task; see
    :func:`cost_lower_bound` for the derivation.

    Attributes:
        seeds: (S,) the reset seeds.
        bounds: (S,) reward units: every controller's return on seed ``seeds[s]`` is at most
            ``-bounds[s]``.
        full_episode: (S,) the bound on the cost of an episode that runs to the time limit,
            ``sum_k w_v E_lb(t_k)`` over its steps.
        failure: (S,) the bound on the cost of an episode that ends in a failure (the penalty,
            less what its last step's vibration term can give back); ``bounds = min(full_episode,
            failure)``.
        initial_energy: (S,) J, the vibration energy at the reset (exact rigid split), ``E(0)``.
        optimisation_gap: (S,) reward units: how much higher the propellant-aware bound could
            still be, had its convex minimisation been run to the end (its duality gap).
        times: (N + 1,) s, ``t_k = k * control_interval``, k = 0..N.
        energy: (S, N + 1) J, the envelope ``E_lb(t_k)`` under which no controller can bring the
            vibration energy, or None when not asked for (``return_energy=False``).
        max_episode_steps: N, the episode's time limit in control steps.
        vibration_weight: per J, the reward's vibration weight over the task's energy scale.
        failure_penalty: the reward's one-off failure penalty.
        constants: each (S,): ``thrust_coefficient`` (b, W/sqrt(J): the thrusters remove at most
            ``b sqrt(E)`` of vibration power), ``dissipation_rate`` (a, 1/s: the damping removes at
            most ``a E``), ``damping_rate`` (alpha, 1/s), ``axial_rate`` (1/s, the cables' part of
            a), ``thrust_torque`` (N m, the thrusters' largest torque on the nominal shape),
            ``bias_coefficient`` (q, N/sqrt(kg): ``sqrt(sum_i |p_i|^2 / m_i)`` of the bias
            thrust), ``inertia_min`` (kg m^2, the nominal shape's smallest principal moment),
            ``potential_floor`` (J, the vibration energy's potential part never goes below it).
    """

    seeds: np.ndarray
    bounds: np.ndarray
    full_episode: np.ndarray
    failure: np.ndarray
    initial_energy: np.ndarray
    optimisation_gap: np.ndarray
    times: np.ndarray
    energy: np.ndarray | None
    max_episode_steps: int
    vibration_weight: float
    failure_penalty: float
    constants: dict[str, np.ndarray]


#: Relative tolerance of the scope checks that compare floats (mass-proportional damping, the
#: bias against the cables' force at the nominal shape).
_SCOPE_RTOL = 1e-9


def _refuse(what: str, why: str) -> CostBoundScopeError:
    return CostBoundScopeError(
        f"cost_lower_bound: {what}; the bound's derivation does not cover it ({why}). In scope: free space "
        "(inertial frame), no disturbances or thrust noise, cable_failure='terminate', diagonal damping "
        "proportional to mass (C = alpha M, alpha may be 0) and a nominal shape that is not collinear"
    )


def _check_task_scope(task: DampingTask) -> None:
    """Refuse the task settings outside the bound's derivation (see :func:`cost_lower_bound`)."""
    config = task.config
    disturbances = config.disturbances
    if disturbances.impulse_magnitude > 0.0 or disturbances.periodic_amplitude > 0.0:
        raise _refuse(
            "the task has external disturbances (impulse_magnitude or periodic_amplitude > 0)",
            "they can do work on the vibration in either direction, beyond the thrusters' limit",
        )
    if disturbances.thrust_noise > 0.0:
        raise _refuse(
            f"thrust_noise={disturbances.thrust_noise:g}",
            "Gaussian thrust noise is unbounded, so the delivered thrust has no largest value",
        )
    if config.cable_failure != "terminate":
        raise _refuse(
            f"cable_failure={config.cable_failure!r}",
            "a broken cable removes its strain energy at once and leaves the bias thrust unbalanced, so "
            "the vibration energy has no floor after it",
        )
    weights = task.reward_weights
    if not (weights.vibration >= 0.0 and weights.failure >= 0.0):
        raise _refuse(
            f"a negative reward weight (vibration {weights.vibration:g} per J, failure {weights.failure:g})",
            "the bound adds the vibration terms and the penalty as costs",
        )
    if task.sim.kernel_settings[_kernels.LINEARISED] != 0.0:
        raise _refuse(
            "the simulator uses the paper's linearised elongation",
            "its cable force is not the gradient of the strain energy the reward measures",
        )


def _seed_constants(task: DampingTask) -> dict[str, Any]:
    """The constants of the bound for cluster 0 of ``task`` in its current (just reset) state:
    see :func:`cost_lower_bound`.  Raises :class:`CostBoundScopeError` outside the derivation."""
    sim = task.sim
    cluster: Cluster = sim.clusters[0]
    if not cluster.frame.is_inertial:
        raise _refuse(
            f"the cluster moves in a turning frame ({cluster.frame.kind})",
            "the centrifugal and tidal potential of a turning frame is not convex, so the vibration energy "
            "has no floor at the nominal shape, and the frame exchanges energy with the rigid motion",
        )
    masses = np.asarray(sim.masses[0], dtype=np.float64)
    damping = np.asarray(sim.damping[0], dtype=np.float64)
    alpha = float(damping[0] / masses[0])
    if not np.allclose(damping, alpha * masses, rtol=_SCOPE_RTOL, atol=0.0):
        raise _refuse(
            "the diagonal damping is not proportional to the masses (e.g. tether beads without damping "
            "beside damped satellites, or randomised masses or damping)",
            "non-uniform damping of the rigid motion feeds the vibration at a rate set by the rigid "
            "velocity, which thrust can make as large as it likes; use damping_rate=0 or C = alpha M",
        )
    bias = np.asarray(task.bias[0], dtype=np.float64)
    nominal = np.asarray(task.nominal[0], dtype=np.float64)
    x0 = np.asarray(sim.positions[0], dtype=np.float64)
    v0 = np.asarray(sim.velocities[0], dtype=np.float64)
    nominal_strain = float(task.nominal_strain_energy[0])

    stiffness = cluster.stiffness
    ends_i, ends_j = cluster.cables[:, 0], cluster.cables[:, 1]

    def cables_potential(x: np.ndarray) -> tuple[float, np.ndarray]:
        """(strain energy of the intact cables at x, J; (n, 3) its gradient, N)."""
        delta = x[ends_j] - x[ends_i]
        lengths = np.linalg.norm(delta, axis=1)
        elastic = np.maximum(cluster.N0 + stiffness * (lengths - cluster.L0), 0.0)
        force = (elastic / lengths)[:, None] * delta
        gradient = np.zeros_like(x)
        np.add.at(gradient, ends_j, force)
        np.subtract.at(gradient, ends_i, force)
        return float((0.5 * elastic**2 / stiffness).sum()), gradient

    nominal_potential, nominal_gradient = cables_potential(nominal)
    residual = float(np.abs(nominal_gradient - bias).max())
    force_scale = max(float(np.abs(nominal_gradient).max()), float(np.abs(bias).max()), 1e-300)
    if residual > 1e-6 * force_scale + 1e-12:
        raise _refuse(
            f"the bias thrust differs from the cables' force at the nominal shape by {residual:.3g} N",
            "the potential of the vibration energy is then not minimal at the nominal shape",
        )
    # The potential part U = V(x) - V_nominal - p.(x - X) is convex (each cable's energy is a
    # convex, non-decreasing function of its convex length; the bias term is linear) with zero
    # gradient at X: its minimum is U(X).
    potential_floor = nominal_potential - nominal_strain

    total = float(masses.sum())
    centre = (masses[:, None] * x0).sum(axis=0) / total
    nominal_centre = (masses[:, None] * nominal).sum(axis=0) / total
    arm = x0 - centre
    reference_arm = nominal - nominal_centre
    relative = v0 - (masses[:, None] * v0).sum(axis=0) / total

    def inertia(r: np.ndarray) -> np.ndarray:
        return np.einsum("i,ij->", masses, r * r) * np.eye(3) - np.einsum("i,ij,ik->jk", masses, r, r)

    reference_inertia = np.linalg.eigvalsh(inertia(reference_arm))
    inertia_min = float(reference_inertia[0])
    if not inertia_min > 1e-9 * float(reference_inertia[-1]):
        raise _refuse(
            "the nominal shape is collinear (no moment of inertia about its axis)",
            "the rigid rotation that the vibration energy leaves out can then spin arbitrarily fast about "
            "that axis, and its exchange with the vibration has no bound",
        )
    momentum = np.einsum("i,ij->j", masses, np.cross(arm, relative))
    rotation = np.linalg.solve(inertia(arm), momentum)
    kinetic_w = 0.5 * float(np.einsum("i,ij->", masses, relative * relative))
    kinetic_rel = kinetic_w - 0.5 * float(momentum @ rotation)
    potential_0 = cables_potential(x0)[0] - nominal_strain - float((bias * (x0 - nominal)).sum())

    thrusters = np.asarray(task.thrusters, dtype=np.int64)
    per_axis = task.config.thrust_limit == "per_axis"
    largest = np.asarray(task.max_thrust, dtype=np.float64) * (math.sqrt(3.0) if per_axis else 1.0)
    # Cables' Kelvin-Voigt damping: sum_c c (dL/dt)^2 <= u^T (L_c x I) u <= lambda_max(M^-1/2 L_c M^-1/2) 2 T_rel.
    laplacian = np.zeros((cluster.num_nodes, cluster.num_nodes))
    c_axial = np.broadcast_to(cluster.axial_damping, (cluster.num_cables,))
    np.add.at(laplacian, (ends_i, ends_i), c_axial)
    np.add.at(laplacian, (ends_j, ends_j), c_axial)
    np.subtract.at(laplacian, (ends_i, ends_j), c_axial)
    np.subtract.at(laplacian, (ends_j, ends_i), c_axial)
    scale = 1.0 / np.sqrt(masses)
    axial_rate = float(np.linalg.eigvalsh(laplacian * scale[:, None] * scale[None, :])[-1]) * (1.0 + 1e-9)
    axial_rate = max(axial_rate, 0.0)
    return {
        "initial_energy": kinetic_rel + potential_0,
        "initial_total": kinetic_w + potential_0,
        "potential_floor": potential_floor,
        "nominal_strain_energy": nominal_strain,
        "deviation_0": math.sqrt(float(np.einsum("i,ij->", masses, (arm - reference_arm) ** 2))),
        "angular_momentum_0": float(np.linalg.norm(momentum)),
        "thrust_beta": math.sqrt(float((largest**2 / masses[thrusters]).sum())),
        "thrust_largest": largest,
        "thrust_masses": masses[thrusters],
        "thrust_torque": float((largest * np.linalg.norm(reference_arm[thrusters], axis=1)).sum()),
        "bias_coefficient": math.sqrt(float(((bias**2).sum(axis=1) / masses).sum())),
        "damping_rate": alpha,
        "axial_rate": axial_rate,
        "inertia_min": inertia_min,
        "arm_norm": math.sqrt(float(np.einsum("i,ij->", masses, reference_arm**2))),
    }


def _rotation_terms(constants: dict[str, Any]) -> Callable[[float], tuple[float, float]]:
    """``t -> (kappa(t), g(t))``: the rigid rotation's exchange with the vibration at time t s,
    bounded for any controller: ``kappa = |omega|^2 |r|_m`` (N/sqrt(kg), added to the thrust's
    coefficient beta: the centrifugal power on the deformation is at most ``kappa sqrt(2 T_rel)``)
    and ``g = |omega| q Delta`` (W, the bias torque's power on the rotation); both grow with t,
    and are inf once the deviation bound reaches the nominal shape's smallest moment of inertia
    (the bound then claims nothing more)."""
    k = constants
    beta, q, alpha = k["thrust_beta"], k["bias_coefficient"], k["damping_rate"]
    root_inertia = math.sqrt(k["inertia_min"])

    def terms(t: float) -> tuple[float, float]:
        # |L(t)| <= |L(0)| + int (thrust and bias torques) (damping only shrinks it), and
        # lambda_min(I(t)) >= (sqrt(lambda_min(I_nominal)) - Delta(t))^2.
        spread = _deviation_bound(k, t)
        decay = t if alpha == 0.0 else -math.expm1(-alpha * t) / alpha
        momentum = k["angular_momentum_0"] + (k["thrust_torque"] + (beta + q) * spread) * decay
        gap = root_inertia - spread
        if not gap > 0.0:
            return math.inf, math.inf
        omega = momentum / (gap * gap)
        return omega * omega * (k["arm_norm"] + spread), omega * q * spread

    return terms


def _deviation_bound(constants: dict[str, Any], t: float) -> float:
    """Delta(t) >= sqrt(sum_i m_i |d_i(t)|^2), kg^(1/2) m: the mass-weighted deviation from the
    nominal shape about the centre of mass, for any controller (``Delta' <= sqrt(2 T_w) <=
    sqrt(2 Y)`` with ``sqrt(Y(t)) <= sqrt(Y(0)) + beta t / sqrt(2)``)."""
    k = constants
    total_0 = max(k["initial_total"] - k["potential_floor"], 0.0)
    return k["deviation_0"] + math.sqrt(2.0 * total_0) * t + 0.5 * k["thrust_beta"] * t * t


def _envelope(
    constants: dict[str, Any], times: np.ndarray, substeps: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(E_lb(t_k), Delta(t_k), rotation_drain_k, exchange_k)`` at ``times`` (N + 1,) s for one
    seed: the full-thrust envelope of :func:`cost_lower_bound` (J), the deviation bound, and for
    the propellant-aware bound the rotation's drain of ``sqrt(y)`` at full damping,
    ``int_0^t exp(-a (t - s) / 2) kappa(s) / sqrt(2) ds`` (sqrt(J)), and ``int_0^t g`` (J).
    Integrated over ``substeps`` pieces per interval with each piece's coefficients at their
    largest (they grow with time)."""
    k = constants
    beta = k["thrust_beta"]
    dissipation = 2.0 * k["damping_rate"] + 2.0 * k["axial_rate"]
    floor = k["potential_floor"]
    terms = _rotation_terms(k)
    energy = np.empty(times.size)
    drains = np.zeros(times.size)
    exchanges = np.zeros(times.size)
    spreads = np.array([_deviation_bound(k, float(t)) for t in times])
    y = max(k["initial_energy"] - floor, 0.0)
    energy[0] = floor + y
    drain = exchange = 0.0
    for step in range(1, times.size):
        t0, t1 = float(times[step - 1]), float(times[step])
        h = (t1 - t0) / substeps
        decay = math.exp(-0.5 * dissipation * h)
        weight = h if dissipation == 0.0 else 2.0 * (1.0 - decay) / dissipation
        for piece in range(1, substeps + 1):
            kappa, g = terms(t0 + piece * h)
            drain = drain * decay + kappa * weight / math.sqrt(2.0)
            exchange += g * h
            if y <= 0.0:
                continue
            b = math.sqrt(2.0) * (beta + kappa)
            if not (math.isfinite(b) and math.isfinite(g)):
                y = 0.0
                continue
            root = math.sqrt(y)
            if dissipation > 0.0:
                root = (root + b / dissipation) * decay - b / dissipation
            else:
                root -= 0.5 * b * h
            y = max(max(root, 0.0) ** 2 - g * h, 0.0)
        energy[step] = floor + y
        drains[step], exchanges[step] = drain, exchange
    return energy, spreads, drains, exchanges


#: Thrusters up to which the thrust's efficiency per newton is bounded by the concave hull of all
#: on/off subsets (2^k points); beyond, by ``min(beta, Phi / sqrt(m_min))``.
_HULL_THRUSTERS = 12


def _thrust_efficiency(largest: np.ndarray, masses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Breakpoints ``(Phi, psi)`` of a concave, piecewise-linear psi(Phi) >= max{sqrt(sum_j
    f_j^2 / m_j) : sum_j f_j = Phi, 0 <= f_j <= Fmax_j}: the largest thrust coefficient (N/sqrt(kg))
    that a total thrust Phi (N, what the propellant term charges) can have.  The maximum of a
    convex function over the box's slice lies below the upper concave hull of the box's vertices,
    the on/off subsets of the thrusters."""
    count = largest.size
    beta = math.sqrt(float((largest**2 / masses).sum()))
    total = float(largest.sum())
    if count > _HULL_THRUSTERS:
        knee = beta * math.sqrt(float(masses.min()))
        return np.array([0.0, min(knee, total), total]), np.array(
            [0.0, min(beta, total / math.sqrt(float(masses.min()))), beta]
        )
    subsets = (np.arange(2**count)[:, None] >> np.arange(count)[None, :]) & 1
    phi = subsets @ largest
    psi = np.sqrt(subsets @ (largest**2 / masses))
    order = np.lexsort((-psi, phi))
    hull: list[tuple[float, float]] = []
    for x, y in zip(phi[order].tolist(), psi[order].tolist(), strict=True):
        if hull and x == hull[-1][0]:
            continue
        while len(hull) >= 2:
            (x1, y1), (x2, y2) = hull[-2], hull[-1]
            if (y2 - y1) * (x - x1) <= (y - y1) * (x2 - x1):  # the middle point is not above the chord
                hull.pop()
            else:
                break
        hull.append((x, y))
    xs, ys = (np.array(v) for v in zip(*hull, strict=True))
    return xs, ys


def _propellant_bound(
    constants: dict[str, Any],
    times: np.ndarray,
    drains: np.ndarray,
    exchanges: np.ndarray,
    vibration_weight: float,
    propellant_weight: float,
    iterations: int,
) -> tuple[float, float]:
    """``(lower bound, gap)``: a lower bound on ``sum_k (w_v E(t_k) + w_p Phi_k dt)`` over the
    episode's N steps for any controller, whose total thrust ``Phi_k`` (N) the propellant term
    charges, and the duality gap left by the optimisation (how much tighter the exact minimum
    could be).

    Relaxation: ``r = sqrt(E - U_min)`` obeys ``r' >= -(psi(Phi) + kappa) / sqrt(2) - a r / 2``
    (psi from :func:`_thrust_efficiency`), and ``E(t_k) >= U_min + max(max(l_k, 0)^2 - Gamma_k,
    0)`` where ``l_k = exp(-a t_k / 2) r_0 - sum_i A_ki psi(Phi_i) / sqrt(2) - drain_k``
    (``A_ki = int_step_i exp(-a (t_k - s) / 2) ds``) and ``Gamma_k = int_0^t_k g``: the cost is
    then a convex function J(Phi) over the box [0, Phi_max]^N.  Projected gradient steps find a
    good Phi-bar; ``J(Phi-bar) + min_box grad J . (Phi - Phi-bar)`` (the Frank-Wolfe gap) is a
    lower bound on J's minimum whatever Phi-bar is.
    """
    k = constants
    steps = times.size - 1
    dt = float(times[1] - times[0])
    dissipation = 2.0 * k["damping_rate"] + 2.0 * k["axial_rate"]
    floor = k["potential_floor"]
    xs, ys = _thrust_efficiency(k["thrust_largest"], k["thrust_masses"])
    slopes = np.diff(ys) / np.diff(xs)
    top = float(xs[-1])
    decay = math.exp(-0.5 * dissipation * dt)
    weight = dt if dissipation == 0.0 else 2.0 * (1.0 - decay) / dissipation
    lags = np.arange(steps)[:, None] - np.arange(steps)[None, :]
    influence = np.where(lags >= 0, weight * decay ** np.maximum(lags, 0), 0.0) / math.sqrt(2.0)  # A / sqrt(2)
    finite = np.isfinite(drains[1:]) & np.isfinite(exchanges[1:])
    r0 = math.sqrt(max(k["initial_energy"] - floor, 0.0))
    free = np.where(finite, r0 * decay ** np.arange(1, steps + 1) - np.where(finite, drains[1:], 0.0), -math.inf)
    gamma = np.where(finite, exchanges[1:], 0.0)
    w_v, w_p = vibration_weight, propellant_weight * dt

    def cost_and_gradient(phi: np.ndarray) -> tuple[float, np.ndarray]:
        piece = np.clip(np.searchsorted(xs, phi, side="right") - 1, 0, slopes.size - 1)
        psi = ys[piece] + slopes[piece] * (phi - xs[piece])
        level = free - influence @ psi
        excess = np.maximum(level, 0.0) ** 2 - gamma
        live = (excess > 0.0) & np.isfinite(level)
        vibration = np.where(live, excess, 0.0)
        cost = float(w_v * (steps * floor + vibration.sum()) + w_p * phi.sum())
        slope_of_cost = np.where(live, 2.0 * level, 0.0) * w_v
        gradient = -(influence.T @ slope_of_cost) * slopes[piece] + w_p
        return cost, gradient

    def bound(phi: np.ndarray) -> tuple[float, float]:
        cost, gradient = cost_and_gradient(phi)
        gap = float(np.maximum(gradient * phi, gradient * (phi - top)).sum())  # max over the box of g.(phi - s)
        return cost - max(gap, 0.0), max(gap, 0.0)

    # Start from the best "full thrust for the first s steps, then none" (the shape of the optimum
    # when thrust pays for itself early and not late), then improve by projected gradient steps.
    switches = np.where(np.arange(steps + 1)[:, None] > np.arange(steps)[None, :], top, 0.0)  # (N + 1, N)
    levels = free - (ys[-1] * (switches > 0)) @ influence.T
    excess = np.maximum(levels, 0.0) ** 2 - gamma
    costs = w_v * np.where((excess > 0.0) & np.isfinite(levels), excess, 0.0).sum(axis=1) + w_p * switches.sum(axis=1)
    best_phi = switches[int(np.argmin(costs))]
    best_cost = cost_and_gradient(best_phi)[0]
    lower, gap = bound(best_phi)
    phi, cost = best_phi, best_cost
    step_size = top * top / max(abs(cost), 1e-12)
    for _ in range(iterations):
        gradient = cost_and_gradient(phi)[1]
        trial = np.clip(phi - step_size * gradient, 0.0, top)
        trial_cost = cost_and_gradient(trial)[0]
        if trial_cost < cost:
            phi, cost = trial, trial_cost
            step_size *= 1.5
            candidate, candidate_gap = bound(phi)
            if candidate > lower:
                lower, gap = candidate, candidate_gap
        else:
            step_size *= 0.5
    return lower, gap


def cost_lower_bound(
    env: str | Any,
    seeds: ArrayLike,
    *,
    max_episode_steps: int | None = None,
    substeps: int = 16,
    iterations: int = 50,
    return_energy: bool = False,
    options: Mapping[str, Any] | None = None,
    **env_kwargs: Any,
) -> CostLowerBound:
    """A rigorous lower bound on the cost (minus the return) of every controller on each seed.

    No controller, however it uses its thrusters, can take the vibration energy out faster than
    their largest force allows; the bound integrates that limit from each seed's own initial state.

    Derivation (free space; details and the argument's fine print in ``docs/benchmark.md``).  Split
    the velocities ``v_i = v_com + omega x r_i + u_i`` into translation, rigid rotation
    (``I omega = L``) and deformation ``u``; the reward's ``E = T_rel + U``, with ``T_rel =
    1/2 sum m |u|^2`` and ``U = V(x) - V_nominal - p.(x - X)`` (cables' strain energy and the
    bias-thrust potential).  ``U`` is convex with zero gradient at the nominal shape ``X``, so
    ``U >= U(X)`` (``potential_floor``, 0 to round-off) and ``T_rel <= E - U(X) =: y``.  With
    damping ``C = alpha M`` and central cable forces, exactly::

        dE/dt = sum_i F_i.u_i - 2 alpha T_rel - D_cables - omega.tau_bias + sum_i m_i (omega x r_i).(omega x u_i)

    * thrust: ``|sum F_i.u_i| <= sum_thrusters Fmax_i |u_i| <= beta sqrt(2 T_rel)``, ``beta =
      sqrt(sum Fmax_i^2 / m_i)`` (Cauchy-Schwarz; ``Fmax = sqrt(3) max_thrust`` per axis,
      ``max_thrust`` for the magnitude limit; only the satellites with thrusters count);
    * damping: ``2 alpha T_rel + D_cables <= a T_rel``, ``a = 2 alpha + 2 lambda_max(M^-1/2 L_c
      M^-1/2)`` (``L_c`` the cables' Laplacian weighted by their Kelvin-Voigt coefficients);
    * rotation: ``|omega| <= |L| / lambda_min(I)``, ``|L(t)|`` bounded by the thrusters' and the
      bias's largest torques, ``lambda_min(I)`` and the arms by the mass-weighted deviation
      ``Delta(t)`` from the nominal shape, itself bounded through an upper energy bound.

    So ``dy/dt >= -b(t) sqrt(y) - a y - g(t)`` (``b = sqrt(2) (beta + |omega|^2 |r|_m)``, ``g =
    |omega| q Delta``), integrated piece by piece (exact in ``sqrt(y)`` for ``b``, ``a``; ``g``
    subtracted), a lower bound by a comparison argument: the envelope ``E_lb(t)``.

    The cost of an episode that runs its ``N`` steps is at least ``sum_k w_v E_lb(t_k)``
    (propellant and slack terms are >= 0), and, tighter, the minimum over every thrust schedule
    of the vibration terms plus the propellant term that schedule pays: with a total thrust
    ``Phi`` (N) the thrust coefficient is at most ``psi(Phi)``, the concave hull over the
    thrusters' on/off subsets (Cauchy-Schwarz on the thrusters that fire), so removing energy
    costs propellant.  That minimum is of a convex function of the per-step ``Phi_k``; projected
    gradient steps and its Frank-Wolfe duality gap give a rigorous lower bound on it
    (``optimisation_gap`` says how much was left).  An episode that fails pays
    ``failure_penalty``, less at most what its last step's vibration term can give back (a
    broken cable's energy leaves the reward's sum).

    Args:
        env: a registered id (made with ``gymnasium.make(env, **env_kwargs)``) or an env whose
            ``unwrapped`` is a :class:`~tether_gym.envs.TetherClusterEnv` (``env_kwargs`` must then
            be empty).
        seeds: (S,) reset seeds, ints >= 0.
        max_episode_steps: N, the time limit in control steps; default the env's spec's.
        substeps: integration pieces per control interval (more: tighter, never looser than
            rigorous).
        iterations: projected-gradient steps of the propellant-aware minimisation (more: tighter,
            to within ``optimisation_gap``; any number gives a rigorous bound).
        return_energy: also return the envelope ``E_lb(t_k)`` (S, N + 1), J.
        options: reset options passed to every reset (an exact initial state, see the env's
            ``reset``); default None: each seed's random initial state.

    Returns:
        A :class:`CostLowerBound`; ``bounds`` (S,) in reward units, returns <= ``-bounds``.

    Raises:
        CostBoundScopeError: a task outside the derivation: a turning frame, disturbances or thrust
            noise, ``cable_failure="continue"``, damping not proportional to mass (beads without
            damping beside damped satellites), a collinear nominal shape, the linearised elongation.
        ValueError: bad ``seeds``, ``substeps``, ``iterations`` or ``max_episode_steps``.
    """
    import gymnasium as gym

    from tether_gym.envs.cluster_env import TetherClusterEnv

    if isinstance(env, str):
        made = gym.make(env, **env_kwargs)
    else:
        if env_kwargs:
            raise ValueError(f"env_kwargs {sorted(env_kwargs)} apply only to an env id; got an env object")
        made = env
    unwrapped = getattr(made, "unwrapped", None)
    if not isinstance(unwrapped, TetherClusterEnv):
        raise TypeError(
            f"env must be a tether-gym id or a TetherClusterEnv (possibly wrapped); got {type(made).__name__}"
        )
    if max_episode_steps is None:
        spec = getattr(made, "spec", None)
        max_episode_steps = getattr(spec, "max_episode_steps", None)
        if max_episode_steps is None:
            raise ValueError("the env has no time limit in its spec: pass max_episode_steps (control steps)")
    if (
        isinstance(max_episode_steps, bool)
        or not isinstance(max_episode_steps, (int, np.integer))
        or max_episode_steps < 1
    ):
        raise ValueError(f"max_episode_steps must be a whole number >= 1; got {max_episode_steps!r}")
    if isinstance(substeps, bool) or not isinstance(substeps, (int, np.integer)) or not 1 <= substeps <= 10_000:
        raise ValueError(f"substeps must be a whole number in [1, 10000]; got {substeps!r}")
    if isinstance(iterations, bool) or not isinstance(iterations, (int, np.integer)) or not 0 <= iterations <= 100_000:
        raise ValueError(f"iterations must be a whole number in [0, 100000]; got {iterations!r}")
    seed_array = np.asarray(seeds)
    if seed_array.ndim != 1 or seed_array.size == 0 or seed_array.dtype.kind not in "iu" or (seed_array < 0).any():
        raise ValueError(f"seeds must be a non-empty 1-d sequence of whole numbers >= 0; got {seeds!r:.80}")
    task = unwrapped.task
    _check_task_scope(task)
    steps = int(max_episode_steps)
    dt = float(task.config.control_interval)
    times = dt * np.arange(steps + 1)
    weights = task.reward_weights
    w_v, w_p, penalty = float(weights.vibration), float(weights.propellant), float(weights.failure)
    keys = (
        "thrust_coefficient",
        "dissipation_rate",
        "damping_rate",
        "axial_rate",
        "thrust_torque",
        "bias_coefficient",
        "inertia_min",
        "potential_floor",
    )
    constants: dict[str, list[float]] = {key: [] for key in keys}
    full, failure, initial, energies, gaps = [], [], [], [], []
    for seed in seed_array.tolist():
        made.reset(seed=int(seed), options=None if options is None else dict(options))
        k = _seed_constants(task)
        energy, spread, drains, exchanges = _envelope(k, times, int(substeps))
        vibration_terms = w_v * energy[1:]  # the steps' vibration costs, k = 1..N
        with_propellant, gap = _propellant_bound(k, times, drains, exchanges, w_v, w_p, iterations)
        full.append(max(float(vibration_terms.sum()), with_propellant))
        gaps.append(gap)
        # A failure at step K costs the penalty plus the steps before it plus step K's vibration
        # term, which is >= min(0, w_v E_lb(t_K)), and after a cable break >= -w_v (V_nominal +
        # q Delta(t_K)) with Delta grown over one more interval by the unbalanced bias.
        beta, q = k["thrust_beta"], k["bias_coefficient"]
        total_0 = max(k["initial_total"] - k["potential_floor"], 0.0)
        upper = (math.sqrt(total_0) + beta * times[1:] / math.sqrt(2.0)) ** 2
        start = upper + k["potential_floor"] + k["nominal_strain_energy"] + q * spread[1:]
        grown = spread[1:] + dt * np.sqrt(2.0 * np.maximum(start, 0.0)) + 0.5 * (beta + q) * dt * dt
        last = np.minimum(np.minimum(0.0, vibration_terms), -w_v * (k["nominal_strain_energy"] + q * grown))
        before = np.concatenate(([0.0], np.cumsum(vibration_terms)[:-1]))
        failure.append(penalty + float((before + last).min()))
        initial.append(k["initial_energy"])
        if return_energy:
            energies.append(energy)
        values = {
            "thrust_coefficient": math.sqrt(2.0) * beta,
            "dissipation_rate": 2.0 * k["damping_rate"] + 2.0 * k["axial_rate"],
            **{key: k[key] for key in keys[2:]},
        }
        for key in keys:
            constants[key].append(values[key])
    full_array, failure_array = np.array(full), np.array(failure)
    return CostLowerBound(
        seeds=seed_array.astype(np.int64),
        bounds=np.minimum(full_array, failure_array),
        full_episode=full_array,
        failure=failure_array,
        initial_energy=np.array(initial),
        optimisation_gap=np.array(gaps),
        times=times,
        energy=np.array(energies) if return_energy else None,
        max_episode_steps=steps,
        vibration_weight=w_v,
        failure_penalty=penalty,
        constants={key: np.array(values) for key, values in constants.items()},
    )
