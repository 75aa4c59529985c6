"""A prototype: the axial direction of a beaded line treated implicitly, against the explicit integrator.

What it is
----------
The explicit central-difference step of a beaded line is bound by its axial waves: a segment's
wave-crossing time ``L / (N c_axial)``, ``c_axial = sqrt(EA / mu)``.  Transverse waves alone
would allow a step ``sqrt(EA / T)`` larger (about 89x for the probe's line).  This prototype
keeps the transverse part explicit and treats each segment's axial force implicitly (an IMEX
scheme), to see whether the step can be lifted towards the transverse limit while staying accurate.

**The scheme.**  The explicit kick is ``M (v_{n+1/2} - v_{n-1/2}) = h_mid (p - G^T N(x_n))``, with
``G`` the segments' elongation rates (row e: ``e_e^T`` at its far node, ``-e_e^T`` at its near one).
The IMEX kick replaces each segment's tension by an implicit one, linearised about the segment's
current direction ``e_e`` (frozen over the step):

    y_e = max(0, N_taut,e(x_n) + k_e h (c1 G_e v_{n-1/2} + c2 G_e dv)),   M dv = h_mid (p - G^T y)

with ``k_e = EA / L0`` per segment.  ``c1 = 0, c2 = 1/4`` is Newmark's average acceleration
(trapezoidal) in the axial direction: unconditionally stable and free of numerical damping for the
linear axial part, with period elongation ``Omega h = 2 atan(omega h / 2)``.  ``c1 = c2 = 1`` is the
tension at the end of the step (implicit Euler in the axial force): stable and strongly damping.
``c2 = 0`` is the explicit scheme itself (``y = max(0, N_taut)``), written here in the same code
as a control.  Eliminating ``dv`` leaves, for the taut (active) segments, a scalar tridiagonal
system along the line in the tensions (``1/(c2 k_e h h_mid) + 1/m_i + 1/m_j`` on the diagonal,
``-(e_e . e_{e+1}) / m_shared`` off it): symmetric, positive definite and diagonally dominant, so
the Thomas algorithm solves it in O(N).  **The tension-only switch** makes the step a linear
complementarity problem (``y >= 0``, the predicted tension ``<= 0`` where ``y = 0``); it is solved by
a primal-dual active-set iteration (a segment is taut where its predicted tension is positive),
with projected Gauss-Seidel as a fallback, so that a segment that snaps taut within the step is
treated implicitly in that very step.  The step is chosen as the explicit integrator chooses its
own (evenly within each interval), from the transverse (geometric) frequency
``(N_e / l_e)(1/m_i^e + 1/m_j^e)`` at the current tensions, capped at ``lift`` times the explicit
critical step of the taut line.

What it measures
----------------
The issue's probe line (L = 100 m, two free 50 kg satellites, a 2 kg tether, EA = 40 kN, T = 5 N,
"half" lumping) in N segments, integrated by the project's ``Simulator`` (explicit, safety
factors 0.1 and 0.3), by this prototype's explicit control, and by the IMEX scheme at step lifts
``h / h_crit`` (``h_crit = L / (N c_axial)``, the explicit critical step):

1. modes: the frequency of transverse modes 1-3 and of the first axial mode, excited alone (the
   discrete mode shape, small amplitude, pretension held at the satellites) and measured from the
   samples (``cos(Omega dt) = sum q_n (q_{n+1} + q_{n-1}) / (2 sum q_n^2)``, exact for a sampled
   sinusoid), as relative errors against the closed forms of the line between two end masses;
2. energy: the books' residual over 100 periods of transverse mode 1, relative to its vibration
   energy; and the axial mode's amplitude after 100 of its periods (numerical damping);
3. snaps: the straight and the sagging slack starts of ``benchmarks/tether_snaps.py`` (no noise, no
   damping), against scipy's DOP853 (rtol 1e-10) on the same bead equations: the first snap's peak
   tension, positions after 1 s and 2 s, the worst relative energy residual, sub-steps per second,
   and the active-set iterations;
4. cost: wall time per simulated second of the taut line vibrating in mode 1, 0.1 s intervals,
   one cluster (``--cost`` only; take it on a quiet machine).

Usage::

    python benchmarks/implicit_axial.py            # modes, energy and snaps: a few minutes on two shared cores
    python benchmarks/implicit_axial.py --cost     # the cost table only
    python benchmarks/implicit_axial.py --quick    # N = 8, a few lifts, short runs
"""

from __future__ import annotations

import argparse
import math
import platform
import subprocess
import time
import warnings
from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.integrate import solve_ivp
from scipy.linalg import eigh
from scipy.optimize import brentq

import tether_gym as tg
from tether_gym.simulator import UnstableSafetyFactorWarning
from tether_gym.tethers import Tether, build_cluster

LENGTH, SAT_MASS, LINE_MASS, EA, TENSION = 100.0, 50.0, 2.0, 40e3, 5.0
MU = LINE_MASS / LENGTH  # kg/m
TRANSVERSE_SPEED = math.sqrt(TENSION / MU)  # m/s
AXIAL_SPEED = math.sqrt(EA / MU)  # m/s
SPEED = 0.5  # m/s, each satellite's speed away from the other in the snaps
SAG, SAG_CHORD = 8.9, 98.0  # m: the sagging start's sine arc and chord (benchmarks/tether_snaps.py)
SNAP_INTERVAL = 0.01  # s, the snaps' sampling interval
FIRST_SNAP = 2.0  # s
COST_INTERVAL = 0.1  # s, the environments' control interval
MAX_ACTIVE_SET_ITERATIONS = 50
GAUSS_SEIDEL_SWEEPS = 500

