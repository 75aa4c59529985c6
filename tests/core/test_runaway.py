"""Settings that would blow up silently: NaN settings, safety factors above the stable range, a
cluster whose energy leaves its books, and an interval refused for its sub-step budget."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

import tether_gym as tg
from tether_gym import Cluster, SimulationDiverged
from tether_gym.envs import EnvArgumentError, TaskConfig
from tether_gym.limits import check_range, check_real
from tether_gym.simulator import (
    ENERGY_RUNAWAY_TOLERANCE,
    MAX_STABLE_SAFETY_FACTOR,
    STATE_FIELDS,
    UnstableSafetyFactorWarning,
)

STATUS_ENERGY_RUNAWAY = 3


# ---------------------------------------------------------------------- NaN settings
@pytest.mark.parametrize("option", ["safety_factor", "max_step"])
def test_nan_settings_are_refused_by_the_simulator_itself(option: str) -> None:
    with pytest.raises(ValueError, match=option):
        tg.Simulator(tg.make_cluster("triangle"), **{option: math.nan})
    with pytest.raises(ValueError, match=option):
        tg.BatchSimulator(tg.make_cluster("triangle"), 2, **{option: np.float64("nan")})


def test_range_checks_refuse_nan_wherever_it_sits() -> None:
    with pytest.raises(ValueError, match="x must lie in"):
        check_range("x", np.array([0.5, math.nan, 0.2]), 0.0, 1.0, "")
    with pytest.raises(ValueError, match="x must lie in"):
        check_real("x", math.nan, 0.0, math.inf, "s")
    check_range("x", np.array([0.0, 1.0]), 0.0, 1.0, "")  # the bounds themselves pass


# ---------------------------------------------------------------------- safety factor range
def test_the_stable_range_needs_no_opt_in_and_beyond_it_one_that_warns() -> None:
    cluster = tg.make_cluster("triangle")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert tg.Simulator(cluster, safety_factor=MAX_STABLE_SAFETY_FACTOR).batch.safety_factor == 0.2
    with pytest.raises(ValueError, match="allow_unstable_safety_factor=True") as refused:
        tg.Simulator(cluster, safety_factor=0.21)
    assert "safety_factor 0.21 is above 0.2" in str(refused.value)
    with pytest.warns(UnstableSafetyFactorWarning, match="safety_factor 1 is above 0.2"):
        sim = tg.BatchSimulator(cluster, 2, safety_factor=1.0, allow_unstable_safety_factor=True)
    assert sim.safety_factor == 1.0
    with pytest.raises(ValueError, match="allow_unstable_safety_factor must be True or False"):
        tg.BatchSimulator(cluster, safety_factor=0.1, allow_unstable_safety_factor="yes")
    with pytest.raises(ValueError, match=r"must lie in \(0, 1\]"):
        tg.BatchSimulator(cluster, safety_factor=1.5, allow_unstable_safety_factor=True)


def test_the_env_config_applies_the_same_range_and_opt_in() -> None:
    with pytest.raises(EnvArgumentError, match="allow_unstable_safety_factor"):
        TaskConfig(safety_factor=0.9)
    with pytest.raises(EnvArgumentError, match="allow_unstable_safety_factor must be"):
        TaskConfig(allow_unstable_safety_factor=1)
    with pytest.warns(UnstableSafetyFactorWarning) as caught:
        env = tg.envs.TetherClusterVectorEnv(4, "chain", safety_factor=0.9, allow_unstable_safety_factor=True)
    assert len(caught) == 1  # once, from the config, not again from each simulator the task builds
    assert env.task.sim.safety_factor == 0.9


# ---------------------------------------------------------------------- the runaway guard
def snapping_pairs(count: int) -> tuple[Cluster, np.ndarray, np.ndarray]:
    """A strongly pretensioned pair, perturbed so that its cable goes slack and snaps taut."""
    pair = Cluster(positions=[[0, 0, 0], [10, 0, 0]], masses=1.0, cables=[(0, 1)], EA=1e4, N0=1000.0)
    rng = np.random.default_rng(0)
    x0 = pair.positions + rng.normal(0, 0.05, (count, 2, 3))
    return pair, x0, rng.normal(0, 0.1, (count, 2, 3))


def run(safety_factor: float, count: int = 32, seconds: float = 10.0, **options: float) -> tg.BatchSimulator:
    pair, x0, v0 = snapping_pairs(count)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UnstableSafetyFactorWarning)
        batch = tg.BatchSimulator(
            pair, count, safety_factor=safety_factor, allow_unstable_safety_factor=True, **options
        )
    batch.reset(x0, v0)
    for _ in range(round(seconds / 0.1)):
        batch.advance(0.1)
    return batch


def test_an_energy_runaway_is_flagged_and_frozen() -> None:
    batch = run(1.0)
    flagged = batch.status == STATUS_ENERGY_RUNAWAY
    assert flagged.all()  # at 1.0 every one of these pairs gains energy it was never given
    report = batch.energy()
    scale = np.maximum(np.abs(report.initial), report.kinetic + report.strain)
    assert (np.abs(report.residual) > ENERGY_RUNAWAY_TOLERANCE * scale).all()
    frozen = batch.node_table.copy()
    stats = batch.advance(0.1)
    assert (stats.substeps == 0).all() and np.array_equal(batch.node_table, frozen) and stats.diverged.all()


def test_the_guard_can_be_turned_off_and_changes_no_bit_of_what_it_does_not_stop() -> None:
    unguarded = run(1.0, energy_tolerance=math.inf)
    assert (unguarded.status == 0).all()  # the same runaways as above, unflagged: the guard flags them
    report = unguarded.energy()
    assert (np.abs(report.residual) > ENERGY_RUNAWAY_TOLERANCE * report.initial).any()
    guarded, loose = run(0.1), run(0.1, energy_tolerance=math.inf)
    assert guarded.node_table.tobytes() == loose.node_table.tobytes()
    for bad in (math.nan, 0.0, 1e-300, 9.9e-4, -1.0, "0.25"):
        with pytest.raises(ValueError, match="energy_tolerance"):
            tg.BatchSimulator(tg.make_cluster("triangle"), energy_tolerance=bad)
    # The smallest accepted tolerance still leaves a triangle settling under its pretension, at rest
    # and in a damped drift, unflagged.
    tight = tg.BatchSimulator(tg.make_cluster("triangle"), 2, energy_tolerance=1e-3)
    drift = np.broadcast_to([3.0, -1.0, 0.5], tight.positions.shape)
    tight.reset(tight.positions, np.stack([np.zeros(tight.positions.shape[1:]), drift[1]]))
    for _ in range(50):
        tight.advance(0.2)
    assert (tight.status == 0).all()


def test_healthy_clusters_are_never_flagged_at_the_default_factor() -> None:
    batch = run(tg.simulator.DEFAULT_SAFETY_FACTOR)
    assert (batch.status == 0).all()
    report = batch.energy()
    assert (np.abs(report.residual) < 0.1 * report.initial).all()


def test_a_single_simulator_raises_on_a_runaway() -> None:
    pair, x0, v0 = snapping_pairs(1)
    with pytest.warns(UnstableSafetyFactorWarning):
        sim = tg.Simulator(pair, safety_factor=1.0, allow_unstable_safety_factor=True)
    sim.reset(x0[0], v0[0])
    with pytest.raises(SimulationDiverged, match="energy left its books"):
        for _ in range(100):
            sim.advance(0.1)


def test_the_unstable_chain_env_ends_its_episodes_as_numerics_diverged() -> None:
    with pytest.warns(UnstableSafetyFactorWarning):
        env = tg.envs.TetherClusterVectorEnv(16, "chain", safety_factor=1.0, allow_unstable_safety_factor=True)
    env.reset(seed=1)
    rng = np.random.default_rng(2)
    flagged = 0
    for _ in range(300):
        env.step(rng.uniform(-1, 1, env.action_space.shape).astype(np.float32))
        flagged += int((env.task.sim.status == STATUS_ENERGY_RUNAWAY).sum())
    assert flagged > 0


# ---------------------------------------------------------------------- refused intervals
def state_bits(batch: tg.BatchSimulator, index: int) -> list[bytes]:
    return [getattr(batch, attribute)[index].tobytes() for attribute in STATE_FIELDS.values() if attribute != "status"]


def collapsing_pair() -> Cluster:
    """A pair whose pretension far exceeds its stiffness: it pulls itself together, and its
    step-limiting frequency N/L grows as it does, so an interval that fits the sub-step budget at
    its start runs out of it halfway."""
    return Cluster(positions=[[0, 0, 0], [1, 0, 0]], masses=1.0, cables=[(0, 1)], EA=1.0, N0=100.0)


def test_a_refusal_halfway_through_an_interval_puts_the_cluster_back() -> None:
    pair = collapsing_pair()
    sim = tg.Simulator(pair, max_substeps=5)
    for _ in range(6):
        sim.advance(0.01)
    before = state_bits(sim.batch, 0)
    with pytest.raises(SimulationDiverged, match="back where it was before this call") as refused:
        sim.advance(0.04)
    assert "advance over shorter intervals" in str(refused.value)
    assert state_bits(sim.batch, 0) == before
    stats = sim.batch.last_advance
    assert stats.substeps[0] == 0 and stats.status[0] == 2
    # The advice works: the same 0.04 s in shorter intervals, bit-identical to a run that never
    # tried the long one.
    fresh = tg.Simulator(pair, max_substeps=5)
    for _ in range(6):
        fresh.advance(0.01)
    for _ in range(4):
        sim.advance(0.01)
        fresh.advance(0.01)
    assert state_bits(sim.batch, 0) == state_bits(fresh.batch, 0)
    assert sim.time == pytest.approx(0.1)


def test_the_refused_steps_were_taken_then_undone() -> None:
    """The test above must exercise a refusal after sub-steps were taken (not before the first)."""
    batch = tg.BatchSimulator(collapsing_pair(), 1, max_substeps=5)
    for _ in range(6):
        batch.advance(0.01)
    stats = batch.advance(0.04, record_steps=20)
    assert stats.status[0] == 2 and np.isfinite(stats.step_sizes[0]).sum() == 4


def test_a_refused_cluster_in_a_batch_takes_the_advice_while_the_others_go_on() -> None:
    cluster = tg.make_cluster("tetrahedron")
    batch = tg.BatchSimulator(cluster, 3, max_substeps=60)
    rng = np.random.default_rng(4)
    batch.reset(cluster.positions + rng.normal(0, 0.01, (3, 4, 3)))
    batch.advance(0.5)
    before = [state_bits(batch, b) for b in range(3)]
    stats = batch.advance(2.0)  # needs more than 60 sub-steps per cluster: each is refused and put back
    assert (stats.status == 2).all() and all(state_bits(batch, b) == before[b] for b in range(3))
    active = np.array([True, False, True])
    for _ in range(4):
        stats = batch.advance(0.5, active=active)
        assert (stats.status[active] == 0).all()
    assert batch.time.tolist() == pytest.approx([2.5, 0.5, 2.5])
    assert state_bits(batch, 1) == before[1]


# ---------------------------------------------------------------------- the guard on a beaded line
def crumpled_line_runs(segments: int, safety_factor: float, energy_tolerance: float) -> tg.BatchSimulator:
    """16 copies of the probe's beaded line (L = 100 m, two 50 kg satellites, m_t = 2 kg, EA = 40 kN,
    T = 5 N), slack on its chord with 0.3 m of noise on every bead, the satellites flying apart at
    0.5 m/s each, after 20 s (0.02 s intervals) at ``safety_factor`` (opt-in above 0.2)."""
    from tether_gym.tethers import Tether, build_cluster

    spec = Tether((0, 1), EA=40e3, segments=segments, mass=2.0, N0=5.0)
    line = build_cluster([[0.0, 0.0, 0.0], [100.0, 0.0, 0.0]], 50.0, [spec])
    rng = np.random.default_rng(0)
    x0 = np.repeat(line.positions[None], 16, axis=0)
    x0[..., 0] *= 0.99
    x0 += rng.normal(0.0, 0.3, x0.shape) * line.is_bead[None, :, None]
    v0 = np.zeros_like(x0)
    v0[:, 0, 0], v0[:, 1, 0] = -0.5, 0.5
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UnstableSafetyFactorWarning)
        batch = tg.BatchSimulator(
            line, 16, safety_factor=safety_factor, allow_unstable_safety_factor=True, energy_tolerance=energy_tolerance
        )
    batch.reset(x0, v0)
    for _ in range(1000):
        batch.advance(0.02)
    return batch


def relative_residual(batch: tg.BatchSimulator) -> np.ndarray:
    report = batch.energy()
    scale = np.maximum(np.abs(report.initial), report.kinetic + report.strain + report.dissipated)
    return np.abs(report.residual) / scale


def test_the_guard_flags_a_snapping_beaded_line_that_runs_away_and_not_at_the_default() -> None:
    """A crumpled slack line snapping taut: at safety 0.5 (opt-in), N = 32, it leaves its books
    with status "ok" when unguarded (measured: 15 kN, beads at 570 m/s, residuals 0.25-0.55 of
    the energy scale); the guard flags 15 of the 16 copies.  At the default factor nothing is flagged and the
    books hold (measured residual 0.007; see benchmarks/tether_snaps.py)."""
    unguarded = crumpled_line_runs(32, 0.5, math.inf)
    assert (unguarded.status == 0).all()
    assert np.median(relative_residual(unguarded)) > ENERGY_RUNAWAY_TOLERANCE  # measured 0.45
    assert np.linalg.norm(unguarded.velocities, axis=2).max() > 100.0  # beads whipped far beyond the 0.5 m/s given
    guarded = crumpled_line_runs(32, 0.5, ENERGY_RUNAWAY_TOLERANCE)
    assert (guarded.status == STATUS_ENERGY_RUNAWAY).sum() >= 12  # measured 15 of 16
    healthy = crumpled_line_runs(32, tg.simulator.DEFAULT_SAFETY_FACTOR, ENERGY_RUNAWAY_TOLERANCE)
    assert (healthy.status == 0).all()
    assert relative_residual(healthy).max() < 0.05 * ENERGY_RUNAWAY_TOLERANCE


def test_the_reports_relative_residual_is_the_residual_over_the_books_largest_entry() -> None:
    batch = tg.BatchSimulator(tg.make_cluster("tetrahedron"), 3)
    assert (batch.energy().relative_residual == 0.0).all()  # at rest at the reset: no books, no error
    positions = batch.positions + np.random.default_rng(0).normal(0.0, 0.5, batch.positions.shape)
    batch.reset(positions)
    batch.advance(5.0, force=np.full(batch.positions.shape, 0.01))
    report = batch.energy()
    largest = np.max([report.initial, report.kinetic + report.strain, report.work, report.dissipated], axis=0)
    np.testing.assert_allclose(report.relative_residual, np.abs(report.residual) / largest, rtol=1e-12)
    assert (report.relative_residual < 0.05).all()
