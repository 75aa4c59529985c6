"""Compiled kernels of the physics core: the only place where the dynamics is written.

Every kernel works on one cluster at a time and is driven over a batch by a serial or a
parallel loop.  Clusters never share data inside a kernel, so a cluster integrated in a batch
follows exactly the same floating-point operations as the same cluster integrated alone
(bit-identical results, whatever the batch size or the number of threads).

Conventions (SI units throughout):

* ``x`` (n, 3) node positions in m; ``v`` (n, 3) velocities in m/s.
* ``cables`` (m, 2) node indices; per cable ``stiffness = EA / L0`` in N/m, ``L0`` in m,
  ``N0`` (pretension) in N, ``inv_split_mass_sum = 1/m_i^e + 1/m_j^e`` in 1/kg, where the node
  masses are split equally among the cables meeting at the node (so that the element masses sum to
  the assembled mass and the Irons-Treharne bound holds).
* ``f_int`` (n, 3) is the restoring force of the equation of motion ``M a + C v + f_int = p``:
  a taut cable contributes ``-N e`` at node i and ``+N e`` at node j, with ``e`` the unit vector
  from i to j.
"""

from __future__ import annotations

import math
import os

import numba
import numpy as np
from numba import njit, prange

# The OpenMP layer scheduled the batched kernels 1.5-2x faster than numba's default
# "workqueue" layer on a busy 2-core machine (N = 1024 vector env: ~0.8 M against 0.4-0.58 M
# env steps/s); results are the same bits either way.  Users keep control through numba's own
# environment variables.
if "NUMBA_THREADING_LAYER" not in os.environ and "NUMBA_THREADING_LAYER_PRIORITY" not in os.environ:
    numba.config.THREADING_LAYER_PRIORITY = ["omp", "tbb", "workqueue"]
# OpenMP threads spin while they wait for work (libgomp: 300 000 spins by default). When other
# jobs share the cores (training next to an evaluation, a benchmark next to the tests), the
# spinning threads starve each other. Measured on this 2-core machine, native vector env at
# N = 64 (and N = 1024), env steps/s:
#   spin count             quiet machine        under load (two other busy processes)
#   default (300 000)      477-523 k (1.20 M)   2.0 k
#   100 000                499 k (1.17 M)       3.0 k
#   1 000                  397 k (1.13 M)       71 k
#   passive waiting        214-263 k (0.8-1.0 M) 105 k
# 1 000 keeps most of the quiet speed and avoids the collapse under load. libgomp reads it when
# numba first loads it (at the first parallel call), so setting it here takes effect; a user's
# own OMP_WAIT_POLICY or GOMP_SPINCOUNT wins.
if "OMP_WAIT_POLICY" not in os.environ:
    os.environ.setdefault("GOMP_SPINCOUNT", "1000")

# Status codes of a cluster in a batch.
STATUS_OK = 0
STATUS_NON_FINITE = 1  # a non-finite state, or a cable of zero length
STATUS_TOO_MANY_SUBSTEPS = 2