#: (name, c1, c2) of the axial treatments
SCHEMES = {"explicit": (0.0, 0.0), "newmark": (0.0, 0.25), "euler": (1.0, 1.0)}


# ---------------------------------------------------------------------------------- the prototype
@njit(cache=True)
def _segments(x: np.ndarray, k: np.ndarray, L0: np.ndarray, N0: np.ndarray, e: np.ndarray, length: np.ndarray) -> None:
    """Unit directions ``e`` (N, 3) and lengths ``length`` (N,) of the segments of a chain ``x``
    ((N + 1, 3) m, nodes in order along the line); returns nothing, fills its outputs."""
    for s in range(k.shape[0]):
        dx = x[s + 1, 0] - x[s, 0]
        dy = x[s + 1, 1] - x[s, 1]
        dz = x[s + 1, 2] - x[s, 2]
        ls = math.sqrt(dx * dx + dy * dy + dz * dz)
        length[s] = ls
        e[s, 0], e[s, 1], e[s, 2] = dx / ls, dy / ls, dz / ls


@njit(cache=True)
def _thomas(main: np.ndarray, lower: np.ndarray, upper: np.ndarray, rhs: np.ndarray, y: np.ndarray) -> None:
    """Solve the tridiagonal system (``lower``, ``main``, ``upper``) y = ``rhs`` in place of ``y``;
    diagonally dominant, so without pivoting (``main`` and ``rhs`` are overwritten)."""
    N = main.shape[0]
    for s in range(1, N):
        w = lower[s] / main[s - 1]
        main[s] -= w * upper[s - 1]
        rhs[s] -= w * rhs[s - 1]
    y[N - 1] = rhs[N - 1] / main[N - 1]
    for s in range(N - 2, -1, -1):
        y[s] = (rhs[s] - upper[s] * y[s + 1]) / main[s]


@njit(cache=True)
def _coupling(b: np.ndarray, off: np.ndarray, y: np.ndarray, s: int) -> float:
    """``b_s`` plus the pull of segment s's neighbours' tensions on its elongation rate, 1/kg * N."""
    value = b[s]
    if s > 0:
        value += off[s - 1] * y[s - 1]
    if s + 1 < b.shape[0]:
        value += off[s] * y[s + 1]
    return value


@njit(cache=True)
def _complementarity(
    r: np.ndarray,
    scale: np.ndarray,
    b: np.ndarray,
    diag: np.ndarray,
    off: np.ndarray,
    y: np.ndarray,
    work: np.ndarray,
    active: np.ndarray,
) -> tuple[int, bool]:
    """The tensions ``y`` (N,) N with ``y = max(0, r + scale (b - diag y + off y_neighbours))``:
    a primal-dual active-set iteration (a tridiagonal solve on the taut segments each), and
    projected Gauss-Seidel from its last iterate if it has not settled in
    ``MAX_ACTIVE_SET_ITERATIONS``.  Scratch: ``work`` (4, N) float, ``active`` (N,) bool.
    Returns ``(iterations, settled)``."""
    N = r.shape[0]
    for s in range(N):
        active[s] = r[s] > 0.0
    main, lower, upper, rhs = work[0], work[1], work[2], work[3]
    iterations = 0
    while iterations < MAX_ACTIVE_SET_ITERATIONS:
        iterations += 1
        for s in range(N):
            if active[s]:
                main[s] = 1.0 / scale[s] + diag[s]
                lower[s] = -off[s - 1] if s > 0 else 0.0
                upper[s] = -off[s] if s + 1 < N else 0.0
                rhs[s] = r[s] / scale[s] + b[s]
            else:
                main[s], lower[s], upper[s], rhs[s] = 1.0, 0.0, 0.0, 0.0
        _thomas(main, lower, upper, rhs, y)
        changed = False
        for s in range(N):
            predicted = r[s] + scale[s] * (_coupling(b, off, y, s) - diag[s] * y[s])
            taut = y[s] > 0.0 if active[s] else predicted > 0.0
            if taut != active[s]:
                active[s] = taut
                changed = True
        if not changed:
            return iterations, True
    for s in range(N):
        y[s] = max(y[s], 0.0)
    for _ in range(GAUSS_SEIDEL_SWEEPS):
        for s in range(N):
            value = (r[s] / scale[s] + _coupling(b, off, y, s)) / (1.0 / scale[s] + diag[s])
            y[s] = value if value > 0.0 else 0.0
    return iterations, False


#: Rows of the kick's workspace (WORK_ROWS, N): the segments' lengths, taut-branch tensions, and
#: the complementarity problem's terms, then the tridiagonal solve's four rows.
LENGTH_ROW, TAUT_ROW, R_ROW, SCALE_ROW, B_ROW, DIAG_ROW, OFF_ROW, SOLVE_ROW = 0, 1, 2, 3, 4, 5, 6, 7
WORK_ROWS = SOLVE_ROW + 4


