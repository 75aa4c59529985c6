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
        "ppo",
        "TetherTriangle-v0",
        seed=0,
        out=out,
        timesteps=256,
        num_envs=4,
        overrides={"n_steps": 64, "batch_size": 64, "residual_on": "lqr"},
        eval_freq=256,
        eval_episodes=2,
        checkpoint_freq=256,
        progress_bar=False,
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


@pytest.mark.slow
def test_a_residual_policy_records_and_applies_its_baseline(residual_run: Path) -> None:
    assert read_metadata(residual_run)["residual_on"] == "lqr"
    envs = gym.make_vec("TetherTriangle-v0", num_envs=2)
    observation, _ = envs.reset(seed=[1, 2])
    policy = make_controller(str(residual_run), envs)
    assert isinstance(policy, TrainedPolicy) and policy.residual_on == "lqr"
    correction = policy.policy.predict(
        policy.normalizer.normalize_obs(observation).astype(np.float32), deterministic=True
    )[0]
    base = make_baseline("lqr", envs).predict(observation)[0]
    assert np.array_equal(policy.predict(observation)[0], np.clip(base + correction, -1, 1).astype(np.float32))
    unattached = TrainedPolicy(residual_run)
    with pytest.raises(RuntimeError, match="attach"):
        unattached.predict(observation)


def test_residual_on_must_name_a_baseline() -> None:
    with pytest.raises(HyperparameterError, match="residual_on"):
        validate_hyperparameters("ppo", {"n_timesteps": 10, "residual_on": "oracle"})


@pytest.mark.parametrize("algo", ["ppo", "sac", "td3"])
def test_a_residual_policy_starts_exactly_at_its_baseline(algo: str) -> None:
    """The actor's last layer is zeroed, so the closed loop starts as the baseline's, for every
    algorithm (SAC and TD3 otherwise start with random corrections of about a third of full thrust)."""
    from agents.safe_format import ALGORITHMS
    from agents.train import start_at_the_baseline

    venv = ResidualVecEnv(make_sb3_vec_env("TetherTriangle-v0", 2, seed=0), "lqr")
    model = ALGORITHMS[algo]("MlpPolicy", venv, seed=0, device="cpu")
    observations = np.random.default_rng(1).normal(size=(16, *venv.observation_space.shape)).astype(np.float32)
    assert np.abs(model.predict(observations, deterministic=True)[0]).max() > 1e-4  # not zero by itself
    start_at_the_baseline(model)
    assert not np.any(model.predict(observations, deterministic=True)[0])
    if algo == "td3":
        import torch

        with torch.no_grad():
            assert not torch.any(model.actor_target(torch.as_tensor(observations)))


def test_action_noise_is_for_off_policy_algorithms() -> None:
    entry = {"n_timesteps": 100, "action_noise_std": 0.1}
    assert validate_hyperparameters("td3", entry)["action_noise_std"] == 0.1
    with pytest.raises(HyperparameterError, match="sac and td3"):
        validate_hyperparameters("ppo", entry)
    with pytest.raises(HyperparameterError, match="action_noise_std.*>= 0"):
        validate_hyperparameters("sac", {"n_timesteps": 100, "action_noise_std": -0.1})
    with pytest.raises(HyperparameterError, match="action_noise_std"):
        validate_hyperparameters("sac", {"n_timesteps": 100, "action_noise_std": "0.1"})
