"""Word to the user when tether-gym's numba kernels compile.

On a fresh install the first ``gym.make(...).step`` compiles the kernels the single env needs,
and the first step of a large vector env the multi-threaded ones, a few seconds each; numba's
cache then keeps them for later processes.  A listener on numba's compile event (fired only when
a kernel is about to compile, not when it loads from the cache) logs one line per kernel group,
when the group's first kernel starts compiling in this process: what it is, its place among the
:data:`GROUPS` and the seconds spent compiling so far.  The first line also says where the cache
is and how to compile everything ahead of time.  The listener counts the compilations for
:mod:`tether_gym.compile`, which reports its own progress instead.
"""

from __future__ import annotations

import logging
import time
from typing import Any

from numba.core import event

__all__ = ["COMPILATIONS", "GROUPS", "HINT", "LOGGER", "MESSAGE", "group_of"]

LOGGER = logging.getLogger("tether_gym")

#: The kernel groups, in the order a single env and then a vector env first need them: (what the
#: group does, the qualified names of the kernels Python calls).  The helpers those kernels call
#: compile within them and are not named.  Every kernel of :data:`tether_gym.compile.KERNELS` is
#: in one group (a test checks it).
GROUPS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("the cable forces of resets and queries", ("evaluate_forces",)),
    ("the initial states and the input checks", ("remove_rigid_velocity", "all_finite", "all_within")),
    ("the observation and reward", ("_compile_cluster_evaluation.<locals>.evaluate_clusters",)),
    (
        "a whole task step, one thread",
        ("_compile_step.<locals>.step_clusters", "_compile_command_forces.<locals>.command_forces"),
    ),
    ("the integrator, one thread", ("_advance_clusters",)),
    ("the integrator, all threads", ("advance_parallel",)),
    ("a vector env's step and evaluation, all threads", ("_compile_parallel_task.<locals>.parallel_task",)),
    (
        "the integrator in SIMD lanes, all threads (batches of 128 or more)",
        ("advance_parallel_in_lanes", "_advance_lanes", "_advance_clusters_in_lanes"),
    ),
    (
        "a vector env's step in SIMD lanes, all threads (128 envs or more)",
        ("_compile_parallel_task.<locals>.parallel_task_in_lanes",),
    ),
)

#: One line per group: ``{what}``, its place ``{index}`` of ``{count}``, ``{seconds}`` so far.
MESSAGE = "tether-gym: compiling numba kernels for first use [{index}/{count}]: {what} ({seconds:.0f} s so far)"
#: Added to the first line of a process; ``{cache}`` is numba's cache directory.
HINT = (
    "; this happens once, later processes load them from numba's cache ({cache}). "
    "To compile them all ahead of time, run: python -m tether_gym.compile"
)

_GROUP_OF = {name: index for index, (_, names) in enumerate(GROUPS) for name in names}


def group_of(qualified_name: str) -> int | None:
    """The index in :data:`GROUPS` of the kernel ``qualified_name`` (None for a helper)."""
    return _GROUP_OF.get(qualified_name)


class _CompilationWatch(event.Listener):
    """Counts the compilations of tether-gym's kernels in this process, and announces each group."""

    def __init__(self) -> None:
        self.compiled: list[str] = []
        #: The groups announced in this process (by index in GROUPS).
        self.announced: set[int] = set()
        #: Set by a caller that reports progress itself (python -m tether_gym.compile).
        self.quiet = False
        self._start: float | None = None

    def on_start(self, compile_event: Any) -> None:
        dispatcher = (compile_event.data or {}).get("dispatcher")
        function = getattr(dispatcher, "py_func", None)
        if not getattr(function, "__module__", "").startswith("tether_gym."):
            return
        name = function.__qualname__  # type: ignore[union-attr]
        self.compiled.append(name)
        group = group_of(name)
        if group is None or group in self.announced or self.quiet:
            return
        now = time.perf_counter()
        if self._start is None:
            self._start = now
        line = MESSAGE.format(index=group + 1, count=len(GROUPS), what=GROUPS[group][0], seconds=now - self._start)
        if not self.announced:
            stats = getattr(dispatcher, "stats", None)
            line += HINT.format(cache=getattr(stats, "cache_path", "numba's cache directory"))
        self.announced.add(group)
        LOGGER.warning(line)

    def on_end(self, compile_event: Any) -> None:
        pass


#: The watch of this process (registered once, when tether_gym is imported).
COMPILATIONS = _CompilationWatch()
event.register("numba:compile", COMPILATIONS)
