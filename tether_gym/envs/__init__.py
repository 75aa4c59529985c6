"""Gymnasium environments over the batched physics core."""

from tether_gym.envs.cluster_env import TetherClusterEnv
from tether_gym.envs.contract import END_REASONS, SCALARS, EndReason, ObservationLayout, RewardWeights, Scalar
from tether_gym.envs.task import DampingTask, EnvArgumentError, TaskConfig, TaskState
from tether_gym.envs.vector_env import TetherClusterVectorEnv

__all__ = [
    "END_REASONS",
    "SCALARS",
    "DampingTask",
    "EndReason",
    "EnvArgumentError",
    "ObservationLayout",
    "RewardWeights",
    "Scalar",
    "TaskConfig",
    "TaskState",
    "TetherClusterEnv",
    "TetherClusterVectorEnv",
]
