"""Compiled measurements of the damping task: rigid motion, vibration energy, observation.

Like the physics kernels they work one cluster at a time, so a cluster measured in a batch gives
the same bits as measured alone.  Shapes: ``x, v`` (B, n, 3) in m and m/s, ``masses`` (B, n) kg.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from tether_gym._kernels import PARALLEL_CHUNKS


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


#: Observations are clipped to +-this (it is reached only far beyond a lost formation).
OBSERVATION_LIMIT = 1e4

#: A step whose |reward| would exceed this (or be NaN) ends as ``numerics_diverged`` with a finite
#: reward.  No accepted setting gets near it unless the state has run away, and it keeps every
#: reward finite also in float32 (max 3.4e38), as Stable-Baselines3 stores them.
REWARD_LIMIT = 1e30


@njit(cache=True, nogil=True, error_model="numpy")
def _bounded(value: float) -> float:
    """An observation entry: NaN as 0, clipped to +-OBSERVATION_LIMIT."""
    if value != value:
        return 0.0
    return min(max(value, -OBSERVATION_LIMIT), OBSERVATION_LIMIT)


@njit(cache=True, nogil=True, error_model="numpy")
def command_forces(
    actions: np.ndarray,
    thrusters: np.ndarray,
    max_thrust: np.ndarray,
    magnitude_limit: bool,
    bias: np.ndarray,
    duration: float,
    active: np.ndarray,
    force: np.ndarray,
    thrust: np.ndarray,
    impulse: np.ndarray,
) -> None:
    """Thruster forces from normalised actions (B, 3k): each command clipped to [-1, 1] (and, with
    ``magnitude_limit``, scaled back to unit length when longer), times ``max_thrust`` (k,) N.
    Writes the thrust (B, n, 3), the total external force ``bias + thrust`` and the thrust impulse
    of the interval ``sum_j |F_j| duration`` (B,) in N*s, for active clusters only."""
    for b in range(actions.shape[0]):
        if not active[b]:
            continue
        thrust[b, :, :] = 0.0
        total = 0.0
        for k in range(thrusters.shape[0]):
            a0 = min(max(actions[b, 3 * k], -1.0), 1.0)
            a1 = min(max(actions[b, 3 * k + 1], -1.0), 1.0)
            a2 = min(max(actions[b, 3 * k + 2], -1.0), 1.0)
            norm = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
            scale = max_thrust[k]
            if magnitude_limit and norm > 1.0:
                scale /= norm
            i = thrusters[k]
            thrust[b, i, 0] = a0 * scale
            thrust[b, i, 1] = a1 * scale
            thrust[b, i, 2] = a2 * scale
            total += norm * scale
        impulse[b] = total * duration
        for i in range(force.shape[1]):
            for d in range(3):
                force[b, i, d] = bias[b, i, d] + thrust[b, i, d]


@njit(cache=True, nogil=True, error_model="numpy")
def _evaluate_clusters(
    first: int,
    stop: int,
    x: np.ndarray,
    v: np.ndarray,
    masses: np.ndarray,
    tension: np.ndarray,
    stiffness: np.ndarray,
    L0: np.ndarray,
    N0: np.ndarray,
    intact: np.ndarray,
    frame_tidal: np.ndarray,
    breaking_load: np.ndarray,
    bias: np.ndarray,
    nominal: np.ndarray,
    nominal_strain_energy: np.ndarray,
    cables: np.ndarray,
    observed: np.ndarray,
    length_scale: float,
    speed_scale: float,
    observe_tensions: bool,
    status: np.ndarray,
    peak_tension: np.ndarray,
    impulse: np.ndarray,
    deviation_limit: float,
    terminate_on_break: bool,
    weights: np.ndarray,
    observation: np.ndarray,
    scalars: np.ndarray,
    end_reason: np.ndarray,
) -> None:
    """Everything the task reads off clusters ``first..stop-1`` after a step (or a reset), one pass
    per cluster.  (The loop lives here, not in the drivers: a call per cluster with this many
    array arguments would cost as much as the work.)

    Writes the observation row (NaN as 0, clipped to +-OBSERVATION_LIMIT; see :class:`~tether_gym.envs.TetherClusterEnv`), ``end_reason``
    (0 running, 1 formation lost, 2 cable broken, 3 numerics diverged) and ``scalars[b]``:
    ``[reward, reward_vibration, reward_propellant, reward_slack, reward_failure,
    vibration_energy (J), max_deviation (m), slack_fraction, kinetic_energy (J),
    strain_energy (J), frame_potential (J)]``.  ``weights`` = ``[vibration_weight / energy_scale,
    propellant_weight / full_impulse, slack_weight, failure_penalty]``.  A cable past its
    breaking load ends the episode only with ``terminate_on_break``.  A cluster whose reward
    would pass ``REWARD_LIMIT`` (or be NaN), or whose energies would not be finite, ends as
    numerics diverged (code 3), with the vibration term (and any non-finite term) set to 0: the
    reward is always finite.

    The strain energy is the elastic part ``N_el^2 / 2k`` of the intact cables (the tension may
    hold a viscous part).  In a turning frame (``frame_tidal`` (B, 3), 1/s^2) the vibration energy
    also holds the change of the frame potential of the shape about its centre of mass,
    ``-1/2 sum_i m_i (r_i.T r_i - R_i.T R_i)`` (``r``, ``R``: current and nominal positions about
    the centre of mass), so that it measures the deformation against the frame's effective
    potential and is zero at the nominal equilibrium.
    """
    n = x.shape[1]
    m = cables.shape[0]
    scratch = np.empty((4, 3))
    motion = scratch[:3]
    nominal_com = scratch[3]
    for b in range(first, stop):
        xb, vb, mb = x[b], v[b], masses[b]
        _rigid_motion(xb, vb, mb, motion)
        total = 0.0
        nominal_com[:] = 0.0
        for i in range(n):
            total += mb[i]
            for d in range(3):
                nominal_com[d] += mb[i] * nominal[b, i, d]
        nominal_com /= total
        kinetic_deformation = 0.0
        kinetic = 0.0
        bias_potential = 0.0
        frame_potential = 0.0
        shape_potential = 0.0
        tidal = frame_tidal[b]
        worst = 0.0
        for i in range(n):
            rx = xb[i, 0] - motion[0, 0]
            ry = xb[i, 1] - motion[0, 1]
            rz = xb[i, 2] - motion[0, 2]
            if tidal[0] != 0.0 or tidal[1] != 0.0 or tidal[2] != 0.0:
                nx = nominal[b, i, 0] - nominal_com[0]
                ny = nominal[b, i, 1] - nominal_com[1]
                nz = nominal[b, i, 2] - nominal_com[2]
                shape_potential -= (
                    0.5
                    * mb[i]
                    * (tidal[0] * (rx * rx - nx * nx) + tidal[1] * (ry * ry - ny * ny) + tidal[2] * (rz * rz - nz * nz))
                )
                frame_potential -= (
                    0.5
                    * mb[i]
                    * (tidal[0] * xb[i, 0] * xb[i, 0] + tidal[1] * xb[i, 1] * xb[i, 1] + tidal[2] * xb[i, 2] * xb[i, 2])
                )
            ux = vb[i, 0] - motion[1, 0] - (motion[2, 1] * rz - motion[2, 2] * ry)
            uy = vb[i, 1] - motion[1, 1] - (motion[2, 2] * rx - motion[2, 0] * rz)
            uz = vb[i, 2] - motion[1, 2] - (motion[2, 0] * ry - motion[2, 1] * rx)
            kinetic_deformation += 0.5 * mb[i] * (ux * ux + uy * uy + uz * uz)
            kinetic += 0.5 * mb[i] * (vb[i, 0] * vb[i, 0] + vb[i, 1] * vb[i, 1] + vb[i, 2] * vb[i, 2])
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
                observation[b, 3 * k + d] = _bounded(deviation / length_scale)
                observation[b, 3 * (observed.shape[0] + k) + d] = _bounded((vb[i, d] - motion[1, d]) / speed_scale)
        strain = 0.0
        slack = 0
        broken = False
        offset = 6 * observed.shape[0]
        for c in range(m):
            i, j = cables[c, 0], cables[c, 1]
            dx = xb[j, 0] - xb[i, 0]
            dy = xb[j, 1] - xb[i, 1]
            dz = xb[j, 2] - xb[i, 2]
            elongation = math.sqrt(dx * dx + dy * dy + dz * dz) - L0[b, c]
            observation[b, offset + c] = _bounded(elongation / length_scale)
            elastic = N0[b, c] + stiffness[b, c] * elongation
            if intact[b, c] and elastic > 0.0:
                strain += 0.5 * elastic * elastic / stiffness[b, c]
            if tension[b, c] <= 0.0:
                slack += 1
            if terminate_on_break and peak_tension[b, c] > breaking_load[b, c]:
                broken = True
            if observe_tensions:
                observation[b, offset + m + c] = _bounded(tension[b, c] / breaking_load[b, c])
        vibration = kinetic_deformation + strain - nominal_strain_energy[b] + bias_potential + shape_potential
        if status[b] != 0:
            reason = 3
            vibration = 0.0
        elif broken:
            reason = 2
        elif not worst <= deviation_limit:
            reason = 1
        else:
            reason = 0
        slack_fraction = slack / m
        terms_vibration = -weights[0] * vibration
        terms_propellant = -weights[1] * impulse[b]
        terms_slack = -weights[2] * slack_fraction
        running_reward = terms_vibration + terms_propellant + terms_slack
        if not (
            abs(running_reward) <= REWARD_LIMIT
            and math.isfinite(kinetic)
            and math.isfinite(strain)
            and math.isfinite(frame_potential)
        ):
            # A state beyond the reward's arithmetic (an energy or a weighted term that overflows
            # or passes REWARD_LIMIT; NaN fails the comparison too) is a divergence: the episode
            # ends there with a finite reward, the vibration term dropped as for a frozen
            # cluster, never a NaN or -inf while it runs on.
            reason = 3
            vibration = 0.0
            terms_vibration = 0.0
            if not math.isfinite(terms_propellant):
                terms_propellant = 0.0
            if not math.isfinite(terms_slack):
                terms_slack = 0.0
        end_reason[b] = reason
        terms_failure = -weights[3] if reason > 0 else 0.0
        scalars[b, 0] = terms_vibration + terms_propellant + terms_slack + terms_failure
        scalars[b, 1] = terms_vibration
        scalars[b, 2] = terms_propellant
        scalars[b, 3] = terms_slack
        scalars[b, 4] = terms_failure
        scalars[b, 5] = vibration
        scalars[b, 6] = worst
        scalars[b, 7] = slack_fraction
        scalars[b, 8] = kinetic
        scalars[b, 9] = strain
        scalars[b, 10] = frame_potential


@njit(cache=True, nogil=True, error_model="numpy")
def evaluate_serial(
    x,
    v,
    masses,
    tension,
    stiffness,
    L0,
    N0,
    intact,
    frame_tidal,
    breaking_load,
    bias,
    nominal,
    nominal_strain_energy,
    cables,
    observed,
    length_scale,
    speed_scale,
    observe_tensions,
    status,
    peak_tension,
    impulse,
    deviation_limit,
    terminate_on_break,
    weights,
    observation,
    scalars,
    end_reason,
):  # pragma: no cover - compiled
    """:func:`_evaluate_clusters` for every cluster of the batch, one thread."""
    _evaluate_clusters(
        0,
        x.shape[0],
        x,
        v,
        masses,
        tension,
        stiffness,
        L0,
        N0,
        intact,
        frame_tidal,
        breaking_load,
        bias,
        nominal,
        nominal_strain_energy,
        cables,
        observed,
        length_scale,
        speed_scale,
        observe_tensions,
        status,
        peak_tension,
        impulse,
        deviation_limit,
        terminate_on_break,
        weights,
        observation,
        scalars,
        end_reason,
    )


@njit(cache=True, nogil=True, error_model="numpy", parallel=True)
def evaluate_parallel(
    x,
    v,
    masses,
    tension,
    stiffness,
    L0,
    N0,
    intact,
    frame_tidal,
    breaking_load,
    bias,
    nominal,
    nominal_strain_energy,
    cables,
    observed,
    length_scale,
    speed_scale,
    observe_tensions,
    status,
    peak_tension,
    impulse,
    deviation_limit,
    terminate_on_break,
    weights,
    observation,
    scalars,
    end_reason,
):  # pragma: no cover - compiled
    """:func:`_evaluate_clusters` for every cluster of the batch, on all threads (same bits)."""
    batch = x.shape[0]
    chunks = min(batch, PARALLEL_CHUNKS)
    for k in prange(chunks):
        _evaluate_clusters(
            k * batch // chunks,
            (k + 1) * batch // chunks,
            x,
            v,
            masses,
            tension,
            stiffness,
            L0,
            N0,
            intact,
            frame_tidal,
            breaking_load,
            bias,
            nominal,
            nominal_strain_energy,
            cables,
            observed,
            length_scale,
            speed_scale,
            observe_tensions,
            status,
            peak_tension,
            impulse,
            deviation_limit,
            terminate_on_break,
            weights,
            observation,
            scalars,
            end_reason,
        )
