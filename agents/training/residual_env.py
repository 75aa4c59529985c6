"""The training side of residual policies: an SB3 vector env whose actions are corrections to a
scripted baseline's (:mod:`agents.controllers.residual` holds the rule, ``clip(baseline + correction,
-1, 1)``, that this env and a loaded residual policy both apply). It lives with the SB3 training
loop because it is an SB3 ``VecEnvWrapper``: the controllers room does not depend on SB3."""

from __future__ import annotations

from typing import Any

import numpy as np

from tether_gym._optional import needs_extra

from ..controllers.registry import make_baseline
from ..controllers.residual import check_residual_on, residual_actions

with needs_extra("train", "residual policies"):
    from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper

__all__ = ["ResidualVecEnv"]


class ResidualVecEnv(VecEnvWrapper):
    """An SB3 VecEnv whose actions are corrections to ``baseline``'s actions (see the module).

    Args:
        venv: the tether-gym SB3 vector env (``tether_gym.sb3.make_sb3_vec_env``), below any
            ``VecNormalize``: the baseline reads raw observations.
        baseline: the name of a scripted baseline (:data:`agents.controllers.registry.BASELINES`).
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
