"""Agents x clusters as one SB3 VecEnv, the decentralised baselines, and training a shared
decentralised policy with agents.train."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from agents.controllers.decentralised import LocalTensionAwareController, LocalVelocityFeedbackController
from agents.controllers.registry import make_baseline
from agents.policies import make_controller
from agents.policies.format import read_metadata
from agents.training.config import TrainConfig
from agents.training.hyperparams import HyperparameterError, validate_hyperparameters
from agents.training.sb3 import train
from tether_gym.envs.arguments import EnvArgumentError
from tether_gym.multiagent import parallel_env
from tether_gym.multiagent.sb3 import AgentVecEnv, make_agent_vec_env


def test_rows_are_the_parallel_envs_agents() -> None:
    venv = make_agent_vec_env("TetherHub-v0", num_envs=3, seed=10, communication={"hops": 1})
    assert venv.num_envs == 3 * 7
    rows = venv.reset()
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (venv.num_envs, 3)).astype(np.float32)
    rows, rewards, dones, infos = venv.step(actions)
    for b in range(3):  # cluster b of the batch is a parallel env reset with seed 10 + b
        env = parallel_env("TetherHub-v0", communication={"hops": 1})
        env.reset(seed=10 + b)
        observations, team, *_ = env.step({name: actions[7 * b + k] for k, name in enumerate(env.possible_agents)})
        for k, name in enumerate(env.possible_agents):
            np.testing.assert_array_equal(rows[7 * b + k], observations[name])
            assert rewards[7 * b + k] == np.float32(team[name])
    assert not dones.any() and infos == [{}] * venv.num_envs


def test_autoreset_reports_the_terminal_observations() -> None:
    venv = AgentVecEnv("TetherTriangle-v0", num_envs=2, max_episode_steps=3)
    venv.seed(0)
    venv.reset()
    for _ in range(2):
        _, _, dones, _ = venv.step(np.zeros((6, 3), np.float32))
        assert not dones.any()
    last = venv.batch.observations().reshape(6, -1)  # what the third step will end on is measured after it
    rows, _, dones, infos = venv.step(np.zeros((6, 3), np.float32))
    assert dones.all()
    for row, info in enumerate(infos):
        assert info["TimeLimit.truncated"] is True and info["end_reason"] == "running"
        assert info["terminal_observation"].shape == last[row].shape
        assert not np.array_equal(info["terminal_observation"], rows[row])  # the new episode's first
    assert (venv.batch.episode_steps == 0).all()
    with pytest.raises(EnvArgumentError, match=r"actions must have shape \(6, 3\)"):
        venv.step(np.zeros((2, 9), np.float32))


def test_local_baselines_read_only_local_quantities() -> None:
    # The same law from the single-agent observation and from the multi-agent local observations.
    env = parallel_env("TetherOctahedron-v0")
    single = gym.make("TetherOctahedron-v0")
    for cls in (LocalVelocityFeedbackController, LocalTensionAwareController):
        controller = cls(single)
        observations, _ = env.reset(seed=3)
        obs, _ = single.reset(seed=3)
        for _ in range(20):
            joint, _ = controller.predict(obs)
            local = controller.act_local(np.stack([observations[name] for name in env.possible_agents])[None])[0]
            np.testing.assert_allclose(joint.reshape(-1, 3), local, atol=2e-5)
            observations, *_ = env.step({name: joint[3 * k : 3 * k + 3] for k, name in enumerate(env.possible_agents)})
            obs, *_ = single.step(joint)


def test_local_velocity_feedback_pushes_no_net_force() -> None:
    env = gym.make("TetherHub-v0")
    controller = make_baseline("local_velocity_feedback", env, gain=0.01)  # small: nothing clipped
    obs, _ = env.reset(seed=0)
    force = controller.thrust(*controller.decode(obs[None].astype(np.float64)))
    np.testing.assert_allclose(force.sum(axis=1), 0.0, atol=1e-12)


def test_multiagent_hyperparameters_are_checked() -> None:
    with pytest.raises(HyperparameterError, match="multi-agent option"):
        validate_hyperparameters("ppo", {"n_timesteps": 10, "multiagent": {"comms": 1}})
    with pytest.raises(HyperparameterError, match="'multiagent' must be a mapping"):
        validate_hyperparameters("ppo", {"n_timesteps": 10, "multiagent": 3})


@pytest.mark.slow
def test_ppo_trains_a_shared_decentralised_policy(tmp_path: Path) -> None:
    run = train(
        TrainConfig(
            env_id="TetherTetrahedron-v0",
            seed=0,
            out=tmp_path,
            hyperparams_file=Path("agents/hyperparams/ppo_multiagent.yml"),
            timesteps=16_384,
            num_envs=4,
            overrides={"n_steps": 256, "batch_size": 512, "multiagent": {"communication": {"hops": 1}}},
            eval_freq=8_192,
            eval_episodes=2,
            progress_bar=False,
        )
    )
    assert run.name == "ppo_multiagent_seed0"
    metadata = read_metadata(run)
    assert metadata["multiagent"] == {"communication": {"hops": 1}}
    assert metadata["num_timesteps"] >= 16_384
    # The saved policy runs wherever a policy runs: on a vector env, through make_controller.
    envs = gym.make_vec("TetherTetrahedron-v0", num_envs=3)
    controller = make_controller(str(run), envs)
    obs, _ = envs.reset(seed=0)
    for _ in range(3):
        actions, _ = controller.predict(obs)
        assert actions.shape == (3, 12) and np.abs(actions).max() <= 1.0
        obs, *_ = envs.step(actions)
    with pytest.raises(ValueError, match="attach"):
        controller.predict(obs[:2])
    # ... and in the multi-agent env, on its local observations.
    env = parallel_env("TetherTetrahedron-v0", communication={"hops": 1})
    observations, _ = env.reset(seed=0)
    local = np.stack([observations[name] for name in env.possible_agents])
    assert controller.act_local(local).shape == (4, 3)


def test_decentralised_models_ship_beside_the_centralised_ones() -> None:
    from agents.training.shipping import model_name, reproduce_command

    assert model_name({"algo": "ppo", "multiagent": None}) == "ppo"
    assert model_name({"algo": "ppo", "multiagent": {}}) == "ppo_multiagent"
    candidate = {
        "env_id": "TetherHub-v0",
        "algo": "ppo_multiagent",
        "seed": 2,
        "command": "python -m agents.train --multiagent --env TetherHub-v0 --seed 2 --no-progress",
    }
    command = reproduce_command(candidate, "agents/models")
    assert "--algo ppo " in command and "--multiagent" in command
    assert command.endswith("--hyperparams agents/models/TetherHub-v0/ppo_multiagent/config.yml")


def test_single_agent_envs_refuse_what_they_cannot_reproduce() -> None:
    from stable_baselines3 import PPO

    from agents.policies import PolicySpec, TrainedPolicy

    options = {"communication": {"hops": 1, "delay": 2}}
    model = PPO("MlpPolicy", make_agent_vec_env("TetherTriangle-v0", num_envs=1, seed=0, **options), device="cpu")
    policy = TrainedPolicy.from_parts(model.policy, None, "TetherTriangle-v0", "ppo", PolicySpec(multiagent=options))
    with pytest.raises(ValueError, match="evaluate it in tether_gym.multiagent.parallel_env"):
        policy.attach(gym.make("TetherTriangle-v0"))
    with pytest.raises(RuntimeError, match="attach"):
        policy.predict(np.zeros(gym.make("TetherTriangle-v0").observation_space.shape))
    stateless = TrainedPolicy.from_parts(model.policy, None, "TetherTriangle-v0", "ppo", PolicySpec(multiagent={}))
    with pytest.raises(ValueError, match="local observations of size"):
        stateless.attach(gym.make("TetherTriangle-v0"))  # trained with messages, attached without
