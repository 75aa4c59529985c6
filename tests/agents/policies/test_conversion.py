"""agents.policies.conversion: ConvertConfig's checks, made when it is built (the conversion
itself is tested end to end in tests/agents/test_agents_safety.py)."""

from __future__ import annotations

from pathlib import Path

import pytest

from agents.convert import build_parser
from agents.policies.conversion import ConvertConfig, convert


def test_the_config_takes_paths_as_text_and_keeps_them_as_paths() -> None:
    config = ConvertConfig("runs/a", "converted/a")
    assert config.source == Path("runs/a") and config.destination == Path("converted/a")
    assert (config.check_observations, config.trust_pickle, config.force) == (512, False, False)


@pytest.mark.parametrize("count", [15, 0, True, 512.0, "512"])
def test_too_few_or_non_integer_check_observations_are_refused(count: object) -> None:
    with pytest.raises(ValueError, match=r"check_observations must be an integer >= 16"):
        ConvertConfig("a", "b", check_observations=count)  # type: ignore[arg-type]


def test_the_command_line_defaults_are_the_configs(tmp_path: Path) -> None:
    args = build_parser().parse_args(["SRC", "DST"])
    assert args.check_observations == ConvertConfig("SRC", "DST").check_observations
    with pytest.raises(FileNotFoundError, match="SRC .* does not exist"):
        convert(ConvertConfig(tmp_path / "nowhere", tmp_path / "out", trust_pickle=True))
    assert not (tmp_path / "out").exists()  # refused before anything was written
