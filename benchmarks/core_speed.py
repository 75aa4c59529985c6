"""Speed of the physics core: cluster sub-steps per second and the cost of the critical-step estimate.

What it measures
----------------
(a) Throughput of :meth:`tether_gym.BatchSimulator.advance` for the default tetrahedron (preset
    damping, default safety factor) started from large random displacements, so that cables go
    slack and snap taut as in training, at several batch sizes B:

    * ``long``    one ``advance(duration)`` call (default 10 s simulated): the kernel's rate with
                  the Python overhead amortised;
    * ``control`` repeated ``advance(0.1)`` calls over the same simulated time: the environment's
                  pattern (one call per control interval), where the per-call overhead shows.

    It reports cluster sub-steps per wall second (sub-steps summed over the B clusters), the
    calls per second of the control pattern, and the environment steps (clusters x control
    intervals) per second.  Every measurement resets the same initial state and is repeated; the
    best and the median are shown.

(b) Cost of the critical-step estimate.  The closed form is computed inside the force pass of the
    kernel, so its cost is that of one force evaluation; it is timed here as
    ``BatchSimulator.internal_forces(X)`` (one Python-level force evaluation of the batch).  The
    paper's finite-difference reference, ``critical_time_step("finite-difference")`` (12 perturbed
    element-force evaluations per cable, in numpy), is timed and expressed as a multiple of that.
    Reading the closed-form value (``critical_time_step("closed-form")``) is also timed: it returns
    the value cached by the last force pass.

The first call compiles the numba kernels (a few seconds, or less from the on-disk cache); it is
done before any timing.  Runs in well under two minutes on two cores (``--quick``: seconds).

Usage::

    python benchmarks/core_speed.py
    python benchmarks/core_speed.py --quick
    python benchmarks/core_speed.py --batches 1 1024 --duration 5 --repeats 5
"""

from __future__ import annotations

import argparse
import os
import platform
import shlex
import statistics
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numba
import numpy as np

import tether_gym as tg
from tether_gym import simulator as simulator_module

CONTROL_INTERVAL = 0.1  # s, the environment's control interval


@dataclass
class Timing:
    """Wall-clock seconds of repeated runs of one measurement."""

    samples: list[float]

    @property
    def best(self) -> float:
        return min(self.samples)

    @property
    def median(self) -> float:
        return statistics.median(self.samples)


def time_repeated(run: Callable[[], object], repeats: int, setup: Callable[[], object] | None = None) -> Timing:
    """Time ``run()`` ``repeats`` times with ``time.perf_counter``; ``setup()`` runs untimed before each."""
    samples = []
    for _ in range(repeats):
        if setup is not None:
            setup()
        start = time.perf_counter()
        run()
        samples.append(time.perf_counter() - start)
    return Timing(samples)


def time_per_call(run: Callable[[], object], repeats: int, min_seconds: float = 0.05) -> Timing:
    """Seconds per call of a fast ``run()``: each sample loops enough calls to last ``min_seconds``."""
    run()
    calls = 1
    while True:
        start = time.perf_counter()
        for _ in range(calls):
            run()
        if time.perf_counter() - start >= min_seconds:
            break
        calls *= 2
    samples = []
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(calls):
            run()
        samples.append((time.perf_counter() - start) / calls)
    return Timing(samples)


def random_state(cluster: tg.Cluster, batch: int, amplitude: float, seed: int) -> np.ndarray:
    """(B, n, 3) nominal positions plus Gaussian displacements of std ``amplitude`` m (centre of
    mass kept): cables start stretched by metres and then go slack and snap taut."""
    rng = np.random.default_rng(seed)
    displacement = amplitude * rng.standard_normal((batch, cluster.num_nodes, 3))
    displacement -= displacement.mean(axis=1, keepdims=True)
    # A draw that shortens every cable would leave a cluster slack and at rest: reverse it.
    x = cluster.positions[None] + displacement
    lengths = np.linalg.norm(x[:, cluster.cables[:, 1]] - x[:, cluster.cables[:, 0]], axis=-1)
    all_slack = (cluster.N0 + cluster.stiffness * (lengths - cluster.L0) <= 0.0).all(axis=1)
    displacement[all_slack] *= -1.0
    return cluster.positions[None] + displacement


@dataclass
class ThroughputRow:
    batch: int
    mode: str
    substeps: int  # cluster sub-steps per measurement (summed over the batch)
    calls: int  # advance calls per measurement
    timing: Timing
    slack_fraction: float  # fraction of (cluster, cable) pairs slack, sampled at the end of each call

    def rate(self, seconds: float) -> float:
        return self.substeps / seconds


