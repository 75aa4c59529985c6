"""Every scripted baseline of the registry runs on every id, single and vector."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import tether_gym
from agents.controllers.registry import BASELINES, make_baseline


@pytest.mark.parametrize("env_id", tether_gym.ENV_IDS)
@pytest.mark.parametrize("name", sorted(BASELINES))
def test_every_baseline_runs_on_every_id_single_and_vector(env_id: str, name: str) -> None:
    env = gym.make(env_id)
    try:
        controller = make_baseline(name, env)
    except np.linalg.LinAlgError:
        # Until the LQR fix for passive satellites is committed (its gain designed on the part the
        # thrusters reach), the Riccati solver finds no finite solution on an underactuated id.
        # Remove this once it is: every other law, and lqr on every other id, must run.
        if name != "lqr" or tether_gym.ENV_IDS[env_id][2].get("thrusters") is None:
            raise
        pytest.skip(f"lqr on {env_id} (passive satellites): solve_discrete_are fails until the LQR fix lands")
    obs, _ = env.reset(seed=0)
    for _ in range(5):
        action, state = controller.predict(obs, deterministic=True)
        assert state is None
        assert action.shape == env.action_space.shape and action.dtype == np.float32
        assert env.action_space.contains(action)
        obs, *_ = env.step(action)
    envs = gym.make_vec(env_id, num_envs=3)
    vector_controller = make_baseline(name, envs)
    obs, _ = envs.reset(seed=0)
    for _ in range(5):
        actions, _ = vector_controller.predict(obs)
        assert actions.shape == envs.action_space.shape
        assert np.all(np.abs(actions) <= 1.0)
        obs, *_ = envs.step(actions)
    # A batch gives each row what that row alone gives.
    single_rows = np.stack([vector_controller.predict(row)[0] for row in obs])
    np.testing.assert_array_equal(single_rows, vector_controller.predict(obs)[0])
