"""Word to the user when tether-gym's numba kernels compile.

On a fresh install the first ``gym.make(...).step`` compiles the kernels, which takes tens of
seconds; numba's cache then keeps them for later processes.  A listener on numba's compile event
(fired only when a kernel is about to compile, not when it loads from the cache) logs one warning
per process the first time one of tether-gym's kernels compiles, and counts the compilations for
:mod:`tether_gym.compile`.
"""

from __future__ import annotations

import logging
from typing import Any

from numba.core import event

__all__ = ["COMPILATIONS", "LOGGER", "MESSAGE"]

LOGGER = logging.getLogger("tether_gym")

#: The one-time message; ``{cache}`` is numba's cache directory of the first kernel compiled.
MESSAGE = (
    "tether-gym is compiling its numba kernels for first use: this takes tens of seconds, once; "
    "later processes load them from numba's cache ({cache}). "
    "To compile them ahead of time, run: python -m tether_gym.compile"
)


class _CompilationWatch(event.Listener):
    """Counts the compilations of tether-gym's kernels in this process, and announces the first."""

    def __init__(self) -> None:
        self.compiled: list[str] = []
        #: Set once the message has been logged (or by a caller that reports progress itself).
        self.announced = False

    def on_start(self, compile_event: Any) -> None:
        dispatcher = (compile_event.data or {}).get("dispatcher")
        function = getattr(dispatcher, "py_func", None)
        if not getattr(function, "__module__", "").startswith("tether_gym."):
            return
        self.compiled.append(function.__qualname__)  # type: ignore[union-attr]
        if not self.announced:
            self.announced = True
            stats = getattr(dispatcher, "stats", None)
            LOGGER.warning(MESSAGE.format(cache=getattr(stats, "cache_path", "numba's cache directory")))

    def on_end(self, compile_event: Any) -> None:
        pass


#: The watch of this process (registered once, when tether_gym is imported).
COMPILATIONS = _CompilationWatch()
event.register("numba:compile", COMPILATIONS)
