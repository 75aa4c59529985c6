"""agents.training.config.TrainConfig: every field is checked when the config is made, in the
words train() used for its keyword arguments, and the counts it holds are Python ints."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from agents.training.config import TrainConfig


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"algo": "a2c"}, "unknown algorithm 'a2c'; choose one of"),
        ({"env_id": "Nope-v0"}, "unknown env id 'Nope-v0'; tether-gym ids are"),
        ({"seed": -1}, "seed must be an integer in 0..2147483647; got -1"),
        ({"seed": True}, "seed must be an integer in 0..2147483647; got True"),
        # numpy's legacy seeding (SB3's) takes seeds below 2**32: this failed after the run directory was made.
        ({"seed": 2**32}, "seed must be an integer in 0..2147483647; got 4294967296"),
        ({"eval_freq": 0}, "eval_freq must be an integer >= 1; got 0"),
        ({"eval_episodes": 1.5}, "eval_episodes must be an integer in 2..100000; got 1.5"),
        ({"eval_episodes": 1}, "eval_episodes must be an integer in 2..100000; got 1"),
        ({"checkpoint_freq": "10"}, "checkpoint_freq must be an integer >= 1; got '10'"),
        ({"verbose": -1}, "verbose must be an integer >= 0; got -1"),
        ({"timesteps": 0}, "timesteps must be an integer >= 1; got 0"),
        ({"num_envs": 0}, "num_envs must be an integer in 1..100000; got 0"),
        ({"num_envs": 100_001}, "num_envs must be an integer in 1..100000; got 100001"),
    ],
)
def test_a_bad_field_is_refused_by_name(fields: dict[str, object], message: str) -> None:
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")):
        TrainConfig(**fields)  # type: ignore[arg-type]


def test_numpy_counts_become_python_ints() -> None:
    """config.yml records the seed, and YAML's safe dumper refuses numpy scalars."""
    config = TrainConfig(seed=np.int64(3), timesteps=np.int32(512), num_envs=np.uint8(4), eval_episodes=np.int16(2))
    for name, value in (("seed", 3), ("timesteps", 512), ("num_envs", 4), ("eval_episodes", 2)):
        assert type(getattr(config, name)) is int and getattr(config, name) == value


def test_the_defaults_are_the_command_lines_and_the_config_is_frozen() -> None:
    from agents.train import build_parser, config_from_args

    config = TrainConfig()
    assert config_from_args(build_parser().parse_args([])) == config
    assert config_from_args(build_parser().parse_args(["--seed", "7"]), command="c") == dataclasses.replace(
        config, seed=7, command="c"
    )
    with pytest.raises(dataclasses.FrozenInstanceError):
        config.seed = 1  # type: ignore[misc]
