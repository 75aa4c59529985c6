"""Observations to compare two implementations of a policy on, and the actions of each.

A policy is converted (:mod:`.conversion`) or shipped (:mod:`agents.training.shipping`) only after
its actions in the safe format are checked bit for bit against another pipeline's on the same
observations: env observations along a policy's own trajectories
(:func:`trajectory_observations`) and draws around its normalisation statistics
(:func:`reference_observations`). :func:`sb3_actions` is the pipeline that SB3's own files were
used with, :func:`safe_actions` the safe format's; ``reference_actions.safetensors`` (the command
line's ``--reference``) keeps such observations and actions beside a policy for later checks.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np

from .format import load_policy

__all__ = ["reference_observations", "safe_actions", "sb3_actions", "trajectory_observations"]


def sb3_actions(model: Any, normalizer: Any, observations: np.ndarray) -> np.ndarray:
    """(N, act_dim) actions of the SB3 pipeline the pickle-based files were used with:
    ``VecNormalize.normalize_obs`` (when ``normalizer`` is not None), then
    ``model.predict(deterministic=True)``, on (N, obs_dim) ``observations``."""
    obs = observations.astype(np.float32)
    if normalizer is not None:
        obs = normalizer.normalize_obs(obs).astype(np.float32)
    return model.predict(obs, deterministic=True)[0]


def safe_actions(directory: Path, observations: np.ndarray) -> np.ndarray:
    """(N, act_dim) actions of the policy in ``directory`` (the safe format) on (N, obs_dim)
    ``observations``: its normalisation statistics, then ``policy.predict(deterministic=True)``
    (without a residual baseline or a decentralised observer: the network's own outputs)."""
    loaded = load_policy(directory)
    obs = observations.astype(np.float32)
    if loaded.normalizer is not None:
        obs = loaded.normalizer.normalize_obs(obs).astype(np.float32)
    return loaded.policy.predict(obs, deterministic=True)[0]


def trajectory_observations(
    act: Callable[[np.ndarray], np.ndarray], env_id: str, env_kwargs: dict[str, Any] | None = None
) -> Callable[[int], np.ndarray]:
    """A function ``n -> (n, obs_dim)`` env observations along the trajectories of ``act`` (a batch
    of observations -> a batch of actions), 8 episodes in parallel, seeds 0-7."""
    import gymnasium as gym
    from gymnasium.vector import AutoresetMode

    import tether_gym  # noqa: F401 - registers the ids

    def observations(count: int) -> np.ndarray:
        envs = gym.make_vec(env_id, num_envs=8, **{"autoreset_mode": AutoresetMode.SAME_STEP, **dict(env_kwargs or {})})
        try:
            obs, _ = envs.reset(seed=list(range(8)))
            rows = [obs]
            while sum(len(r) for r in rows) < count:
                obs, *_ = envs.step(act(obs))
                rows.append(obs)
        finally:
            envs.close()
        return np.concatenate(rows)[:count]

    return observations


def reference_observations(
    count: int,
    observation_space: gymnasium.spaces.Box,
    mean: np.ndarray | float,
    var: np.ndarray | float,
    rng: np.random.Generator,
    rollout: Callable[[int], np.ndarray] | None = None,
) -> np.ndarray:
    """(count, obs_dim) float32 observations to compare two implementations of a policy on: env
    observations from ``rollout(n)`` when given (half of them), the rest drawn around ``mean``
    with variance ``var`` (the normalisation statistics) at 0.3, 1, 3 and 30 standard deviations,
    so that the normaliser's clipping is exercised too."""
    rows = []
    if rollout is not None:
        rows.append(np.asarray(rollout(count // 2), dtype=np.float32).reshape(-1, *observation_space.shape))
    remaining = count - sum(len(r) for r in rows)
    scales = np.array([0.3, 1.0, 3.0, 30.0])[rng.integers(0, 4, size=(remaining, 1))]
    noise = rng.standard_normal((remaining,) + observation_space.shape)
    drawn = np.asarray(mean) + np.sqrt(np.asarray(var)) * scales * noise
    rows.append(np.clip(drawn, observation_space.low, observation_space.high).astype(np.float32))
    return np.concatenate(rows)[:count]
