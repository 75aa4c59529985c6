"""Cost of a beaded line per simulated second against its segment count N.

What it measures
----------------
The issue's probe line (L = 100 m between two 50 kg satellites, a 2 kg tether, EA = 40 kN,
pretension 5 N) split into N segments (N = 1: the massless cable of the paper), taut and
vibrating in its first transverse mode (0.05 m), at the default safety factor.  For one cluster
and for a batch (default 256 clusters), advanced in 0.1 s intervals (the environments' pattern):

* wall time per simulated second of one cluster (for a batch: of the whole batch, and per
  cluster), ms;
* the ratio to the massless line;
* sub-steps per simulated second, and the wall time per node and sub-step, ns (what the bead
  loops cost per unit of work: flat when the time goes into the per-node loops, higher at small
  N where the per-call Python overhead dominates).

Each measurement runs at least ``--target`` seconds of wall time, after a warm-up call that
compiles the kernels; the best of ``--repeats`` is shown (the machine is shared).

With ``--profile`` it shows instead where one cluster's sub-step spends its time, piece by
piece of ``tether_gym._kernels`` (each piece looped on its own over the same tables, one thread):
the velocity and position updates per node, the cable forces per cable (the integrator's
undamped path), the rest of a sub-step (step size, the pair's bookkeeping, the call), and what
each 0.1 s interval adds once (the energy books and the damping step).

Usage::

    python benchmarks/tether_cost.py            # about 30 s on two shared cores
    python benchmarks/tether_cost.py --quick    # N up to 16, batches 1 and 16
    python benchmarks/tether_cost.py --profile  # where a sub-step's time goes, N = 1, 8, 32 (about 20 s)
"""

from __future__ import annotations

import argparse
import math
import time
from typing import Any

import numpy as np
from numba import njit

import tether_gym as tg
from tether_gym import _kernels as kernels
from tether_gym.tethers import Tether, build_cluster

LENGTH, SAT_MASS, LINE_MASS, EA, TENSION = 100.0, 50.0, 2.0, 40e3, 5.0
INTERVAL = 0.1  # s, the environments' control interval
AMPLITUDE = 0.05  # m, first transverse mode


def probe_line(segments: int) -> tg.Cluster:
    """The probe's line along x in N segments; N = 1 is the massless cable (no line mass)."""
    if segments == 1:
        spec = Tether((0, 1), EA=EA, segments=1, mass=0.0, N0=TENSION, lumping="none")
    else:
        spec = Tether((0, 1), EA=EA, segments=segments, mass=LINE_MASS, N0=TENSION)
    return build_cluster([[0.0, 0.0, 0.0], [LENGTH, 0.0, 0.0]], SAT_MASS, [spec])


def timed_run(cluster: tg.Cluster, batch: int, target: float) -> tuple[float, float]:
    """(wall seconds per simulated second of the whole batch, sub-steps per simulated second of one
    cluster), advancing ``batch`` copies in 0.1 s intervals for at least ``target`` wall seconds."""
    sim = tg.BatchSimulator(cluster, batch)
    x0 = cluster.positions.copy()
    x0[:, 1] = AMPLITUDE * np.sin(math.pi * x0[:, 0] / LENGTH)
    hold = np.zeros((batch, *x0.shape))
    hold[:, 0, 0], hold[:, 1, 0] = -TENSION, TENSION  # the pretension held at the satellites
    sim.reset(np.repeat(x0[None], batch, axis=0))
    sim.advance(INTERVAL, hold)  # compile / warm up
    sim.reset(np.repeat(x0[None], batch, axis=0))
    calls, began = 0, time.perf_counter()
    substeps = 0
    while True:
        stats = sim.advance(INTERVAL, hold)
        substeps += int(stats.substeps[0])
        calls += 1
        elapsed = time.perf_counter() - began
        if elapsed >= target:
            break
    simulated = calls * INTERVAL
    return elapsed / simulated, substeps / simulated


# The pieces of a sub-step, each looped ``repeats`` times on one cluster's tables (the state
# barely moves: a zero step for the position update, the same positions for the forces).
@njit(error_model="numpy")
def _loop_kick(nodes: np.ndarray, repeats: int) -> None:
    for _ in range(repeats):
        kernels._kick(nodes, 1e-4, 0.0)


@njit(error_model="numpy")
def _loop_drift(nodes: np.ndarray, repeats: int) -> float:
    work = dissipated = 0.0
    for _ in range(repeats):
        work, dissipated = kernels._drift(nodes, 0.0, work, dissipated)
    return work + dissipated


@njit(error_model="numpy")
def _loop_forces(nodes: np.ndarray, cables: np.ndarray, topology: np.ndarray, repeats: int) -> float:
    total = 0.0
    for _ in range(repeats):
        total += kernels._update_forces(nodes, cables, topology, False, False)[0]
    return total