def measure_throughput(
    cluster: tg.Cluster, batch: int, duration: float, amplitude: float, repeats: int, seed: int
) -> list[ThroughputRow]:
    """Sub-step rates of one long advance and of repeated control-interval advances."""
    sim = tg.BatchSimulator(cluster, batch)
    x0 = random_state(cluster, batch, amplitude, seed)
    sim.reset(x0)
    calls = max(1, round(duration / CONTROL_INTERVAL))
    counted: dict[str, int] = {}

    def reset() -> None:
        sim.reset(x0)
        counted.clear()

    def long_run() -> None:
        stats = sim.advance(duration)
        counted["substeps"] = int(stats.substeps.sum())

    def control_run() -> None:
        total = 0
        for _ in range(calls):
            total += int(sim.advance(CONTROL_INTERVAL).substeps.sum())
        counted["substeps"] = total

    rows = []
    for mode, run, n_calls in (("long", long_run, 1), ("control", control_run, calls)):
        timing = time_repeated(run, repeats, setup=reset)
        substeps = counted["substeps"]
        # Slack statistics (untimed): one more control-pattern pass, sampling after every call.
        reset()
        fractions = []
        for _ in range(calls):
            sim.advance(CONTROL_INTERVAL)
            fractions.append(float(sim.slack.mean()))
        rows.append(ThroughputRow(batch, mode, substeps, n_calls, timing, float(np.mean(fractions))))
        if sim.status.any():
            raise RuntimeError(f"{int(np.count_nonzero(sim.status))} clusters diverged at B={batch}")
    return rows


@dataclass
class EstimateRow:
    batch: int
    force: Timing  # one internal_forces(X) call
    closed_form: Timing  # critical_time_step("closed-form")
    finite_difference: Timing  # critical_time_step("finite-difference")
    fd_over_closed_step: tuple[float, float]  # (min, max) of the FD step / closed-form step


def measure_estimates(cluster: tg.Cluster, batch: int, amplitude: float, repeats: int, seed: int) -> EstimateRow:
    """Cost of one force evaluation and of the two critical-step estimates at a slack/snap state."""
    sim = tg.BatchSimulator(cluster, batch)
    sim.reset(random_state(cluster, batch, amplitude, seed))
    sim.advance(3.0)  # a state with a mix of slack and taut cables
    x = np.array(sim.positions)
    force = time_per_call(lambda: sim.internal_forces(x), repeats)
    closed = time_per_call(lambda: sim.critical_time_step("closed-form"), repeats)
    fd = time_per_call(lambda: sim.critical_time_step("finite-difference"), repeats)
    ratio = sim.critical_time_step("finite-difference") / sim.critical_time_step("closed-form")
    return EstimateRow(batch, force, closed, fd, (float(ratio.min()), float(ratio.max())))


def human_rate(value: float) -> str:
    """1.23e6 -> '1.23 M'."""
    for scale, suffix in ((1e9, " G"), (1e6, " M"), (1e3, " k")):
        if value >= scale:
            return f"{value / scale:.3g}{suffix}"
    return f"{value:.3g}  "


