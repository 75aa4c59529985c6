"""Residual policies: a learned correction on top of a scripted controller's action.

A policy trained with ``residual_on: <baseline>`` (a hyperparameter of ``agents.train``) outputs
a correction that is added to that baseline's action, and the sum is clipped to [-1, 1]. At
initialisation the policy's mean action is near zero, so training starts from the baseline's
performance instead of from random thrust. The baseline reads the same observation as the
policy (before normalisation). The trained policy stores the baseline's name in its
``policy.json`` (``residual_on``), and :class:`agents.policies.TrainedPolicy` applies it the
same way.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from tether_gym._optional import needs_extra

from .baselines import BASELINES, make_baseline

with needs_extra("train", "residual policies"):
    from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper

__all__ = ["ResidualVecEnv", "check_residual_on", "residual_actions"]


def check_residual_on(name: Any, where: str = "residual_on") -> str | None:
    """``name`` if it is a baseline or None; otherwise a ValueError naming ``where``."""
    if name is None or (isinstance(name, str) and name in BASELINES):
        return name
    raise ValueError(f"{where} must be one of {sorted(BASELINES)} (or absent); got {name!r}")


def residual_actions(baseline: Any, observation: np.ndarray, correction: np.ndarray) -> np.ndarray:
    """``clip(baseline(observation) + correction, -1, 1)`` as float32, for one or a batch of
    observations (the baseline's own clipping and saturation count apply to its part)."""
    base, _ = baseline.predict(observation)
    return np.clip(base + np.asarray(correction, dtype=np.float32), -1.0, 1.0).astype(np.float32)


class ResidualVecEnv(VecEnvWrapper):
    """An SB3 VecEnv whose actions are corrections to ``baseline``'s actions (see the module).

    Args:
        venv: the tether-gym SB3 vector env (``tether_gym.sb3.make_sb3_vec_env``), below any
            ``VecNormalize``: the baseline reads raw observations.
        baseline: the name of a scripted baseline (``agents.baselines.BASELINES``).
    """

    def __init__(self, venv: VecEnv, baseline: str) -> None:
        super().__init__(venv)
        check_residual_on(baseline)
        self.baseline = make_baseline(baseline, venv)
        self.last_observation: np.ndarray | None = None

    def reset(self) -> np.ndarray:
        self.last_observation = self.venv.reset()
        return self.last_observation

    def step_async(self, actions: np.ndarray) -> None:
        if self.last_observation is None:
            raise RuntimeError("reset() the residual env before stepping it")
        self.venv.step_async(residual_actions(self.baseline, self.last_observation, actions))

    def step_wait(self) -> Any:
        observation, rewards, dones, infos = self.venv.step_wait()
        self.last_observation = observation  # after an autoreset: the new episode's first observation
        return observation, rewards, dones, infos