@njit(error_model="numpy")
def _loop_interval(
    nodes: np.ndarray, cables: np.ndarray, cluster: np.ndarray, topology: np.ndarray, repeats: int
) -> float:
    total = 0.0
    for _ in range(repeats):
        total += kernels._energy_runaway(nodes, cables, cluster, topology, False, False, math.inf)
        total += kernels._damping_step(nodes, 0.1)
    return total


def _per_call(function: Any, arguments: tuple[Any, ...], repeats: int) -> float:
    """Best of 5 timings of ``function(*arguments, repeats)``, ns per repeat."""
    function(*arguments, 2)
    best = math.inf
    for _ in range(5):
        began = time.perf_counter()
        function(*arguments, repeats)
        best = min(best, time.perf_counter() - began)
    return 1e9 * best / repeats


def profile(segment_counts: tuple[int, ...] = (1, 8, 32)) -> None:
    """Print where one cluster's sub-step spends its time, per piece (see the module docstring)."""
    print("one cluster, one thread, ns; a sub-step = kick + drift + cable forces + the rest")
    print("    N  nodes  sub-step  kick/node  drift/node  forces/cable  rest of the sub-step  once per interval")
    for segments in segment_counts:
        cluster = probe_line(segments)
        sim = tg.BatchSimulator(cluster, 1)
        x0 = cluster.positions.copy()
        x0[:, 1] = AMPLITUDE * np.sin(math.pi * x0[:, 0] / LENGTH)
        sim.reset(x0[None])
        hold = np.zeros((1, *x0.shape))
        hold[:, 0, 0], hold[:, 1, 0] = -TENSION, TENSION  # as timed_run: the line stays taut
        sim.advance(INTERVAL, hold)
        nodes, cables, clusters = sim.node_table[0].copy(), sim.cable_table[0].copy(), sim.cluster_table[0].copy()
        n, m = cluster.num_nodes, cluster.num_cables
        repeats = max(2_000, 400_000 // (n + m))
        kick = _per_call(_loop_kick, (nodes.copy(),), repeats)
        drift = _per_call(_loop_drift, (nodes.copy(),), repeats)
        forces = _per_call(_loop_forces, (nodes.copy(), cables.copy(), sim.cables), repeats)
        interval = _per_call(_loop_interval, (nodes, cables, clusters, sim.cables), max(200, repeats // 10))
        duration = 10.0 if segments == 1 else 0.5  # one long advance: no per-call overhead
        kernels.advance_serial(
            0.01, sim._all_active, sim.kernel_settings, sim.cables, sim.node_table, sim.cable_table,
            sim.cluster_table, sim.counter_table, sim._no_record,
        )  # fmt: skip
        best = math.inf
        for _ in range(5):
            began = time.perf_counter()
            kernels.advance_serial(
                duration, sim._all_active, sim.kernel_settings, sim.cables, sim.node_table, sim.cable_table,
                sim.cluster_table, sim.counter_table, sim._no_record,
            )  # fmt: skip
            best = min(best, time.perf_counter() - began)
        substep = 1e9 * best / int(sim.counter_table[0, kernels.SUBSTEPS])
        rest = substep - kick - drift - forces
        print(
            f"{segments:5d}  {n:5d}  {substep:8.1f}  {kick / n:9.2f}  {drift / n:10.2f}  {forces / m:12.2f}  "
            f"{rest:20.1f}  {interval:17.1f}",
            flush=True,
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="N = 1, 4, 16; batches 1 and 16; short runs")
    parser.add_argument("--batch", type=int, default=256, help="the batch size besides one cluster")
    parser.add_argument("--target", type=float, default=1.0, help="wall seconds per measurement")
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--profile", action="store_true", help="where one cluster's sub-step spends its time")
    args = parser.parse_args()
    if args.profile:
        profile()
        return
    segment_counts: tuple[int, ...]
    batches: tuple[int, ...]
    if args.quick:
        segment_counts, batches, target, repeats = (1, 4, 16), (1, 16), 0.1, 1
    else:
        segment_counts, batches, target, repeats = (1, 4, 8, 16, 32, 64), (1, args.batch), args.target, args.repeats
    print(
        f"probe line, taut, first transverse mode {AMPLITUDE:g} m, safety factor {tg.simulator.DEFAULT_SAFETY_FACTOR:g}"
    )
    print("    B     N  substeps/sim-s  ms wall/sim-s (batch)  ms/sim-s per cluster  x massless  ns per node-substep")
    for batch in batches:
        massless = math.nan
        for segments in segment_counts:
            cluster = probe_line(segments)
            best, substeps = math.inf, 0.0
            for _ in range(repeats):
                wall, substeps = timed_run(cluster, batch, target)
                best = min(best, wall)
            per_cluster = best / batch
            if segments == 1:
                massless = per_cluster
            node_ns = 1e9 * per_cluster / (substeps * cluster.num_nodes)
            print(
                f"{batch:5d}  {segments:4d}  {substeps:14.0f}  {1e3 * best:21.3f}  {1e3 * per_cluster:20.4f}  "
                f"{per_cluster / massless:10.0f}  {node_ns:18.1f}",
                flush=True,
            )


if __name__ == "__main__":
    main()
