"""Property-based fuzzing of the commands' arguments: every command of
:mod:`agents.common.commands`, found there, so that a new command is fuzzed from the day it lands.

* Every argument list either parses into valid settings, or argparse exits with status 2 and a
  message that names the offending option (or the missing or unrecognised one). A parsed
  integer option is never out of its range: the custom argument types refuse it first.
* Every argument list run through the command's ``main`` either reaches the command's work (a
  stand-in here) with settings that were all checked, or is refused by argparse (status 2) or with
  one of the command's own errors (``ERRORS``, which its ``__main__`` block turns into
  ``<program>: error: <message>``): never a traceback of another kind.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import io
import os
import tempfile
from types import ModuleType
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from agents.common import commands
from agents.common.checks import MAX_TRAINING_SEED

#: Property-based, with many generated examples per property: the fast suite (-m 'not slow') leaves them out.
pytestmark = pytest.mark.slow

#: Every command: the console scripts' and the module-only ones.
COMMANDS = sorted({*commands.SCRIPTS, *commands.MODULE_ONLY_COMMANDS})
MODULES: dict[str, ModuleType] = {name: importlib.import_module(f"agents.{name}") for name in COMMANDS}
PARSERS = {name: module.build_parser for name, module in MODULES.items()}

#: The function each command's ``main`` hands its checked settings to, in the command's module: the
#: work (training, rollouts, files), which the fuzzing replaces by a stand-in. A new command needs an
#: entry here (a test fails until it has one). A command with several kinds of work names a
#: function for each (``scoring --ceiling`` prints a table instead of writing a file).
WORK: dict[str, str | tuple[str, ...]] = {
    "ars": "train_ars",
    "benchmark": "benchmark",
    "ceiling": "run_ceiling",
    "compare": "compare",
    "convert": "convert",
    "dagger": "train_dagger",
    "scoring": ("write_reference", "ceiling_report"),
    "ship": "ship",
    "train": "train",
    "train_rllib": "train_rllib",
}


def options_of(parser: argparse.ArgumentParser) -> list[str]:
    """The long options of ``parser``, without --help (which exits 0 by design)."""
    return [
        option
        for action in parser._actions
        for option in action.option_strings
        if option.startswith("--") and option != "--help"
    ]


values = st.one_of(
    st.integers(-(10**6), 10**12).map(str),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.sampled_from(
        [
            "",
            "-",
            "--",
            "ppo",
            "lqr",
            "mpc",
            "TetherTetrahedron-v0",
            "NoSuchEnv-v0",
            "1e6",
            "0x10",
            "nan",
            "inf",
            "/dev/null",
            "out dir",
            "é",
        ]
    ),
    st.text(max_size=6),
)


@settings(max_examples=200, deadline=None, derandomize=True)
@given(command=st.sampled_from(sorted(PARSERS)), data=st.data())
def test_any_argument_list_parses_or_names_the_option(command: str, data: st.DataObject) -> None:
    parser = PARSERS[command]()
    options = options_of(parser) + ["--no-such-option"]
    tokens: list[str] = []
    for option in data.draw(st.lists(st.sampled_from(options), max_size=4), label="options"):
        tokens.append(option)
        tokens.extend(data.draw(st.lists(values, max_size=2), label=option))
    tokens.extend(data.draw(st.lists(values, max_size=2), label="positionals"))
    stderr = io.StringIO()
    try:
        with contextlib.redirect_stderr(stderr):
            namespace = parser.parse_args(tokens)
    except SystemExit as exit_:
        message = stderr.getvalue()
        assert exit_.code == 2, message
        named = [option for option in options if option in message]
        assert named or "required" in message or "unrecognized arguments" in message or "argument" in message, message
        assert "Traceback" not in message
        return
    check_parsed(vars(namespace))


def check_parsed(arguments: dict[str, Any]) -> None:
    """What a successful parse may hold: the commands' whole-number options are in range."""
    minimum = {
        "episodes": 2,
        "seed": 0,
        "satellite": 0,
        "timesteps": 1,
        "n_envs": 1,
        "eval_freq": 1,
        "eval_episodes": 2,
        "checkpoint_freq": 1,
        "verbose": 0,
        "check_observations": 16,
        "bootstrap_reps": 100,
        "num_env_runners": 0,
        "envs_per_runner": 1,
        "num_cpus": 1,
        "iterations": 1,
    }
    for key, low in minimum.items():
        value = arguments.get(key)
        if isinstance(value, int):
            assert value >= low, (key, value)
    for fraction in arguments.get("curriculum") or ():
        assert 0.0 <= fraction <= 1.0, arguments["curriculum"]


