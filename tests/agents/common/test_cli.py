"""The commands' command lines: every option explained, ``--help`` fast, parsers in one place.

A console script parses its command line with :func:`agents.common.cli.build_parser` before importing
its module, so ``--help`` must not import torch, Stable-Baselines3 or scipy (seconds), and every
option must say what it does.
"""

from __future__ import annotations

import argparse
import importlib
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

from agents.common import cli, commands

ROOT = Path(__file__).resolve().parents[3]
SCRIPTS = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]["scripts"]
#: Generous: the target is 1.5 s, but this machine may be loaded by other jobs.
HELP_SECONDS = 3.0
#: What --help must not import (tether_gym itself brings numba, which loads scipy's core, and yaml).
HEAVY = ("torch", "stable_baselines3", "scipy.stats", "scipy.linalg", "matplotlib", "rliable", "ray")


def _core_parser(module: str) -> argparse.ArgumentParser:
    """The parser a tether_gym command's main builds (caught as it parses --help)."""
    parsers: list[argparse.ArgumentParser] = []
    original = argparse.ArgumentParser.parse_args

    def capture(self: argparse.ArgumentParser, *args: object, **kwargs: object) -> argparse.Namespace:
        parsers.append(self)
        raise SystemExit(0)

    argparse.ArgumentParser.parse_args = capture  # type: ignore[method-assign]
    try:
        with pytest.raises(SystemExit):
            importlib.import_module(module).main(["--help"])
    finally:
        argparse.ArgumentParser.parse_args = original  # type: ignore[method-assign]
    return parsers[0]


def all_parsers() -> dict[str, argparse.ArgumentParser]:
    """Every console script's parser, by script name."""
    parsers = {script: cli.build_parser(command) for command, script in commands.SCRIPTS.items()}
    parsers["tether-gym-bench"] = _core_parser("tether_gym.bench")
    parsers["tether-gym-compile"] = _core_parser("tether_gym.compile")
    parsers["tether-gym-view"] = _core_parser("tether_gym.view")
    assert set(parsers) == set(SCRIPTS)
    return parsers


def test_every_option_of_every_command_has_help() -> None:
    missing = [
        f"{script} {action.option_strings or action.dest}"
        for script, parser in all_parsers().items()
        for action in parser._actions
        if not action.help or action.help == argparse.SUPPRESS
    ]
    assert not missing, f"options without a help text: {missing}"


def test_every_command_has_its_parser_in_cli() -> None:
    assert set(cli._PARSERS) == set(commands.SCRIPTS)
    with pytest.raises(ValueError, match="unknown command 'evaluate'"):
        cli.build_parser("evaluate")


def test_the_command_modules_use_the_cli_parsers() -> None:
    """Each module's build_parser is cli's, and its description is the module docstring's first
    paragraph (cli reads it from the source, without importing the module)."""
    for command in commands.SCRIPTS:
        if command == "train_rllib":
            continue  # imports without ray, but its description is checked through cli all the same
        module = importlib.import_module(f"agents.{command}")
        ours, theirs = module.build_parser(), cli.build_parser(command)
        assert [a.option_strings for a in ours._actions] == [a.option_strings for a in theirs._actions]
        if command != "benchmark":  # its description is written out in cli
            assert theirs.description == commands.description(module.__doc__, command)


def test_the_algorithm_names_match_the_policy_format() -> None:
    from agents.policies.format import ALGORITHMS

    assert tuple(sorted(ALGORITHMS)) == cli.TRAIN_ALGORITHMS


def test_help_names_installed_paths_not_the_checkout_only(monkeypatch: pytest.MonkeyPatch) -> None:
    """Imported as the installed package, the help texts name its paths and commands
    (tether_gym_agents/..., python -m tether_gym_agents.<command>), never the checkout's
    agents/... or a .venv/bin/python that a wheel user does not have."""
    monkeypatch.setattr(cli, "PACKAGE", "tether_gym_agents")
    monkeypatch.setattr(commands, "PACKAGE", "tether_gym_agents")
    for command in commands.SCRIPTS:
        text = " ".join(cli.build_parser(command).format_help().split())
        # ship's default --out is the checkout's models folder, and says so.
        text = text.replace("default agents/models: the checkout's", "").replace("the checkout's agents/models", "")
        assert ".venv" not in text, command
        assert "python -m agents." not in text, command
        assert "agents/" not in text.replace("tether_gym_agents/", ""), (command, text)
        assert "tether_gym_agents/hyperparams" in text or command in ("compare", "benchmark", "ship", "convert")


