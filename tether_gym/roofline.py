"""The hardware limit of a cluster sub-step on this machine: an operation count and a microbenchmark.

A sub-step of the explicit integrator (:mod:`tether_gym._kernels`) does, per cluster,

* per **cable** (the force pass, ``cable_forces``): the end-to-end vector (3 subtractions), its
  length (3 multiplications, 2 additions, 1 square root), the unit vector (1 division, 3
  multiplications), the elongation (1 subtraction), the tension-only law (1 fused multiply-add,
  1 comparison), the element's stiffness and frequency for the critical step (2 multiplications,
  2 comparisons), the peak and breaking checks (2 comparisons), the force vector (3
  multiplications) and its scatter to both ends (6 additions): **26 floating-point operations,
  a square root and a division**, 7 comparisons. A cable with Kelvin-Voigt damping adds the
  stretching rate (3 subtractions, 3 multiply-adds), the damped tension (1 multiply-add, 1
  comparison), the dissipated power (1 subtraction, 1 multiply-add) and the damping's stable-step
  factor (3 multiplications, 2 additions, 1 division, 2 square roots): **17 more operations, 2
  square roots and a division**. It reads 6 position values and 7 cable values and writes the
  tension and 6 force values: 13 loads and 7 stores of 8 bytes, or 136 bytes that the vector
  registers and the L1 cache serve (one cluster's tables are under 2 kB for the tetrahedron and
  about 10 kB for a beaded one, and the kernels finish a cluster's interval before the next).
* per **node** (the kick and the drift): the inertia and the damped denominator (1 division, 3
  multiply-adds), and per axis the blended applied force (1 subtraction, 1 multiply-add), the
  velocity update (1 multiply-add, 2 additions, 1 multiplication), the position update (1
  multiply-add) and the work and damping books (2 multiply-adds): **about 27 operations and a
  division** (fused multiply-adds counted once), 18 loads and 6 stores.
* per **cluster**: the step size from the largest element frequency (a square root, a division,
  a few comparisons), which a batch of clusters amortises over its cables and nodes.

So the sub-step is compute-bound, not memory-bound, and its limit is set by how fast a core
retires that mix of square roots, divisions and fused multiply-adds. :func:`measure_limits`
measures it: the same arithmetic, branch-free, over independent elements in L1-resident arrays,
which the compiler turns into SIMD instructions (4 doubles per AVX2 instruction, 8 with
AVX-512). :func:`substep_limit_ns` adds the parts up for a cluster, and ``python -m
tether_gym.bench`` divides that by the measured sub-step time: the **fraction of the limit**.
"""

from __future__ import annotations

import dataclasses
import math
import re
import time
from collections.abc import Callable

import numpy as np
from numba import njit

from tether_gym.cluster import Cluster

__all__ = ["RooflineLimits", "measure_limits", "simd_width", "substep_limit_ns"]

#: Doubles per vector register, by the register's name in x86 assembly.
WIDTHS = {"xmm": 2, "ymm": 4, "zmm": 8}

#: Elements per array of the microbenchmark: 13 arrays of them stay within a 32 kB L1 cache.
ELEMENTS = 256


# Not cached: numba inspects the assembly of code it compiled in this process only, and
# simd_width reads it (compiling takes about a second).
@njit(nogil=True, error_model="numpy")
def _cable_mix(
    xi: np.ndarray,
    xj: np.ndarray,
    rest: np.ndarray,
    stiffness: np.ndarray,
    pretension: np.ndarray,
    inverse_mass: np.ndarray,
    vi: np.ndarray,
    vj: np.ndarray,
    damping: np.ndarray,
    force: np.ndarray,
    tension: np.ndarray,
    omega2: np.ndarray,
    viscous: bool,
    repeats: int,
) -> float:
    """The cable update's arithmetic over independent elements (arrays (3, K) and (K,)),
    branch-free, ``repeats`` times; returns a checksum so that nothing is optimised away."""
    k = rest.shape[0]
    checksum = 0.0
    for _ in range(repeats):
        for e in range(k):
            dx = xj[0, e] - xi[0, e]
            dy = xj[1, e] - xi[1, e]
            dz = xj[2, e] - xi[2, e]
            length = math.sqrt(dx * dx + dy * dy + dz * dz)
            inverse_length = 1.0 / length
            ex = dx * inverse_length
            ey = dy * inverse_length
            ez = dz * inverse_length
            n_taut = pretension[e] + stiffness[e] * (length - rest[e])
            n_cable = n_taut if n_taut > 0.0 else 0.0
            power = 0.0
            if viscous:
                rate = (vj[0, e] - vi[0, e]) * ex + (vj[1, e] - vi[1, e]) * ey + (vj[2, e] - vi[2, e]) * ez
                damped = n_taut + damping[e] * rate
                n_cable = damped if damped > 0.0 else 0.0
                power = (n_cable - n_taut) * rate
            geometric = n_cable * inverse_length
            k_max = stiffness[e] if stiffness[e] >= geometric else geometric
            omega2_e = k_max * inverse_mass[e]
            if viscous:
                xi_e = 0.5 * damping[e] * inverse_mass[e] / math.sqrt(omega2_e)
                factor = math.sqrt(1.0 + xi_e * xi_e) + xi_e
                omega2_e *= factor * factor
            tension[e] = n_cable + power
            omega2[e] = omega2_e if omega2_e > omega2[e] else omega2[e]
            force[0, e] += n_cable * ex
            force[1, e] += n_cable * ey
            force[2, e] += n_cable * ez
        checksum += force[0, 0] + tension[k - 1]
    return checksum


