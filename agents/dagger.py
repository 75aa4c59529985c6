"""Distil the reference ceiling planner into a fast residual network with DAgger: python -m agents.dagger --env ID.

The algorithm, what the student observes and what the teacher reads, are described in
:mod:`agents.training.dagger`, which holds the trainer
(:func:`~agents.training.dagger.train_dagger`); this module is its command line.

Evaluation and selection follow ``agents.ars``: the run directory
``<out>/<env>/dagger_seed<seed>`` holds ``config.yml`` (settings, the teacher's settings and the
exact command), ``best/`` (the student with the best mean return on the evaluation seeds,
1 000 000 up, never the benchmark's held-out seeds) with ``best/evaluations.json`` (every
iteration, and the student's and the planner's compute per step), and the final student. The
policy is stored in the safe format (:mod:`agents.policies.format`) as the MLP actor of SB3's
``ActorCriticPolicy`` with ``algo: dagger`` and ``residual_on``, so ``agents.compare``,
``agents.benchmark`` and ``agents.ship`` load it like any trained model. Settings per id are in
the package's ``hyperparams/dagger.yml``, the teacher's in ``hyperparams/ceiling.yml``
(``agents/hyperparams`` in a checkout). Console script: ``tether-gym-train-dagger``.
"""

from __future__ import annotations

if __name__ == "__main__":  # --help and bad options answered before the slow imports below
    from .common.cli import parse_before_imports

    parse_before_imports("dagger")

import functools
import sys
from pathlib import Path
from typing import Any

from .common import cli
from .common.commands import command_line, exit_on_error
from .common.files import OutputError
from .policies.layout import PolicyFormatError
from .training.dagger import load_dagger_settings, train_dagger

__all__ = ["ERRORS", "build_parser", "main"]

#: The refusals that end the command with ``<program>: error: <message>`` (see :func:`exit_on_error`).
ERRORS = (OutputError, PolicyFormatError, ValueError, OSError)


#: The command line of ``dagger``, from :mod:`agents.common.cli` (where the console script parses it
#: before this module's slow imports).
build_parser = functools.partial(cli.build_parser, "dagger")


def main(argv: list[str] | None = None) -> Path:
    """Train as the command line ``argv`` (default: ``sys.argv[1:]``) asks; returns the run directory."""
    args = build_parser().parse_args(argv)
    overrides: dict[str, Any] = {}
    for name in ("iterations", "episodes"):
        if getattr(args, name) is not None:
            overrides[name] = getattr(args, name)
    settings = load_dagger_settings(args.env, args.hyperparams, **overrides)
    return train_dagger(
        args.env,
        args.seed,
        args.out,
        settings,
        force=args.force,
        progress=not args.no_progress,
        command=command_line("dagger", sys.argv[1:] if argv is None else argv),
    )


if __name__ == "__main__":
    exit_on_error("dagger", main, ERRORS)