def _make_cable_forces(viscous: bool):  # noqa: ANN202 - returns a compiled function
    """Compile :func:`cable_forces` with the Kelvin-Voigt term (``viscous=True``: the general
    kernel) or without it.  ``viscous`` is frozen into the compiled code: merely having the
    viscous term in the loop made the common, undamped case 30 % slower, even when skipped."""

    @njit(cache=True, nogil=True, error_model="numpy")
    def cable_forces(
        x: np.ndarray,
        v: np.ndarray,
        reference: np.ndarray,
        cables: np.ndarray,
        stiffness: np.ndarray,
        L0: np.ndarray,
        N0: np.ndarray,
        axial_damping: np.ndarray,
        inv_split_mass_sum: np.ndarray,
        breaking_load: np.ndarray,
        intact: np.ndarray,
        linearised: bool,
        taut_branch: bool,
        may_break: bool,
        f_int: np.ndarray,
        tension: np.ndarray,
        peak: np.ndarray,
    ) -> tuple[float, bool, float, float]:
        """Restoring forces and cable tensions of one cluster, plus its largest element frequency.

        Writes ``f_int`` (n, 3) in N and ``tension`` (m,) in N (0 for slack and broken cables), and
        raises ``peak`` (m,) to any larger tension.  A taut cable carries
        ``N = max(0, N0 + EA/L0 dL + c_ax dL')``, its stretching rate ``dL'`` taken from the
        velocities ``v`` (n, 3) m/s: in the integrator these are the half-step velocities
        ``v_{n-1/2}``, the usual explicit (lagged) treatment of a velocity-dependent internal force.
        With ``may_break``, a cable whose tension passes its ``breaking_load`` is marked broken in
        ``intact`` (m,) and carries nothing from then on.

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

        ``taut_branch=True`` drops the tension-only cut-off (``N`` may go negative): the smooth law
        that the finite-difference critical-step estimate perturbs.
        """
        f_int[:, :] = 0.0
        omega2_max = 0.0
        length_sum = 0.0
        shortest = math.inf
        viscous_power = 0.0
        released = 0.0
        for c in range(cables.shape[0]):
            if not intact[c]:
                tension[c] = 0.0
                continue
            i = cables[c, 0]
            j = cables[c, 1]
            dx = x[j, 0] - x[i, 0]
            dy = x[j, 1] - x[i, 1]
            dz = x[j, 2] - x[i, 2]
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
                    (dx - (reference[j, 0] - reference[i, 0])) * ex
                    + (dy - (reference[j, 1] - reference[i, 1])) * ey
                    + (dz - (reference[j, 2] - reference[i, 2])) * ez
                )
            else:
                elongation = length - L0[c]
            n_taut = N0[c] + stiffness[c] * elongation
            n_cable = n_taut if (n_taut > 0.0 or taut_branch) else 0.0
            damping_c = axial_damping[c]
            if viscous and damping_c > 0.0 and n_cable != 0.0:
                rate = (v[j, 0] - v[i, 0]) * ex + (v[j, 1] - v[i, 1]) * ey + (v[j, 2] - v[i, 2]) * ez
                n_cable = n_taut + damping_c * rate
                if n_cable < 0.0 and not taut_branch:
                    n_cable = 0.0
                viscous_power += (n_cable - n_taut) * rate
            geometric = n_cable * inverse_length
            k_max = stiffness[c] if stiffness[c] >= geometric else geometric
            omega2 = k_max * inv_split_mass_sum[c]
            if damping_c > 0.0:
                xi = 0.5 * damping_c * inv_split_mass_sum[c] / math.sqrt(omega2)
                factor = math.sqrt(1.0 + xi * xi) + xi
                omega2 *= factor * factor
            if omega2 > omega2_max:
                omega2_max = omega2
            if n_cable > peak[c]:
                peak[c] = n_cable
            if may_break and n_cable > breaking_load[c]:
                intact[c] = False
                elastic = n_taut if n_taut > 0.0 else 0.0
                released += 0.5 * elastic * elastic / stiffness[c]
                n_cable = 0.0
            tension[c] = n_cable
            if n_cable != 0.0:
                fx = n_cable * ex
                fy = n_cable * ey
                fz = n_cable * ez
                f_int[i, 0] -= fx
                f_int[i, 1] -= fy
                f_int[i, 2] -= fz
                f_int[j, 0] += fx
                f_int[j, 1] += fy
                f_int[j, 2] += fz
        finite = math.isfinite(length_sum) and shortest > 0.0
        return omega2_max, finite, viscous_power, released

    return cable_forces


#: The general kernel (any axial damping).
cable_forces = _make_cable_forces(True)
#: The same for clusters without axial damping: the integrator's hot path.
_cable_forces_undamped = _make_cable_forces(False)


@njit(cache=True, nogil=True, error_model="numpy")
def _largest_tidal(tidal: np.ndarray) -> float:
    """``max |T_d|`` of a frame's tidal diagonal (3,), 1/s^2: the frame's share of omega_max^2."""
    return max(abs(tidal[0]), abs(tidal[1]), abs(tidal[2]))


@njit(cache=True, nogil=True, error_model="numpy")
def _solve_gyroscopic(lhs: float, gyro: float, rx: float, ry: float) -> tuple[float, float]:
    """Solve ``lhs vx - gyro vy = rx, lhs vy + gyro vx = ry``: the in-plane part of a velocity
    update whose Coriolis term is taken at the centred velocity (a Cayley rotation, which, like
    the exact Coriolis force, does no work)."""
    det = lhs * lhs + gyro * gyro
    return (lhs * rx + gyro * ry) / det, (lhs * ry - gyro * rx) / det