@njit(cache=True)
def _kick_core(
    v: np.ndarray,
    inv_m: np.ndarray,
    k: np.ndarray,
    p: np.ndarray,
    h_mid: float,
    h: float,
    c1: float,
    c2: float,
    dv: np.ndarray,
    y: np.ndarray,
    e: np.ndarray,
    work: np.ndarray,
    active: np.ndarray,
) -> tuple[int, bool]:
    """:func:`_kick` on the segments' directions ``e`` (N, 3) and the workspace ``work``
    (WORK_ROWS, N), whose LENGTH_ROW and TAUT_ROW hold the lengths (m) and taut-branch tensions
    (N) at ``x``; ``active`` (N,) bool is scratch.  Returns ``(iterations, converged)``."""
    N = k.shape[0]
    n = N + 1
    a = work[TAUT_ROW]
    iterations, converged = 0, True
    if c2 == 0.0:
        for s in range(N):
            y[s] = a[s] if a[s] > 0.0 else 0.0
    else:
        r, scale, b, diag, off = work[R_ROW], work[SCALE_ROW], work[B_ROW], work[DIAG_ROW], work[OFF_ROW]
        for s in range(N):
            rate = 0.0
            accel = 0.0
            for d in range(3):
                rate += e[s, d] * (v[s + 1, d] - v[s, d])
                accel += e[s, d] * (p[s + 1, d] * inv_m[s + 1] - p[s, d] * inv_m[s])
            r[s] = a[s] + c1 * k[s] * h * rate
            scale[s] = c2 * k[s] * h * h_mid  # the implicit coefficient
            b[s] = accel
            diag[s] = inv_m[s] + inv_m[s + 1]
            # off[s]: the coupling of segments s and s + 1 through their shared node
            off[s] = (
                (e[s, 0] * e[s + 1, 0] + e[s, 1] * e[s + 1, 1] + e[s, 2] * e[s + 1, 2]) * inv_m[s + 1]
                if s + 1 < N
                else 0.0
            )
        iterations, converged = _complementarity(r, scale, b, diag, off, y, work[SOLVE_ROW:], active)
    for i in range(n):
        for d in range(3):
            force = p[i, d]
            if i < N:
                force += y[i] * e[i, d]
            if i > 0:
                force -= y[i - 1] * e[i - 1, d]
            dv[i, d] = h_mid * inv_m[i] * force
    return iterations, converged


@njit(cache=True)
def _measure(x: np.ndarray, k: np.ndarray, L0: np.ndarray, N0: np.ndarray, e: np.ndarray, work: np.ndarray) -> float:
    """Directions into ``e``, lengths and taut-branch tensions into ``work``'s LENGTH_ROW and
    TAUT_ROW; returns the largest tension (N, the model's own: 0 if all are slack)."""
    length, a = work[LENGTH_ROW], work[TAUT_ROW]
    _segments(x, k, L0, N0, e, length)
    peak = 0.0
    for s in range(k.shape[0]):
        a[s] = N0[s] + k[s] * (length[s] - L0[s])
        if a[s] > peak:
            peak = a[s]
    return peak


@njit(cache=True)
def _kick(
    x: np.ndarray,
    v: np.ndarray,
    inv_m: np.ndarray,
    k: np.ndarray,
    L0: np.ndarray,
    N0: np.ndarray,
    p: np.ndarray,
    h_mid: float,
    h: float,
    c1: float,
    c2: float,
    dv: np.ndarray,
    y: np.ndarray,
) -> tuple[int, bool, float]:
    """The velocity change ``dv`` (n, 3) m/s of one kick and the tensions ``y`` (N,) N it used.

    Returns ``(iterations, converged, peak)``: the active-set iterations, whether the
    complementarity problem was solved, and the largest tension at ``x`` (N, the model's own)."""
    N = k.shape[0]
    e = np.empty((N, 3))
    work = np.empty((WORK_ROWS, N))
    peak = _measure(x, k, L0, N0, e, work)
    iterations, converged = _kick_core(v, inv_m, k, p, h_mid, h, c1, c2, dv, y, e, work, np.empty(N, np.bool_))
    return iterations, converged, peak


@njit(cache=True)
def advance(
    x: np.ndarray,
    v: np.ndarray,
    state: np.ndarray,
    inv_m: np.ndarray,
    inv_split: np.ndarray,
    k: np.ndarray,
    L0: np.ndarray,
    N0: np.ndarray,
    p: np.ndarray,
    c1: float,
    c2: float,
    h_cap: float,
    safety: float,
    slack_safety: float,
    duration: float,
) -> tuple[int, float, int, int]:
    """Advance a chain by ``duration`` s in place: positions ``x`` and half-step velocities ``v``
    (n, 3), ``state[0]`` the last step (0 after a reset: the first kick is a half one).

    The step is ``safety * 2 / omega`` spread evenly over the interval, capped at ``h_cap``;
    ``omega`` is the axial estimate ``max(k, N/l) (1/m_i^e + 1/m_j^e)`` for the explicit scheme
    (``c2 == 0``, the project's), else the geometric one ``(N / l)(1/m_i^e + 1/m_j^e)`` with the
    larger of the tension now and the last kick's.  With ``slack_safety > 0`` (the slack guard), an
    IMEX step is also at most ``slack_safety * 2 / omega_axial`` while any segment is slack, now or in
    the last kick: the explicit step, where the tension-only switch acts.  Returns ``(steps, peak tension (N) at the
    steps' starts, largest active-set iterations, failed active-set solves)``."""
    N = k.shape[0]
    n = N + 1
    dv = np.empty((n, 3))
    y = np.zeros(N)
    e = np.empty((N, 3))
    work = np.empty((WORK_ROWS, N))
    active = np.empty(N, np.bool_)
    length, taut = work[LENGTH_ROW], work[TAUT_ROW]
    elapsed, steps, peak, worst_iterations, failures = 0.0, 0, 0.0, 0, 0
    while True:
        tension_peak = _measure(x, k, L0, N0, e, work)
        omega2 = 0.0
        omega2_axial = 0.0
        slack = False
        for s in range(N):
            tension = taut[s]
            slack = slack or tension <= 0.0 or (steps > 0 and y[s] <= 0.0)
            if y[s] > tension:
                tension = y[s]
            geometric = tension / length[s] if tension > 0.0 else 0.0
            stiffness = geometric if c2 != 0.0 else max(k[s], geometric)
            if stiffness * inv_split[s] > omega2:
                omega2 = stiffness * inv_split[s]
            if k[s] * inv_split[s] > omega2_axial:
                omega2_axial = k[s] * inv_split[s]
        h_stable = safety * 2.0 / math.sqrt(omega2) if omega2 > 0.0 else math.inf
        if h_stable > h_cap:
            h_stable = h_cap
        if slack and slack_safety > 0.0 and h_stable > slack_safety * 2.0 / math.sqrt(omega2_axial):
            h_stable = slack_safety * 2.0 / math.sqrt(omega2_axial)
        remaining = duration - elapsed
        steps_left = math.ceil(remaining / h_stable - 1e-9)
        last = steps_left <= 1
        h = remaining if last else remaining / steps_left
        h_mid = 0.5 * h if state[0] == 0.0 else 0.5 * (state[0] + h)
        iterations, converged = _kick_core(v, inv_m, k, p, h_mid, h, c1, c2, dv, y, e, work, active)
        if tension_peak > peak:
            peak = tension_peak
        if iterations > worst_iterations:
            worst_iterations = iterations
        if not converged:
            failures += 1
        for i in range(n):
            for d in range(3):
                v[i, d] += dv[i, d]
                x[i, d] += h * v[i, d]
        state[0] = h
        steps += 1
        if last:
            break
        elapsed += h
    return steps, peak, worst_iterations, failures


