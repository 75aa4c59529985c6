"""Argument parsing shared by the agents' commands."""

from __future__ import annotations

import argparse
from collections.abc import Callable

__all__ = ["add_env_argument", "int_at_least"]


def int_at_least(minimum: int) -> Callable[[str], int]:
    """An argparse ``type`` for whole numbers >= ``minimum``: a bad value is reported by argparse
    under the option's name ("argument --episodes: must be at least 2; got 1")."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be an integer; got {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be at least {minimum}; got {value}")
        return value

    return parse


def add_env_argument(parser: argparse.ArgumentParser) -> None:
    """``--env ID``: one of the registered ids, the default id by default."""
    from tether_gym.registration import DEFAULT_ENV_ID, ENV_IDS

    parser.add_argument(
        "--env",
        default=DEFAULT_ENV_ID,
        choices=list(ENV_IDS),
        metavar="ID",
        help=f"env id (default {DEFAULT_ENV_ID}; one of {', '.join(ENV_IDS)})",
    )