@njit(cache=True, nogil=True, error_model="numpy")
def _advance_clusters(
    first: int,
    stop: int,
    active: np.ndarray,
    duration: float,
    time: np.ndarray,
    x: np.ndarray,
    v_half: np.ndarray,
    v_sync: np.ndarray,
    f_int: np.ndarray,
    tension: np.ndarray,
    h_prev: np.ndarray,
    omega2: np.ndarray,
    force: np.ndarray,
    previous_force: np.ndarray,
    masses: np.ndarray,
    damping: np.ndarray,
    cables: np.ndarray,
    stiffness: np.ndarray,
    L0: np.ndarray,
    N0: np.ndarray,
    axial_damping: np.ndarray,
    inv_split_mass_sum: np.ndarray,
    breaking_load: np.ndarray,
    intact: np.ndarray,
    frame_rate: np.ndarray,
    frame_tidal: np.ndarray,
    reference: np.ndarray,
    linearised: bool,
    safety_factor: float,
    max_step: float,
    max_substeps: int,
    work: np.ndarray,
    dissipated: np.ndarray,
    substeps: np.ndarray,
    step_min: np.ndarray,
    step_max: np.ndarray,
    status: np.ndarray,
    step_record: np.ndarray,
    peak_tension: np.ndarray,
    status_out: np.ndarray,
) -> None:
    """Integrate clusters ``first..stop-1`` over ``duration`` seconds, each with its external force
    held constant.  A cluster that is inactive or unhealthy takes no step (zero sub-steps).

    Central differences in half-step (leapfrog) form, valid for variable steps::

        h_n        = (h_{n-1/2} + h_{n+1/2}) / 2
        v_{n+1/2}  = [(M/h_n - C/2) v_{n-1/2} + p - f_int(u_n)] / (M/h_n + C/2)
        u_{n+1}    = u_n + h_{n+1/2} v_{n+1/2}

    which at constant step is the paper's three-level scheme (eqs. 7-9).  ``h_prev[b] == 0`` marks
    a fresh state (just reset): ``v_half`` then holds the initial velocity and the first interval
    assumes uniformly accelerated motion, ``v_{1/2} = v_0 + h/2 a_0`` (paper, section 2).

    In a turning frame (``frame_rate[b] = Omega`` about z, tidal diagonal ``frame_tidal[b]``,
    1/s^2) the force gains ``M diag(T) u_n`` and the Coriolis force ``-2 M Omega x v``, which is
    taken at the centred velocity ``(v_{n-1/2} + v_{n+1/2}) / 2`` like the diagonal damping: the
    update stays explicit (a 2x2 solve per satellite), unconditionally stable in the Coriolis
    term and free of spurious Coriolis work.

    The force is piecewise constant and switches at the start of the interval.  The first velocity
    update spans ``[t_n - h_{n-1/2}/2, t_n + h_{n+1/2}/2]``, half under the previous interval's force
    ``previous_force`` and half under the new one, so it uses their time-weighted mean: the impulse
    of every force switch is then exact, instead of half a sub-step early.

    Each sub-step is ``min(safety_factor * 2 / omega_est, safety_factor * 2 min(m/c), max_step)``,
    re-estimated at every configuration, then shortened so that the rest of the interval splits into equal steps; the
    interval ends exactly at ``duration``.  A cluster whose remaining sub-steps at the current step
    size would exceed ``max_substeps`` is flagged ``STATUS_TOO_MANY_SUBSTEPS`` without taking
    them.  ``omega_est^2`` is the largest element value of
    :func:`cable_forces` plus ``max |T|``.  Cables whose tension passes their breaking load break
    (``intact``) and the cluster goes on without them.  ``peak_tension[b]`` receives each cable's
    largest tension over the interval, N.  ``status_out[b]`` receives the cluster's status, and a
    cluster that stays healthy has ``duration`` added to its ``time[b]``.

    The loop over clusters lives inside this function (the drivers hand it a range) because a
    call per cluster with this many array arguments cost more than the whole sub-stepping of a
    short interval.
    """
    for b in range(first, stop):
        if not (active[b] and status[b] == STATUS_OK):
            substeps[b] = 0
            step_min[b] = math.inf
            step_max[b] = 0.0
            peak_tension[b, :] = tension[b, :]
            status_out[b] = status[b]
            continue
        n_nodes = x.shape[1]
        xb = x[b]
        vb = v_half[b]
        fb = f_int[b]
        pb = force[b]
        mb = masses[b]
        cb = damping[b]
        wb = frame_rate[b]
        tb = frame_tidal[b]
        tidal_max = _largest_tidal(tb)
        turning = wb != 0.0 or tidal_max != 0.0
        viscous = False
        for c in range(axial_damping.shape[1]):
            viscous = viscous or axial_damping[b, c] > 0.0
        n_record = step_record.shape[1]
        elapsed = 0.0
        count = 0
        h_lo = math.inf
        h_hi = 0.0
        work_b = work[b]
        dissipated_b = dissipated[b]
        h_last = h_prev[b]
        peak = peak_tension[b]
        tension_b = tension[b]
        for c in range(tension_b.shape[0]):
            peak[c] = tension_b[c]
        # The centred damping update scales v by (m/h - c/2) / (m/h + c/2): stable for any h, but
        # past h = 2 m/c it reverses the velocity, which free damped motion never does.  So the
        # step also respects the damping time scale, with the same safety factor; it binds only
        # where no cable limits the step more (all cables broken, or very heavy damping).
        h_damping = math.inf
        for i in range(n_nodes):
            if cb[i] > 0.0 and 2.0 * mb[i] / cb[i] < h_damping:
                h_damping = 2.0 * mb[i] / cb[i]
        h_damping *= safety_factor
        while True:
            h_stable = safety_factor * 2.0 / math.sqrt(omega2[b]) if omega2[b] > 0.0 else math.inf
            if h_stable > h_damping:
                h_stable = h_damping
            if h_stable > max_step:
                h_stable = max_step
            remaining = duration - elapsed
            # The step count is compared as a float before it becomes an integer: a duration
            # far beyond the budget would overflow the integer, and the cluster is flagged
            # before it takes steps it could not finish.
            steps_wanted = remaining / h_stable - 1e-9
            if count >= max_substeps or steps_wanted > max_substeps - count:
                status[b] = STATUS_TOO_MANY_SUBSTEPS
                break
            # Spread what remains evenly over the fewest steps no longer than h_stable: equal steps
            # within an interval, and no sliver step before its end.
            steps_left = math.ceil(steps_wanted)
            if steps_left <= 1:
                h = remaining
                last = True
            else:
                h = remaining / steps_left
                last = False
            if h_last == 0.0:
                for i in range(n_nodes):
                    ax = (pb[i, 0] - fb[i, 0] - cb[i] * vb[i, 0] + mb[i] * tb[0] * xb[i, 0]) / mb[i] + 2.0 * wb * vb[
                        i, 1
                    ]
                    ay = (pb[i, 1] - fb[i, 1] - cb[i] * vb[i, 1] + mb[i] * tb[1] * xb[i, 1]) / mb[i] - 2.0 * wb * vb[
                        i, 0
                    ]
                    az = (pb[i, 2] - fb[i, 2] - cb[i] * vb[i, 2] + mb[i] * tb[2] * xb[i, 2]) / mb[i]
                    vb[i, 0] = vb[i, 0] + 0.5 * h * ax
                    vb[i, 1] = vb[i, 1] + 0.5 * h * ay
                    vb[i, 2] = vb[i, 2] + 0.5 * h * az
            else:
                h_mid = 0.5 * (h_last + h)
                blend = h_last / (h_last + h) if count == 0 else 0.0
                inverse_h_mid = 1.0 / h_mid
                if not turning:
                    # The inertial frame, kept free of the frame terms: it is the hot loop.
                    for i in range(n_nodes):
                        inertia = mb[i] * inverse_h_mid
                        inverse_lhs = 1.0 / (inertia + 0.5 * cb[i])
                        rhs_factor = inertia - 0.5 * cb[i]
                        for d in range(3):
                            p_dual = pb[i, d] + blend * (previous_force[b, i, d] - pb[i, d])
                            vb[i, d] = (rhs_factor * vb[i, d] + p_dual - fb[i, d]) * inverse_lhs
                else:
                    for i in range(n_nodes):
                        inertia = mb[i] * inverse_h_mid
                        lhs = inertia + 0.5 * cb[i]
                        rhs_factor = inertia - 0.5 * cb[i]
                        gyro = mb[i] * wb
                        r0 = rhs_factor * vb[i, 0] + gyro * vb[i, 1]
                        r1 = rhs_factor * vb[i, 1] - gyro * vb[i, 0]
                        r2 = rhs_factor * vb[i, 2]
                        r0 += (
                            pb[i, 0]
                            + blend * (previous_force[b, i, 0] - pb[i, 0])
                            - fb[i, 0]
                            + mb[i] * tb[0] * xb[i, 0]
                        )
                        r1 += (
                            pb[i, 1]
                            + blend * (previous_force[b, i, 1] - pb[i, 1])
                            - fb[i, 1]
                            + mb[i] * tb[1] * xb[i, 1]
                        )
                        r2 += (
                            pb[i, 2]
                            + blend * (previous_force[b, i, 2] - pb[i, 2])
                            - fb[i, 2]
                            + mb[i] * tb[2] * xb[i, 2]
                        )
                        vb[i, 0], vb[i, 1] = _solve_gyroscopic(lhs, gyro, r0, r1)
                        vb[i, 2] = r2 / lhs
            for i in range(n_nodes):
                speed2 = 0.0
                for d in range(3):
                    dx = h * vb[i, d]
                    work_b += pb[i, d] * dx
                    speed2 += vb[i, d] * vb[i, d]
                    xb[i, d] += dx
                dissipated_b += h * cb[i] * speed2
            if count < n_record:
                step_record[b, count] = h
            count += 1
            h_last = h
            if h < h_lo:
                h_lo = h
            if h > h_hi:
                h_hi = h
            if viscous:
                omega2_cables, finite, viscous_power, released = cable_forces(
                    xb,
                    vb,
                    reference[b],
                    cables,
                    stiffness[b],
                    L0[b],
                    N0[b],
                    axial_damping[b],
                    inv_split_mass_sum[b],
                    breaking_load[b],
                    intact[b],
                    linearised,
                    False,
                    True,
                    fb,
                    tension_b,
                    peak,
                )
            else:
                omega2_cables, finite, viscous_power, released = _cable_forces_undamped(
                    xb,
                    vb,
                    reference[b],
                    cables,
                    stiffness[b],
                    L0[b],
                    N0[b],
                    axial_damping[b],
                    inv_split_mass_sum[b],
                    breaking_load[b],
                    intact[b],
                    linearised,
                    False,
                    True,
                    fb,
                    tension_b,
                    peak,
                )
            omega2[b] = omega2_cables + tidal_max
            dissipated_b += h * viscous_power + released
            if not finite:
                status[b] = STATUS_NON_FINITE
                break
            if last:
                break
            elapsed += h
        h_prev[b] = h_last
        work[b] = work_b
        dissipated[b] = dissipated_b
        substeps[b] = count
        step_min[b] = h_lo
        step_max[b] = h_hi
        if count == 0:  # refused before its first step: the state is left exactly as it was
            status_out[b] = status[b]
            continue
        previous_force[b, :, :] = pb
        # Velocity at the end of the interval, consistent with the force just applied:
        # (M + h/2 C) v_n + h M Omega x v_n = M v_{n-1/2} + h/2 (p - f_int(u_n) + M T u_n).
        half = 0.5 * h_last
        for i in range(n_nodes):
            denominator = mb[i] + half * cb[i]
            r0 = mb[i] * vb[i, 0] + half * (pb[i, 0] - fb[i, 0] + mb[i] * tb[0] * xb[i, 0])
            r1 = mb[i] * vb[i, 1] + half * (pb[i, 1] - fb[i, 1] + mb[i] * tb[1] * xb[i, 1])
            r2 = mb[i] * vb[i, 2] + half * (pb[i, 2] - fb[i, 2] + mb[i] * tb[2] * xb[i, 2])
            if wb == 0.0:
                v_sync[b, i, 0] = r0 / denominator
                v_sync[b, i, 1] = r1 / denominator
            else:
                v_sync[b, i, 0], v_sync[b, i, 1] = _solve_gyroscopic(denominator, h_last * mb[i] * wb, r0, r1)
            v_sync[b, i, 2] = r2 / denominator
        if status[b] == STATUS_OK:
            time[b] += duration
        status_out[b] = status[b]