@dataclass
class Chain:
    """A beaded line in the prototype's layout: nodes in order along the line (satellite 0, the
    beads, satellite 1)."""

    x: np.ndarray  # (n, 3) m
    v: np.ndarray  # (n, 3) m/s, v_{n-1/2} (v_0 after a reset)
    state: np.ndarray  # (1,) s, the last step
    inv_m: np.ndarray  # (n,) 1/kg
    inv_split: np.ndarray  # (N,) 1/kg, 1/m_i^e + 1/m_j^e with masses split among the node's segments
    k: np.ndarray  # (N,) N/m
    L0: np.ndarray  # (N,) m
    N0: np.ndarray  # (N,) N
    p: np.ndarray  # (n, 3) N, held
    c1: float
    c2: float
    h_cap: float  # s
    safety: float
    slack_safety: float  # 0: no slack guard
    x0: np.ndarray  # (n, 3) m, at the reset (the work of p is p . (x - x0))
    energy0: float  # J

    def advance(self, duration: float) -> tuple[int, float, int, int]:
        """:func:`advance` over ``duration`` s."""
        return advance(
            self.x,
            self.v,
            self.state,
            self.inv_m,
            self.inv_split,
            self.k,
            self.L0,
            self.N0,
            self.p,
            self.c1,
            self.c2,
            self.h_cap,
            self.safety,
            self.slack_safety,
            duration,
        )

    def tension(self) -> np.ndarray:
        """(N,) segment tensions at the current positions, N."""
        length = np.linalg.norm(np.diff(self.x, axis=0), axis=1)
        return np.maximum(self.N0 + self.k * (length - self.L0), 0.0)

    def velocity_now(self) -> np.ndarray:
        """(n, 3) velocities at the current time, m/s: half of a tentative kick of the last step's
        size (the scheme's own acceleration, implicit part included)."""
        h = float(self.state[0])
        if h == 0.0:
            return self.v.copy()
        dv = np.empty_like(self.v)
        y = np.zeros_like(self.k)
        _kick(self.x, self.v, self.inv_m, self.k, self.L0, self.N0, self.p, h, h, self.c1, self.c2, dv, y)
        return self.v + 0.5 * dv

    def energy(self) -> float:
        """Kinetic plus strain energy minus the work of the held forces since the reset, J."""
        v = self.velocity_now()
        masses = 1.0 / self.inv_m
        kinetic = 0.5 * float((masses[:, None] * v * v).sum())
        strain = float((0.5 * self.tension() ** 2 / self.k).sum())
        return kinetic + strain - float((self.p * (self.x - self.x0)).sum())


def chain_order(segments: int) -> np.ndarray:
    """The cluster's node indices from satellite 0 to satellite 1 (``build_cluster``'s layout)."""
    return np.r_[0, np.arange(2, segments + 1), 1]


def probe_cluster(segments: int) -> tg.Cluster:
    """The probe's line along x in N segments, ``"half"`` lumping."""
    spec = Tether((0, 1), EA=EA, segments=segments, mass=LINE_MASS, N0=TENSION)
    return build_cluster([[0.0, 0.0, 0.0], [LENGTH, 0.0, 0.0]], SAT_MASS, [spec])


def critical_step(segments: int) -> float:
    """The explicit critical step of the taut line, ``L / (N c_axial)``, s."""
    return LENGTH / (segments * AXIAL_SPEED)


def make_chain(
    cluster: tg.Cluster,
    scheme: str,
    x0: np.ndarray,
    v0: np.ndarray,
    hold: np.ndarray,
    *,
    lift: float = math.inf,
    safety: float = tg.simulator.DEFAULT_SAFETY_FACTOR,
    slack_safety: float = 0.0,
) -> Chain:
    """The prototype's chain of ``cluster`` (a single tether), from positions ``x0`` and velocities
    ``v0`` (n, 3) in the cluster's node order, with the held force ``hold`` (n, 3) N."""
    segments = cluster.num_cables
    order = chain_order(segments)
    masses = cluster.masses[order]
    degree = np.full(segments + 1, 2.0)
    degree[[0, -1]] = 1.0
    split = masses / degree
    c1, c2 = SCHEMES[scheme]
    chain = Chain(
        x=np.ascontiguousarray(x0[order], dtype=float),
        v=np.ascontiguousarray(v0[order], dtype=float),
        state=np.zeros(1),
        inv_m=1.0 / masses,
        inv_split=1.0 / split[:-1] + 1.0 / split[1:],
        k=cluster.stiffness.copy(),
        L0=cluster.L0.copy(),
        N0=cluster.N0.copy(),
        p=np.ascontiguousarray(hold[order], dtype=float),
        c1=c1,
        c2=c2,
        h_cap=lift * critical_step(segments),
        safety=safety,
        slack_safety=slack_safety,
        x0=np.ascontiguousarray(x0[order], dtype=float),
        energy0=0.0,
    )
    chain.energy0 = chain.energy()
    return chain


