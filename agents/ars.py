"""Train a linear residual policy with Augmented Random Search on paired seeds: python -m agents.ars --env TetherHub-v0.

The algorithm, and why it runs on paired seeds, are described in :mod:`agents.training.ars`, which
holds the trainer (:func:`~agents.training.ars.train_ars`); this module is its command line.

Training, evaluation and selection follow ``agents.train``: the run directory
``<out>/<env>/ars_seed<seed>`` holds ``config.yml`` (settings and the exact command), TensorBoard
logs, ``best/`` (the policy with the best mean return on the evaluation seeds, 1 000 000 up,
never the benchmark's held-out seeds) with ``best/evaluations.json``, and the final policy. The
policy is stored in the safe format (:mod:`agents.policies.format`) as the linear actor of SB3's
``ActorCriticPolicy`` (``net_arch: {pi: [], vf: []}``) with ``algo: ars``, so ``agents.compare``,
``agents.benchmark`` and ``agents.ship`` load it like any trained model. Settings per id are in
the package's ``hyperparams/ars.yml`` (``agents/hyperparams`` in a checkout). Console script:
``tether-gym-train-ars``.
"""

from __future__ import annotations

if __name__ == "__main__":  # --help and bad options answered before the slow imports below
    from .common.cli import parse_before_imports

    parse_before_imports("ars")

import functools
import sys
from pathlib import Path

from .common import cli
from .common.commands import command_line, exit_on_error
from .common.files import OutputError
from .policies.layout import PolicyFormatError
from .training.ars import load_ars_settings, train_ars

__all__ = ["ERRORS", "build_parser", "main"]

#: The refusals that end the command with ``<program>: error: <message>`` (see :func:`exit_on_error`).
ERRORS = (OutputError, PolicyFormatError, ValueError, OSError)


#: The command line of ``ars``, from :mod:`agents.common.cli` (where the console script parses it
#: before this module's slow imports).
build_parser = functools.partial(cli.build_parser, "ars")


def main(argv: list[str] | None = None) -> Path:
    """Train as the command line ``argv`` (default: ``sys.argv[1:]``) asks; returns the run directory."""
    args = build_parser().parse_args(argv)
    overrides = {} if args.iterations is None else {"iterations": args.iterations}
    settings = load_ars_settings(args.env, args.hyperparams, **overrides)
    return train_ars(
        args.env,
        args.seed,
        args.out,
        settings,
        force=args.force,
        progress=not args.no_progress,
        command=command_line("ars", sys.argv[1:] if argv is None else argv),
    )


if __name__ == "__main__":
    exit_on_error("ars", main, ERRORS)
