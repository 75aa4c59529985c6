"""The comparison's settings (``agents.evaluation.comparison.CompareConfig``): checked when made,
and frozen. (The comparison's runs and refusals are tested with the command, in
``tests/agents/test_agents.py`` and ``tests/agents/test_agents_safety.py``.)"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from agents.evaluation.comparison import CompareConfig


def test_the_config_keeps_checked_values_and_is_frozen() -> None:
    config = CompareConfig(controllers=["passive", "lqr"], episodes=np.int64(3), seed=np.int32(7))
    assert config.controllers == ("passive", "lqr")
    assert (config.episodes, config.seed) == (3, 7)
    assert type(config.episodes) is int and type(config.seed) is int
    with pytest.raises(dataclasses.FrozenInstanceError):
        config.episodes = 4  # type: ignore[misc]


@pytest.mark.parametrize(
    ("settings", "message"),
    [
        ({"episodes": 1}, "episodes must be an integer >= 2; got 1"),
        ({"episodes": True}, "episodes must be an integer >= 2; got True"),
        ({"satellite": -1}, "satellite must be an integer >= 0; got -1"),
        ({"controllers": "lqr"}, "controllers must be a list of names or paths"),
        ({"controllers": ["lqr", ""]}, "controllers must be a list of names or paths"),
    ],
)
def test_bad_settings_are_refused_with_their_name(settings: dict[str, object], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        CompareConfig(**settings)  # type: ignore[arg-type]