class Explicit:
    """The project's ``Simulator`` behind the prototype's small interface (positions in chain order)."""

    def __init__(self, cluster: tg.Cluster, x0: np.ndarray, v0: np.ndarray, hold: np.ndarray, safety: float) -> None:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UnstableSafetyFactorWarning)
            self.sim = tg.Simulator(
                cluster, safety_factor=safety, allow_unstable_safety_factor=safety > 0.2, energy_tolerance=math.inf
            )
        self.sim.reset(x0, v0)
        self.hold = hold
        self.order = chain_order(cluster.num_cables)

    def advance(self, duration: float) -> tuple[int, float, int, int]:
        stats = self.sim.advance(duration, self.hold)
        return int(np.asarray(stats.substeps).sum()), float(np.max(stats.peak_tension)), 0, 0

    @property
    def x(self) -> np.ndarray:
        return self.sim.positions[self.order]

    def tension(self) -> np.ndarray:
        return self.sim.tension

    def relative_residual(self) -> float:
        return float(self.sim.energy().relative_residual)


def nominal_hold(cluster: tg.Cluster) -> np.ndarray:
    """(n, 3) N: the pretension held at the satellites (the line's nominal shape at rest)."""
    hold = np.zeros_like(cluster.positions)
    hold[0, 0], hold[1, 0] = -TENSION, TENSION
    return hold


def end_mass_roots(count: int) -> np.ndarray:
    """The first ``count`` roots ``beta = kL/2`` of a uniform line between two equal end masses
    (``beta tan beta = r`` and ``tan beta = -beta / r``, ``r = m_t / (2 M)``)."""
    r = LINE_MASS / (2 * SAT_MASS)
    tiny = 1e-12
    roots = []
    for j in range(count):
        roots.append(brentq(lambda b: b * math.tan(b) - r, j * math.pi + tiny, j * math.pi + math.pi / 2 - tiny))
        roots.append(brentq(lambda b: math.tan(b) + b / r, j * math.pi + math.pi / 2 + tiny, (j + 1) * math.pi - tiny))
    return np.sort(roots)[:count]


def exact_omega(axis: int, mode: int) -> float:
    """rad/s of flexible mode ``mode`` (1, 2, ...) along ``axis`` (0 axial, 1 transverse) of the
    line between its two free end masses."""
    speed = AXIAL_SPEED if axis == 0 else TRANSVERSE_SPEED
    return 2.0 * float(end_mass_roots(mode)[mode - 1]) / LENGTH * speed


def discrete_mode(cluster: tg.Cluster, axis: int, mode: int) -> tuple[np.ndarray, float]:
    """The chain's mode ``mode`` along ``axis`` (mass-normalised, chain order, (n,)) and its
    frequency, rad/s: the bead equations linearised about the straight taut line."""
    segments = cluster.num_cables
    masses = cluster.masses[chain_order(segments)]
    per_segment = cluster.stiffness if axis == 0 else cluster.N0 / cluster.L0
    K = np.zeros((segments + 1, segments + 1))
    for s, ks in enumerate(per_segment):
        K[s : s + 2, s : s + 2] += ks * np.array([[1.0, -1.0], [-1.0, 1.0]])
    omega2, shapes = eigh(K, np.diag(masses))
    return shapes[:, mode], math.sqrt(omega2[mode])  # mode 0 is the rigid translation


def sample_interval(runner: Runner, segments: int, wanted: float) -> float:
    """The sampling interval, s: ``wanted`` for the explicit integrators; for IMEX the smallest
    whole number of step caps not below it, so that sampling never shortens the step under test."""
    if runner.scheme in ("project", "explicit"):
        return wanted
    cap = runner.lift * critical_step(segments)
    return cap * math.ceil(wanted / cap - 1e-9)


def sampled_amplitude(q: np.ndarray, dt: float) -> float:
    """Amplitude of a sinusoid sampled every ``dt`` s (least squares at its sampled frequency)."""
    omega = sampled_frequency(q, dt)
    t = dt * np.arange(len(q))
    basis = np.stack([np.cos(omega * t), np.sin(omega * t)], axis=1)
    coefficients = np.linalg.lstsq(basis, q, rcond=None)[0]
    return float(np.hypot(*coefficients))


def sampled_frequency(q: np.ndarray, dt: float) -> float:
    """rad/s of a sinusoid sampled every ``dt`` s: ``cos(Omega dt) = sum q_n (q_{n+1} + q_{n-1}) / (2 sum q_n^2)``."""
    ratio = float((q[1:-1] * (q[2:] + q[:-2])).sum() / (2.0 * (q[1:-1] ** 2).sum()))
    return math.acos(max(-1.0, min(1.0, ratio))) / dt


