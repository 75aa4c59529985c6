"""A prototype of the integrator written once for the CPU and for CUDA GPUs (numba).

The functions of :func:`build_kernels` are plain Python over scalars and arrays indexed
``[node, axis, cluster]``: the cluster index innermost, so that neighbouring GPU threads (one
cluster each) read neighbouring memory, and a CPU loop over clusters reads contiguous lanes.
:func:`build_kernels` compiles them either with ``numba.njit`` (the CPU) or with
``numba.cuda.jit(device=True)`` (a GPU, or numba's CUDA simulator on a machine without one), from
the same source.

What it integrates: the project's scheme (:mod:`tether_gym._kernels`) on its hot path, operation
for operation, so that on the CPU it reproduces :class:`~tether_gym.BatchSimulator` to the bit:
central differences with diagonal mass and damping, the first half step as uniformly accelerated
motion, the applied force of the previous interval blended into the first kick, tension-only
cables with pretension, and the per-cluster critical step (``safety_factor * 2 / omega``, the
damping's limit, equal steps that land on the interval's end). What it leaves out, as a
prototype: turning frames, Kelvin-Voigt damping, breaking cables, the energy books, the sub-step
budget and the status flags. :class:`PortableBatch` refuses a cluster that needs the first two.

A third target, ``"lanes"``, runs the same scheme on the CPU over blocks of clusters in SIMD lanes
(:func:`_advance_lanes`): every loop over nodes, axes and cables has the block's clusters
innermost and branch-free, each lane with its own step, a lane that has finished its interval
masked. It also reproduces ``BatchSimulator`` to the bit. The integrator itself now runs large
batches this way (``tether_gym._kernels._advance_lanes``, with breaking cables, the energy books,
the sub-step budget and the status flags, on the simulator's own tables); this target stays as
the bare hot path on arrays already in the lane layout: what the layout is worth without the
rest (docs/speed.md, the roofline).

Status: tested on the CPU, compiled by ``njit`` and run by the CUDA simulator
(``NUMBA_ENABLE_CUDASIM=1``) on tiny batches, against ``BatchSimulator``; not run on a GPU
(docs/accelerators.md has the cost model and what a GPU run would have to show).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
from numba import njit

from tether_gym import _kernels as k
from tether_gym.simulator import BatchSimulator

__all__ = ["PortableBatch", "build_kernels"]


# One closure per target, so that each compiled function calls its own target's helpers: the
# nested functions count toward the builder's complexity, which is the kernels' own.
def build_kernels(device: Callable[[Callable[..., Any]], Any]) -> Callable[..., Any]:  # noqa: C901
    """The interval advance of one cluster, ``advance_cluster(b, duration, ...)``, with every
    function compiled by ``device`` (``njit(...)`` or ``cuda.jit(device=True)``)."""

    @device
    def cable_forces(b, x, f_int, topology, rest, stiffness, pretension, inverse_mass_sum):  # type: ignore[no-untyped-def]
        """Internal forces and tensions at positions ``x``; returns the largest omega^2."""
        n = x.shape[0]
        for i in range(n):
            for d in range(3):
                f_int[i, d, b] = 0.0
        omega2_max = 0.0
        for c in range(topology.shape[0]):
            i = topology[c, 0]
            j = topology[c, 1]
            dx = x[j, 0, b] - x[i, 0, b]
            dy = x[j, 1, b] - x[i, 1, b]
            dz = x[j, 2, b] - x[i, 2, b]
            length = math.sqrt(dx * dx + dy * dy + dz * dz)
            inverse_length = 1.0 / length
            ex = dx * inverse_length
            ey = dy * inverse_length
            ez = dz * inverse_length
            elongation = length - rest[c, b]
            n_taut = pretension[c, b] + stiffness[c, b] * elongation
            n_cable = n_taut if n_taut > 0.0 else 0.0
            geometric = n_cable * inverse_length
            k_max = stiffness[c, b] if stiffness[c, b] >= geometric else geometric
            omega2 = k_max * inverse_mass_sum[c, b]
            if omega2 > omega2_max:
                omega2_max = omega2
            if n_cable != 0.0:
                fx = n_cable * ex
                fy = n_cable * ey
                fz = n_cable * ez
                f_int[i, 0, b] -= fx
                f_int[i, 1, b] -= fy
                f_int[i, 2, b] -= fz
                f_int[j, 0, b] += fx
                f_int[j, 1, b] += fy
                f_int[j, 2, b] += fz
        return omega2_max

    @device
    def step_size(omega2, h_damping, safety_factor, max_step, remaining):  # type: ignore[no-untyped-def]
        """``(h, last)`` as the project's ``_step_size`` chooses them (no sub-step budget)."""
        h_stable = safety_factor * 2.0 / math.sqrt(omega2) if omega2 > 0.0 else math.inf
        if h_stable > h_damping:
            h_stable = h_damping
        if h_stable > max_step:
            h_stable = max_step
        steps_left = math.ceil(remaining / h_stable - 1e-9)
        if steps_left <= 1:
            return remaining, True
        return remaining / steps_left, False

    @device
    def advance_cluster(  # type: ignore[no-untyped-def]
        b, duration, safety_factor, max_step, topology, x, v, f_int, f_applied, f_previous, mass, damping,
        rest, stiffness, pretension, inverse_mass_sum, last_step, omega2, substeps,
    ):  # fmt: skip
        """Advance cluster ``b`` over ``duration`` s with its applied force held."""
        n = x.shape[0]
        h_damping = math.inf
        for i in range(n):
            if damping[i, b] > 0.0 and 2.0 * mass[i, b] / damping[i, b] < h_damping:
                h_damping = 2.0 * mass[i, b] / damping[i, b]
        h_damping *= safety_factor
        elapsed = 0.0
        count = 0
        h_last = last_step[b]
        last = False
        while not last:
            h, last = step_size(omega2[b], h_damping, safety_factor, max_step, duration - elapsed)
            if h_last == 0.0:  # the first half step after a reset: uniformly accelerated motion
                for i in range(n):
                    for d in range(3):
                        acceleration = (f_applied[i, d, b] - f_int[i, d, b] - damping[i, b] * v[i, d, b]) / mass[i, b]
                        v[i, d, b] = v[i, d, b] + 0.5 * h * acceleration
            else:
                blend = h_last / (h_last + h) if count == 0 else 0.0
                inverse_h_mid = 1.0 / (0.5 * (h_last + h))
                for i in range(n):
                    inertia = mass[i, b] * inverse_h_mid
                    inverse_lhs = 1.0 / (inertia + 0.5 * damping[i, b])
                    rhs_factor = inertia - 0.5 * damping[i, b]
                    for d in range(3):
                        applied = f_applied[i, d, b]
                        p_dual = applied + blend * (f_previous[i, d, b] - applied)
                        v[i, d, b] = (rhs_factor * v[i, d, b] + p_dual - f_int[i, d, b]) * inverse_lhs
            for i in range(n):
                for d in range(3):
                    x[i, d, b] += h * v[i, d, b]
            count += 1
            h_last = h
            omega2[b] = cable_forces(b, x, f_int, topology, rest, stiffness, pretension, inverse_mass_sum)
            if not last:
                elapsed += h
        for i in range(n):
            for d in range(3):
                f_previous[i, d, b] = f_applied[i, d, b]
        last_step[b] = h_last
        substeps[b] = count

    return advance_cluster


