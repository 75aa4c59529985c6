"""Linear analysis of a cluster: assembled tangent stiffness and normal modes.

The integrator never assembles a stiffness matrix.  These functions do, for what needs one:
verifying the critical-step estimate against the true largest frequency, and designing linear
controllers (LQR) about a nominal state.  They use the exact elongation ``|x_j - x_i| - L0``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from tether_gym.cluster import Cluster

__all__ = [
    "axial_damping_matrix",
    "frame_stiffness",
    "gyroscopic_matrix",
    "max_frequency",
    "normal_modes",
    "tangent_stiffness",
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