@njit(cache=True, nogil=True, error_model="numpy")
def _node_mix(
    mass: np.ndarray,
    damping: np.ndarray,
    velocity: np.ndarray,
    position: np.ndarray,
    applied: np.ndarray,
    previous: np.ndarray,
    internal: np.ndarray,
    books: np.ndarray,
    h: float,
    repeats: int,
) -> float:
    """The kick and drift of a node over independent elements (arrays (3, K) and (K,)),
    ``repeats`` times; returns a checksum."""
    k = mass.shape[0]
    checksum = 0.0
    blend = 0.25
    for _ in range(repeats):
        for e in range(k):
            inertia = mass[e] / h
            inverse_lhs = 1.0 / (inertia + 0.5 * damping[e])
            rhs_factor = inertia - 0.5 * damping[e]
            speed2 = 0.0
            work = 0.0
            for d in range(3):
                p = applied[d, e] + blend * (previous[d, e] - applied[d, e])
                v = (rhs_factor * velocity[d, e] + p - internal[d, e]) * inverse_lhs
                velocity[d, e] = v
                step = h * v
                position[d, e] += step
                work += applied[d, e] * step
                speed2 += v * v
            books[e] += work + h * damping[e] * speed2
        checksum += books[0] + position[0, k - 1]
    return checksum


@dataclasses.dataclass(frozen=True)
class RooflineLimits:
    """This machine's limits for one thread, ns per element (best of the repeats).

    Attributes:
        cable_ns: one undamped cable update.
        viscous_cable_ns: one cable update with Kelvin-Voigt damping.
        node_ns: one node's kick and drift.
        simd: doubles per vector instruction the compiled microbenchmark uses (4: AVX2, 8: AVX-512,
            1: scalar), read from its assembly.
    """

    cable_ns: float
    viscous_cable_ns: float
    node_ns: float
    simd: int


def _best_ns(call: Callable[[int], float], elements: int, repeats: int, seconds: float) -> float:
    """The best ns per element of ``call(count)`` (``count`` passes over ``elements``)."""
    call(1)
    count = 1
    while True:
        started = time.perf_counter()
        call(count)
        if time.perf_counter() - started >= seconds / repeats:
            break
        count *= 2
    best = math.inf
    for _ in range(repeats):
        started = time.perf_counter()
        call(count)
        best = min(best, (time.perf_counter() - started) / (count * elements))
    return 1e9 * best


def simd_width() -> int:
    """Doubles per vector instruction in the compiled cable microbenchmark: 8 if it uses 512-bit
    (zmm) square roots, 4 for 256-bit (ymm), 2 for 128-bit packed (xmm), else 1."""
    signatures = list(_cable_mix.signatures)
    if not signatures:
        return 1
    assembly = _cable_mix.inspect_asm(signatures[0]).lower()
    registers = set(re.findall(r"v?sqrtpd[^\n]*%(zmm|ymm|xmm)", assembly))
    return max((WIDTHS[register] for register in registers), default=1)


def measure_limits(seconds: float = 1.0, repeats: int = 5, seed: int = 0) -> RooflineLimits:
    """Measure :class:`RooflineLimits` on this machine (about ``seconds`` per part, one thread;
    the first call compiles the kernels, or loads them from numba's cache)."""
    rng = np.random.default_rng(seed)
    k = ELEMENTS
    # Cables of a tetrahedron's scale: 100 m, stretched by millimetres, so the law stays in range.
    xi = rng.normal(0.0, 1.0, (3, k))
    direction = rng.normal(0.0, 1.0, (3, k))
    direction /= np.linalg.norm(direction, axis=0)
    xj = xi + 100.0 * direction
    rest = np.full(k, 99.999)
    stiffness = np.full(k, 400.0)
    pretension = np.full(k, 5.0)
    inverse_mass = np.full(k, 0.04)
    vi, vj = rng.normal(0.0, 0.01, (3, k)), rng.normal(0.0, 0.01, (3, k))
    damping = np.full(k, 2.0)
    force, tension, omega2 = np.zeros((3, k)), np.zeros(k), np.zeros(k)

    def cables(viscous: bool) -> Callable[[int], float]:
        return lambda count: _cable_mix(
            xi, xj, rest, stiffness, pretension, inverse_mass, vi, vj, damping, force, tension, omega2, viscous, count
        )

    mass, node_damping = np.full(k, 25.0), np.full(k, 0.1)
    velocity, position = rng.normal(0.0, 1e-3, (3, k)), rng.normal(0.0, 50.0, (3, k))
    applied, previous, internal = (rng.normal(0.0, 1.0, (3, k)) for _ in range(3))
    books = np.zeros(k)

    def nodes(count: int) -> float:
        return _node_mix(mass, node_damping, velocity, position, applied, previous, internal, books, 1e-3, count)

    cable_ns = _best_ns(cables(False), k, repeats, seconds)
    viscous_ns = _best_ns(cables(True), k, repeats, seconds)
    node_ns = _best_ns(nodes, k, repeats, seconds)
    return RooflineLimits(cable_ns, viscous_ns, node_ns, simd_width())


def substep_limit_ns(cluster: Cluster, limits: RooflineLimits) -> float:
    """The least time one sub-step of ``cluster`` can take on one thread, ns: its cables (the
    viscous update for a cable with Kelvin-Voigt damping) and its nodes at the measured limits.
    The per-cluster step-size work is left out, so the limit is a little optimistic."""
    viscous = int(np.count_nonzero(np.asarray(cluster.axial_damping) > 0.0))
    plain = cluster.num_cables - viscous
    return plain * limits.cable_ns + viscous * limits.viscous_cable_ns + cluster.num_nodes * limits.node_ns
