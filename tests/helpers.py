"""Test helpers: small clusters with closed-form answers, an independent numpy force oracle, and
the loading of the repository's scripts and hooks, which are files rather than modules."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

import tether_gym as tg


def pair(
    m1: float = 10.0,
    m2: float = 30.0,
    length: float = 100.0,
    EA: float = 5e4,
    N0: float = 0.0,
    damping: float | tuple[float, float] = 0.0,
    L0: float | None = None,
) -> tg.Cluster:
    """Two satellites on the x axis joined by one cable (stiffness EA / L0)."""
    return tg.Cluster(
        positions=[[-length / 2, 0.0, 0.0], [length / 2, 0.0, 0.0]],
        masses=[m1, m2],
        cables=[(0, 1)],
        EA=EA,
        N0=N0,
        damping=damping,
        L0=L0,
        name="pair",
    )


def reference_internal_forces(cluster: tg.Cluster, x: np.ndarray) -> np.ndarray:
    """f_int (n, 3) from the model's definition, written independently of the compiled kernels."""
    i, j = cluster.cables[:, 0], cluster.cables[:, 1]
    delta = x[j] - x[i]
    length = np.linalg.norm(delta, axis=1)
    tension = np.maximum(cluster.N0 + cluster.EA / cluster.L0 * (length - cluster.L0), 0.0)
    pull = (tension / length)[:, None] * delta
    f_int = np.zeros_like(x)
    np.add.at(f_int, i, -pull)
    np.add.at(f_int, j, pull)
    return f_int


def separation(x: np.ndarray) -> float:
    """Distance between the first two satellites, m."""
    return float(np.linalg.norm(x[1] - x[0]))


def env_state(env: Any) -> dict[str, Any]:
    """Copies of every piece of state a reset or a step of a single or vector env could change
    (its task's simulator state and books, its generators, a vector env's step counters)."""
    inner = env.unwrapped
    task = inner.task
    vector = hasattr(inner, "_rngs")
    state: dict[str, Any] = {
        "positions": task.sim.positions.copy(),
        "velocities": task.sim.velocities.copy(),
        "time": task.sim.time.copy(),
        "masses": task.sim.masses.copy(),
        "observation": task.observation.copy(),
        "scalars": task.scalars.copy(),
        "propellant": task.propellant.copy(),
        "queue": task.action_queue.copy(),
        "difficulty": task.difficulty,
        "rngs": [rng.bit_generator.state for rng in (inner._rngs if vector else [inner.np_random])],
    }
    if vector:
        state["steps"] = inner._episode_steps.copy()
    return state


def assert_unchanged(before: dict[str, Any], after: dict[str, Any]) -> None:
    """Fail naming the first piece of :func:`env_state` that a refused call changed."""
    for key, value in before.items():
        same = np.array_equal(value, after[key]) if isinstance(value, np.ndarray) else value == after[key]
        assert same, f"a refused call changed {key}"


#: The repository's root, where the scripts and docs hooks that the tests load live.
ROOT = Path(__file__).resolve().parents[1]


def load_file(name: str, relative_path: str) -> ModuleType:
    """The Python file at ``relative_path`` (from the repository's root) as the module ``name``,
    loaded once per process. It is registered in ``sys.modules`` under that name before it runs,
    as its dataclasses look their module up there (and as the docs hook finds scripts/figures.py)."""
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, ROOT / relative_path)
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
    return sys.modules[name]
