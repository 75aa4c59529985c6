"""The cluster linearised about its nominal state, in elastic modal coordinates: the model behind
the velocity-feedback gain rule and the LQR design (:mod:`agents.controllers.centralised`).

:func:`elastic_modes` gives the mass-normalised elastic normal modes (the rigid-body motions
removed); :class:`LinearModel` projects the dynamics on them, with every cable taut or every
cable slack, continuous and sampled with the env's zero-order hold, and evaluates state-feedback
gains on it (expected vibration energy, slowest decay rate).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from tether_gym._optional import needs_extra
from tether_gym.analysis import axial_damping_matrix, frame_stiffness, gyroscopic_matrix, tangent_stiffness
from tether_gym.cluster import Cluster
from tether_gym.envs.task import DampingTask

with needs_extra("train", "the linear model of the velocity-feedback and LQR baselines"):
    import scipy.linalg

__all__ = ["LinearModel", "elastic_modes"]


def elastic_modes(cluster: Any) -> tuple[np.ndarray, np.ndarray]:
    """Elastic normal modes at the nominal state: ``(omega2, modes)``, (r,) in (rad/s)^2 and
    (3n, r) mass-normalised shapes, r = 3n - 6 (3n - 5 for a collinear cluster).

    The modes span the M-orthogonal complement of the rigid-body motions (translations and
    rotations about the centre of mass). Plain normal modes would not separate them: with
    pretension and a fixed bias thrust, rigid rotations carry a small geometric stiffness
    (about 0.03 rad/s for the default tetrahedron). Those motions are not vibration, the
    observation's vibration energy excludes them, and the controllers do not act on them.

    In a turning frame the stiffness includes the frame's centrifugal and tidal terms
    (:func:`~tether_gym.analysis.frame_stiffness`), so the frequencies are those of the
    deformation in the frame's effective potential.
    """
    positions = cluster.positions - (cluster.masses[:, None] * cluster.positions).sum(axis=0) / cluster.masses.sum()
    n = cluster.num_nodes
    rigid = np.zeros((3 * n, 6))
    for axis in range(3):
        rigid[axis::3, axis] = 1.0
        unit = np.zeros(3)
        unit[axis] = 1.0
        rigid[:, 3 + axis] = np.cross(unit, positions).ravel()
    sqrt_mass = np.sqrt(np.repeat(cluster.masses, 3))
    scaled_rigid = sqrt_mass[:, None] * rigid
    complement = scipy.linalg.null_space(scaled_rigid.T, rcond=1e-9)  # orthonormal, (3n, r)
    stiffness = (tangent_stiffness(cluster) + frame_stiffness(cluster)) / sqrt_mass[:, None] / sqrt_mass[None, :]
    reduced = complement.T @ (0.5 * (stiffness + stiffness.T)) @ complement
    omega2, vectors = np.linalg.eigh(reduced)
    return omega2, (complement @ vectors) / sqrt_mass[:, None]


class LinearModel:
    """The cluster linearised about its nominal state, in elastic modal coordinates, sampled with
    the env's zero-order hold.

    ``M q'' + (C + C_ax + G) q' + (K + K_frame) q = S F``, with ``K`` the tangent stiffness at
    nominal (every cable taut, with its pretension's geometric stiffness), ``C`` the diagonal and
    ``C_ax`` the cables' axial damping, and in a turning frame ``G`` the Coriolis (gyroscopic)
    matrix and ``K_frame`` the centrifugal and tidal stiffness, is projected on the r mass-normalised elastic
    modes ``Phi`` (``Phi^T M Phi = I``; the six rigid modes are dropped: thrust that moves the
    cluster as a rigid body does not damp anything, and the rigid modes would make the Riccati
    equation singular; see :func:`elastic_modes`). State ``z = [q, q']`` (2r), input ``F`` (3k) N. ``A, B`` are
    continuous; ``Ad, Bd`` are exact for a force held over one control interval.

    ``cables="slack"`` gives the same coordinates for the other extreme of a tension-only
    cluster, every cable slack: the cables add neither stiffness (``K = 0``) nor axial damping
    (``C_ax = 0``), and what is left is the satellites' own damping and the frame's terms,
    ``q'' + Phi^T (C + G) Phi q' + Phi^T K_frame Phi q = Phi^T S F``. The modes ``Phi`` and
    :attr:`omega2` (hence :meth:`energy_weight`, the vibration energy with taut cables) stay
    those of the taut cluster, so states and gains of the two models are interchangeable.

    Args:
        task: the env's task (its nominal cluster, thrusters and control interval).
        cables: ``"taut"`` (every cable taut, the linearisation about nominal) or ``"slack"``
            (every cable slack).
        cluster: the cluster to linearise, with ``task``'s satellites as its first nodes
            (default ``task.cluster``). With tethers that have mass the controllers pass
            :func:`agents.controllers.base.equivalent_cluster`: each tether one cable, so the
            model is that of the satellites.
    """

    def __init__(self, task: DampingTask, cables: str = "taut", cluster: Cluster | None = None) -> None:
        if cables not in ("taut", "slack"):
            raise ValueError(f"cables must be 'taut' or 'slack'; got {cables!r}")
        self.cables = cables
        cluster = task.cluster if cluster is None else cluster
        n = cluster.num_nodes
        self.omega2, self.modes = elastic_modes(cluster)
        r = self.omega2.size
        self.num_modes = r
        mass = np.repeat(cluster.masses, 3)
        cable_damping = axial_damping_matrix(cluster) if cables == "taut" else 0.0
        damping = np.diag(np.repeat(cluster.damping, 3)) + cable_damping + gyroscopic_matrix(cluster)
        selection = np.zeros((3 * n, 3 * task.thrusters.size))
        for k, node in enumerate(task.thrusters):
            selection[3 * node : 3 * node + 3, 3 * k : 3 * k + 3] = np.eye(3)
        self.modal_damping = self.modes.T @ damping @ self.modes
        self.modal_input = self.modes.T @ selection  # (r, 3k)
        if cables == "taut":
            self.modal_stiffness = np.diag(self.omega2)
        else:
            frame = frame_stiffness(cluster)
            self.modal_stiffness = self.modes.T @ frame @ self.modes
        self.A = np.block([[np.zeros((r, r)), np.eye(r)], [-self.modal_stiffness, -self.modal_damping]])
        self.B = np.vstack([np.zeros((r, selection.shape[1])), self.modal_input])
        self.interval = task.config.control_interval
        augmented = np.zeros((2 * r + self.B.shape[1],) * 2)
        augmented[: 2 * r, : 2 * r] = self.A
        augmented[: 2 * r, 2 * r :] = self.B
        exponential = scipy.linalg.expm(augmented * self.interval)
        self.Ad = exponential[: 2 * r, : 2 * r]
        self.Bd = exponential[: 2 * r, 2 * r :]
        # q = Phi^T M d projects any displacement on the elastic modes (rigid parts drop out).
        self.projection = self.modes.T * mass[None, :]  # (r, 3n)
        # The env draws independent Gaussian displacements and velocities per component.
        spread = self.projection @ self.projection.T
        config = task.config
        self.initial_covariance = scipy.linalg.block_diag(
            config.initial_displacement**2 * spread, config.initial_velocity**2 * spread
        )  # (2r, 2r)

    def modal_state(self, displacement: np.ndarray, velocity: np.ndarray) -> np.ndarray:
        """(N, 2r) modal state ``[q, q']`` from (N, n, 3) displacements (m) and velocities
        (m/s)."""
        count = displacement.shape[0]
        q = displacement.reshape(count, -1) @ self.projection.T
        dq = velocity.reshape(count, -1) @ self.projection.T
        return np.hstack([q, dq])

    def energy_weight(self) -> np.ndarray:
        """(2r, 2r) matrix of the vibration energy ``z^T W z = q^T Omega^2 q / 2 + q'^T q' / 2``,
        J."""
        return 0.5 * np.diag(np.concatenate([self.omega2, np.ones(self.num_modes)]))

    def expected_vibration_energy(self, gain: np.ndarray) -> float:
        """Expected time integral of the vibration energy, J*s, of the sampled closed loop
        ``z+ = (Ad - Bd G) z`` under ``F = -G z``, over the env's initial-state distribution:
        ``interval * trace(X Sigma_0)`` with ``X`` the solution of the discrete Lyapunov equation
        ``Acl^T X Acl - X + W = 0`` (W: :meth:`energy_weight`).  Infinite if the loop is
        unstable."""
        closed = self.Ad - self.Bd @ gain
        if np.abs(np.linalg.eigvals(closed)).max() >= 1.0:
            return math.inf
        lyapunov = scipy.linalg.solve_discrete_lyapunov(closed.T, self.energy_weight())
        return self.interval * float(np.trace(lyapunov @ self.initial_covariance))

    def slowest_decay_rate(self, gain: np.ndarray) -> float:
        """Slowest decay rate (1/s) of the sampled closed loop ``z+ = (Ad - Bd G) z`` under state
        feedback ``F = -G z``: ``-ln(max |eigenvalue|) / interval``. Negative means unstable."""
        radius = float(np.abs(np.linalg.eigvals(self.Ad - self.Bd @ gain)).max())
        return -math.log(max(radius, 1e-300)) / self.interval