def human_time(seconds: float) -> str:
    """Seconds with a unit: ns, us, ms or s."""
    for scale, suffix in ((1.0, "s"), (1e-3, "ms"), (1e-6, "us")):
        if seconds >= scale:
            return f"{seconds / scale:.3g} {suffix}"
    return f"{seconds / 1e-9:.3g} ns"


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        description="Sub-step throughput of the physics core and cost of the critical-step estimates.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    parser.add_argument("--batches", nargs="+", type=int, default=[1, 16, 64, 1024, 4096], help="batch sizes B")
    parser.add_argument("--duration", type=float, default=10.0, help="simulated seconds per measurement")
    parser.add_argument("--repeats", type=int, default=5, help="timed repetitions of each measurement")
    parser.add_argument(
        "--estimate-batches", nargs="+", type=int, default=[1, 1024], help="batch sizes for the critical-step cost"
    )
    parser.add_argument("--amplitude", type=float, default=2.0, help="std of the initial displacements, m")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--quick", action="store_true", help="smoke test: 1 s simulated, B up to 1024, 2 repeats")
    args = parser.parse_args(argv)
    if args.quick:
        args.duration, args.repeats = 1.0, 2
        args.batches = [b for b in args.batches if b <= 1024]
    if args.duration < CONTROL_INTERVAL or args.repeats < 1 or min(args.batches + args.estimate_batches) < 1:
        parser.error(f"need --duration >= {CONTROL_INTERVAL} s, --repeats >= 1 and positive batch sizes")
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    words = [Path(sys.argv[0]).name, *(sys.argv[1:] if argv is None else argv)]
    command = " ".join(shlex.quote(word) for word in words)
    cluster = tg.make_cluster("tetrahedron")
    print(f"command:  python {command}")
    print(
        f"versions: python {platform.python_version()}, numpy {np.__version__}, numba {numba.__version__}, "
        f"tether-gym {tg.__version__}"
    )
    print(
        f"machine:  {os.cpu_count()} cores, numba threads {numba.get_num_threads()}, "
        f"threading layer {numba.config.THREADING_LAYER}; {platform.machine()} {platform.system()}"
    )

    # Compile every kernel (serial and parallel advance, force evaluation) before timing.
    start = time.perf_counter()
    for batch in (1, simulator_module.PARALLEL_MIN_BATCH):
        warm = tg.BatchSimulator(cluster, batch)
        warm.advance(CONTROL_INTERVAL)
        warm.critical_time_step("finite-difference")
    print(f"warm-up (compilation or cache load): {time.perf_counter() - start:.2f} s, excluded from timings")

    probe = tg.BatchSimulator(cluster, 1)
    h_crit = float(probe.critical_time_step()[0])
    print(
        f"cluster:  {cluster!r}, safety factor {tg.DEFAULT_SAFETY_FACTOR:g}, closed-form critical step "
        f"{h_crit * 1e3:.1f} ms; initial displacements std {args.amplitude:g} m; parallel kernel from "
        f"B >= {simulator_module.PARALLEL_MIN_BATCH}"
    )

    # ------------------------------------------------------------------ (a) throughput
    print(
        f"\n(a) advance() throughput, {args.duration:g} s simulated per measurement, best / median of "
        f"{args.repeats}; 'long' = one advance({args.duration:g}), 'control' = advance({CONTROL_INTERVAL:g}) "
        "repeated"
    )
    header = (
        f"{'B':>6} {'mode':<8}{'calls':>6}{'sub-steps':>11}{'wall best':>11}{'substeps/s best':>17}"
        f"{'median':>10}{'calls/s':>10}{'env steps/s':>13}{'ns/substep':>12}{'slack':>7}"
    )
    print(header)
    print("-" * len(header))
    all_rows: list[ThroughputRow] = []
    for batch in args.batches:
        rows = measure_throughput(cluster, batch, args.duration, args.amplitude, args.repeats, args.seed)
        all_rows += rows
        for row in rows:
            best = row.timing.best
            env_steps = batch * round(args.duration / CONTROL_INTERVAL) / best  # cluster-intervals per s
            print(
                f"{batch:>6} {row.mode:<8}{row.calls:>6}{row.substeps:>11}{human_time(best):>11}"
                f"{human_rate(row.rate(best)):>17}{human_rate(row.rate(row.timing.median)):>10}"
                f"{(human_rate(row.calls / best) if row.mode == 'control' else '-'):>10}"
                f"{human_rate(env_steps):>13}{1e9 * best / row.substeps:>12.1f}{row.slack_fraction:>7.0%}"
            )
    print(
        "sub-steps are summed over the B clusters; env steps/s = clusters x 0.1 s intervals per wall second; "
        "ns/substep = wall time per cluster sub-step; slack = mean fraction of cables slack."
    )
    by_mode = {row.mode: row for row in all_rows if row.batch == all_rows[0].batch}
    per_cluster = {mode: row.substeps / all_rows[0].batch for mode, row in by_mode.items()}
    print(
        f"'control' takes {per_cluster['control'] / per_cluster['long'] - 1:.0%} more sub-steps than "
        f"'long': each {CONTROL_INTERVAL:g} s interval is split into equal steps no longer than the stable "
        f"one, so the effective factor is {args.duration / per_cluster['control'] / h_crit:.3f}, "
        f"not {tg.DEFAULT_SAFETY_FACTOR:g}."
    )

    # ------------------------------------------------------------------ (b) critical-step estimate
    print(
        "\n(b) cost of the critical-step estimate (per call, best / median), relative to one force "
        "evaluation internal_forces(X)"
    )
    header = (
        f"{'B':>6}{'force eval':>12}{'(median)':>10}{'/cluster':>10}{'closed-form read':>18}"
        f"{'finite-diff':>13}{'(median)':>10}{'/cluster':>10}{'FD / force':>12}{'FD / substep':>14}"
        f"{'FD step / closed':>18}"
    )
    print(header)
    print("-" * len(header))
    for batch in args.estimate_batches:
        row = measure_estimates(cluster, batch, args.amplitude, max(args.repeats, 5), args.seed)
        # In-kernel cost of one sub-step of the whole batch (force pass + update), from the long
        # advance at the nearest batch size measured in (a).
        longs = [r for r in all_rows if r.mode == "long"]
        nearest = min(longs, key=lambda r: abs(r.batch - batch), default=None)
        kernel_step = nearest.timing.best / nearest.substeps * batch if nearest else float("nan")
        print(
            f"{batch:>6}{human_time(row.force.best):>12}{human_time(row.force.median):>10}"
            f"{human_time(row.force.best / batch):>10}{human_time(row.closed_form.best):>18}"
            f"{human_time(row.finite_difference.best):>13}{human_time(row.finite_difference.median):>10}"
            f"{human_time(row.finite_difference.best / batch):>10}"
            f"{row.finite_difference.best / row.force.best:>11.1f}x"
            f"{row.finite_difference.best / kernel_step:>13.0f}x"
            f"{row.fd_over_closed_step[0]:>11.3f}-{row.fd_over_closed_step[1]:.3f}"
        )
    print(
        "force eval: BatchSimulator.internal_forces(X), Python checks included; the closed form is\n"
        "  computed in this same pass at no extra cost.  closed-form read: critical_time_step(\n"
        "  'closed-form'), the value cached by the last force pass.  FD / substep: the finite-difference\n"
        "  reference against one in-kernel sub-step of the whole batch (force pass + update; from (a),\n"
        "  'long', nearest B).  FD step / closed: range over clusters of the ratio of the two estimates\n"
        "  (<= 1 expected)."
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
