"""The integrator prototype written once for the CPU and CUDA (tether_gym.portable): compiled by
njit it reproduces BatchSimulator to the bit, and numba's CUDA simulator reproduces it."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import tether_gym as tg
from tether_gym.portable import PortableBatch

ROOT = Path(__file__).resolve().parents[2]


def started(preset: str, batch: int, seed: int = 0) -> tg.BatchSimulator:
    cluster = tg.make_cluster(preset)
    sim = tg.BatchSimulator(cluster, batch)
    rng = np.random.default_rng(seed)
    sim.reset(cluster.positions[None] + 0.05 * rng.standard_normal((batch, cluster.num_nodes, 3)))
    return sim


@pytest.mark.parametrize("preset", ["tetrahedron", "hub", "beaded_chain"])
def test_the_cpu_prototype_reproduces_the_batch_simulator_to_the_bit(preset: str) -> None:
    """Three control intervals from random displacements (cables go slack and snap taut), with a
    thrust that changes every interval (the blended first kick), beads included."""
    sim = started(preset, batch=4)
    portable = PortableBatch(sim)
    rng = np.random.default_rng(1)
    for _ in range(3):
        force = rng.normal(0.0, 0.5, sim.positions_.shape)
        stats = sim.advance(0.1, force)
        portable.set_force(force)
        portable.advance(0.1)
        np.testing.assert_array_equal(portable.positions, sim.positions_)
        np.testing.assert_array_equal(portable.substeps, stats.substeps)
    assert stats.substeps.min() > 1


def test_the_prototype_refuses_what_it_does_not_integrate() -> None:
    with pytest.raises(ValueError, match="inertial frames only"):
        PortableBatch(started("spinning_triangle", batch=1))
    with pytest.raises(ValueError, match="target must be 'cpu' or 'cuda'"):
        PortableBatch(started("tetrahedron", batch=1)).advance(0.1, target="tpu")


SIMULATED = """
import json, numpy as np, tether_gym as tg
from tether_gym.portable import PortableBatch
cluster = tg.make_cluster("tetrahedron")
sim = tg.BatchSimulator(cluster, 3)
rng = np.random.default_rng(0)
sim.reset(cluster.positions[None] + 0.05 * rng.standard_normal((3, 4, 3)))
batch = PortableBatch(sim)
force = rng.normal(0.0, 0.5, (3, 4, 3))
batch.set_force(force)
batch.advance(0.1, target="cuda", threads_per_block=2)
print(json.dumps({"positions": batch.positions.tolist(), "substeps": batch.substeps.tolist(),
                  "force": force.tolist(), "start": sim.positions_.tolist()}))
"""


def test_the_cuda_kernel_run_by_numbas_cuda_simulator_matches_the_cpu_to_the_bit() -> None:
    """The same source compiled with cuda.jit, run by the simulator (NUMBA_ENABLE_CUDASIM=1, which
    must be set before numba is imported: a process of its own), over two blocks of threads."""
    environment = {**os.environ, "NUMBA_ENABLE_CUDASIM": "1", "PYTHONPATH": str(ROOT)}
    process = subprocess.run(
        [sys.executable, "-c", SIMULATED], capture_output=True, text=True, env=environment, timeout=300, check=False
    )
    assert process.returncode == 0, process.stderr[-2000:]
    result = json.loads(process.stdout.strip().splitlines()[-1])
    sim = started("tetrahedron", batch=3)
    np.testing.assert_array_equal(sim.positions_, np.array(result["start"]))
    stats = sim.advance(0.1, np.array(result["force"]))
    np.testing.assert_array_equal(np.array(result["positions"]), sim.positions_)
    np.testing.assert_array_equal(np.array(result["substeps"]), stats.substeps)