#: Chunks the parallel driver splits a batch into: enough to even out clusters that sub-step more
#: over any likely number of threads, few enough that the per-chunk call costs nothing.
PARALLEL_CHUNKS = 64


@njit(cache=True, nogil=True, error_model="numpy")
def advance_serial(
    active,
    duration,
    time,
    x,
    v_half,
    v_sync,
    f_int,
    tension,
    h_prev,
    omega2,
    force,
    previous_force,
    masses,
    damping,
    cables,
    stiffness,
    L0,
    N0,
    axial_damping,
    inv_split_mass_sum,
    breaking_load,
    intact,
    frame_rate,
    frame_tidal,
    reference,
    linearised,
    safety_factor,
    max_step,
    max_substeps,
    work,
    dissipated,
    substeps,
    step_min,
    step_max,
    status,
    step_record,
    peak_tension,
    status_out,
):  # pragma: no cover - compiled
    _advance_clusters(
        0,
        x.shape[0],
        active,
        duration,
        time,
        x,
        v_half,
        v_sync,
        f_int,
        tension,
        h_prev,
        omega2,
        force,
        previous_force,
        masses,
        damping,
        cables,
        stiffness,
        L0,
        N0,
        axial_damping,
        inv_split_mass_sum,
        breaking_load,
        intact,
        frame_rate,
        frame_tidal,
        reference,
        linearised,
        safety_factor,
        max_step,
        max_substeps,
        work,
        dissipated,
        substeps,
        step_min,
        step_max,
        status,
        step_record,
        peak_tension,
        status_out,
    )


