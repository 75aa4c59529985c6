"""Residual policies: a learned correction on top of a scripted controller's action.

A policy trained with ``residual_on: <baseline>`` (a hyperparameter of ``agents.train``) outputs
a correction that is added to that baseline's action, and the sum is clipped to [-1, 1]. At
initialisation the policy's mean action is near zero, so training starts from the baseline's
performance instead of from random thrust. The baseline reads the same observation as the
policy (before normalisation). The trained policy stores the baseline's name in its
``policy.json`` (``residual_on``), and :class:`agents.policies.TrainedPolicy` applies it the
same way.

This module holds the rule both apply, :func:`residual_actions`, and the check of a baseline's
name, :func:`check_residual_on`. The SB3 vector env that trains such a policy is
:class:`agents.training.residual_env.ResidualVecEnv`, with the training loop that uses it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .base import Policy
from .registry import BASELINES

__all__ = ["check_residual_on", "residual_actions"]


def check_residual_on(name: Any, where: str = "residual_on") -> str | None:
    """``name`` if it is a baseline or None; otherwise a ValueError naming ``where``."""
    if name is None or (isinstance(name, str) and name in BASELINES):
        return name
    raise ValueError(f"{where} must be one of {sorted(BASELINES)} (or absent); got {name!r}")


def residual_actions(baseline: Policy, observation: np.ndarray, correction: np.ndarray) -> np.ndarray:
    """``clip(baseline(observation) + correction, -1, 1)`` as float32, for one or a batch of
    observations (the baseline's own clipping and saturation count apply to its part)."""
    base, _ = baseline.predict(observation)
    return np.clip(base + np.asarray(correction, dtype=np.float32), -1.0, 1.0).astype(np.float32)