#: The commands without a count option (the others' first count is checked below).
NO_COUNT = {"scoring"}


@pytest.mark.parametrize("command", sorted(set(PARSERS) - NO_COUNT))
def test_a_bad_count_names_its_option(command: str) -> None:
    parser = PARSERS[command]()
    counts = [
        o for o in ("--episodes", "--timesteps", "--check-observations", "--iterations") if o in options_of(parser)
    ]
    assert counts, f"{command} has no count option"
    option = counts[0]
    stderr = io.StringIO()
    with contextlib.redirect_stderr(stderr), pytest.raises(SystemExit):
        parser.parse_args([option, "-5"])
    assert option in stderr.getvalue()


@pytest.mark.parametrize("command", ["train", "train_rllib"])
def test_a_training_seed_beyond_numpy_s_seeding_is_refused_by_the_parser(command: str) -> None:
    """SB3 and RLlib seed numpy's legacy generator, which takes seeds below 2**32: a larger --seed
    was accepted, made the run directory, and failed there in numpy's words without naming --seed."""
    parser = PARSERS[command]()
    assert parser.parse_args(["--seed", str(MAX_TRAINING_SEED)]).seed == MAX_TRAINING_SEED
    for seed in (MAX_TRAINING_SEED + 1, 2**32, 2**64):
        stderr = io.StringIO()
        with contextlib.redirect_stderr(stderr), pytest.raises(SystemExit):
            parser.parse_args(["--seed", str(seed)])
        assert "--seed" in stderr.getvalue() and f"must be at most {MAX_TRAINING_SEED}" in stderr.getvalue()


@pytest.mark.parametrize("command", sorted(PARSERS))
def test_a_count_that_becomes_a_vector_env_is_bounded_by_the_largest_one(command: str) -> None:
    """--n-envs, --envs-per-runner and --episodes (which run as one batch) become a vector env,
    which tether_gym refuses above MAX_NUM_ENVS: that failed after the work began (the run
    directory made, the controllers loaded). The parser refuses it under the option's name."""
    from agents.common.checks import MAX_NUM_ENVS

    parser = PARSERS[command]()
    options = [o for o in ("--n-envs", "--envs-per-runner", "--episodes", "--eval-episodes") if o in options_of(parser)]
    for option in options:
        action = next(a for a in parser._actions if option in a.option_strings)
        assert action.type is not None and action.type(str(MAX_NUM_ENVS)) == MAX_NUM_ENVS
        stderr = io.StringIO()
        with contextlib.redirect_stderr(stderr), pytest.raises(SystemExit):
            parser.parse_args([option, str(MAX_NUM_ENVS + 1)])
        assert option in stderr.getvalue() and f"must be at most {MAX_NUM_ENVS}" in stderr.getvalue()


#: The settings that are paths a command reads or writes.
PATH_DESTS = {
    "out",
    "resume",
    "runs",
    "source",
    "destination",
    "hyperparams",
    "benchmark_json",
    "file",
    "ceiling_file",
    "reference_file",
}


@pytest.mark.parametrize("command", sorted(PARSERS))
def test_an_empty_or_nul_path_is_refused_under_its_option_s_name(command: str) -> None:
    """``--out ""`` (an unset variable) named the current directory: the command wrote its outputs
    there, or read it as a checkpoint; a NUL raised a bare ValueError. Every path option refuses
    both, by name, and every path option has a path type (a new one too)."""
    from agents.common.cli import existing_file, path_argument

    parser = PARSERS[command]()
    paths = [action for action in parser._actions if action.dest in PATH_DESTS]
    assert paths, f"{command} has no path argument"
    for action in paths:
        assert action.type in (path_argument, existing_file), f"{command}: {action.dest} has no path type"
        name = action.option_strings[0] if action.option_strings else (action.metavar or action.dest)
        for bad in ("", "  ", "a\x00b"):
            stderr = io.StringIO()
            with contextlib.redirect_stderr(stderr), pytest.raises(SystemExit) as exit_:
                parser.parse_args(_arguments_with(parser, action, bad))
            assert exit_.value.code == 2 and str(name) in stderr.getvalue(), stderr.getvalue()


