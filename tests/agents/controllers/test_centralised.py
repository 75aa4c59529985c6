"""The centralised scripted laws: velocity feedback and LQR against passive, the gain rule, the
tension-aware struts, and their input errors."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

from agents.controllers.centralised import (
    LQRController,
    PassiveController,
    TensionAwareController,
    VelocityFeedbackController,
)
from agents.controllers.registry import make_baseline
from agents.policies import make_controller
from tether_gym.envs.contract import Scalar


def small_perturbation_energy(controller_class: type, steps: int = 30) -> np.ndarray:
    envs = gym.make_vec("TetherTetrahedron-v0", num_envs=8, initial_displacement=1e-4, initial_velocity=1e-4)
    controller = controller_class(envs)
    obs, _ = envs.reset(seed=3)
    start = envs.unwrapped.task.scalars[:, Scalar.VIBRATION_ENERGY].copy()
    for _ in range(steps):
        obs, _, terminated, _, infos = envs.step(controller.predict(obs)[0])
        assert not terminated.any()
    assert infos["slack_count"].max() == 0  # the linear regime: every cable stays taut
    return infos["vibration_energy"] / start


def test_lqr_and_velocity_feedback_beat_passive_on_small_perturbations() -> None:
    passive = small_perturbation_energy(PassiveController)
    assert np.all(passive > 0.5)
    for controller_class in (LQRController, VelocityFeedbackController):
        controlled = small_perturbation_energy(controller_class)
        assert np.all(controlled < 0.01 * passive)


@pytest.mark.parametrize("env_id", ["TetherTetrahedron-v0", "TetherRadialChain-v0"])
def test_velocity_feedback_gain_rule_minimises_the_expected_vibration_energy(env_id: str) -> None:
    controller = VelocityFeedbackController(gym.make(env_id))
    cost = lambda gain: controller.model.expected_vibration_energy(controller.feedback_matrix(gain))  # noqa: E731
    best = cost(controller.gain)
    assert 0 < best < math.inf
    for factor in (0.5, 0.9, 1.1, 2.0):
        assert cost(factor * controller.gain) > best


def test_tension_aware_struts_act_only_across_slack_cables() -> None:
    env = gym.make("TetherTetrahedron-v0")
    controller = TensionAwareController(env)
    task = env.unwrapped.task
    positions = controller.nominal_relative[None].copy()
    taut = np.zeros((1, task.cluster.num_cables))
    np.testing.assert_array_equal(controller.strut_forces(positions, taut), 0.0)
    slack = taut.copy()
    slack[0, 0] = -0.01  # cable 0 (satellites 0 and 1) is 1 cm short: slack
    force = controller.strut_forces(positions, slack)[0]
    apart = positions[0, 1] - positions[0, 0]
    assert np.dot(force[1], apart) > 0 > np.dot(force[0], apart)  # pushed apart along the cable
    np.testing.assert_allclose(np.linalg.norm(force[0]), controller.strut_stiffness * 0.01)
    np.testing.assert_array_equal(force[2:], 0.0)


def test_bad_input_gets_clear_errors() -> None:
    env = gym.make("TetherTetrahedron-v0")
    with pytest.raises(ValueError, match="unknown baseline"):
        make_baseline("pid", env)
    with pytest.raises(ValueError, match="unknown controller"):
        make_controller("no-such-model", env)
    controller = make_baseline("velocity_feedback", env)
    with pytest.raises(ValueError, match="shape"):
        controller.predict(np.zeros(5))
    with pytest.raises(ValueError, match="NaN"):
        controller.predict(np.full(env.observation_space.shape, np.nan))
    with pytest.raises(ValueError, match="observed"):
        make_baseline("lqr", gym.make("TetherTetrahedron-v0", observed_satellites=[0, 1]))
    with pytest.raises(TypeError, match="not a tether-gym environment"):
        make_baseline("passive", gym.make("CartPole-v1"))
    with pytest.raises(ValueError, match="gain"):
        VelocityFeedbackController(env, gain=-1.0)
