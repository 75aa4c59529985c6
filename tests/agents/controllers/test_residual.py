"""Residual policies: corrections learned on top of a scripted baseline's action."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

from agents.controllers.registry import make_baseline
from agents.policies import TrainedPolicy, make_controller
from agents.policies.format import read_metadata
from agents.training.config import TrainConfig
from agents.training.hyperparams import HyperparameterError, validate_hyperparameters
from agents.training.residual_env import ResidualVecEnv
from agents.training.sb3 import train
from tether_gym.sb3 import make_sb3_vec_env


@pytest.fixture(scope="module")
def residual_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("runs")
    return train(
        TrainConfig(
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
    from agents.policies.format import ALGORITHMS
    from agents.training.sb3 import start_at_the_baseline

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


def _actor_and_critic(model: Any) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Copies of the actor's and the critic's weights (SAC/TD3: ``model.critic``; PPO: the rest
    of the policy)."""
    from agents.training.callbacks import actor_parameters

    actor = actor_parameters(model)
    actor_ids = {id(p) for p in actor}
    critic = model.critic.parameters() if hasattr(model, "critic") else model.policy.parameters()
    return [p.detach().numpy().copy() for p in actor], [
        p.detach().numpy().copy() for p in critic if id(p) not in actor_ids
    ]


@pytest.mark.parametrize("algo", ["ppo", "td3", "sac"])
def test_critic_warmup_freezes_the_actor_and_then_releases_it(algo: str) -> None:
    """While warming up only the critic learns (the actor's weights stay bit-identical); after the
    warm-up the actor learns too."""
    from agents.policies.format import ALGORITHMS
    from agents.training.callbacks import CriticWarmup

    venv = ResidualVecEnv(make_sb3_vec_env("TetherTriangle-v0", 2, seed=0), "local_tension_aware")
    options: dict[str, Any] = {"n_steps": 32, "batch_size": 32} if algo == "ppo" else {"learning_starts": 16}
    model = ALGORITHMS[algo]("MlpPolicy", venv, seed=0, device="cpu", **options)
    actor0, critic0 = _actor_and_critic(model)
    warmup = CriticWarmup(10_000)
    model.learn(total_timesteps=128, callback=warmup)
    assert warmup.frozen
    actor1, critic1 = _actor_and_critic(model)
    assert all(np.array_equal(a, b) for a, b in zip(actor0, actor1, strict=True))
    assert any(not np.array_equal(a, b) for a, b in zip(critic0, critic1, strict=True))
    warmup.steps = 0  # released from the next update on
    model.learn(total_timesteps=128, callback=warmup, reset_num_timesteps=False)
    assert warmup.frozen is False
    actor2, _ = _actor_and_critic(model)
    assert any(not np.array_equal(a, b) for a, b in zip(actor1, actor2, strict=True))


def test_critic_warmup_is_checked() -> None:
    assert validate_hyperparameters("ppo", {"n_timesteps": 10, "critic_warmup": 5})["critic_warmup"] == 5
    with pytest.raises(HyperparameterError, match="critic_warmup.*>= 0"):
        validate_hyperparameters("ppo", {"n_timesteps": 10, "critic_warmup": -1})
