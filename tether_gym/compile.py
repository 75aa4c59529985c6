"""Compile tether-gym's numba kernels ahead of time: ``python -m tether_gym.compile``.

Without it, the first ``gym.make(...).step`` of a fresh install compiles the kernels the single
env needs (8.6-9.1 s from import to the first step on the project's quiet 2-core machine), and
the first step of a vector env of 16 or more the multi-threaded ones (about 2.5 s more); the
log says which group of kernels is compiling.  This command compiles all of them once, with a
line per kernel, into numba's cache (next to the package, or in ``NUMBA_CACHE_DIR``), from
which every later process loads them.  Run it after installing, or in a container image build.
Exit status 0 when every kernel is in the cache.

It runs two processes where there are two cores or more (``--jobs 1``: one): numba compiles one
function at a time per process, and a second process compiles the task's evaluation while this
one compiles the integrator (the two share no kernel).  On the quiet 2-core machine that took
10.3-11.7 s against 13.2 s in one process; with one of its cores busy elsewhere the second
process only shared the other (13.9-14.5 s against 13.1-13.9 s).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import threading
import time
from collections.abc import Callable

import numpy as np

import tether_gym
from tether_gym import _kernels
from tether_gym._cli import program
from tether_gym._compilation import COMPILATIONS, GROUPS, group_of
from tether_gym._kernels import LANE_MIN_BATCH
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
    for checked in (np.zeros((4, 3)), np.zeros((1, 4, 3))):  # the simulators' checks of their inputs
        _kernels.all_within(checked, 1.0)


def _parallel_task(batch: int) -> Callable[[], None]:
    def build() -> None:
        task = DampingTask(make_cluster(_CLUSTER), batch, TaskConfig())
        task.evaluate()  # a vector env's reset
        task.step(np.zeros((batch, task.action_size)), rngs=[np.random.default_rng(0)] * batch)

    return build


def _lanes() -> None:
    """The lanes' block kernel alone, with the argument types the lane driver passes."""
    sim = BatchSimulator(make_cluster(_CLUSTER), 1)
    members = np.zeros(1, dtype=np.int64)
    tables = (sim.node_table, sim.cable_table, sim.cluster_table, sim.counter_table)
    _kernels._advance_lanes(1e-3, sim.kernel_settings, sim.cables, *tables, np.zeros((1, 0)), members)


#: What to compile, in order: (kernel, its qualified name, by which ``tether_gym._compilation``
#: finds its group, a call that needs it and little else, its stage).  Each line compiles what it
#: names: the fused step after the kernels it calls, the parallel kernels after the serial ones
#: they call on chunks.  With two processes the ``"alongside"`` kernels compile in the second one
#: while this one compiles the integrator (they share no kernel: two processes compiling one would
#: both write its entry in the cache), after the ``"first"`` one, whose cable forces every
#: simulator the task's lines build calls, and before the ``"last"`` ones, which call both.
KERNELS: tuple[tuple[str, str, Callable[[], None], str], ...] = (
    ("evaluate_forces", "evaluate_forces", _queries, "first"),
    ("advance_serial", "_advance_clusters", _advance(1), "here"),
    ("advance_parallel", "advance_parallel", _advance(PARALLEL_MIN_BATCH), "here"),
    ("remove_rigid_velocity", "remove_rigid_velocity", _initial_states_and_actions, "alongside"),
    ("evaluate_serial", "_compile_cluster_evaluation.<locals>.evaluate_clusters", _task(1, step=False), "alongside"),
    (
        "command_forces",
        "_compile_command_forces.<locals>.command_forces",
        _task(1, step=True, thrust_noise=0.1),
        "last",
    ),
    ("step_serial", "_compile_step.<locals>.step_clusters", _task(1, step=True), "last"),
    ("parallel_task", "_compile_parallel_task.<locals>.parallel_task", _parallel_task(PARALLEL_MIN_BATCH), "last"),
    ("advance_lanes", "_advance_lanes", _lanes, "alongside"),
    ("advance_parallel_in_lanes", "advance_parallel_in_lanes", _advance(LANE_MIN_BATCH), "here"),
    (
        "parallel_task_in_lanes",
        "_compile_parallel_task.<locals>.parallel_task_in_lanes",
        _parallel_task(LANE_MIN_BATCH),
        "last",
    ),
)

#: A line of the second process that carries one kernel's result: ``<tag> <index> <compiled> <seconds>``.
_RESULT_TAG = "tether-gym-compile-result"


def _what(qualified_name: str) -> str:
    group = group_of(qualified_name)
    assert group is not None, f"{qualified_name} is in no group of tether_gym._compilation.GROUPS"
    return GROUPS[group][0]