def _script_command(script: str) -> list[str]:
    """The console script as installed, or (when the checkout is not installed) the same entry
    point run by the interpreter, as the script would run it."""
    installed = Path(sys.executable).parent / script
    if installed.is_file():
        return [str(installed)]
    module, function = SCRIPTS[script].split(":")
    module = module.replace("tether_gym_agents", "agents")
    run = f"import sys; sys.argv[0] = {script!r}; from {module} import {function}; {function}()"
    return [sys.executable, "-c", run]


@pytest.mark.parametrize("script", sorted(SCRIPTS))
def test_help_is_fast_and_imports_nothing_heavy(script: str) -> None:
    started = time.perf_counter()
    result = subprocess.run(
        [*_script_command(script), "--help"], capture_output=True, text=True, timeout=120, cwd=ROOT, env=os.environ
    )
    seconds = time.perf_counter() - started
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith(f"usage: {script} "), result.stdout[:200]
    assert seconds < HELP_SECONDS, f"{script} --help took {seconds:.2f} s"


@pytest.mark.parametrize("command", sorted(commands.SCRIPTS))
@pytest.mark.parametrize("form", ["console script", "python -m"])
def test_a_command_parses_before_its_slow_imports(command: str, form: str) -> None:
    """--help and a bad option are answered before torch, SB3 or scipy's statistics are imported,
    whether the command runs as its console script or as ``python -m agents.<command>``."""
    run = (
        f"commands.{command}()"
        if form == "console script"
        else f"runpy.run_module('agents.{command}', run_name='__main__', alter_sys=True)"
    )
    probe = (
        "import runpy, sys\n"
        "from agents.common import commands\n"
        "for argv in (['--help'], ['--no-such-option']):\n"
        f"    sys.argv = [{commands.SCRIPTS[command]!r}, *argv]\n"
        "    try:\n"
        f"        {run}\n"
        "    except SystemExit as stop:\n"
        "        print('exit', stop.code)\n"
        f"print(sorted(name for name in {HEAVY!r} if name in sys.modules))\n"
    )
    result = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert "exit 0" in lines and "exit 2" in lines, result.stdout[-500:]
    assert lines[-1] == "[]", f"{command} --help imported {lines[-1]}"
    assert "error:" in result.stderr


@pytest.mark.parametrize(
    ("command", "arguments", "message"),
    [
        # One evaluation episode has no interval of its paired difference: it failed at the first evaluation.
        ("train", ["--eval-episodes", "1"], "argument --eval-episodes: must be at least 2; got 1"),
        ("train_rllib", ["--eval-episodes", "1"], "argument --eval-episodes: must be at least 2; got 1"),
        ("train", ["--curriculum", "nan", "0.5"], r"argument --curriculum: must be a finite number in \[0, 1\]"),
        ("train", ["--curriculum", "0.5", "2"], r"argument --curriculum: must be a finite number in \[0, 1\]"),
        ("train", ["--hyperparams", "no-such.yml"], "argument --hyperparams: 'no-such.yml' does not exist"),
        ("ars", ["--hyperparams", "."], "argument --hyperparams: '.' is a directory, not a file"),
        ("ars", ["--seed", "1000"], "argument --seed: must be at most 999; got 1000"),
        # An unknown id was refused only after SRC was unpickled.
        ("convert", ["SRC", "DST", "--env", "TetherChian-v0"], "argument --env: invalid choice: 'TetherChian-v0'"),
        ("train_rllib", ["--hyperparams", "no-such.yml"], "argument --hyperparams: 'no-such.yml' does not exist"),
    ],
)
def test_the_parser_refuses_what_would_fail_later_by_name(
    command: str, arguments: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exit_:
        cli.build_parser(command).parse_args(arguments)
    assert exit_.value.code == 2
    assert re.search(message, capsys.readouterr().err)
