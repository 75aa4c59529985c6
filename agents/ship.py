"""Choose the model to ship for each id from several training runs, and record every run's result:
``python -m agents.ship RUN [RUN ...]`` (into ``--out``, by default the checkout's ``agents/models``).

Each ``RUN`` is a run directory of ``agents.train`` (its ``best/`` policy is the candidate), or a
policy directory (a checkpoint, or a model shipped earlier). Every candidate is rolled out on the
evaluation seeds (:func:`agents.training.selection.evaluation_seeds`, 1 000 000 up), the seeds training
selected its ``best/`` on, alongside every scripted baseline. Per id and algorithm, the candidate
with the highest mean return there is shipped: its policy files, ``config.yml`` and training log
are copied to ``OUT/<id>/<algo>/`` under a fresh ``MANIFEST.sha256``. The held-out seeds the
benchmark reports (10 000 up) play no part in the choice.

Every candidate's result goes to ``OUT/training_runs.json`` and ``OUT/training_runs.md``: the
training seed, steps, wall time, mean return on the evaluation seeds and its paired difference
from the best scripted baseline there (95 % t interval), and the wall time at which its training
first beat each baseline (from the run's ``best/evaluations.json``). Entries of earlier calls for
other ids or algorithms are kept, so runs can be shipped id by id.

This module is the command line; :mod:`agents.training.shipping` does the work.
"""

from __future__ import annotations

if __name__ == "__main__":  # --help and bad options answered before the slow imports below
    from .common.cli import parse_before_imports

    parse_before_imports("ship")

import functools
import sys
from typing import Any

from .common import cli
from .common.commands import command_line, exit_on_error
from .common.files import OutputError
from .policies.layout import PolicyFormatError
from .training.shipping import ship

__all__ = ["ERRORS", "build_parser", "main"]

#: The refusals that end the command with ``<program>: error: <message>`` (see :func:`exit_on_error`).
ERRORS = (OutputError, PolicyFormatError, FileNotFoundError, ValueError)


#: The command line of ``ship``, from :mod:`agents.common.cli` (where the console script parses it
#: before this module's slow imports).
build_parser = functools.partial(cli.build_parser, "ship")


def main(argv: list[str] | None = None) -> list[dict[str, Any]]:
    """Ship as the command line ``argv`` (default: ``sys.argv[1:]``) asks; returns every
    candidate's record (:func:`agents.training.shipping.ship`)."""
    arguments = sys.argv[1:] if argv is None else list(argv)
    args = build_parser().parse_args(arguments)
    return ship(
        args.runs,
        args.out,
        episodes=args.episodes,
        force=args.force,
        command=command_line("ship", arguments),
    )


if __name__ == "__main__":
    exit_on_error("ship", main, ERRORS)
