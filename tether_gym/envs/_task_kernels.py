"""Compiled measurements of the damping task: rigid motion, vibration energy, observation.

Like the physics kernels they work one cluster at a time, so a cluster measured in a batch gives
the same bits as measured alone.  Shapes: ``x, v`` (B, n, 3) in m and m/s, ``masses`` (B, n) kg.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, error_model="numpy")
def _rigid_motion(x: np.ndarray, v: np.ndarray, masses: np.ndarray, out: np.ndarray) -> None:
    """Centre of mass, its velocity and the rigid angular velocity of one cluster, into ``out``
    (3, 3) rows: com (m), v_com (m/s), omega (rad/s), with ``I omega = angular momentum``."""
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
    inertia = np.zeros((3, 3))
    momentum = np.zeros(3)
    r2_total = 0.0
    for i in range(n):
        rx, ry, rz = x[i, 0] - out[0, 0], x[i, 1] - out[0, 1], x[i, 2] - out[0, 2]
        ux, uy, uz = v[i, 0] - out[1, 0], v[i, 1] - out[1, 1], v[i, 2] - out[1, 2]
        m = masses[i]
        momentum[0] += m * (ry * uz - rz * uy)
        momentum[1] += m * (rz * ux - rx * uz)
        momentum[2] += m * (rx * uy - ry * ux)
        r2 = rx * rx + ry * ry + rz * rz
        r2_total += m * r2
        inertia[0, 0] += m * (r2 - rx * rx)
        inertia[1, 1] += m * (r2 - ry * ry)
        inertia[2, 2] += m * (r2 - rz * rz)
        inertia[0, 1] -= m * rx * ry
        inertia[0, 2] -= m * rx * rz
        inertia[1, 2] -= m * ry * rz
    # A collinear cluster has no inertia about its axis; the small regularisation keeps the solve
    # defined and leaves the other axes untouched.
    for d in range(3):
        inertia[d, d] += 1e-9 * r2_total
    inertia[1, 0] = inertia[0, 1]
    inertia[2, 0] = inertia[0, 2]
    inertia[2, 1] = inertia[1, 2]
    a, b, c = inertia[0, 0], inertia[0, 1], inertia[0, 2]
    e, f, i_ = inertia[1, 1], inertia[1, 2], inertia[2, 2]
    c00 = e * i_ - f * f
    c01 = c * f - b * i_
    c02 = b * f - c * e
    c11 = a * i_ - c * c
    c12 = b * c - a * f
    c22 = a * e - b * b
    det = a * c00 + b * c01 + c * c02
    if det > 0.0:
        out[2, 0] = (c00 * momentum[0] + c01 * momentum[1] + c02 * momentum[2]) / det
        out[2, 1] = (c01 * momentum[0] + c11 * momentum[1] + c12 * momentum[2]) / det
        out[2, 2] = (c02 * momentum[0] + c12 * momentum[1] + c22 * momentum[2]) / det
    else:
        out[2, :] = 0.0


@njit(cache=True, nogil=True, error_model="numpy")
def remove_rigid_velocity(x: np.ndarray, v: np.ndarray, masses: np.ndarray) -> None:
    """Subtract from ``v`` (in place) each cluster's rigid translation and rotation."""
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


@njit(cache=True, nogil=True, error_model="numpy")
def measure(
    x: np.ndarray,
    v: np.ndarray,
    masses: np.ndarray,
    tension: np.ndarray,
    stiffness: np.ndarray,
    L0: np.ndarray,
    tension_scale: np.ndarray,
    bias: np.ndarray,
    nominal: np.ndarray,
    nominal_strain_energy: np.ndarray,
    cables: np.ndarray,
    observed: np.ndarray,
    length_scale: float,
    speed_scale: float,
    observe_tensions: bool,
    observation: np.ndarray,
    vibration_energy: np.ndarray,
    max_deviation: np.ndarray,
    slack_fraction: np.ndarray,
) -> None:
    """Per cluster: the observation row, vibration energy (J), largest deviation from the
    nominal place in the cluster frame (m) and the fraction of slack cables.  See :class:`~tether_gym.envs.TetherClusterEnv` for the
    observation layout and the vibration-energy definition."""
    n = x.shape[1]
    m = cables.shape[0]
    motion = np.empty((3, 3))
    nominal_com = np.empty(3)
    for b in range(x.shape[0]):
        xb, vb, mb = x[b], v[b], masses[b]
        _rigid_motion(xb, vb, mb, motion)
        total = 0.0
        nominal_com[:] = 0.0
        for i in range(n):
            total += mb[i]
            for d in range(3):
                nominal_com[d] += mb[i] * nominal[b, i, d]
        nominal_com /= total
        kinetic = 0.0
        bias_potential = 0.0
        worst = 0.0
        for i in range(n):
            rx = xb[i, 0] - motion[0, 0]
            ry = xb[i, 1] - motion[0, 1]
            rz = xb[i, 2] - motion[0, 2]
            ux = vb[i, 0] - motion[1, 0] - (motion[2, 1] * rz - motion[2, 2] * ry)
            uy = vb[i, 1] - motion[1, 1] - (motion[2, 2] * rx - motion[2, 0] * rz)
            uz = vb[i, 2] - motion[1, 2] - (motion[2, 0] * ry - motion[2, 1] * rx)
            kinetic += 0.5 * mb[i] * (ux * ux + uy * uy + uz * uz)
            deviation2 = 0.0
            for d in range(3):
                bias_potential -= bias[b, i, d] * (xb[i, d] - nominal[b, i, d])
                deviation = (xb[i, d] - motion[0, d]) - (nominal[b, i, d] - nominal_com[d])
                deviation2 += deviation * deviation
            deviation_norm = math.sqrt(deviation2)
            if deviation_norm > worst or not math.isfinite(deviation_norm):
                worst = deviation_norm
        for k in range(observed.shape[0]):
            i = observed[k]
            for d in range(3):
                deviation = (xb[i, d] - motion[0, d]) - (nominal[b, i, d] - nominal_com[d])
                observation[b, 3 * k + d] = deviation / length_scale
                observation[b, 3 * (observed.shape[0] + k) + d] = (vb[i, d] - motion[1, d]) / speed_scale
        strain = 0.0
        slack = 0
        offset = 6 * observed.shape[0]
        for c in range(m):
            i, j = cables[c, 0], cables[c, 1]
            dx = xb[j, 0] - xb[i, 0]
            dy = xb[j, 1] - xb[i, 1]
            dz = xb[j, 2] - xb[i, 2]
            observation[b, offset + c] = (math.sqrt(dx * dx + dy * dy + dz * dz) - L0[b, c]) / length_scale
            strain += 0.5 * tension[b, c] * tension[b, c] / stiffness[b, c]
            if tension[b, c] <= 0.0:
                slack += 1
            if observe_tensions:
                observation[b, offset + m + c] = tension[b, c] / tension_scale[b, c]
        vibration_energy[b] = kinetic + strain - nominal_strain_energy[b] + bias_potential
        max_deviation[b] = worst
        slack_fraction[b] = slack / m
