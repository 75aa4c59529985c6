"""First use: the one-time word that the kernels compile, and ``python -m tether_gym.compile``.

Each test runs Python in a subprocess with an empty numba cache (``NUMBA_CACHE_DIR``), as on a
fresh install; the package under test is the one of this checkout.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from numba.core.caching import NullCache
from numba.core.registry import CPUDispatcher as Dispatcher

from tether_gym import _kernels
from tether_gym._compilation import GROUPS, group_of
from tether_gym.compile import KERNELS, warm
from tether_gym.envs import _task_kernels

ROOT = Path(__file__).resolve().parents[2]
#: The start of each group's line, and of the hint the first line of a process carries.
ANNOUNCEMENT = "tether-gym: compiling numba kernels for first use ["
HINT = "this happens once, later processes load them from numba's cache"


def run_python(args: list[str], cache: Path, timeout: float = 900.0) -> subprocess.CompletedProcess[str]:
    environment = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    return subprocess.run(
        [sys.executable, *args], cwd=ROOT, env=environment, capture_output=True, text=True, timeout=timeout, check=False
    )


SMALL_KERNELS = """
import numpy as np
from tether_gym import _kernels
from tether_gym.envs import _task_kernels
_task_kernels.remove_rigid_velocity(np.ones((1, 2, 3)), np.zeros((1, 2, 3)), np.ones((1, 2)))
_kernels.all_finite(np.zeros(3))
_kernels.all_within(np.zeros((1, 2, 3)), 1.0)
_kernels._solve_gyroscopic(1.0, 0.5, 1.0, 2.0)
"""


def test_each_kernel_group_is_announced_once_per_process(tmp_path: Path) -> None:
    first = run_python(["-c", SMALL_KERNELS], tmp_path)
    assert first.returncode == 0, first.stderr
    # Two kernels of one group and a helper in no group compiled: one line, with the hint.
    group = group_of("remove_rigid_velocity")
    assert group is not None
    assert first.stderr.count(ANNOUNCEMENT) == 1, first.stderr
    assert f"[{group + 1}/{len(GROUPS)}]: {GROUPS[group][0]}" in first.stderr, first.stderr
    assert first.stderr.count(HINT) == 1 and str(tmp_path) in first.stderr, first.stderr
    assert "python -m tether_gym.compile" in first.stderr
    # The cached kernels load silently; an uncached one of another group speaks (with the hint:
    # the first line of its process).
    forces = "from tether_gym import BatchSimulator, make_cluster\nBatchSimulator(make_cluster('triangle'), 1)\n"
    second = run_python(["-c", SMALL_KERNELS.split("_kernels._solve")[0] + forces], tmp_path)
    assert second.returncode == 0, second.stderr
    lines = [line for line in second.stderr.splitlines() if line.startswith(ANNOUNCEMENT)]
    forces_group = group_of("evaluate_forces")
    assert forces_group is not None and forces_group != group
    assert len(lines) == 1 and f"[{forces_group + 1}/{len(GROUPS)}]: {GROUPS[forces_group][0]}" in lines[0], lines
    assert HINT in lines[0]
    cached = run_python(["-c", SMALL_KERNELS.split("_kernels._solve")[0] + forces], tmp_path)
    assert cached.returncode == 0 and ANNOUNCEMENT not in cached.stderr, cached.stderr


def test_every_cached_kernel_is_in_one_group_and_the_command_compiles_every_group() -> None:
    named = [qualified_name for _, qualified_name, _, _ in KERNELS]
    assert all(group_of(name) is not None for name in named), named
    assert {group_of(name) for name in named} == set(range(len(GROUPS)))
    grouped = [name for _, names in GROUPS for name in names]
    assert len(grouped) == len(set(grouped))
    cached = {
        value.py_func.__qualname__
        for module in (_kernels, _task_kernels)
        for value in vars(module).values()
        if isinstance(value, Dispatcher) and not isinstance(value._cache, NullCache)
    }
    # cable_forces compiles within the kernels that call it; nothing calls it from Python.
    assert cached - set(grouped) == {"_make_cable_forces.<locals>.cable_forces"}, cached - set(grouped)
    assert set(grouped) <= cached, set(grouped) - cached


def test_the_parallel_step_and_evaluation_share_one_compiled_kernel() -> None:
    """A vector env's reset (the evaluation) and step run one compiled variant of one kernel."""
    import gymnasium as gym

    envs = gym.make_vec("tether_gym:TetherTetrahedron-v0", num_envs=16)
    envs.reset(seed=0)
    envs.step(envs.action_space.sample())
    envs.reset(seed=1)
    kernel = _task_kernels.parallel_task
    assert len(kernel.signatures) == 1, kernel.signatures


@pytest.mark.slow  # compiles every kernel from an empty cache: about 30 s
def test_the_compile_command_warms_the_cache_for_every_env(tmp_path: Path) -> None:
    """After the command, neither a single nor a vector env compiles anything on first use."""
    warm = run_python(["-m", "tether_gym.compile"], tmp_path)
    assert warm.returncode == 0, warm.stderr
    lines = [line for line in warm.stdout.splitlines() if line.startswith("[")]
    assert len(lines) == len(KERNELS) and all("compiled" in line for line in lines), warm.stdout
    assert ANNOUNCEMENT not in warm.stderr  # the command reports its own progress
    assert ("in two processes" in warm.stdout) == ((os.cpu_count() or 1) >= 2)  # the default on 2+ cores
    again = run_python(["-m", "tether_gym.compile", "--jobs", "1"], tmp_path)
    assert again.returncode == 0 and again.stdout.count("loaded from the cache") == len(KERNELS), again.stdout
    assert f"0 compiled, {len(KERNELS)} already cached" in again.stdout
    first_use = run_python(
        [
            "-c",
            "import gymnasium as gym, tether_gym\n"
            "env = gym.make('TetherRadialChain-v0', observe_tensions=True, thrust_delay=1, thrust_noise=0.1)\n"
            "env.reset(seed=0); env.step(env.action_space.sample())\n"
            "envs = gym.make_vec('TetherHub-v0', num_envs=16)\n"
            "envs.reset(seed=0); envs.step(envs.action_space.sample())\n"
            "tether_gym.Simulator(tether_gym.make_cluster('chain')).critical_time_step('finite-difference')\n",
        ],
        tmp_path,
    )
    assert first_use.returncode == 0, first_use.stderr
    assert ANNOUNCEMENT not in first_use.stderr, first_use.stderr


def test_the_compile_command_takes_one_or_two_processes() -> None:
    with pytest.raises(ValueError, match="jobs must be 1 or 2"):
        warm(jobs=3)


def test_the_compile_command_has_help() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "tether_gym.compile", "--help"], cwd=ROOT, capture_output=True, text=True, check=False
    )
    assert result.returncode == 0 and "Compile tether-gym's numba kernels ahead of time" in result.stdout