def _arguments_with(parser: argparse.ArgumentParser, target: argparse.Action, value: str) -> list[str]:
    """A command line giving ``target`` the value ``value`` and every other positional a plausible path."""
    tokens: list[str] = []
    for action in parser._actions:
        if action.option_strings:
            if action is target:
                tokens += [action.option_strings[0], value]
            elif action.required:
                tokens += [action.option_strings[0], "x"]
        elif action is not target and action.dest != "help":
            tokens.append("some/path")
        elif action is target:
            tokens.append(value)
    return tokens


def test_every_command_is_fuzzed() -> None:
    """A command added to agents.common.commands is fuzzed from the day it lands: it needs a
    parser, an ``ERRORS`` tuple and an entry in :data:`WORK` naming its work function."""
    for name in COMMANDS:
        module = MODULES[name]
        assert name in WORK, f"agents.{name} has no entry in WORK: name the function its main() hands the work to"
        for work in _works(name):
            assert callable(getattr(module, work, None)), f"agents.{name} has no {work}"
        errors = getattr(module, "ERRORS", None)
        assert isinstance(errors, tuple) and errors, f"agents.{name} has no ERRORS tuple of its refusals"
        assert isinstance(module.build_parser(), argparse.ArgumentParser)


#: Values an option may plausibly get: boundaries of the counts, non-finite numbers, near-miss names.
plausible_values = st.one_of(
    st.integers(-2, 3).map(str),
    st.integers(0, 10**7).map(str),
    st.sampled_from(["nan", "inf", "-inf", "0.5", "1.5", "1e6", "mcp", "lqr", "mpc", "passive", "TetherChain-v0"]),
    st.sampled_from(["out", "out/sub", "/dev/null", "policy_dir", "benchmark.json", "."]),
    # Paths that name nothing: empty or blank (an unset shell variable), or with a NUL.
    st.sampled_from(["", " ", "out\x00dir"]),
    # Seeds at the edge of what numpy's legacy generator (SB3's and RLlib's seeding) takes.
    st.sampled_from(["2147483647", "2147483648", "4294967295", "4294967296", str(2**64)]),
)


@st.composite
def plausible_command_lines(draw: st.DrawFn, parser: argparse.ArgumentParser) -> list[str]:
    """A command line made from ``parser``'s own actions: each option with as many values as it
    takes (a choice, a near-miss of one, or a plausible value), the positionals filled in."""
    tokens: list[str] = []

    def values_for(action: argparse.Action) -> list[str]:
        count = {None: 1, "?": draw(st.integers(0, 1)), "+": draw(st.integers(1, 3)), "*": draw(st.integers(0, 2))}.get(
            action.nargs, action.nargs
        )
        strategy = plausible_values
        if action.choices:
            choices = [str(choice) for choice in action.choices]
            strategy = st.one_of(st.sampled_from(choices), st.sampled_from(choices).map(lambda c: c[:-1] or "x"))
        return [draw(strategy) for _ in range(int(count))]

    optionals = [a for a in parser._actions if a.option_strings and "--help" not in a.option_strings]
    for action in draw(st.lists(st.sampled_from(optionals), max_size=5, unique_by=id)):
        tokens.append(next(o for o in action.option_strings if o.startswith("--")))
        if action.nargs != 0:
            tokens.extend(values_for(action))
    for action in (a for a in parser._actions if not a.option_strings):
        tokens.extend(values_for(action))
    return tokens


def argument_names(parser: argparse.ArgumentParser) -> set[str]:
    """How a message may name one of ``parser``'s arguments: an option (``--eval-episodes``), its
    setting's name (``eval_episodes``, as the configs' errors do) or a positional's metavar (``SRC``)."""
    names: set[str] = set()
    for action in parser._actions:
        names.update(action.option_strings)
        names.update({action.dest, action.dest.replace("_", "-")})
        metavars = action.metavar if isinstance(action.metavar, tuple) else (action.metavar,)
        names.update(m for m in metavars if m)
    names.discard("help")
    return names


