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
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from tether_gym import _kernels
from tether_gym.cluster import Cluster
from tether_gym.limits import check_real

if TYPE_CHECKING:
    from tether_gym.simulator import BatchSimulator

#: The topology of a lone cable element: node 0 to node 1 (read-only, like every topology the
#: kernels get, so that they run the variant already compiled).
_ELEMENT_TOPOLOGY = np.array([[0, 1]], dtype=np.int64)
_ELEMENT_TOPOLOGY.flags.writeable = False

__all__ = [
    "axial_damping_matrix",
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