_advance_cluster_cpu = build_kernels(njit(inline="always", error_model="numpy"))


@njit(error_model="numpy")
def _advance_cpu(duration, safety_factor, max_step, topology, arrays):  # type: ignore[no-untyped-def]
    x, v, f_int, f_applied, f_previous, mass, damping, rest, stiffness, pretension, inverse_mass_sum = arrays[:11]
    last_step, omega2, substeps = arrays[11:]
    for b in range(x.shape[2]):
        _advance_cluster_cpu(
            b, duration, safety_factor, max_step, topology, x, v, f_int, f_applied, f_previous, mass, damping,
            rest, stiffness, pretension, inverse_mass_sum, last_step, omega2, substeps,
        )  # fmt: skip


def gpu_kernel() -> Any:
    """The CUDA kernel (one thread per cluster), compiled on first use: on a GPU, or by numba's
    CUDA simulator when ``NUMBA_ENABLE_CUDASIM=1`` was set before numba was imported."""
    from tether_gym import _portable_cuda

    return _portable_cuda.advance


class PortableBatch:
    """A batch's state in the prototype's layout, taken from a :class:`~tether_gym.BatchSimulator`.

    Args:
        sim: the batch to copy (its state, forces and settings at the time of the call).

    Raises:
        ValueError: the cluster turns (a Hill or rotating frame), has Kelvin-Voigt damping, or
            uses the linearised elongation: the prototype integrates none of them.
    """

    NODE_FIELDS = ("x", "v", "f_int", "f_applied", "f_previous")

    def __init__(self, sim: BatchSimulator) -> None:
        if not all(cluster.frame.is_inertial for cluster in sim.clusters):
            raise ValueError("the portable prototype integrates inertial frames only; a cluster of this batch turns")
        if np.any(sim.cable_table[:, :, k.AXIAL_DAMPING] > 0.0):
            raise ValueError("the portable prototype has no Kelvin-Voigt damping; a cable of this batch has it")
        settings = sim.kernel_settings
        if settings[k.LINEARISED] != 0.0:
            raise ValueError("the portable prototype uses the exact elongation only (linearised=False)")
        nodes, cables, table = sim.node_table, sim.cable_table, sim.cluster_table

        def lanes(values: np.ndarray) -> np.ndarray:  # (B, a, ...) -> (a, ..., B): a contiguous copy
            return np.array(np.moveaxis(values, 0, -1), order="C", copy=True)

        self.topology = np.array(sim.cables, dtype=np.int64, order="C", copy=True)
        self.x = lanes(nodes[:, :, k.POSITION : k.POSITION + 3])
        self.v = lanes(nodes[:, :, k.HALF_STEP_VELOCITY : k.HALF_STEP_VELOCITY + 3])
        self.f_int = lanes(nodes[:, :, k.INTERNAL_FORCE : k.INTERNAL_FORCE + 3])
        self.f_applied = lanes(nodes[:, :, k.APPLIED_FORCE : k.APPLIED_FORCE + 3])
        self.f_previous = lanes(nodes[:, :, k.PREVIOUS_FORCE : k.PREVIOUS_FORCE + 3])
        self.mass = lanes(nodes[:, :, k.MASS])
        self.damping = lanes(nodes[:, :, k.DAMPING])
        self.rest = lanes(cables[:, :, k.REST_LENGTH])
        self.stiffness = lanes(cables[:, :, k.STIFFNESS])
        self.pretension = lanes(cables[:, :, k.PRETENSION])
        self.inverse_mass_sum = lanes(cables[:, :, k.INV_SPLIT_MASS_SUM])
        self.last_step = np.array(table[:, k.LAST_STEP], copy=True)
        self.omega2 = np.array(table[:, k.OMEGA2], copy=True)
        self.substeps = np.zeros(sim.num_clusters, dtype=np.int64)
        self.safety_factor = float(settings[k.SAFETY_FACTOR])
        self.max_step = float(settings[k.MAX_STEP])
        #: Clusters per block of the ``"lanes"`` target: 128 measured best on the tetrahedron
        #: (3.2x the blocks of 8, whose vector loops run once per pass).
        self.lanes = 128

    def _arrays(self) -> tuple[np.ndarray, ...]:
        return (
            self.x, self.v, self.f_int, self.f_applied, self.f_previous, self.mass, self.damping, self.rest,
            self.stiffness, self.pretension, self.inverse_mass_sum, self.last_step, self.omega2, self.substeps,
        )  # fmt: skip

    def set_force(self, force: np.ndarray) -> None:
        """Hold the applied force (B, n, 3), N, over the next interval."""
        self.f_applied[...] = np.moveaxis(np.asarray(force, dtype=float), 0, -1)

    def advance(self, duration: float, target: str = "cpu", threads_per_block: int = 32) -> None:
        """Advance every cluster over ``duration`` s: ``target`` ``"cpu"`` (njit, a cluster at a
        time), ``"lanes"`` (njit, blocks of :attr:`lanes` clusters in SIMD lanes) or ``"cuda"`` (a
        GPU, or the CUDA simulator). The arrays stay on the host: a prototype, not a pipeline."""
        if target == "cpu":
            _advance_cpu(duration, self.safety_factor, self.max_step, self.topology, self._arrays())
        elif target == "lanes":
            lanes_kernel: Any = _advance_lanes  # a numba dispatcher: its arguments are checked when it compiles
            lanes_kernel(duration, self.safety_factor, self.max_step, self.topology, *self._arrays(), self.lanes)
        elif target == "cuda":
            batch = self.x.shape[2]
            blocks = (batch + threads_per_block - 1) // threads_per_block
            gpu_kernel()[blocks, threads_per_block](
                duration, self.safety_factor, self.max_step, self.topology, *self._arrays()
            )
        else:
            raise ValueError(f"target must be 'cpu', 'lanes' or 'cuda'; got {target!r}")

    @property
    def positions(self) -> np.ndarray:
        """(B, n, 3) node positions, m."""
        return np.moveaxis(self.x, -1, 0).copy()


