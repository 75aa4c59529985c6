"""Property-based fuzzing of the commands' arguments (compare, train, benchmark, convert).

Every argument list either parses into valid settings, or argparse exits with status 2 and a
message that names the offending option (or the missing or unrecognised one). A parsed
integer option is never out of its range: the custom argument types refuse it first.
"""

from __future__ import annotations

import argparse
import contextlib
import io
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agents import benchmark, compare, convert, train

#: Property-based, with many generated examples per property: the fast suite (-m 'not slow') leaves them out.
pytestmark = pytest.mark.slow

PARSERS = {
    "compare": compare.build_parser,
    "train": train.build_parser,
    "benchmark": benchmark.build_parser,
    "convert": convert.build_parser,
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
        "eval_episodes": 1,
        "checkpoint_freq": 1,
        "verbose": 0,
        "check_observations": 16,
    }
    for key, low in minimum.items():
        value = arguments.get(key)
        if isinstance(value, int):
            assert value >= low, (key, value)


@pytest.mark.parametrize("command", sorted(PARSERS))
def test_a_bad_count_names_its_option(command: str) -> None:
    parser = PARSERS[command]()
    counts = [o for o in ("--episodes", "--timesteps", "--check-observations") if o in options_of(parser)]
    assert counts, f"{command} has no count option"
    option = counts[0]
    stderr = io.StringIO()
    with contextlib.redirect_stderr(stderr), pytest.raises(SystemExit):
        parser.parse_args([option, "-5"])
    assert option in stderr.getvalue()
