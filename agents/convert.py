"""Convert a pickle-based SB3 model to the safe policy format:
``python -m agents.convert SRC DST --trust-pickle``.

``SRC`` is an SB3 run directory (``model.zip`` and ``vecnormalize.pkl``, or with ``--best``
``best/best_model.zip``) or a model ``.zip`` (its statistics are found next to it). Converting
unpickles ``SRC``, which runs any code a crafted file contains, so it needs ``--trust-pickle``:
convert only files you made or trust. The result, ``DST``, holds ``policy.json``,
``policy.safetensors``, ``normalization.json``, the run's ``config.yml`` (provenance) and a
``MANIFEST.sha256``, and loads without unpickling anything.

Before writing, the converter loads the converted policy back and checks that its actions are
bit-identical to the SB3 original's on ``--check-observations`` observations (env observations
along the original's own trajectories, and draws around the normalisation statistics).
``--reference`` also keeps those observations and actions in ``DST/reference_actions.safetensors``
so that tests can check the shipped policy against the original long after the pickle files are
gone. ``--training-state`` keeps the optimizer states, so that ``agents.train --resume DST``
continues training.
"""

from __future__ import annotations

if __name__ == "__main__":  # --help and bad options answered before the slow imports below
    from .common.cli import parse_before_imports

    parse_before_imports("convert")

import functools
from pathlib import Path

from .common import cli
from .common.commands import exit_on_error
from .common.files import OutputError
from .policies.conversion import ConvertConfig, convert
from .policies.layout import PolicyFormatError
from .policies.pickled import PickleNotTrustedError

__all__ = ["build_parser", "main"]

#: The refusals that end the command with ``<program>: error: <message>`` (see :func:`exit_on_error`).
ERRORS = (PickleNotTrustedError, OutputError, PolicyFormatError, ValueError, OSError)


#: The command line of ``convert``, from :mod:`agents.common.cli` (where the console script parses it
#: before this module's slow imports).
build_parser = functools.partial(cli.build_parser, "convert")


def main(argv: list[str] | None = None) -> Path:
    """Convert with the command line ``argv`` (default: the process's arguments); returns ``DST``."""
    args = build_parser().parse_args(argv)
    config = cli.config_from_args(ConvertConfig, args, env_id=args.env)
    return convert(config)


if __name__ == "__main__":
    exit_on_error("convert", main, ERRORS)