# ---------------------------------------------------------------------------------------------
# The same scheme over blocks of clusters in SIMD lanes (CPU): every loop over nodes, axes and
# cables has the clusters of a block innermost, branch-free, so that one vector instruction
# updates several clusters. Each lane keeps its own step; a lane whose interval has ended keeps
# its velocity (a select) and moves by a zero step, which leaves its positions and forces as
# they were, bit for bit, while the other lanes finish.


@njit(error_model="numpy")
def _advance_lanes(  # type: ignore[no-untyped-def]  # noqa: C901 - the kernel
    duration, safety_factor, max_step, topology, x, v, f_int, f_applied, f_previous, mass, damping,
    rest, stiffness, pretension, inverse_mass_sum, last_step, omega2, substeps, width,
):  # fmt: skip
    n = x.shape[0]
    batch = x.shape[2]
    cables = topology.shape[0]
    h = np.zeros(width)
    h_last = np.zeros(width)
    h_damping = np.zeros(width)
    elapsed = np.zeros(width)
    blend = np.zeros(width)
    inverse_h_mid = np.zeros(width)
    omega2_max = np.zeros(width)
    inverse_lhs = np.zeros(width)
    rhs_factor = np.zeros(width)
    running = np.zeros(width, dtype=np.bool_)
    from_rest = np.zeros(width, dtype=np.bool_)
    for start in range(0, batch, width):
        lanes = min(width, batch - start)
        for lane in range(lanes):
            b = start + lane
            limit = math.inf
            for i in range(n):
                if damping[i, b] > 0.0 and 2.0 * mass[i, b] / damping[i, b] < limit:
                    limit = 2.0 * mass[i, b] / damping[i, b]
            h_damping[lane] = limit * safety_factor
            elapsed[lane] = 0.0
            h_last[lane] = last_step[b]
            running[lane] = True
            substeps[b] = 0
        active = lanes
        while active > 0:
            for lane in range(lanes):
                b = start + lane
                if not running[lane]:
                    h[lane] = 0.0
                    continue
                remaining = duration - elapsed[lane]
                w2 = omega2[b]
                h_stable = safety_factor * 2.0 / math.sqrt(w2) if w2 > 0.0 else math.inf
                if h_stable > h_damping[lane]:
                    h_stable = h_damping[lane]
                if h_stable > max_step:
                    h_stable = max_step
                steps_left = math.ceil(remaining / h_stable - 1e-9)
                if steps_left <= 1:
                    h[lane] = remaining
                    running[lane] = False
                    active -= 1
                else:
                    h[lane] = remaining / steps_left
                    elapsed[lane] += h[lane]
                from_rest[lane] = h_last[lane] == 0.0
                blend[lane] = h_last[lane] / (h_last[lane] + h[lane]) if substeps[b] == 0 else 0.0
                inverse_h_mid[lane] = 1.0 / (0.5 * (h_last[lane] + h[lane]))
            stop = start + lanes
            # 1-D views over the block's lanes, taken out of the lane loops: with them LLVM
            # vectorises the loops (indexing the 3-D arrays inside them, it did not).
            any_from_rest = False
            for lane in range(lanes):
                any_from_rest = any_from_rest or (from_rest[lane] and h[lane] > 0.0)
            for i in range(n):
                node_mass = mass[i, start:stop]
                node_damping = damping[i, start:stop]
                # Per node, as the scalar kick computes them once for its three axes.
                for lane in range(lanes):
                    inertia = node_mass[lane] * inverse_h_mid[lane]
                    inverse_lhs[lane] = 1.0 / (inertia + 0.5 * node_damping[lane])
                    rhs_factor[lane] = inertia - 0.5 * node_damping[lane]
                for d in range(3):
                    vel = v[i, d, start:stop]
                    pos = x[i, d, start:stop]
                    internal = f_int[i, d, start:stop]
                    applied_now = f_applied[i, d, start:stop]
                    applied_before = f_previous[i, d, start:stop]
                    if any_from_rest:  # the first sub-step after a reset, in some lane: both kicks
                        for lane in range(lanes):
                            step = h[lane]
                            velocity = vel[lane]
                            force = internal[lane]
                            applied = applied_now[lane]
                            accelerated = velocity + 0.5 * step * (
                                (applied - force - node_damping[lane] * velocity) / node_mass[lane]
                            )
                            p_dual = applied + blend[lane] * (applied_before[lane] - applied)
                            kicked = (rhs_factor[lane] * velocity + p_dual - force) * inverse_lhs[lane]
                            updated = accelerated if from_rest[lane] else kicked
                            velocity = updated if step > 0.0 else velocity
                            vel[lane] = velocity
                            pos[lane] += step * velocity
                            internal[lane] = 0.0
                    else:
                        for lane in range(lanes):
                            step = h[lane]
                            velocity = vel[lane]
                            applied = applied_now[lane]
                            p_dual = applied + blend[lane] * (applied_before[lane] - applied)
                            kicked = (rhs_factor[lane] * velocity + p_dual - internal[lane]) * inverse_lhs[lane]
                            velocity = kicked if step > 0.0 else velocity
                            vel[lane] = velocity
                            pos[lane] += step * velocity
                            internal[lane] = 0.0
            for lane in range(lanes):
                omega2_max[lane] = 0.0
            for c in range(cables):
                i = topology[c, 0]
                j = topology[c, 1]
                xi0, xi1, xi2 = x[i, 0, start:stop], x[i, 1, start:stop], x[i, 2, start:stop]
                xj0, xj1, xj2 = x[j, 0, start:stop], x[j, 1, start:stop], x[j, 2, start:stop]
                fi0, fi1, fi2 = f_int[i, 0, start:stop], f_int[i, 1, start:stop], f_int[i, 2, start:stop]
                fj0, fj1, fj2 = f_int[j, 0, start:stop], f_int[j, 1, start:stop], f_int[j, 2, start:stop]
                cable_rest = rest[c, start:stop]
                cable_stiffness = stiffness[c, start:stop]
                cable_pretension = pretension[c, start:stop]
                cable_inverse_mass = inverse_mass_sum[c, start:stop]
                for lane in range(lanes):
                    dx = xj0[lane] - xi0[lane]
                    dy = xj1[lane] - xi1[lane]
                    dz = xj2[lane] - xi2[lane]
                    length = math.sqrt(dx * dx + dy * dy + dz * dz)
                    inverse_length = 1.0 / length
                    n_taut = cable_pretension[lane] + cable_stiffness[lane] * (length - cable_rest[lane])
                    n_cable = n_taut if n_taut > 0.0 else 0.0
                    geometric = n_cable * inverse_length
                    k_max = cable_stiffness[lane] if cable_stiffness[lane] >= geometric else geometric
                    w2 = k_max * cable_inverse_mass[lane]
                    omega2_max[lane] = w2 if w2 > omega2_max[lane] else omega2_max[lane]
                    fx = n_cable * (dx * inverse_length)
                    fy = n_cable * (dy * inverse_length)
                    fz = n_cable * (dz * inverse_length)
                    fi0[lane] -= fx
                    fi1[lane] -= fy
                    fi2[lane] -= fz
                    fj0[lane] += fx
                    fj1[lane] += fy
                    fj2[lane] += fz
            for lane in range(lanes):
                b = start + lane
                if h[lane] > 0.0:
                    omega2[b] = omega2_max[lane]
                    h_last[lane] = h[lane]
                    substeps[b] += 1
        for lane in range(lanes):
            b = start + lane
            last_step[b] = h_last[lane]
            for i in range(n):
                for d in range(3):
                    f_previous[i, d, b] = f_applied[i, d, b]
