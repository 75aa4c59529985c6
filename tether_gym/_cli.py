"""The name a command of tether_gym goes by, for argparse's usage lines and error prefixes."""

from __future__ import annotations

import sys
from pathlib import Path


def program(module: str, script: str) -> str:
    """``script`` (a console script of pyproject, e.g. ``tether-gym-bench``) when that is what
    runs now, else ``python -m <module>``: the way the user started the command."""
    return script if Path(sys.argv[0]).name == script else f"python -m {module}"
