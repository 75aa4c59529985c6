"""The model-predictive reference controller ``mpc``: it plans on clones of the true state,
leaves the controlled env untouched, is reproducible, and beats doing nothing on every id."""

from __future__ import annotations

import dataclasses

import gymnasium as gym
import numpy as np
import pytest

from agents.controllers.mpc import MPCController, MPCSettings, load_mpc_settings
from agents.evaluation.rollout import rollout
from agents.policies import make_controller
from tests.helpers import assert_unchanged, env_state
from tether_gym.registration import ENV_IDS

#: Small enough for CI: 8 candidates over 5 steps, around velocity feedback.
SMALL = MPCSettings(samples=8, horizon=5, knots=2, noise=0.3, terminal_weight=10.0, prior="velocity_feedback")
#: Plain sampling around zero thrust, no prior.
OPEN_LOOP = MPCSettings(samples=16, horizon=8, knots=3, noise=0.4, terminal_weight=10.0)


@pytest.mark.slow
@pytest.mark.parametrize("env_id", list(ENV_IDS))
def test_mpc_beats_passive_on_every_id(env_id: str) -> None:
    seeds = [3000, 3001, 3002]  # not the comparison's held-out seeds
    short = {"max_episode_steps": 60}
    probe = gym.make_vec(env_id, num_envs=1)
    passive = rollout(make_controller("passive", probe), env_id, seeds, env_kwargs=short)
    mpc = rollout(MPCController(probe, SMALL), env_id, seeds, env_kwargs=short)
    passive_return, mpc_return = passive.rewards.sum(axis=1), mpc.rewards.sum(axis=1)
    assert mpc_return.mean() > passive_return.mean(), (mpc_return, passive_return)
    assert not mpc.terminated.any()


@pytest.mark.parametrize("env_id", ["TetherTetrahedron-v0", "TetherTriangle-v0"])
def test_open_loop_sampling_alone_beats_passive(env_id: str) -> None:
    """Without a prior the planner finds damping thrust on its own."""
    seeds, short = [3000, 3001], {"max_episode_steps": 40}
    probe = gym.make_vec(env_id, num_envs=1)
    passive = rollout(make_controller("passive", probe), env_id, seeds, env_kwargs=short)
    mpc = rollout(MPCController(probe, OPEN_LOOP), env_id, seeds, env_kwargs=short)
    assert mpc.rewards.sum(axis=1).mean() > passive.rewards.sum(axis=1).mean()


def test_planning_leaves_the_controlled_env_untouched_and_is_reproducible() -> None:
    envs = gym.make_vec("TetherTetrahedron-v0", num_envs=3)
    observation, _ = envs.reset(seed=[1, 2, 3])
    first, second = MPCController(envs, SMALL), MPCController(envs, SMALL)
    before = env_state(envs)
    a, _ = first.predict(observation)
    assert_unchanged(before, env_state(envs))
    b, _ = second.predict(observation)
    assert a.shape == (3, 12) and a.dtype == np.float32 and np.all(np.abs(a) <= 1.0)
    assert np.array_equal(a, b)
    assert first.seconds_per_step > 0.0


def test_past_the_control_horizon_the_prior_alone_acts() -> None:
    """Candidates differ only within the control horizon; the rest of each rollout is the
    prior's closed loop, its estimate of the cost-to-go."""
    env = gym.make_vec("TetherTriangle-v0", num_envs=1)
    env.reset(seed=[4])
    controller = MPCController(env, MPCSettings(samples=6, horizon=12, control_horizon=4, knots=2, prior="lqr"))
    candidates = controller._candidates(0.5)
    assert np.all(candidates[:, :, 4:] == 0.0) and np.any(candidates[:, 1:, :4] != 0.0)


def test_the_plan_is_scored_with_the_tasks_reward() -> None:
    """Against a planner that keeps its nominal plan (noise 0), the best of the samples is never
    worse over the horizon: sampling searches, it does not just add noise."""
    env = gym.make_vec("TetherTriangle-v0", num_envs=2)
    observation, _ = env.reset(seed=[5, 6])
    searching = MPCController(env, MPCSettings(samples=16, horizon=6, knots=3, noise=0.5))
    snapshot = searching.task.snapshot().select(searching.rows)
    candidates = searching._candidates(0.5)
    costs = searching._rollout(snapshot, candidates)
    best = searching._update(candidates, costs)
    assert np.all(costs.min(axis=1) <= costs[:, 0])  # sample 0 is the nominal (zero) plan
    assert np.array_equal(best, candidates[np.arange(2), np.argmin(costs, axis=1)])


def test_an_episode_gets_the_same_plans_in_any_batch() -> None:
    """Each environment draws from its own generator, keyed by its episode's initial state."""
    seeds = [3100, 3101, 3102]
    short = {"max_episode_steps": 15}
    probe = gym.make_vec("TetherTriangle-v0", num_envs=1)
    together = rollout(MPCController(probe, SMALL), "TetherTriangle-v0", seeds, env_kwargs=short)
    alone = rollout(MPCController(probe, SMALL), "TetherTriangle-v0", seeds[2:], env_kwargs=short)
    assert together.rewards[2].tobytes() == alone.rewards[0].tobytes()


def test_without_warm_start_every_step_searches_from_the_prior_alone() -> None:
    """``warm_start: false`` carries no plan between steps: the next search's nominal candidate
    is the zero plan, where the default carries the shifted best plan."""
    env = gym.make_vec("TetherTriangle-v0", num_envs=2)
    observation, _ = env.reset(seed=[7, 8])
    settings = MPCSettings(samples=8, horizon=6, knots=3, noise=0.5, prior="lqr")
    warm = MPCController(env, settings)
    cold = MPCController(env, MPCSettings(**{**dataclasses.asdict(settings), "warm_start": False}))
    warm_action, _ = warm.predict(observation)
    cold_action, _ = cold.predict(observation)
    assert np.array_equal(warm_action, cold_action)  # the same search from the same state
    assert np.any(warm._candidates(0.5)[:, 0] != 0.0)
    assert np.all(cold._candidates(0.5)[:, 0] == 0.0)


def test_mpc_is_refused_clearly() -> None:
    with pytest.raises(ValueError, match="samples"):
        MPCSettings(samples=1)
    with pytest.raises(ValueError, match="knots"):
        MPCSettings(horizon=3, knots=4)
    with pytest.raises(ValueError, match="control_horizon"):
        MPCSettings(horizon=3, control_horizon=4)
    with pytest.raises(ValueError, match="knots"):
        MPCSettings(horizon=30, control_horizon=2, knots=3)
    with pytest.raises(ValueError, match="prior"):
        MPCSettings(prior="oracle")
    with pytest.raises(ValueError, match="warm_start must be true or false"):
        MPCSettings(warm_start="no")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="unknown mpc setting"):
        load_mpc_settings("TetherTetrahedron-v0", samplez=3)
    envs = gym.make_vec("TetherTetrahedron-v0", num_envs=2)
    controller = MPCController(envs, SMALL)
    with pytest.raises(ValueError, match="attach"):
        controller.predict(np.zeros((3, 30), np.float32))
    with pytest.raises(TypeError, match="tether-gym envs"):
        MPCController(gym.make("CartPole-v1"), SMALL)
    assert isinstance(make_controller("mpc", envs), MPCController)
