"""The linear model of the cluster: elastic modes without rigid motion, and the expected
vibration energy against a Monte Carlo average."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

from agents.controllers.centralised import (
    VelocityFeedbackController,
)
from agents.controllers.linear_model import LinearModel


def test_elastic_modes_exclude_rigid_motion() -> None:
    model = LinearModel(gym.make("TetherTetrahedron-v0").unwrapped.task)
    assert model.num_modes == 6  # 3n - 6
    np.testing.assert_allclose(np.sqrt(model.omega2)[[0, -1]], [np.sqrt(50.0), np.sqrt(200.0)], rtol=1e-4)
    chain = LinearModel(gym.make("TetherChain-v0").unwrapped.task)
    assert chain.num_modes == 3 * 5 - 5  # collinear: no rotation about the axis


@pytest.mark.slow
def test_expected_vibration_energy_matches_a_monte_carlo_average() -> None:
    """The Lyapunov formula against brute force: sampled initial states run through the sampled
    closed loop, the energy summed over 3000 intervals."""
    env = gym.make("TetherTetrahedron-v0")
    controller = VelocityFeedbackController(env)
    model = controller.model
    gain = controller.feedback_matrix(controller.gain)
    task = env.unwrapped.task
    rng = np.random.default_rng(0)
    count = 4000
    n = task.cluster.num_nodes
    displacement = task.config.initial_displacement * rng.standard_normal((count, n, 3))
    velocity = task.config.initial_velocity * rng.standard_normal((count, n, 3))
    state = model.modal_state(displacement, velocity)
    closed = model.Ad - model.Bd @ gain
    weight = model.energy_weight()
    total = np.zeros(count)
    for _ in range(3000):
        total += np.einsum("ki,ij,kj->k", state, weight, state) * model.interval
        state = state @ closed.T
    standard_error = total.std() / math.sqrt(count)
    assert abs(total.mean() - model.expected_vibration_energy(gain)) < 4 * standard_error
