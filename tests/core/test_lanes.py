"""The integrator in SIMD lanes (tether_gym._kernels._advance_lanes) against the integrator a
cluster at a time (_advance_pair): every table, bit for bit, over what a block can mix: fresh
and running clusters, slack cables snapping taut, cables that break, intervals refused for their
sub-step budget, a collapsed cable, inactive clusters, and clusters the lanes do not take
(axial damping), in one batch."""

from __future__ import annotations

import numpy as np
import pytest

import tether_gym as tg
from tether_gym import _kernels as k

BATCH = k.LANE_WIDTH + 21  # a full block and a partial one


def mixed_batch(preset: str, seed: int, **settings: float | bool) -> tg.BatchSimulator:
    """``BATCH`` clusters of ``preset`` with every third one stiffer, every fourth with cables that
    break, every seventh with axial damping, from large random displacements and velocities."""
    cluster = tg.make_cluster(preset)
    sim = tg.BatchSimulator(cluster, BATCH, **settings)
    pretension = float(np.max(cluster.N0))
    for index in range(BATCH):
        variant = cluster
        if index % 3 == 0:
            variant = variant.replace(EA=2.25 * np.asarray(cluster.EA))
        if index % 4 == 1:
            variant = variant.replace(breaking_load=3.0 * pretension + 1.0)
        if index % 7 == 2:
            variant = variant.replace(axial_damping=0.5)
        if variant is not cluster:
            sim.set_cluster(index, variant)
    rng = np.random.default_rng(seed)
    shape = (BATCH, cluster.num_nodes, 3)
    sim.reset(cluster.positions[None] + 0.3 * rng.standard_normal(shape), 0.2 * rng.standard_normal(shape))
    return sim


def tables(sim: tg.BatchSimulator) -> tuple[np.ndarray, ...]:
    return sim.node_table, sim.cable_table, sim.cluster_table, sim.counter_table


def as_bits(array: np.ndarray) -> np.ndarray:
    """The array's bytes as integers: equal only if every bit is (NaN payloads and signed zeros)."""
    return np.ascontiguousarray(array).view(np.uint8)


def advance_alone(sim: tg.BatchSimulator, duration: float, active: np.ndarray, record: np.ndarray) -> None:
    """Advance each cluster of ``sim`` in a batch of its own: the pairs' path (one cluster is
    fewer than LANE_MIN_CLUSTERS)."""
    nodes, cables, clusters, counters = tables(sim)
    for b in range(sim.num_clusters):
        own = [np.array(table[b : b + 1]) for table in (nodes, cables, clusters, counters)]
        own_record = np.array(record[b : b + 1])
        k.advance_serial(duration, active[b : b + 1], sim.kernel_settings, sim.cables, *own, own_record)
        for table, result in zip((nodes, cables, clusters, counters), own, strict=True):
            table[b] = result[0]
        record[b] = own_record[0]


@pytest.mark.parametrize(
    ("preset", "settings"),
    [
        ("tetrahedron", {}),
        ("hub", {"safety_factor": 0.2}),
        ("tetrahedron", {"max_substeps": 12}),  # intervals refused for their budget, and rolled back
        ("beaded_chain", {}),
        # A tolerance the coarse step breaks: energy runaways flagged by the lanes' books.
        ("tetrahedron", {"energy_tolerance": 1e-3, "safety_factor": 0.9, "allow_unstable_safety_factor": True}),
    ],
)
def test_the_lanes_reproduce_the_pairs_bit_for_bit(preset: str, settings: dict[str, float | bool]) -> None:
    together, alone = mixed_batch(preset, seed=3, **settings), mixed_batch(preset, seed=3, **settings)
    ready = [k._lane_ready(together.cable_table[b], together.cluster_table[b]) for b in range(BATCH)]
    assert k.LANE_MIN_CLUSTERS <= sum(ready) < BATCH, "the batch must take both paths"
    rng = np.random.default_rng(4)
    record_together, record_alone = np.zeros((BATCH, 30)), np.zeros((BATCH, 30))
    seen: set[int] = set()
    for _ in range(6):
        force = rng.normal(0.0, 2.0, together.positions_.shape)
        active = rng.random(BATCH) > 0.1
        together.applied_force[...] = force
        alone.applied_force[...] = force
        k._advance_clusters_in_lanes(
            0.1, active, together.kernel_settings, together.cables, *tables(together), record_together
        )
        advance_alone(alone, 0.1, active, record_alone)
        for mine, theirs in zip(tables(together), tables(alone), strict=True):
            np.testing.assert_array_equal(as_bits(mine), as_bits(theirs))
        np.testing.assert_array_equal(as_bits(record_together), as_bits(record_alone))
        seen |= set(together.counter_table[:, k.STATUS].tolist())
    assert (together.cable_table[:, :, k.INTACT] == 0.0).any(), "some cable should have broken"
    if "max_substeps" in settings:
        assert k.STATUS_TOO_MANY_SUBSTEPS in seen
    if "energy_tolerance" in settings:
        assert k.STATUS_ENERGY_RUNAWAY in seen


def test_a_collapsed_cable_is_flagged_in_its_lane_alone() -> None:
    """Two satellites at one point, at rest and unforced: the cable between them has no length,
    the lane is flagged non-finite at its first sub-step and its state is kept, as a cluster alone
    would have it, while the rest of the block goes on."""
    together, alone = mixed_batch("tetrahedron", seed=5), mixed_batch("tetrahedron", seed=5)
    for sim in (together, alone):
        sim.advance(0.1, np.zeros(sim.positions_.shape))  # running states (LAST_STEP > 0)
        nodes = sim.node_table
        for b in (0, 10, 40):
            nodes[b, 1, k.POSITION : k.POSITION + 3] = nodes[b, 0, k.POSITION : k.POSITION + 3]
            for column in (k.HALF_STEP_VELOCITY, k.INTERNAL_FORCE, k.PREVIOUS_FORCE, k.APPLIED_FORCE):
                nodes[b, :, column : column + 3] = 0.0
            nodes[b, :, k.DAMPING] = 0.0
    active = np.ones(BATCH, dtype=bool)
    record_together, record_alone = np.zeros((BATCH, 30)), np.zeros((BATCH, 30))
    k._advance_clusters_in_lanes(
        0.1, active, together.kernel_settings, together.cables, *tables(together), record_together
    )
    advance_alone(alone, 0.1, active, record_alone)
    status = together.counter_table[:, k.STATUS]
    assert (status[[0, 10, 40]] == k.STATUS_NON_FINITE).all()
    assert (status[status != k.STATUS_NON_FINITE] == k.STATUS_OK).all()
    for mine, theirs in zip(tables(together), tables(alone), strict=True):
        np.testing.assert_array_equal(as_bits(mine), as_bits(theirs))


def test_the_parallel_chunks_fill_the_lanes() -> None:
    """Every chunk holds at least LANE_WIDTH clusters where the batch has enough for
    PARALLEL_MIN_CHUNKS such chunks; never fewer than PARALLEL_MIN_CHUNKS chunks, nor an empty one."""
    for batch in (*range(1, 300), 1023, 1024, 4096, 100_000):
        chunks = k.parallel_chunks(batch)
        assert 1 <= chunks <= batch
        assert chunks >= min(batch, k.PARALLEL_MIN_CHUNKS)
        if batch >= k.LANE_WIDTH * k.PARALLEL_MIN_CHUNKS:
            assert batch // chunks >= k.LANE_WIDTH
