"""Why the batched advance gains less than 2x from a second thread: ``python benchmarks/thread_scaling.py``.

``BatchSimulator.advance`` on the default id at N = 1 024 (control intervals of 0.1 s from the
env's random initial states), in cluster sub-steps per second, measured in rounds. Each round
runs, one after the other:

1. **one thread** (``numba.set_num_threads(1)``);
2. **two threads** (the parallel kernel, each thread taking chunks of the batch);
3. **two processes**, each advancing its own batch on one thread at the same time: their rates
   added up. This is the most any two-thread version of the same kernel could reach in that
   round: no shared work, no synchronisation, only the hardware that the two share.

Rounds, rather than one long measurement each, because on a virtual machine what two CPUs add
up to can change from one second to the next (the host places and loads the two virtual CPUs),
and a comparison is only fair inside one round: ``threads/processes`` is the threading's
efficiency against the hardware of that round.

Then it takes the two-thread advance apart: the time per call inside the compiled kernel and in
the Python around it (argument checks, copying the force in, the result's copies), for one and
two threads; and the cost of a parallel region with no work, back to back and after 100 µs in
Python (libgomp's worker sleeps after ``GOMP_SPINCOUNT`` spins, and the next region waits for
it to wake). It prints the CPU model and numba's threading layer with the numbers. Run it on a quiet
machine: about 10 s per round plus 15 s.
"""

from __future__ import annotations

import argparse
import multiprocessing
import multiprocessing.synchronize
import os
import statistics
import time
from typing import Any, NamedTuple

import numpy as np

BATCH = 1024
#: Seconds of Python between parallel regions in the wake-up measurement: about what the vector
#: env spends between two steps' kernels at N = 1 024.
GAP_S = 100e-6


class Measurement(NamedTuple):
    """One measurement of the batched advance."""

    rate: float  #: cluster sub-steps per second
    whole_us: float  #: median time of one ``advance(0.1)`` call, µs
    kernel_us: float  #: median time of that call inside the compiled kernel, µs


def _batch() -> tuple[Any, np.ndarray]:
    """The default id's simulator at N = :data:`BATCH` from the env's random initial states, and
    the force that holds its nominal shape."""
    import gymnasium as gym

    import tether_gym  # noqa: F401 - registers the ids

    envs = gym.make_vec(tether_gym.DEFAULT_ENV_ID, num_envs=BATCH)
    envs.reset(seed=0)
    task = envs.unwrapped.task  # type: ignore[attr-defined]
    sim, force = task.sim, np.array(task.force)
    sim.advance(0.1, force)  # compilation or cache load
    return sim, force


def measure(sim: Any, force: np.ndarray, threads: int, seconds: float) -> Measurement:
    """Advance ``sim`` by 0.1 s intervals for ``seconds`` on ``threads`` threads."""
    import numba

    numba.set_num_threads(threads)
    kernel_times: list[float] = []
    run_kernel = type(sim).advance_unchecked

    def timed_kernel(*args: Any) -> None:
        began = time.perf_counter()
        run_kernel(sim, *args)
        kernel_times.append(time.perf_counter() - began)

    sim.advance_unchecked = timed_kernel  # the instance's attribute: advance() calls it
    whole_times: list[float] = []
    substeps, began = 0, time.perf_counter()
    try:
        while time.perf_counter() - began < seconds:
            call = time.perf_counter()
            substeps += int(sim.advance(0.1, force).substeps.sum())
            whole_times.append(time.perf_counter() - call)
    finally:
        del sim.advance_unchecked
    elapsed = time.perf_counter() - began
    return Measurement(substeps / elapsed, 1e6 * statistics.median(whole_times), 1e6 * statistics.median(kernel_times))


def _worker(seconds: float, rounds: int, start: multiprocessing.synchronize.Barrier, results: Any) -> None:
    sim, force = _batch()
    measure(sim, force, 1, 0.2)  # warm
    for _ in range(rounds):
        start.wait()
        results.put(measure(sim, force, 1, seconds).rate)


def region_cost() -> tuple[float, float]:
    """Median µs of a two-thread parallel region with no work: back to back, and after
    :data:`GAP_S` of Python."""
    import numba

    @numba.njit(parallel=True)
    def no_work(out: np.ndarray) -> None:  # pragma: no cover - compiled
        for k in numba.prange(out.shape[0]):
            out[k] += 1.0

    out = np.zeros(16)
    numba.set_num_threads(2)
    no_work(out)
    costs = []
    for gap in (0.0, GAP_S):
        times = []
        for _ in range(2000):
            until = time.perf_counter() + gap
            while time.perf_counter() < until:
                pass
            began = time.perf_counter()
            no_work(out)
            times.append(time.perf_counter() - began)
        costs.append(1e6 * statistics.median(times))
    return costs[0], costs[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=3.0, help="seconds per measurement")
    parser.add_argument("--rounds", type=int, default=3, help="rounds of the three measurements")
    args = parser.parse_args()
    import numba

    from tether_gym.bench import cpu_model

    context = multiprocessing.get_context("spawn")
    start, results = context.Barrier(3), context.Queue()
    workers = [
        context.Process(target=_worker, args=(args.seconds, args.rounds, start, results), daemon=True) for _ in range(2)
    ]
    for worker in workers:
        worker.start()
    sim, force = _batch()
    measure(sim, force, 2, 0.2)  # warm
    spin = os.environ.get("GOMP_SPINCOUNT", "libgomp's default")
    print(f"CPU: {cpu_model()}; numba threading layer: {numba.threading_layer()}; GOMP_SPINCOUNT {spin}")
    print(f"batch {BATCH}, default id, 0.1 s intervals; M sub-steps/s, {args.seconds:g} s per measurement")
    print(
        f"{'round':>5}  {'1 thread':>9}  {'2 threads (parallel kernel)':>27}  {'2 processes of 1 thread':>23}"
        f"  {'threads/processes':>17}"
    )
    ones, twos = [], []
    for round_ in range(1, args.rounds + 1):
        one = measure(sim, force, 1, args.seconds)
        two = measure(sim, force, 2, args.seconds)
        start.wait()  # the workers' round: this process waits on the queue meanwhile
        pair = results.get() + results.get()
        ones.append(one)
        twos.append(two)
        print(
            f"{round_:>5}  {one.rate / 1e6:9.2f}  {two.rate / 1e6:12.2f} ({two.rate / one.rate:.2f}x)"
            f"{'':>7}  {pair / 1e6:10.2f} ({pair / one.rate:.2f}x){'':>4}  {two.rate / pair:17.2f}"
        )
    for worker in workers:
        worker.join()
    back_to_back, after_gap = region_cost()
    print("Per 0.1 s call (medians over the rounds' calls, µs):")
    for threads, runs in ((1, ones), (2, twos)):
        whole = statistics.median(run.whole_us for run in runs)
        kernel = statistics.median(run.kernel_us for run in runs)
        label = f"{threads} thread{'s' if threads > 1 else ' '}"
        print(f"  {label}: whole {whole:7.1f} = kernel {kernel:7.1f} + Python {whole - kernel:6.1f}")
    print(
        f"  a two-thread parallel region with no work: {back_to_back:.1f} back to back, "
        f"{after_gap:.1f} after {GAP_S * 1e6:.0f} µs in Python"
    )


if __name__ == "__main__":
    main()