@njit(cache=True, nogil=True, error_model="numpy", parallel=True)
def advance_parallel(
    active,
    duration,
    time,
    x,
    v_half,
    v_sync,
    f_int,
    tension,
    h_prev,
    omega2,
    force,
    previous_force,
    masses,
    damping,
    cables,
    stiffness,
    L0,
    N0,
    axial_damping,
    inv_split_mass_sum,
    breaking_load,
    intact,
    frame_rate,
    frame_tidal,
    reference,
    linearised,
    safety_factor,
    max_step,
    max_substeps,
    work,
    dissipated,
    substeps,
    step_min,
    step_max,
    status,
    step_record,
    peak_tension,
    status_out,
):  # pragma: no cover - compiled
    batch = x.shape[0]
    chunks = min(batch, PARALLEL_CHUNKS)
    for k in prange(chunks):
        _advance_clusters(
            k * batch // chunks,
            (k + 1) * batch // chunks,
            active,
            duration,
            time,
            x,
            v_half,
            v_sync,
            f_int,
            tension,
            h_prev,
            omega2,
            force,
            previous_force,
            masses,
            damping,
            cables,
            stiffness,
            L0,
            N0,
            axial_damping,
            inv_split_mass_sum,
            breaking_load,
            intact,
            frame_rate,
            frame_tidal,
            reference,
            linearised,
            safety_factor,
            max_step,
            max_substeps,
            work,
            dissipated,
            substeps,
            step_min,
            step_max,
            status,
            step_record,
            peak_tension,
            status_out,
        )


