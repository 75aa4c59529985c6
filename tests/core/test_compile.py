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

from tether_gym._compilation import MESSAGE
from tether_gym.compile import KERNELS

ROOT = Path(__file__).resolve().parents[2]
#: The start of the one-time message, which holds a path after it.
ANNOUNCEMENT = MESSAGE.split("(")[0]


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
_kernels._solve_gyroscopic(1.0, 0.5, 1.0, 2.0)
"""


def test_the_first_compilation_of_a_process_is_announced_once(tmp_path: Path) -> None:
    first = run_python(["-c", SMALL_KERNELS], tmp_path)
    assert first.returncode == 0, first.stderr
    assert first.stderr.count(ANNOUNCEMENT) == 1, first.stderr  # two kernels compiled, one message
    assert str(tmp_path) in first.stderr and "python -m tether_gym.compile" in first.stderr
    # The cached kernel loads silently; only an uncached one (the small helper) speaks again.
    cached = run_python(["-c", SMALL_KERNELS.split("_kernels._solve")[0]], tmp_path)
    assert cached.returncode == 0 and ANNOUNCEMENT not in cached.stderr, cached.stderr


@pytest.mark.slow  # compiles every kernel from an empty cache: about 30 s
def test_the_compile_command_warms_the_cache_for_every_env(tmp_path: Path) -> None:
    """After the command, neither a single nor a vector env compiles anything on first use."""
    warm = run_python(["-m", "tether_gym.compile"], tmp_path)
    assert warm.returncode == 0, warm.stderr
    lines = [line for line in warm.stdout.splitlines() if line.startswith("[")]
    assert len(lines) == len(KERNELS) and all("compiled" in line for line in lines), warm.stdout
    assert ANNOUNCEMENT not in warm.stderr  # the command reports its own progress
    again = run_python(["-m", "tether_gym.compile"], tmp_path)
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


def test_the_compile_command_has_help() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "tether_gym.compile", "--help"], cwd=ROOT, capture_output=True, text=True, check=False
    )
    assert result.returncode == 0 and "Compile tether-gym's numba kernels ahead of time" in result.stdout
