"""Residual policies: corrections learned on top of a scripted baseline's action."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from agents.baselines import make_baseline
from agents.policies import TrainedPolicy, make_controller
from agents.residual import ResidualVecEnv
from agents.safe_format import read_metadata
from agents.train import HyperparameterError, train, validate_hyperparameters
from tether_gym.sb3 import make_sb3_vec_env


@pytest.fixture(scope="module")
def residual_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("runs")
    return train(
        "ppo", "TetherTriangle-v0", seed=0, out=out, timesteps=256, num_envs=4,
        overrides={"n_steps": 64, "batch_size": 64, "residual_on": "lqr"}, eval_freq=256, eval_episodes=2,
        checkpoint_freq=256, progress_bar=False,
    )


def test_the_env_adds_the_correction_to_the_baseline_action() -> None:
    venv = make_sb3_vec_env("TetherTriangle-v0", 3, seed=4)
    plain = make_sb3_vec_env("TetherTriangle-v0", 3, seed=4)
    residual = ResidualVecEnv(venv, "lqr")
    lqr = make_baseline("lqr", plain)
    obs, plain_obs = residual.reset(), plain.reset()
    rng = np.random.default_rng(0)
    for _ in range(5):
        correction = rng.uniform(-0.3, 0.3, (3, 9)).astype(np.float32)
        expected = np.clip(lqr.predict(plain_obs)[0] + correction, -1, 1).astype(np.float32)
        obs, rewards, _, _ = residual.step(correction)
        plain_obs, plain_rewards, _, _ = plain.step(expected)
        assert np.array_equal(obs, plain_obs) and np.array_equal(rewards, plain_rewards)


def test_a_residual_policy_records_and_applies_its_baseline(residual_run: Path) -> None:
    assert read_metadata(residual_run)["residual_on"] == "lqr"
    envs = gym.make_vec("TetherTriangle-v0", num_envs=2)
    observation, _ = envs.reset(seed=[1, 2])
    policy = make_controller(str(residual_run), envs)
    assert isinstance(policy, TrainedPolicy) and policy.residual_on == "lqr"
    correction = policy.policy.predict(policy.normalizer.normalize_obs(observation).astype(np.float32),
                                       deterministic=True)[0]
    base = make_baseline("lqr", envs).predict(observation)[0]
    assert np.array_equal(policy.predict(observation)[0], np.clip(base + correction, -1, 1).astype(np.float32))
    unattached = TrainedPolicy(residual_run)
    with pytest.raises(RuntimeError, match="attach"):
        unattached.predict(observation)


def test_residual_on_must_name_a_baseline() -> None:
    with pytest.raises(HyperparameterError, match="residual_on"):
        validate_hyperparameters("ppo", {"n_timesteps": 10, "residual_on": "oracle"})
