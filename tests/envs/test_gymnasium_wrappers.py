"""Gymnasium's own vector wrappers on the default ``gym.make_vec`` env, unchanged.

They assume next-step autoreset (Gymnasium's default and the native env's): each wrapper here is
checked against the same env stepped without it, on the same seeds and actions, across episode
ends (short episodes, so several autoresets happen)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode
from gymnasium.wrappers.vector import ClipAction, NormalizeObservation, NormalizeReward, RecordEpisodeStatistics

ENV_ID = "tether_gym:TetherTriangle-v0"
NUM_ENVS = 4
#: Episodes of 3 steps, so 12 steps hold three autoresets per sub-env.
EPISODE_STEPS = 3
STEPS = 12


def _envs() -> gym.vector.VectorEnv:
    return gym.make_vec(ENV_ID, num_envs=NUM_ENVS, max_episode_steps=EPISODE_STEPS)


def _actions(shape: tuple[int, ...], scale: float = 1.0) -> list[np.ndarray]:
    rng = np.random.default_rng(3)
    return [(scale * rng.uniform(-1, 1, shape)).astype(np.float32) for _ in range(STEPS)]


def test_the_default_is_next_step() -> None:
    assert _envs().metadata["autoreset_mode"] is AutoresetMode.NEXT_STEP


def test_record_episode_statistics_sums_each_episode() -> None:
    raw, wrapped = _envs(), RecordEpisodeStatistics(_envs())
    raw.reset(seed=0)
    wrapped.reset(seed=0)
    running = np.zeros(NUM_ENVS)
    recorded = 0
    for action in _actions(raw.action_space.shape):
        _, reward, terminated, truncated, _ = raw.step(action)
        _, wrapped_reward, _, _, infos = wrapped.step(action)
        np.testing.assert_array_equal(wrapped_reward, reward)
        running += reward
        ended = terminated | truncated
        if ended.any():
            assert np.array_equal(infos["_episode"], ended)
            np.testing.assert_allclose(infos["episode"]["r"][ended], running[ended], rtol=1e-6)
            np.testing.assert_array_equal(infos["episode"]["l"][ended], EPISODE_STEPS)
            recorded += int(ended.sum())
            running[ended] = 0.0
    # Three whole episodes per sub-env: the 13th step would be the third autoreset.
    assert recorded == 3 * NUM_ENVS
    assert len(wrapped.return_queue) == recorded


def test_normalize_observation_tracks_the_raw_observations() -> None:
    raw, wrapped = _envs(), NormalizeObservation(_envs())
    observations = [raw.reset(seed=1)[0]]
    normalised = wrapped.reset(seed=1)[0]
    for action in _actions(raw.action_space.shape):
        observations.append(raw.step(action)[0])
        normalised = wrapped.step(action)[0]
    seen = np.concatenate(observations)
    # Gymnasium's running statistics start from a pseudo-count of 1e-4 at zero mean.
    np.testing.assert_allclose(wrapped.obs_rms.mean, seen.mean(axis=0), rtol=1e-4, atol=1e-9)
    expected = (observations[-1] - wrapped.obs_rms.mean) / np.sqrt(wrapped.obs_rms.var + 1e-8)
    np.testing.assert_allclose(normalised, expected.astype(np.float32), rtol=1e-5, atol=1e-5)
    assert np.isfinite(normalised).all()


def test_normalize_reward_scales_by_the_discounted_return() -> None:
    raw, wrapped = _envs(), NormalizeReward(_envs(), gamma=0.9)
    raw.reset(seed=2)
    wrapped.reset(seed=2)
    checked = 0
    for action in _actions(raw.action_space.shape):
        _, reward, *_ = raw.step(action)
        _, scaled, *_ = wrapped.step(action)
        # One positive scale per step, shared by the sub-envs: 1 / sqrt(var of the discounted
        # return), with the statistics as this step left them (Gymnasium updates, then divides).
        scale = 1.0 / np.sqrt(wrapped.return_rms.var + 1e-8)
        nonzero = reward != 0.0  # an autoreset step's reward is 0
        np.testing.assert_allclose(scaled[nonzero], reward[nonzero] * scale, rtol=1e-5)
        checked += int(nonzero.sum())
    # Every step but the three autoreset steps of each sub-env carries a reward.
    assert checked == NUM_ENVS * (STEPS - 3)


@pytest.mark.parametrize("scale", [0.5, 3.0])
def test_clip_action_equals_stepping_clipped_actions(scale: float) -> None:
    raw, wrapped = _envs(), ClipAction(_envs())
    np.testing.assert_array_equal(raw.reset(seed=4)[0], wrapped.reset(seed=4)[0])
    for action in _actions(raw.action_space.shape, scale):
        expected = raw.step(np.clip(action, -1.0, 1.0))
        got = wrapped.step(action)
        for a, b in zip(expected[:4], got[:4], strict=True):
            np.testing.assert_array_equal(a, b)


def test_the_wrappers_stack_as_in_gymnasiums_docs() -> None:
    envs = ClipAction(NormalizeReward(NormalizeObservation(RecordEpisodeStatistics(_envs()))))
    envs.reset(seed=5)
    for action in _actions(envs.action_space.shape, 2.0):
        observation, reward, *_ = envs.step(action)
        assert np.isfinite(observation).all() and np.isfinite(reward).all()
