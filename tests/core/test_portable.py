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


def started(preset: str, batch: int, seed: int = 0, randomised: bool = True) -> tg.BatchSimulator:
    """``batch`` clusters of ``preset`` from random displacements; with ``randomised``, every
    third one with cables 2.25 times stiffer (domain randomisation), so that clusters take
    different numbers of sub-steps per interval."""
    cluster = tg.make_cluster(preset)
    sim = tg.BatchSimulator(cluster, batch)
    for index in range(0, batch, 3) if randomised else ():
        sim.set_cluster(index, cluster.replace(EA=2.25 * np.asarray(cluster.EA)))
    rng = np.random.default_rng(seed)
    sim.reset(cluster.positions[None] + 0.05 * rng.standard_normal((batch, cluster.num_nodes, 3)))
    return sim


@pytest.mark.parametrize(
    ("preset", "target", "batch", "lanes"),
    [
        ("tetrahedron", "cpu", 4, 0),
        ("hub", "cpu", 4, 0),
        ("beaded_chain", "cpu", 4, 0),
        ("tetrahedron", "lanes", 4, 128),
        ("tetrahedron", "lanes", 37, 8),  # four full blocks and a partial one
        ("hub", "lanes", 20, 16),
        ("beaded_chain", "lanes", 6, 4),
    ],
)
def test_the_cpu_prototypes_reproduce_the_batch_simulator_to_the_bit(
    preset: str, target: str, batch: int, lanes: int
) -> None:
    """Three control intervals from random displacements (cables go slack and snap taut), with a
    thrust that changes every interval (the blended first kick), beads included; in SIMD lanes,
    clusters whose intervals take different numbers of sub-steps share a block."""
    # Stiffened beaded lines would break cables, which the prototype does not model.
    sim = started(preset, batch=batch, randomised=not preset.startswith("beaded"))
    portable = PortableBatch(sim)
    portable.lanes = lanes or portable.lanes
    rng = np.random.default_rng(1)
    counts = set()
    for _ in range(3):
        force = rng.normal(0.0, 0.5, sim.positions_.shape)
        stats = sim.advance(0.1, force)
        portable.set_force(force)
        portable.advance(0.1, target)
        np.testing.assert_array_equal(portable.positions, sim.positions_)
        np.testing.assert_array_equal(portable.substeps, stats.substeps)
        counts |= set(stats.substeps.tolist())
    assert min(counts) > 1
    assert not sim.broken.any(), "the prototype does not break cables: the test's states must not either"
    if target == "lanes" and batch > 8:
        assert len(counts) > 1, "the blocks should mix clusters of different sub-step counts"


def test_the_prototype_refuses_what_it_does_not_integrate() -> None:
    with pytest.raises(ValueError, match="inertial frames only"):
        PortableBatch(started("spinning_triangle", batch=1))
    with pytest.raises(ValueError, match="target must be 'cpu', 'lanes' or 'cuda'"):
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
    sim = started("tetrahedron", batch=3, randomised=False)
    np.testing.assert_array_equal(sim.positions_, np.array(result["start"]))
    stats = sim.advance(0.1, np.array(result["force"]))
    np.testing.assert_array_equal(np.array(result["positions"]), sim.positions_)
    np.testing.assert_array_equal(np.array(result["substeps"]), stats.substeps)
