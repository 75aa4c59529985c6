"""Gymnasium environments over the batched physics core."""

from tether_gym.envs.cluster_env import TetherClusterEnv
from tether_gym.envs.task import END_REASONS, DampingTask, EnvArgumentError, TaskConfig, TaskState
from tether_gym.envs.vector_env import TetherClusterVectorEnv

__all__ = [
    "END_REASONS",
    "DampingTask",
    "EnvArgumentError",
    "TaskConfig",
    "TaskState",
    "TetherClusterEnv",
    "TetherClusterVectorEnv",
]
