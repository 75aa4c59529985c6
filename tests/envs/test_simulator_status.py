"""An episode that ends as ``numerics_diverged`` says why, in ``info["simulator_status"]``:
a non-finite state, an interval refused for its sub-step budget, or an energy runaway."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import tether_gym  # noqa: F401  (registers the ids)
from tether_gym import _kernels
from tether_gym.simulator import STATUS_NAMES


# The frozen states (a refused interval, status 2, is retried by the next step instead).
@pytest.mark.parametrize("status", [_kernels.STATUS_NON_FINITE, _kernels.STATUS_ENERGY_RUNAWAY])
def test_the_single_env_reports_why_the_numerics_ended_the_episode(status: int) -> None:
    env = gym.make("TetherTetrahedron-v0")
    env.reset(seed=0)
    _, _, terminated, _, info = env.step(np.zeros(env.action_space.shape, dtype=np.float32))
    assert info["simulator_status"] == _kernels.STATUS_OK and not terminated
    env.unwrapped.task.sim.counter_table[0, _kernels.STATUS] = status  # type: ignore[attr-defined]  # as the kernels flag it
    _, _, terminated, _, info = env.step(np.zeros(env.action_space.shape, dtype=np.float32))
    assert terminated and info["end_reason"] == "numerics_diverged"
    assert STATUS_NAMES[info["simulator_status"]] == STATUS_NAMES[status]


def test_the_vector_env_reports_it_per_row() -> None:
    venv = gym.make_vec("TetherTetrahedron-v0", num_envs=3)
    venv.reset(seed=0)
    venv.unwrapped.task.sim.counter_table[1, _kernels.STATUS] = _kernels.STATUS_ENERGY_RUNAWAY  # type: ignore[attr-defined]
    _, _, terminated, _, info = venv.step(np.zeros((3, 12)))
    assert terminated.tolist() == [False, True, False]
    assert info["simulator_status"].tolist() == [0, _kernels.STATUS_ENERGY_RUNAWAY, 0]
    assert info["end_reason"][1] == "numerics_diverged"


def test_a_task_snapshot_with_a_non_finite_cluster_restores() -> None:
    venv = gym.make_vec("TetherTetrahedron-v0", num_envs=2)
    venv.reset(seed=0)
    task = venv.unwrapped.task  # type: ignore[attr-defined]
    task.sim.positions_[1, 0] = np.nan  # the writable view: a state the kernels then flag
    venv.step(np.zeros((2, 12)))
    assert task.sim.status.tolist() == [0, _kernels.STATUS_NON_FINITE]
    state = task.snapshot()
    task.step(np.zeros((2, 12)))
    task.restore(state)  # the frozen cluster's NaN is what it diverged to, not a bad state
    assert task.sim.status.tolist() == [0, _kernels.STATUS_NON_FINITE]
    assert np.array_equal(task.sim.positions[0], state.simulator.positions[0])
