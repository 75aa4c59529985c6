"""The agents' commands and their names: ``python -m <package>.<command>`` and the console scripts.

This folder is the package ``agents`` in a checkout and ``tether_gym_agents`` when installed from
a wheel (``pyproject.toml`` maps the installed name onto the folder, so that a generic top-level
``agents`` never lands in site-packages). The modules import each other relatively, and every
command line they print or record is built here from the package name, so it is one the user can
run under either name.

The console scripts of ``pyproject.toml`` (``tether-gym-train``, ``tether-gym-compare``,
``tether-gym-benchmark``, ``tether-gym-ship``, ``tether-gym-convert``, ``tether-gym-train-rllib``,
``tether-gym-train-ars``, ``tether-gym-train-dagger``)
run their module exactly as ``python -m`` does, ``__main__`` block and its error handling
included, so the two ways to run a command cannot drift apart. That block starts by parsing
the command line with the command's parser (:func:`agents.common.cli.parse_before_imports`, which
imports nothing heavy): ``--help`` and a bad option are answered in a fraction of a second, not
after the seconds that importing torch and Stable-Baselines3 takes.
"""

from __future__ import annotations

import runpy
import shlex
import sys
from collections.abc import Callable, Sequence
from typing import Any

from tether_gym._optional import MissingExtraError

__all__ = [
    "MODULE_ONLY_COMMANDS",
    "PACKAGE",
    "SCRIPTS",
    "ars",
    "benchmark",
    "command_line",
    "compare",
    "convert",
    "dagger",
    "description",
    "exit_on_error",
    "program",
    "ship",
    "train",
    "train_rllib",
]

#: The command modules of this package and the console script that runs each.
SCRIPTS: dict[str, str] = {
    "train": "tether-gym-train",
    "compare": "tether-gym-compare",
    "benchmark": "tether-gym-benchmark",
    "ship": "tether-gym-ship",
    "convert": "tether-gym-convert",
    "train_rllib": "tether-gym-train-rllib",
    "ars": "tether-gym-train-ars",
    "dagger": "tether-gym-train-dagger",
}

#: Command modules run only as ``python -m`` (no console script): ``scoring``, the maintainers'
#: converter that writes the shipped reference scores, and ``ceiling``, which computes the shipped
#: reference ceiling.
MODULE_ONLY_COMMANDS = ("scoring", "ceiling")

#: The agents package as it is imported now: ``agents`` in a checkout, ``tether_gym_agents`` installed
#: (this module lives in its ``common`` sub-package).
PACKAGE = (__package__ or "agents.common").rpartition(".")[0]

# The console script running now (set by its entry point before the module runs), or None under
# ``python -m`` and when a command's ``main`` is called from Python.
_running_script: str | None = None


def program(command: str) -> str:
    """How the user runs ``command`` (a key of :data:`SCRIPTS`, or one of
    :data:`MODULE_ONLY_COMMANDS`): its console script's name when that is what runs now, else
    ``python -m <package>.<command>``. It is the argparse ``prog`` (usage lines and error
    prefixes) and the head of the command lines a run records."""
    if command not in SCRIPTS and command not in MODULE_ONLY_COMMANDS:
        known = ", ".join((*SCRIPTS, *MODULE_ONLY_COMMANDS))
        raise ValueError(f"unknown command {command!r}: expected one of {known}")
    if _running_script is not None and _running_script == SCRIPTS.get(command):
        return _running_script
    return f"python -m {PACKAGE}.{command}"


def command_line(command: str, arguments: Sequence[str]) -> str:
    """The shell command that runs ``command`` with ``arguments`` the way it runs now (see
    :func:`program`), quoted so that it can be pasted back into a shell."""
    return shlex.join([*shlex.split(program(command)), *arguments])


def description(docstring: str | None, command: str | None = None) -> str:
    """The argparse description of a command module with docstring ``docstring``: its first
    paragraph, without reST markup, with its ``python -m agents.<command>`` (how the checkout runs
    it) naming the package it is imported as, and ``command``'s own one named as the user runs
    it (:func:`program`: its console script, when that is what runs)."""
    if not docstring:
        raise ValueError("a command module needs a docstring: its first paragraph is the --help description")
    first_paragraph = docstring.split("\n\n")[0].replace("``", "")
    if command is not None:
        first_paragraph = first_paragraph.replace(f"python -m agents.{command}", program(command))
    return first_paragraph.replace("python -m agents.", f"python -m {PACKAGE}.")


def exit_on_error(command: str, main: Callable[[], Any], errors: tuple[type[BaseException], ...]) -> None:
    """Run a command's ``main()`` as its ``__main__`` block does: one of ``errors`` (the refusals
    whose message names the problem and the fix) ends the process with
    ``<program>: error: <message>`` and exit status 1, as argparse reports a bad argument, instead
    of a traceback. Any other exception is a bug and keeps its traceback."""
    try:
        main()
    except errors as error:
        sys.exit(f"{program(command)}: error: {error}")


def _run(command: str) -> None:
    """Run ``<package>.<command>`` as ``python -m`` does, as its console script; a missing
    optional dependency ends it with the message that names its extra, without a traceback."""
    global _running_script
    _running_script = SCRIPTS[command]
    try:
        runpy.run_module(f"{PACKAGE}.{command}", run_name="__main__", alter_sys=True)
    except MissingExtraError as error:  # the message names the extra to install: no traceback needed
        sys.exit(f"{program(command)}: error: {error}")


def train() -> None:
    """``tether-gym-train``: ``python -m tether_gym_agents.train``."""
    _run("train")


def compare() -> None:
    """``tether-gym-compare``: ``python -m tether_gym_agents.compare``."""
    _run("compare")


def benchmark() -> None:
    """``tether-gym-benchmark``: ``python -m tether_gym_agents.benchmark``."""
    _run("benchmark")


def ship() -> None:
    """``tether-gym-ship``: ``python -m tether_gym_agents.ship``."""
    _run("ship")


def convert() -> None:
    """``tether-gym-convert``: ``python -m tether_gym_agents.convert``."""
    _run("convert")


def train_rllib() -> None:
    """``tether-gym-train-rllib``: ``python -m tether_gym_agents.train_rllib`` (needs the rllib extra)."""
    _run("train_rllib")


def ars() -> None:
    """``tether-gym-train-ars``: ``python -m tether_gym_agents.ars``."""
    _run("ars")


def dagger() -> None:
    """``tether-gym-train-dagger``: ``python -m tether_gym_agents.dagger``."""
    _run("dagger")