# ---------------------------------------------------------------------------------- 1. modes
@dataclass
class Runner:
    """One integrator to compare: a label, the scheme, a lift (IMEX) or safety factor (explicit)."""

    label: str
    scheme: str  # "project", or a key of SCHEMES
    lift: float = math.inf
    safety: float = tg.simulator.DEFAULT_SAFETY_FACTOR
    slack_safety: float = 0.0  # IMEX: the slack guard's safety factor on the axial step (0: none)

    def build(
        self, cluster: tg.Cluster, x0: np.ndarray, v0: np.ndarray, hold: np.ndarray, geometric_safety: float
    ) -> Chain | Explicit:
        if self.scheme == "project":
            return Explicit(cluster, x0, v0, hold, self.safety)
        safety = self.safety if self.scheme == "explicit" else geometric_safety
        return make_chain(
            cluster, self.scheme, x0, v0, hold, lift=self.lift, safety=safety, slack_safety=self.slack_safety
        )


def mode_error(runner: Runner, segments: int, axis: int, mode: int, periods: float, geometric_safety: float) -> float:
    """Relative error of the measured frequency of one mode against the closed form."""
    cluster = probe_cluster(segments)
    shape, omega_discrete = discrete_mode(cluster, axis, mode)
    amplitude = 1e-4 if axis == 0 else 0.01  # m
    order = chain_order(segments)
    x0 = cluster.positions.copy()
    x0[order, axis] += amplitude * shape / np.abs(shape).max()
    hold = nominal_hold(cluster)
    integrator = runner.build(cluster, x0, np.zeros_like(x0), hold, geometric_safety)
    period = 2 * math.pi / omega_discrete
    dt = sample_interval(runner, segments, period / 40)
    samples = round(periods * period / dt)
    masses = cluster.masses[order]
    reference = cluster.positions[order, axis]
    q = np.empty(samples + 1)
    for s in range(samples + 1):
        if s:
            integrator.advance(dt)
        q[s] = float((masses * shape * (integrator.x[:, axis] - reference)).sum())
    return sampled_frequency(q, dt) / exact_omega(axis, mode) - 1.0


def modes_table(segment_counts: tuple[int, ...], runners: list[Runner], geometric_safety: float) -> None:
    print("\n1. Modes: relative frequency error against the closed form (line between two free 50 kg end masses)")
    print("   transverse 1-3 (0.01 m) and axial 1 (1e-4 m), 20 periods; 'space only' is the bead equations' own error")
    print(
        f"   {'N':>3}  {'integrator':24s}  {'transverse 1':>12}  {'transverse 2':>12}  {'transverse 3':>12}  "
        f"{'axial 1':>10}"
    )
    for segments in segment_counts:
        cluster = probe_cluster(segments)
        spatial = [discrete_mode(cluster, 1, m)[1] / exact_omega(1, m) - 1 for m in (1, 2, 3)]
        spatial.append(discrete_mode(cluster, 0, 1)[1] / exact_omega(0, 1) - 1)
        print(
            f"   {segments:3d}  {'space only':24s}  "
            + "  ".join(f"{v:+12.2e}" for v in spatial[:3])
            + f"  {spatial[3]:+10.2e}"
        )
        for runner in runners:
            errors = [mode_error(runner, segments, 1, m, 20, geometric_safety) for m in (1, 2, 3)]
            errors.append(mode_error(runner, segments, 0, 1, 20, geometric_safety))
            print(
                f"   {segments:3d}  {runner.label:24s}  "
                + "  ".join(f"{v:+12.2e}" for v in errors[:3])
                + f"  {errors[3]:+10.2e}",
                flush=True,
            )


# ---------------------------------------------------------------------------------- 2. energy
def energy_table(segments: int, runners: list[Runner], periods: int, geometric_safety: float) -> None:
    """Transverse mode 1 over ``periods`` periods: worst |residual| / vibration energy; axial mode 1
    over ``periods`` of its periods: the amplitude left (numerical damping) and the phase lag."""
    print(f"\n2. Energy over {periods} periods, N = {segments}")
    print(
        f"   {'integrator':24s}  {'transverse 1: worst residual / vibration energy':>48}  "
        f"{'axial 1: amplitude left':>24}"
    )
    cluster = probe_cluster(segments)
    hold = nominal_hold(cluster)
    order = chain_order(segments)
    masses = cluster.masses[order]
    for runner in runners:
        results = []
        for axis in (1, 0):
            shape, omega = discrete_mode(cluster, axis, 1)
            amplitude = 0.05 if axis == 1 else 1e-4
            x0 = cluster.positions.copy()
            x0[order, axis] += amplitude * shape / np.abs(shape).max()
            integrator = runner.build(cluster, x0, np.zeros_like(x0), hold, geometric_safety)
            period = 2 * math.pi / omega
            pretension_energy = float((0.5 * cluster.N0**2 / cluster.stiffness).sum())
            if axis == 1:
                if isinstance(integrator, Explicit):
                    energy0 = float(integrator.sim.energy().initial)
                else:
                    energy0 = integrator.energy0
                vibration = energy0 - pretension_energy
                worst = 0.0
                for _ in range(periods):
                    integrator.advance(period)
                    residual = (
                        float(integrator.sim.energy().residual)
                        if isinstance(integrator, Explicit)
                        else integrator.energy() - integrator.energy0
                    )
                    worst = max(worst, abs(residual))
                results.append(worst / vibration)
            else:
                # The amplitude fitted to the samples of the last two periods, over the first two's.
                reference = cluster.positions[order, 0]
                dt = sample_interval(runner, segments, period / 40)
                count = max(round(2 * period / dt), 8)
                amplitudes = []
                for block in range(2):
                    if block:
                        integrator.advance((periods - 4) * period)
                    q = np.empty(count + 1)
                    for s in range(count + 1):
                        if s:
                            integrator.advance(dt)
                        q[s] = float((masses * shape * (integrator.x[:, 0] - reference)).sum())
                    amplitudes.append(sampled_amplitude(q, dt))
                results.append(amplitudes[1] / amplitudes[0])
        print(f"   {runner.label:24s}  {results[0]:48.2e}  {results[1]:24.3g}", flush=True)


