"""Environment ids for ``gymnasium.make``: one per preset, all version 0.

``gym.make("tether_gym:TetherTetrahedron-v0")`` works without importing tether_gym first.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym

#: The task settings of the orbital radial chain: its cables carry only about 0.1 N, so it gets
#: cold-gas thrusters of 0.1 N, gentler initial conditions, and 0.5 s control intervals over its
#: ~4 s axial period (200 s episodes).
ORBITAL_TASK: dict[str, Any] = {
    "control_interval": 0.5,
    "max_thrust": 0.1,
    "initial_displacement": 0.02,
    "initial_velocity": 0.02,
}

#: id -> (preset, max_episode_steps, task keyword arguments).  300 steps of 0.1 s = 30 s per episode
#: unless the task says otherwise.
ENV_IDS: dict[str, tuple[str, int, dict[str, Any]]] = {
    "TetherTetrahedron-v0": ("tetrahedron", 300, {}),
    "TetherChain-v0": ("chain", 300, {}),
    "TetherTriangle-v0": ("triangle", 300, {}),
    "TetherOctahedron-v0": ("octahedron", 300, {}),
    "TetherHub-v0": ("hub", 300, {}),
    "TetherRadialChain-v0": ("radial_chain", 400, ORBITAL_TASK),
    "TetherSpinningTriangle-v0": ("spinning_triangle", 300, {}),
    "TetherSpinningHub-v0": ("spinning_hub", 300, {}),
}

#: The paper's case, and the default task.
DEFAULT_ENV_ID = "TetherTetrahedron-v0"


def register_envs() -> None:
    """Register every id (idempotent)."""
    for env_id, (preset, steps, task) in ENV_IDS.items():
        if env_id in gym.registry:
            continue
        gym.register(
            id=env_id,
            entry_point="tether_gym.envs.cluster_env:TetherClusterEnv",
            vector_entry_point="tether_gym.envs.vector_env:TetherClusterVectorEnv",
            max_episode_steps=steps,
            kwargs={"preset": preset, **task},
        )
