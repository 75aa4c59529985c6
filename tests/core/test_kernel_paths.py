"""The integrator's fast path through the cable forces gives the same bits as the general kernel.

Clusters without axial damping run :func:`tether_gym._kernels._cable_forces_undamped`, which
takes the step-limiting frequency from the largest axial element value of the intact cables
(:func:`~tether_gym._kernels._axial_omega2`, once per interval) instead of every cable's own, and
falls back to the cable-by-cable maximum for a state that is not finite.  The property: from any
state (exact or linearised elongation, lines turned past a right angle from their reference,
breaking cables, NaN and coinciding nodes), that path and the general kernel write the same
forces, tensions, peaks and broken cables, and return the same frequency, to the bit.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import tether_gym as tg
from tether_gym import _kernels as k
from tether_gym.tethers import Tether, build_cluster

#: Property-based, with many generated examples: the fast suite (-m 'not slow') leaves it out.
pytestmark = pytest.mark.slow

PATHS = settings(
    max_examples=200,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow],
)


def _bits(value: float) -> bytes:
    return np.float64(value).tobytes()


def _cluster(kind: str, segments: int) -> tg.Cluster:
    if kind == "line":
        spec = Tether((0, 1), EA=40e3, segments=segments, mass=2.0, N0=5.0, breaking_load=50.0)
        return build_cluster([[0.0, 0.0, 0.0], [100.0, 0.0, 0.0]], 50.0, [spec])
    if segments == 1:
        return tg.make_cluster(kind)
    return tg.make_cluster(kind, tether_mass=2.0, segments=segments)


@PATHS
@given(
    kind=st.sampled_from(["line", "tetrahedron", "chain"]),
    segments=st.sampled_from([1, 2, 4]),
    linearised=st.booleans(),
    scale=st.sampled_from([0.0, 0.01, 1.0, 30.0]),
    turned=st.booleans(),
    breaking_load=st.sampled_from([np.inf, 5.5, 40.0]),
    damaged=st.sampled_from(["none", "nan", "inf", "coincide", "broken"]),
    seed=st.integers(0, 2**16),
)
def test_undamped_path_matches_general_kernel(
    kind: str,
    segments: int,
    linearised: bool,
    scale: float,
    turned: bool,
    breaking_load: float,
    damaged: str,
    seed: int,
) -> None:
    cluster = _cluster(kind, segments)
    sim = tg.BatchSimulator(cluster, 1)
    rng = np.random.default_rng(seed)
    nodes = sim.node_table[0].copy()
    cables = sim.cable_table[0].copy()
    positions = nodes[:, k.POSITION : k.POSITION + 3]
    positions += scale * rng.normal(size=positions.shape)
    if turned:  # half the nodes mirrored: with the linearised elongation N/L then passes EA/L0
        positions[::2] *= -1.0
    cables[:, k.BREAKING_LOAD] = breaking_load
    if damaged == "nan":
        positions[rng.integers(len(positions)), rng.integers(3)] = np.nan
    elif damaged == "inf":
        positions[rng.integers(len(positions)), rng.integers(3)] = np.inf
    elif damaged == "coincide":
        i, j = sim.cables[rng.integers(len(sim.cables))]
        positions[j] = positions[i]
    elif damaged == "broken":
        cables[rng.integers(len(cables)), k.INTACT] = 0.0

    intact_before = cables[:, k.INTACT].copy()
    general_nodes, general_cables = nodes.copy(), cables.copy()
    with np.errstate(all="ignore"):
        expected = k.cable_forces(general_nodes, general_cables, sim.cables, linearised, False, True, 0.0)
        omega2_axial = k._axial_omega2(cables)
        fast = k._update_forces(nodes, cables, sim.cables, linearised, False, omega2_axial)

    assert _bits(fast[0]) == _bits(expected[0]), (fast[0], expected[0])
    assert fast[1] == expected[1]
    assert _bits(fast[3]) == _bits(expected[3])
    broke = bool((cables[:, k.INTACT] != intact_before).any())
    assert (fast[4] >= 0.0) == (expected[4] >= 0.0) == broke
    assert nodes.tobytes() == general_nodes.tobytes()
    assert cables.tobytes() == general_cables.tobytes()


def test_a_broken_cable_stops_limiting_the_step() -> None:
    """The fast path's axial maximum is taken again when a cable breaks, within the interval: a
    stiff line that snaps apart leaves two free satellites, which take the rest of the interval in
    one sub-step after the next (the breaking sub-step's own estimate still counts the cable)."""
    spec = Tether((0, 1), EA=4e6, N0=5.0, breaking_load=200.0)  # breaks after about 6 sub-steps
    sim = tg.BatchSimulator(build_cluster([[0.0, 0.0, 0.0], [100.0, 0.0, 0.0]], 50.0, [spec]), 1)
    sim.reset(sim.reference, np.array([[[-0.11, 0.0, 0.0], [0.11, 0.0, 0.0]]]))
    first = sim.advance(0.1, record_steps=100)
    steps = first.step_sizes[0][: first.substeps[0]]
    assert sim.broken.all() and 3 <= steps.size < 100
    assert steps[-1] > 2.0 * steps[0], steps
    assert [sim.advance(0.1).substeps[0] for _ in range(3)] == [1, 1, 1]
