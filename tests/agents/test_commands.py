"""Errors that name the argument, from the library's configs and from every command's parser."""

from __future__ import annotations

import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import agents.compare
import agents.convert
import agents.evaluation.comparison
import agents.policies
import agents.policies.loaded
import agents.train
import agents.training.sb3
from agents.evaluation.comparison import CompareConfig, compare
from agents.evaluation.rollout import rollout
from agents.policies import OtherIdWarning, TrainedPolicy, make_controller, shipped_models
from agents.training.config import TrainConfig
from agents.training.sb3 import train
from tests.agents.helpers import ENV


def _quietly_on_another_id(model: Path, env_id: str = ENV) -> None:
    """make_controller(model) on ``env_id`` with the other-id opt-in, its warning expected and silenced."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OtherIdWarning)
        make_controller(str(model), gym.make_vec(env_id, num_envs=1), allow_other_id=True)


def test_bad_arguments_name_the_argument(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    cases = [
        (lambda: compare(CompareConfig(ENV, episodes=-3, out=out)), "episodes must be an integer in 2..100000"),
        (lambda: compare(CompareConfig(ENV, seed=-1, out=out)), "seed must be an integer >= 0"),
        (lambda: compare(CompareConfig(ENV, seed=1.5, out=out)), "seed must be an integer"),
        (lambda: compare(CompareConfig("Nope-v0", out=out)), "unknown env id 'Nope-v0'"),
        (
            lambda: compare(CompareConfig(ENV, controllers=["passive", "nope"], out=out, episodes=2)),
            "unknown controller 'nope'",
        ),
        (lambda: compare(CompareConfig(ENV, controllers=["lqr", "lqr"], out=out)), r"\['lqr'\] more than once"),
        (lambda: compare(CompareConfig(ENV, controllers=[], out=out)), "at least one controller"),
        (lambda: compare(CompareConfig(ENV, satellite=9, out=out, episodes=2)), r"satellite must be in 0\.\.3"),
        (
            lambda: rollout(make_controller("passive", gym.make_vec(ENV, num_envs=1)), ENV, [1.5]),
            r"seeds must be non-negative integers; got \[1\.5\]",
        ),
        (lambda: train(TrainConfig("ppo", ENV, seed=-1, out=out)), "seed must be an integer in 0..2147483647"),
        (
            lambda: train(TrainConfig("ppo", ENV, eval_episodes=1, out=out)),
            "eval_episodes must be an integer in 2..100000",
        ),
        (lambda: train(TrainConfig("ppo", ENV, timesteps=0, out=out)), "timesteps must be an integer >= 1"),
        (lambda: train(TrainConfig("a2c", ENV, out=out)), "unknown algorithm 'a2c'"),
        (lambda: train(TrainConfig("ppo", "Nope-v0", out=out)), "unknown env id 'Nope-v0'"),
        (
            lambda: make_controller(
                str(shipped_models("TetherSpinningTriangle-v0")["ppo"]), gym.make_vec(ENV, num_envs=1)
            ),
            "trained on TetherSpinningTriangle-v0, not TetherTetrahedron-v0: .*--allow-other-id",
        ),
        (
            lambda: _quietly_on_another_id(shipped_models("TetherSpinningTriangle-v0")["ppo"]),
            r"acts with 9 actions \(policy.json: action_space.shape \[9\]\), but TetherTetrahedron-v0 takes 12",
        ),
        (
            # The same 9 actions, one observation fewer: the observation check names the sizes.
            lambda: _quietly_on_another_id(shipped_models("TetherRadialChain-v0")["ppo"], "TetherTriangle-v0"),
            "takes observations of shape .20,., but TetherTriangle-v0 gives .21,.",
        ),
    ]
    shipped = TrainedPolicy(shipped_models(ENV)["ppo"])
    cases += [
        (lambda: shipped.predict(np.full(30, np.nan)), "NaN"),
        (lambda: shipped.predict(np.zeros(29)), r"shape \(30,\) or \(N, 30\)"),
    ]
    for attempt, message in cases:
        with pytest.raises(ValueError, match=message):
            attempt()
    with pytest.raises(FileNotFoundError, match="has no best/ directory"):
        TrainedPolicy(shipped_models(ENV)["ppo"], best=True)
    with pytest.raises(FileNotFoundError, match="no trained policy at"):
        TrainedPolicy(tmp_path / "nowhere")
    for main, argv, argument in [
        (agents.compare.main, ["--episodes", "-3"], "--episodes"),
        (agents.compare.main, ["--env", "Nope-v0"], "--env"),
        (agents.train.main, ["--seed", "x"], "--seed"),
        (agents.train.main, ["--timesteps", "0"], "--timesteps"),
        (agents.convert.main, ["a", "b", "--check-observations", "3"], "--check-observations"),
    ]:
        with pytest.raises(SystemExit) as exit_info:
            main(argv)
        assert exit_info.value.code == 2 and argument in capsys.readouterr().err
