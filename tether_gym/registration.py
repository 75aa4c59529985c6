"""Environment ids for ``gymnasium.make``: one per preset, all version 0.

``gym.make("tether_gym:TetherTetrahedron-v0")`` works without importing tether_gym first.
"""

from __future__ import annotations

import gymnasium as gym

#: id -> (preset, max_episode_steps).  300 steps of 0.1 s = 30 s per episode.
ENV_IDS: dict[str, tuple[str, int]] = {
    "TetherTetrahedron-v0": ("tetrahedron", 300),
    "TetherChain-v0": ("chain", 300),
    "TetherTriangle-v0": ("triangle", 300),
    "TetherOctahedron-v0": ("octahedron", 300),
    "TetherHub-v0": ("hub", 300),
}

#: The paper's case, and the default task.
DEFAULT_ENV_ID = "TetherTetrahedron-v0"


def register_envs() -> None:
    """Register every id (idempotent)."""
    for env_id, (preset, steps) in ENV_IDS.items():
        if env_id in gym.registry:
            continue
        gym.register(
            id=env_id,
            entry_point="tether_gym.envs.cluster_env:TetherClusterEnv",
            vector_entry_point="tether_gym.envs.vector_env:TetherClusterVectorEnv",
            max_episode_steps=steps,
            kwargs={"preset": preset},
        )