def _warm_one(index: int, report: Callable[[str], None]) -> tuple[str, int, float]:
    """Compile (or load) kernel ``index`` (1-based) of :data:`KERNELS`, reporting its line."""
    name, qualified_name, call, _ = KERNELS[index - 1]
    before = len(COMPILATIONS.compiled)
    start = time.perf_counter()
    call()
    seconds = time.perf_counter() - start
    compiled = len(COMPILATIONS.compiled) - before
    how = f"compiled ({compiled} function{'s' if compiled != 1 else ''})" if compiled else "loaded from the cache"
    report(f"[{index}/{len(KERNELS)}] {name:<22} {_what(qualified_name):<48} {how} in {seconds:.1f} s")
    return name, compiled, seconds


def _start_second_process(indices: list[int]) -> subprocess.Popen[str]:
    command = [sys.executable, "-m", "tether_gym.compile", "--kernels", ",".join(map(str, indices))]
    return subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def warm(report: Callable[[str], None] = print, jobs: int = 2) -> list[tuple[str, int, float]]:
    """Compile (or load from numba's cache) every kernel of :data:`KERNELS`, reporting a line per
    kernel through ``report``, in ``jobs`` processes (1 or 2); returns ``(kernel, functions
    compiled, seconds)`` per kernel, in the order of :data:`KERNELS`."""
    if jobs not in (1, 2):
        raise ValueError(f"jobs must be 1 or 2 (the kernels fall into two independent lines); got {jobs!r}")
    COMPILATIONS.quiet = True  # this command reports its own progress
    results: dict[int, tuple[str, int, float]] = {}

    def stage(name: str) -> list[int]:
        return [index for index, entry in enumerate(KERNELS, start=1) if entry[3] == name]

    def run(indices: list[int]) -> None:
        for index in indices:
            results[index] = _warm_one(index, report)

    run(stage("first"))
    if jobs == 2:
        second = _start_second_process(stage("alongside"))
        relay = threading.Thread(target=_relay, args=(second, report, results), daemon=True)
        relay.start()
        run(stage("here"))
        _finish(second, relay)
    else:
        run(stage("here") + stage("alongside"))
    run(stage("last"))
    missing = [KERNELS[index - 1][0] for index in range(1, len(KERNELS) + 1) if index not in results]
    if missing:
        raise RuntimeError(f"the second compiling process reported no result for {missing}")
    return [results[index] for index in range(1, len(KERNELS) + 1)]


def _relay(
    process: subprocess.Popen[str], report: Callable[[str], None], results: dict[int, tuple[str, int, float]]
) -> None:
    """Pass the second process's lines on to ``report`` as they come, and keep its results."""
    assert process.stdout is not None
    for line in process.stdout:
        if line.startswith(_RESULT_TAG):
            _, index, compiled, seconds = line.split()
            results[int(index)] = (KERNELS[int(index) - 1][0], int(compiled), float(seconds))
        else:
            report(line.rstrip("\n"))


def _finish(process: subprocess.Popen[str], relay: threading.Thread) -> None:
    relay.join()
    assert process.stderr is not None
    errors = process.stderr.read()
    if process.wait() != 0:
        raise RuntimeError(f"the second compiling process failed (exit status {process.returncode}):\n{errors}")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        prog=program("tether_gym.compile", "tether-gym-compile"), description=(__doc__ or "").split("\n\n")[0]
    )
    parser.add_argument(
        "--jobs",
        type=int,
        choices=(1, 2),
        default=min(2, os.cpu_count() or 1),
        help="processes (default: 2 where there are 2 cores or more)",
    )
    parser.add_argument(
        "--kernels",
        metavar="I,J,...",
        help="compile only these kernels (1-based places in tether_gym.compile.KERNELS, comma-separated): how the "
        "first process hands kernels to the second",
    )
    arguments = parser.parse_args(argv)
    if arguments.kernels:
        COMPILATIONS.quiet = True
        for index in map(int, arguments.kernels.split(",")):
            _, compiled, seconds = _warm_one(index, lambda line: print(line, flush=True))
            print(f"{_RESULT_TAG} {index} {compiled} {seconds}", flush=True)
        return
    cache = _kernels.advance_serial.stats.cache_path
    processes = "one process" if arguments.jobs == 1 else "two processes"
    print(f"tether-gym {tether_gym.__version__}: compiling {len(KERNELS)} kernels in {processes} into {cache}")
    start = time.perf_counter()
    results = warm(jobs=arguments.jobs)
    compiled = sum(1 for _, count, _ in results if count)
    print(f"done in {time.perf_counter() - start:.1f} s: {compiled} compiled, {len(results) - compiled} already cached")


if __name__ == "__main__":
    main()
