"""The RLlib trainer's configuration and hyperparameters (agents.training.rllib), checked before Ray
starts: these run without the rllib extra (test_rllib.py, which trains, needs it)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from agents.common.data import HYPERPARAMS_DIR
from agents.training.hyperparams import HyperparameterError
from agents.training.rllib import ALGO, RLlibConfig, resolve_hyperparameters

ENV_ID = "TetherTetrahedron-v0"


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        ({"env_id": "TetherNothing-v0"}, "unknown env id 'TetherNothing-v0'"),
        ({"seed": -1}, "seed must be an integer in 0..2147483647; got -1"),
        ({"seed": None}, "seed must be an integer in 0..2147483647; got None"),
        ({"seed": 2**32}, "seed must be an integer in 0..2147483647; got 4294967296"),
        ({"num_env_runners": -1}, "num_env_runners must be an integer >= 0"),
        ({"eval_freq": 0}, "eval_freq must be an integer >= 1"),
        ({"eval_episodes": 2.0}, "eval_episodes must be an integer in 2..100000; got 2.0"),
        ({"checkpoint_freq": True}, "checkpoint_freq must be an integer >= 1; got True"),
        ({"timesteps": 0}, "timesteps must be an integer >= 1"),
        ({"envs_per_runner": 0}, "envs_per_runner must be an integer >= 1"),
        ({"num_cpus": 0}, "num_cpus must be an integer >= 1"),
        ({"num_cpus": 2, "address": "10.0.0.1:6379"}, "num_cpus sets the size of a local Ray instance"),
    ],
)
def test_bad_arguments_are_named(arguments: dict[str, object], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        RLlibConfig(**arguments)  # type: ignore[arg-type]


def test_the_config_holds_plain_integers() -> None:
    """A numpy integer passes the checks and is stored as an int, which config.yml can hold."""
    config = RLlibConfig(seed=np.int64(3), timesteps=np.int32(800), envs_per_runner=None)
    assert type(config.seed) is int and type(config.timesteps) is int and config.envs_per_runner is None
    assert yaml.safe_load(yaml.safe_dump({"seed": config.seed, "timesteps": config.timesteps})) == {
        "seed": 3,
        "timesteps": 800,
    }
    with pytest.raises(AttributeError):
        config.seed = 4  # type: ignore[misc]


def test_the_overrides_go_on_top_of_the_file(tmp_path: Path) -> None:
    default = yaml.safe_load((HYPERPARAMS_DIR / f"{ALGO}.yml").read_text())["default"]
    hyperparams = resolve_hyperparameters(RLlibConfig(ENV_ID, timesteps=800, envs_per_runner=3))
    assert hyperparams["n_timesteps"] == 800 and hyperparams["num_envs_per_env_runner"] == 3
    assert hyperparams["minibatch_size"] == default["minibatch_size"] and "multiagent" not in hyperparams
    # The multi-agent flag on an entry without multi-agent options: their defaults.
    centralised = tmp_path / "centralised.yml"
    centralised.write_text(yaml.safe_dump({"default": {"n_timesteps": 800, "num_envs_per_env_runner": 1}}))
    assert "multiagent" not in resolve_hyperparameters(RLlibConfig(ENV_ID, hyperparams_file=centralised))
    multiagent = resolve_hyperparameters(RLlibConfig(ENV_ID, hyperparams_file=centralised, multiagent=True))
    assert multiagent["multiagent"] == {}


def test_bad_hyperparameters_fail_before_ray(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="envs_per_runner must be at most"):
        resolve_hyperparameters(RLlibConfig(ENV_ID, envs_per_runner=10**9))
    bad = tmp_path / "bad.yml"
    bad.write_text(yaml.safe_dump({"default": {"n_timesteps": 800, "learning_rate": 0.1}}))
    with pytest.raises(HyperparameterError, match="unknown key 'learning_rate'"):
        resolve_hyperparameters(RLlibConfig(ENV_ID, hyperparams_file=bad))
    # The multi-agent options are tried on the env, whose message names the bad one.
    bad.write_text(yaml.safe_dump({"default": {"n_timesteps": 800, "multiagent": {"reward": "sharez"}}}))
    with pytest.raises(HyperparameterError, match="'multiagent'.*'sharez'"):
        resolve_hyperparameters(RLlibConfig(ENV_ID, hyperparams_file=bad))
    # The centralised file's observation filter cannot be exported with one shared policy.
    with pytest.raises(HyperparameterError, match="'normalize_obs' must be false with 'multiagent'"):
        resolve_hyperparameters(RLlibConfig(ENV_ID, multiagent=True))
