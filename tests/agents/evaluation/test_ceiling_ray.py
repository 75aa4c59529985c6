"""The ceiling on Ray gives the returns of the serial loop, to the bit (bash scripts/test_rllib.sh
runs it, in the venv with the rllib extra; without Ray it is skipped)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from agents.common.cli import HELD_OUT_SEED
from agents.controllers.mpc import MPCSettings
from agents.evaluation.ceiling import ceiling_chunk, iterate_chunks

ray = pytest.importorskip("ray")

pytestmark = pytest.mark.rllib

#: A planner small enough that an episode takes about a second.
TINY = dataclasses.asdict(MPCSettings(samples=3, horizon=2, knots=1, noise=0.2, prior="velocity_feedback"))


def test_ray_tasks_return_the_serial_loop_s_returns() -> None:
    from agents.ceiling import ray_map

    jobs = [("TetherTetrahedron-v0", [HELD_OUT_SEED + k], TINY, {}) for k in range(3)]
    serial = [result.returns for result in iterate_chunks(ceiling_chunk, jobs)]
    # Ray may already run in this process (the RLlib tests before this one leave it up): the map
    # then uses it and leaves it up; one it starts itself, it shuts down.
    running = ray.is_initialized()
    parallel = [result.returns for result in ray_map(None, 2)(ceiling_chunk, jobs)]
    assert ray.is_initialized() == running, "the map shuts down only an instance it started"
    np.testing.assert_array_equal(np.array(parallel), np.array(serial))