@njit(cache=True, nogil=True, error_model="numpy")
def evaluate_batch(
    x: np.ndarray,
    v: np.ndarray,
    reference: np.ndarray,
    cables: np.ndarray,
    stiffness: np.ndarray,
    L0: np.ndarray,
    N0: np.ndarray,
    axial_damping: np.ndarray,
    inv_split_mass_sum: np.ndarray,
    intact: np.ndarray,
    frame_tidal: np.ndarray,
    linearised: bool,
    taut_branch: bool,
    f_int: np.ndarray,
    tension: np.ndarray,
    omega2: np.ndarray,
    finite: np.ndarray,
) -> None:
    """``cable_forces`` for every cluster of a batch, without breaking any cable: fills f_int
    (B, n, 3), tension (B, m), omega2 (B,) (the step-limiting value, tidal term included) and
    finite (B,)."""
    peak = np.empty(cables.shape[0])
    for b in range(x.shape[0]):
        # may_break=False: the breaking-load argument is never read, any (m,) array will do.
        omega2_cables, finite[b], _, _ = cable_forces(
            x[b],
            v[b],
            reference[b],
            cables,
            stiffness[b],
            L0[b],
            N0[b],
            axial_damping[b],
            inv_split_mass_sum[b],
            stiffness[b],
            intact[b],
            linearised,
            taut_branch,
            False,
            f_int[b],
            tension[b],
            peak,
        )
        omega2[b] = omega2_cables + _largest_tidal(frame_tidal[b])
