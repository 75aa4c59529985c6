"""Compare controllers side by side: ``python -m agents.compare`` (the project's main job).

Every controller (by default the four scripted baselines and every model shipped in
the package's ``models/<env id>/``) runs the same held-out episodes: episode e starts from the reset
seeded ``seed + e``. The command prints a table, and writes to ``--out``:

* ``comparison.md`` and ``comparison.csv``: the table (see :data:`agents.evaluation.rollout.METRICS`);
* ``energy.png``: vibration energy over time, E(t)/E0, median and interquartile band per
  controller;
* ``displacement.png``: one satellite's displacement from its nominal place over time, in the
  first episode, for every controller.

The command is careful with files: it checks ``--out`` (a writable directory, not a symlink,
not inside a file) and refuses to replace an earlier comparison there without ``--force``
before it loads a controller or runs a rollout, and it writes each file atomically (a temporary
file, then a rename). Trained models are read from the safe format (JSON + safetensors);
a pickle-based SB3 model path is refused unless ``--trust-pickle`` is given.

The seeds default to 10 000 and up, far from the seeds that training and its evaluation
callback use (0 and up, and 1 000 000 and up).

The comparison itself is :func:`agents.evaluation.comparison.compare`; this module is its
command line, which builds a :class:`~agents.evaluation.comparison.CompareConfig` from the
arguments.
"""

from __future__ import annotations

if __name__ == "__main__":  # --help and bad options answered before the slow imports below
    from .common.cli import parse_before_imports

    parse_before_imports("compare")

import functools
from typing import Any

from .common import cli
from .common.commands import exit_on_error
from .common.files import OutputError
from .evaluation.comparison import CompareConfig, compare
from .evaluation.rollout import EpisodeRecord
from .policies.layout import PolicyFormatError
from .policies.pickled import PickleNotTrustedError

__all__ = ["build_parser", "main"]

#: The refusals that end the command with ``<program>: error: <message>`` (see :func:`exit_on_error`).
ERRORS = (PickleNotTrustedError, OutputError, PolicyFormatError, ValueError, OSError, ImportError)


#: The command line of ``compare``, from :mod:`agents.common.cli` (where the console script parses it
#: before this module's slow imports).
build_parser = functools.partial(cli.build_parser, "compare")


def main(argv: list[str] | None = None) -> tuple[list[EpisodeRecord], list[dict[str, Any]]]:
    """Run the comparison with the command line ``argv`` (default: the process's arguments);
    returns the episode records and the summaries, in the controllers' order."""
    args = build_parser().parse_args(argv)
    config = cli.config_from_args(CompareConfig, args, env_id=args.env, plots=not args.no_plots)
    return compare(config)


if __name__ == "__main__":
    exit_on_error("compare", main, ERRORS)
