"""Compile tether-gym's numba kernels ahead of time: ``python -m tether_gym.compile``.

Without it, the first ``gym.make(...).step`` of a fresh install compiles the kernels the single
env needs, and the first step of a vector env the multi-threaded ones, tens of seconds each.
This command compiles all of them once, with a line per kernel, into numba's cache (next to the
package, or in ``NUMBA_CACHE_DIR``), from which every later process loads them.  Run it after
installing, or in a container image build.  Exit status 0 when every kernel is in the cache.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numpy as np

import tether_gym
from tether_gym import _kernels
from tether_gym._cli import program
from tether_gym._compilation import COMPILATIONS, GROUPS, group_of
from tether_gym.envs import _task_kernels
from tether_gym.envs.config import TaskConfig
from tether_gym.envs.task import DampingTask
from tether_gym.presets import make_cluster
from tether_gym.simulator import PARALLEL_MIN_BATCH, BatchSimulator

__all__ = ["KERNELS", "main", "warm"]

#: A small cluster whose kernels' signatures are those of every cluster (the topology is data).
_CLUSTER = "tetrahedron"


def _queries() -> None:
    BatchSimulator(make_cluster(_CLUSTER), 1)


def _advance(batch: int) -> Callable[[], None]:
    def advance() -> None:
        BatchSimulator(make_cluster(_CLUSTER), batch).advance(1e-3)

    return advance


def _initial_states() -> None:
    x = np.zeros((1, 4, 3))
    _task_kernels.remove_rigid_velocity(x, np.zeros((1, 4, 3)), np.ones((1, 4)))


def _task(batch: int, step: bool, thrust_noise: float = 0.0) -> Callable[[], None]:
    def build() -> None:
        task = DampingTask(make_cluster(_CLUSTER), batch, TaskConfig(thrust_noise=thrust_noise))
        if step:
            task.step(np.zeros((batch, task.action_size)), rngs=[np.random.default_rng(0) for _ in range(batch)])

    return build


def _initial_states_and_actions() -> None:
    _initial_states()
    for shape in ((3,), (1, 3)):  # a single env's action and a vector env's
        _kernels.all_finite(np.zeros(shape))


def _parallel_task() -> None:
    task = DampingTask(make_cluster(_CLUSTER), PARALLEL_MIN_BATCH, TaskConfig())
    task.evaluate()  # a vector env's reset
    task.step(np.zeros((PARALLEL_MIN_BATCH, task.action_size)), rngs=[np.random.default_rng(0)] * PARALLEL_MIN_BATCH)


#: What to compile, in order: (kernel, its qualified name, by which ``tether_gym._compilation``
#: finds its group, a call that needs it and little else).  Each line compiles what it names: the
#: fused step after the three kernels it calls, the parallel kernels after the serial ones they
#: call on chunks.
KERNELS: tuple[tuple[str, str, Callable[[], None]], ...] = (
    ("evaluate_forces", "evaluate_forces", _queries),
    ("advance_serial", "_advance_clusters", _advance(1)),
    ("advance_parallel", "advance_parallel", _advance(PARALLEL_MIN_BATCH)),
    ("remove_rigid_velocity", "remove_rigid_velocity", _initial_states_and_actions),
    ("evaluate_serial", "_compile_cluster_evaluation.<locals>.evaluate_clusters", _task(1, step=False)),
    ("command_forces", "_compile_command_forces.<locals>.command_forces", _task(1, step=True, thrust_noise=0.1)),
    ("step_serial", "_compile_step.<locals>.step_clusters", _task(1, step=True)),
    ("parallel_task", "_compile_parallel_task.<locals>.parallel_task", _parallel_task),
)


def _what(qualified_name: str) -> str:
    group = group_of(qualified_name)
    assert group is not None, f"{qualified_name} is in no group of tether_gym._compilation.GROUPS"
    return GROUPS[group][0]


def warm(report: Callable[[str], None] = print) -> list[tuple[str, int, float]]:
    """Compile (or load from numba's cache) every kernel of :data:`KERNELS`, reporting a line per
    kernel through ``report``; returns ``(kernel, functions compiled, seconds)`` per kernel."""
    COMPILATIONS.quiet = True  # this command reports its own progress
    results = []
    for index, (name, qualified_name, call) in enumerate(KERNELS, start=1):
        what = _what(qualified_name)
        before = len(COMPILATIONS.compiled)
        start = time.perf_counter()
        call()
        seconds = time.perf_counter() - start
        compiled = len(COMPILATIONS.compiled) - before
        how = f"compiled ({compiled} function{'s' if compiled != 1 else ''})" if compiled else "loaded from the cache"
        report(f"[{index}/{len(KERNELS)}] {name:<22} {what:<48} {how} in {seconds:.1f} s")
        results.append((name, compiled, seconds))
    return results


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        prog=program("tether_gym.compile", "tether-gym-compile"), description=(__doc__ or "").split("\n\n")[0]
    )
    parser.parse_args(argv)
    cache = _kernels.advance_serial.stats.cache_path
    print(f"tether-gym {tether_gym.__version__}: compiling {len(KERNELS)} kernels into numba's cache ({cache})")
    start = time.perf_counter()
    results = warm()
    compiled = sum(1 for _, count, _ in results if count)
    print(f"done in {time.perf_counter() - start:.1f} s: {compiled} compiled, {len(results) - compiled} already cached")


if __name__ == "__main__":
    main()
