"""The benchmark: every id, every controller, on held-out seeds: ``python -m agents.benchmark``.

It runs, on every tether-gym id of both tracks (``--track standard``, ``hard`` or ``all``, the
default), every scripted baseline, the model-predictive reference ``mpc`` and every model shipped
for the id, on the comparison's held-out episodes, and reports per id the mean returns, the best
eligible scripted baseline, every controller's paired difference against it and the normalised
score (0 = passive, 100 = ``mpc``), across the ids of each track rliable's IQM and mean of the
normalised scores, and every controller's excess cost over the shipped reference ceiling, which
it reads (``--ceiling-file``) instead of rerunning the planner.

**Run time.** The full run (every id, 64 episodes, ``mpc`` included) takes about 2 h on a
2-core machine by the cost model, most of it ``mpc`` (39 min for the 8 massless standard ids,
about 25 min for each id with beaded tethers; the 4-segment one took 8); the command prints its
estimate before it starts. ``--quick`` is a smoke
check of 2 to 4 minutes: 8 episodes (the ceiling's first seeds), no ``mpc``, noisier numbers.

:mod:`agents.evaluation.benchmark` defines every statistic and every file it writes to ``--out``;
this module is its command line, which builds a
:class:`~agents.evaluation.benchmark.BenchmarkConfig` from the arguments.
"""

from __future__ import annotations

if __name__ == "__main__":  # --help and bad options answered before the slow imports below
    from .common.cli import parse_before_imports

    parse_before_imports("benchmark")

import functools
import sys
from typing import Any

from .common import cli
from .common.commands import command_line, exit_on_error
from .common.files import OutputError
from .evaluation.benchmark import BenchmarkConfig, benchmark
from .policies.layout import PolicyFormatError
from .policies.pickled import PickleNotTrustedError

__all__ = ["build_parser", "main"]

#: The refusals that end the command with ``<program>: error: <message>`` (see :func:`exit_on_error`).
ERRORS = (PickleNotTrustedError, OutputError, PolicyFormatError, ValueError, OSError, ImportError)


#: The command line of ``benchmark``, from :mod:`agents.common.cli` (where the console script parses it
#: before this module's slow imports).
build_parser = functools.partial(cli.build_parser, "benchmark")


def main(argv: list[str] | None = None) -> dict[str, Any]:
    """Run the benchmark with the command line ``argv`` (default: the process's arguments), recorded
    in its outputs; returns its results (what ``benchmark.json`` holds)."""
    arguments = sys.argv[1:] if argv is None else list(argv)
    args = build_parser().parse_args(arguments)
    config = cli.config_from_args(
        BenchmarkConfig,
        args,
        env_ids=args.envs,
        plots=not args.no_plots,
        command=command_line("benchmark", arguments),
    )
    return benchmark(config)


if __name__ == "__main__":
    exit_on_error("benchmark", main, ERRORS)
