"""Why the batched advance gains little from a second thread: ``python benchmarks/thread_scaling.py``.

Three measurements of ``BatchSimulator.advance`` on the default id at N = 1 024 (control
intervals of 0.1 s from the env's random initial states), in cluster sub-steps per second:

1. **one thread** (``numba.set_num_threads(1)``);
2. **two threads** (the parallel kernel, each thread taking chunks of the batch);
3. **two processes**, each advancing its own batch on one thread, started together: their rates
   added up. This is the most any two-thread version of the same kernel could reach on this
   machine: no shared work, no synchronisation, only the hardware that the two share.

If (3) is close to twice (1), the hardware scales and the threading costs what (2) lacks; if (3)
is no better than (2), the two CPUs do not add up for this kernel (they share a physical core's
floating-point units, or its caches), and no threading change would help. It prints the CPU
model and numba's threading layer with the numbers. Run it on a quiet machine: about 30 s.
"""

from __future__ import annotations

import argparse
import multiprocessing
import time

import numpy as np

BATCH = 1024


def rate(threads: int, seconds: float, start: multiprocessing.synchronize.Event | None = None) -> float:
    """Sub-steps per second of the default id's batched advance on ``threads`` threads."""
    import gymnasium as gym
    import numba

    import tether_gym  # noqa: F401 - registers the ids

    envs = gym.make_vec(tether_gym.DEFAULT_ENV_ID, num_envs=BATCH)
    envs.reset(seed=0)
    task = envs.unwrapped.task  # type: ignore[attr-defined]
    sim, force = task.sim, np.array(task.force)
    numba.set_num_threads(threads)
    sim.advance(0.1, force)  # compilation or cache load
    if start is not None:
        start.wait()
    substeps, began = 0, time.perf_counter()
    while time.perf_counter() - began < seconds:
        substeps += int(sim.advance(0.1, force).substeps.sum())
    return substeps / (time.perf_counter() - began)


def _worker(seconds: float, start: multiprocessing.synchronize.Event, results: multiprocessing.Queue) -> None:
    results.put(rate(1, seconds, start))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=5.0, help="seconds per measurement")
    args = parser.parse_args()
    import numba

    from tether_gym.bench import cpu_model

    cpu = cpu_model()
    one = rate(1, args.seconds)
    two = rate(2, args.seconds)
    context = multiprocessing.get_context("spawn")
    start, results = context.Event(), context.Queue()
    workers = [context.Process(target=_worker, args=(args.seconds, start, results)) for _ in range(2)]
    for worker in workers:
        worker.start()
    time.sleep(8.0)  # both have loaded the kernels and wait at the start line
    start.set()
    each = [results.get() for _ in workers]
    for worker in workers:
        worker.join()
    print(f"CPU: {cpu}; numba threading layer: {numba.threading_layer()}; batch {BATCH}, default id")
    print(f"  1 thread                     {one / 1e6:6.2f} M sub-steps/s")
    print(f"  2 threads (parallel kernel)  {two / 1e6:6.2f} M sub-steps/s  ({two / one:.2f}x)")
    print(
        f"  2 processes of 1 thread      {sum(each) / 1e6:6.2f} M sub-steps/s  ({sum(each) / one:.2f}x; "
        f"each {each[0] / 1e6:.2f} and {each[1] / 1e6:.2f})"
    )


if __name__ == "__main__":
    main()