class ReachedTheWork(Exception):
    """The stand-in for a command's work: everything before it (the checks) passed."""


def _works(command: str) -> tuple[str, ...]:
    """The names of ``command``'s work functions (:data:`WORK`)."""
    work = WORK[command]
    return (work,) if isinstance(work, str) else work


def _reach_the_work(*args: Any, **kwargs: Any) -> None:
    raise ReachedTheWork


@settings(
    max_examples=400,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
)
@given(command=st.sampled_from(COMMANDS), data=st.data())
def test_any_command_line_reaches_the_work_or_is_refused_by_name(command: str, data: st.DataObject) -> None:
    module = MODULES[command]
    parser = PARSERS[command]()
    tokens = data.draw(plausible_command_lines(parser), label="command line")
    stderr, stdout = io.StringIO(), io.StringIO()
    with (
        tempfile.TemporaryDirectory() as scratch,
        pytest.MonkeyPatch.context() as patch,
        contextlib.redirect_stderr(stderr),
        contextlib.redirect_stdout(stdout),
    ):
        for work in _works(command):
            patch.setattr(module, work, _reach_the_work)
        patch.chdir(scratch)  # relative paths among the values land in a scratch directory
        try:
            module.main(tokens)
        except ReachedTheWork:
            assert sorted(os.listdir(scratch)) == [], "the checks wrote into the working directory"
            return
        except SystemExit as exit_:
            assert exit_.code == 2, stderr.getvalue()
            assert "Traceback" not in stderr.getvalue()
            return
        except module.ERRORS as error:
            message = str(error)
            assert any(name in message for name in argument_names(parser)), (
                f"agents.{command} {tokens}: {type(error).__name__} names no argument: {message}"
            )
            return
    pytest.fail(f"agents.{command} {tokens} returned without reaching its work")


def test_a_conversion_checks_at_most_what_its_reference_file_can_hold() -> None:
    """--check-observations 10**9 allocated hundreds of GB before the first check, and a large
    count wrote a reference file above the 128 MiB its reader accepts."""
    from agents.common.checks import MAX_CHECK_OBSERVATIONS
    from agents.policies.conversion import ConvertConfig

    parser = PARSERS["convert"]()
    assert parser.parse_args(["a", "b", "--check-observations", str(MAX_CHECK_OBSERVATIONS)]).check_observations
    stderr = io.StringIO()
    with contextlib.redirect_stderr(stderr), pytest.raises(SystemExit):
        parser.parse_args(["a", "b", "--check-observations", str(MAX_CHECK_OBSERVATIONS + 1)])
    assert "--check-observations" in stderr.getvalue()
    with pytest.raises(ValueError, match=f"check_observations must be an integer in 16..{MAX_CHECK_OBSERVATIONS}"):
        ConvertConfig("a", "b", check_observations=10**9)


def test_the_configs_bound_their_vector_env_counts_as_the_parsers_do(tmp_path: Any) -> None:
    """The same bound for callers from Python: each config (and ship) refuses the count by name."""
    from agents.common.checks import MAX_NUM_ENVS
    from agents.evaluation.benchmark import BenchmarkConfig
    from agents.evaluation.comparison import CompareConfig
    from agents.training.config import TrainConfig
    from agents.training.shipping import ship

    for make, name in (
        (lambda n: CompareConfig("TetherChain-v0", episodes=n), "episodes"),
        (lambda n: BenchmarkConfig(episodes=n), "episodes"),
        (lambda n: TrainConfig(num_envs=n), "num_envs"),
        (lambda n: ship([], tmp_path / "models", episodes=n), "episodes"),
    ):
        with pytest.raises(
            ValueError, match=rf"{name} must be an integer in \d+..{MAX_NUM_ENVS}; got {MAX_NUM_ENVS + 1}"
        ):
            make(MAX_NUM_ENVS + 1)
    assert not (tmp_path / "models").exists()  # ship refused before it made --out