# ---------------------------------------------------------------------------------- 3. snaps
def slack_start(cluster: tg.Cluster, start: str) -> tuple[np.ndarray, np.ndarray]:
    """(n, 3) positions and velocities of the straight or sagging slack start (cluster order)."""
    x = cluster.positions.copy()
    if start == "straight":
        x[:, 0] *= 0.99
    else:
        x[:, 0] = 0.5 * (LENGTH - SAG_CHORD) + x[:, 0] * SAG_CHORD / LENGTH
        x[:, 1] = SAG * np.sin(math.pi * (x[:, 0] - x[0, 0]) / SAG_CHORD)
    v = np.zeros_like(x)
    v[0, 0], v[1, 0] = -SPEED, SPEED
    return x, v


@njit(cache=True)
def _peer_rhs(y: np.ndarray, masses: np.ndarray, k: np.ndarray, L0: np.ndarray, N0: np.ndarray) -> np.ndarray:
    """The bead equations from their definition (a chain, nodes in order along the line)."""
    n = masses.shape[0]
    size = 3 * n
    out = np.empty_like(y)
    out[:size] = y[size:]
    force = np.zeros((n, 3))
    for s in range(n - 1):
        d = y[3 * (s + 1) : 3 * (s + 2)] - y[3 * s : 3 * (s + 1)]
        length = math.sqrt((d * d).sum())
        tension = max(N0[s] + k[s] * (length - L0[s]), 0.0)
        force[s] += tension * d / length
        force[s + 1] -= tension * d / length
    for i in range(n):
        out[size + 3 * i : size + 3 * i + 3] = force[i] / masses[i]
    return out


def peer(
    cluster: tg.Cluster, x0: np.ndarray, v0: np.ndarray, times: np.ndarray
) -> tuple[np.ndarray, float, np.ndarray]:
    """DOP853 (rtol 1e-10) on the bead equations: positions (len(times), n, 3) in chain order, the
    peak tension over [0, times[-1]] (densely sampled, N), and the positions on the 0.01 s grid."""
    order = chain_order(cluster.num_cables)
    masses = cluster.masses[order]
    args = (masses, cluster.stiffness.copy(), cluster.L0.copy(), cluster.N0.copy())
    y0 = np.r_[x0[order].ravel(), v0[order].ravel()]
    solution = solve_ivp(
        lambda _t, y: _peer_rhs(y, *args),
        (0.0, times[-1]),
        y0,
        method="DOP853",
        rtol=1e-10,
        atol=1e-12,
        dense_output=True,
    )
    size = 3 * len(masses)
    grid = solution.sol(np.linspace(0.0, times[-1], 20001))[:size].T.reshape(-1, len(masses), 3)
    lengths = np.linalg.norm(np.diff(grid, axis=1), axis=2)
    peak = float(np.maximum(cluster.N0 + cluster.stiffness * (lengths - cluster.L0), 0.0).max())
    at = solution.sol(times)[:size].T.reshape(len(times), len(masses), 3)
    return at, peak, grid


def snaps_table(segment_counts: tuple[int, ...], runners: list[Runner], geometric_safety: float) -> None:
    print(f"\n3. Snaps over {FIRST_SNAP:g} s against DOP853 (rtol 1e-10) on the same bead equations")
    print(
        "   peak: the first snap's largest tension, its error against DOP853's; "
        "dx: largest position error at 1 s / 2 s;"
    )
    print("   residual: worst relative energy residual (0.01 s samples); AS: most active-set iterations (failures)")
    print(
        f"   {'N':>3}  {'start':8s}  {'integrator':24s}  {'substeps/s':>10}  {'peak (N)':>9}  {'peak err':>9}  "
        f"{'dx 1 s (m)':>10}  {'dx 2 s (m)':>10}  {'residual':>9}  {'AS':>7}"
    )
    times = np.array([1.0, FIRST_SNAP])
    for segments in segment_counts:
        cluster = probe_cluster(segments)
        zero = np.zeros_like(cluster.positions)
        for start in ("straight", "sagging"):
            x0, v0 = slack_start(cluster, start)
            reference, reference_peak, _ = peer(cluster, x0, v0, times)
            print(f"   {segments:3d}  {start:8s}  {'DOP853':24s}  {'':>10}  {reference_peak:9.1f}", flush=True)
            for runner in runners:
                integrator = runner.build(cluster, x0, v0, zero, geometric_safety)
                steps, peak, iterations, failures, worst = 0, 0.0, 0, 0, 0.0
                errors = []
                # IMEX: sampled at its step cap (rounded down to hit 1 s), not at 0.01 s, which would cap it
                explicit = runner.scheme in ("project", "explicit")
                interval_s = (
                    SNAP_INTERVAL if explicit else 1.0 / math.ceil(1.0 / (runner.lift * critical_step(segments)))
                )
                for interval in range(round(FIRST_SNAP / interval_s)):
                    taken, tension_peak, its, fails = integrator.advance(interval_s)
                    steps += taken
                    peak = max(peak, tension_peak, float(integrator.tension().max()))
                    iterations, failures = max(iterations, its), failures + fails
                    if isinstance(integrator, Explicit):
                        residual = integrator.relative_residual()
                    else:
                        energy = integrator.energy()
                        residual = abs(energy - integrator.energy0) / max(abs(integrator.energy0), 1e-300)
                    worst = max(worst, residual if math.isfinite(residual) else math.inf)
                    if round((interval + 1) * interval_s, 9) in times:
                        errors.append(float(np.abs(integrator.x - reference[len(errors)]).max()))
                print(
                    f"   {segments:3d}  {start:8s}  {runner.label:24s}  {steps / FIRST_SNAP:10.0f}  {peak:9.1f}  "
                    f"{peak / reference_peak - 1:+9.1e}  {errors[0]:10.1e}  {errors[1]:10.1e}  {worst:9.1e}  "
                    f"{iterations:3d}({failures})",
                    flush=True,
                )


