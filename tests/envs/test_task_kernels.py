"""The task kernel's guarantee: a reward is finite, and a state beyond its arithmetic ends the
episode as ``numerics_diverged`` instead of returning NaN or -inf while the episode runs on."""

from __future__ import annotations

import numpy as np

from tether_gym.envs.task import END_REASONS, task_from_arguments


def test_a_state_whose_energy_overflows_ends_as_numerics_diverged_with_a_finite_reward() -> None:
    task = task_from_arguments(3, "tetrahedron")
    task.reset([np.random.default_rng(k) for k in range(3)], np.arange(3))
    # Validated inputs cannot reach such a state (tether_gym.limits bounds speeds), so it is
    # planted directly: 0.5 m v^2 overflows for cluster 1 and is NaN (inf - inf) for cluster 2.
    task.sim.velocities_[1] = 1e200
    task.sim.velocities_[2, 0] = 1e200
    task.sim.velocities_[2, 1] = -1e200
    task._evaluate()
    reasons = [END_REASONS[k] for k in task.end_reason]
    assert reasons == ["running", "numerics_diverged", "numerics_diverged"]
    assert np.all(np.isfinite(task.scalars[:, :5]))
    assert task.scalars[1, 0] == -task.config.failure_penalty and task.scalars[1, 1] == 0.0
    assert np.all(np.isfinite(task.observation))


def test_the_healthy_clusters_of_the_batch_are_untouched_by_the_guard() -> None:
    task = task_from_arguments(2, "tetrahedron")
    task.reset([np.random.default_rng(7)] * 2, np.arange(2))
    task._evaluate()
    healthy = task.scalars[0].copy()
    task.sim.velocities_[1] = 1e200
    task._evaluate()
    assert np.array_equal(task.scalars[0], healthy) and task.end_reason[0] == 0
