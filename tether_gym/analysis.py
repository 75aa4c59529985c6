"""Linear analysis of a cluster: assembled tangent stiffness and normal modes.

The integrator never assembles a stiffness matrix.  These functions do, for what needs one:
verifying the critical-step estimate against the true largest frequency, and designing linear
controllers (LQR) about a nominal state.  They use the exact elongation ``|x_j - x_i| - L0``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from tether_gym.cluster import Cluster

__all__ = ["max_frequency", "normal_modes", "tangent_stiffness"]


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