# ---------------------------------------------------------------------------------- 4. cost
def cost_table(segment_counts: tuple[int, ...], runners: list[Runner], geometric_safety: float, target: float) -> None:
    print("\n4. Cost: the taut line in transverse mode 1 (0.05 m), pretension held, 0.1 s intervals, one cluster")
    print("   best of 3 interleaved runs of at least the target wall time each")
    print(
        f"   {'N':>3}  {'integrator':24s}  {'substeps/sim-s':>14}  {'ms wall/sim-s':>13}  {'x project 0.1':>13}  "
        f"{'us/substep':>10}"
    )
    for segments in segment_counts:
        cluster = probe_cluster(segments)
        x0 = cluster.positions.copy()
        x0[:, 1] = 0.05 * np.sin(math.pi * x0[:, 0] / LENGTH)
        hold = nominal_hold(cluster)
        best = {runner.label: (math.inf, 0.0) for runner in runners}
        for _ in range(3):
            for runner in runners:  # interleaved: each repeat runs every integrator once
                integrator = runner.build(cluster, x0, np.zeros_like(x0), hold, geometric_safety)
                integrator.advance(COST_INTERVAL)  # compiled already; warms the caches
                calls, substeps, began = 0, 0, time.perf_counter()
                while True:
                    substeps += integrator.advance(COST_INTERVAL)[0]
                    calls += 1
                    elapsed = time.perf_counter() - began
                    if elapsed >= target:
                        break
                wall = elapsed / (calls * COST_INTERVAL)
                if wall < best[runner.label][0]:
                    best[runner.label] = (wall, substeps / (calls * COST_INTERVAL))
        baseline = best[runners[0].label][0]
        for runner in runners:
            wall, rate = best[runner.label]
            print(
                f"   {segments:3d}  {runner.label:24s}  {rate:14.0f}  {1e3 * wall:13.3f}  {wall / baseline:13.3f}  "
                f"{1e6 * wall / rate:10.2f}",
                flush=True,
            )


def cpu_model() -> str:
    """The CPU's model name (lscpu), for the record."""
    try:
        out = subprocess.run(["lscpu"], capture_output=True, text=True, check=True).stdout
        return next(line.split(":", 1)[1].strip() for line in out.splitlines() if line.startswith("Model name"))
    except (OSError, subprocess.CalledProcessError, StopIteration):
        return platform.processor() or "unknown"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="N = 8, three lifts, short runs")
    parser.add_argument("--cost", action="store_true", help="the cost table only (on a quiet machine)")
    parser.add_argument("--target", type=float, default=1.0, help="wall seconds per cost measurement")
    parser.add_argument(
        "--geometric-safety", type=float, default=0.5, help="IMEX step over 2 / omega_transverse (default 0.5)"
    )
    args = parser.parse_args()
    gs = args.geometric_safety
    print(
        f"probe line L={LENGTH:g} m, satellites {SAT_MASS:g} kg (free), m_t={LINE_MASS:g} kg, EA={EA:g} N, "
        f"T={TENSION:g} N, 'half' lumping; c_axial {AXIAL_SPEED:.0f} m/s, c_transverse {TRANSVERSE_SPEED:.1f} m/s"
    )
    print(
        "lift: IMEX step cap over the explicit critical step L/(N c_axial); "
        f"IMEX step also <= {gs:g} x 2/omega_transverse"
    )
    print(f"CPU: {cpu_model()}")
    project = [Runner("project explicit 0.1", "project"), Runner("project explicit 0.3", "project", safety=0.3)]
    taut_only = [Runner("project explicit 0.9", "project", safety=0.9)]  # stable while taut; snaps run away
    if args.quick:
        lifts: tuple[float, ...] = (1.0, 8.0)
        counts: tuple[int, ...] = (8,)
        periods = 10
    else:
        lifts = (0.5, 1.0, 2.0, 4.0, 8.0, 32.0)
        counts = (8, 16, 32)
        periods = 100
    imex = [Runner(f"IMEX newmark lift {lift:g}", "newmark", lift=lift) for lift in lifts]
    euler = [Runner(f"IMEX euler lift {lift:g}", "euler", lift=lift) for lift in (1.0, 8.0)]
    guarded = [Runner("IMEX newmark 8, guard 0.1", "newmark", lift=8.0, slack_safety=0.1)]
    control = [Runner("prototype explicit 0.1", "explicit")]
    began = time.perf_counter()
    if args.cost:
        cost_lifts = (1.0, 4.0, 32.0) if not args.quick else (4.0,)
        runners = project[:1] + taut_only + control
        runners += [Runner(f"IMEX newmark lift {lift:g}", "newmark", lift=lift) for lift in cost_lifts]
        cost_table((8, 32, 64) if not args.quick else (8,), runners, gs, args.target if not args.quick else 0.1)
    else:
        modes_table(counts, project + taut_only + control + imex + euler, gs)
        energy_table(8, project + taut_only + control + imex + euler, periods, gs)
        snaps_table(counts[:2] if not args.quick else counts, project + control + imex + guarded + euler, gs)
    print(f"done in {time.perf_counter() - began:.0f} s")


if __name__ == "__main__":
    main()
