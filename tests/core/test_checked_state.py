"""Snapshot and restore as a checked public API: ``SimulatorState.select`` takes indices or a
mask and nothing else, and ``BatchSimulator.restore`` checks every part of a state, which a user
may build by hand, before it writes anything."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import pytest

import tether_gym as tg
from tether_gym.simulator import STATE_FIELDS, SimulatorState


def busy_batch(count: int = 3) -> tg.BatchSimulator:
    """Clusters of different parameters in motion, with a broken cable."""
    base = tg.make_cluster("spinning_triangle").replace(breaking_load=[1e9, 1e9, 3.0])
    batch = tg.BatchSimulator([base.replace(masses=base.masses * (1 + 0.1 * k)) for k in range(count)])
    rng = np.random.default_rng(3)
    batch.reset(base.positions + rng.normal(0, 0.05, (count, 3, 3)), rng.normal(0, 0.2, (count, 3, 3)))
    for _ in range(5):
        batch.advance(0.1, rng.normal(0, 0.3, (count, 3, 3)))
    return batch


def tables(batch: tg.BatchSimulator) -> tuple[bytes, ...]:
    """Every bit the batch holds, and which cluster objects it integrates."""
    arrays = (batch.node_table, batch.cable_table, batch.cluster_table, batch.counter_table)
    return tuple(a.tobytes() for a in arrays) + (bytes(str([id(c) for c in batch.clusters]), "ascii"),)


def with_array(state: SimulatorState, name: str, value: Any) -> SimulatorState:
    arrays = dict(state.arrays)
    arrays[name] = value
    return dataclasses.replace(state, arrays=arrays)


# ---------------------------------------------------------------------- select
def test_select_takes_indices_with_repeats_or_a_mask() -> None:
    state = busy_batch().snapshot()
    picked = state.select([2, 0, 2])
    assert picked.num_clusters == 3 and picked.clusters[0] is state.clusters[2]
    assert np.array_equal(picked.positions, state.positions[[2, 0, 2]])
    masked = state.select(np.array([True, False, True]))
    assert np.array_equal(masked.positions, state.positions[[0, 2]])
    assert state.select(np.array([1], dtype=np.uint8)).clusters[0] is state.clusters[1]


@pytest.mark.parametrize(
    "rows",
    [
        [0.0, 1.0],  # floats are not indices, even whole ones
        np.array([1.7]),  # would be truncated to 1
        [True, 1],  # a boolean among numbers
        [True, False],  # a mask of the wrong length
        np.ones((3, 1), dtype=bool),
        [3],  # out of range: a bare IndexError before
        [-1],  # would wrap around
        [[0, 1]],
        1,
        "0",
        [0, "1"],
        None,
        [[0], [1, 2]],
        [10**30],
    ],
)
def test_select_refuses_everything_else_by_name(rows: Any) -> None:
    state = busy_batch().snapshot()
    with pytest.raises(ValueError, match="rows"):
        state.select(rows)


# ---------------------------------------------------------------------- restore
def bad_arrays(state: SimulatorState) -> list[tuple[str, Any]]:
    """(field, bad value) pairs covering each class of defect, for every field of a state of k = 3."""
    cases: list[tuple[str, Any]] = []
    for name, value in state.arrays.items():
        cases.append((name, value.tolist()))  # not a numpy array
        cases.append((name, value[:1]))  # one row for three clusters: no silent broadcasting
        cases.append((name, value[..., None]))  # an extra axis
        cases.append((name, value.astype(np.float32 if value.dtype != np.float32 else np.float64)))
        if value.dtype == np.float64:
            for poison in (math.nan, math.inf, -math.inf):
                bad = value.copy()
                bad.flat[-1] = poison
                cases.append((name, bad))
    out_of_range = {
        "positions": 2e8,
        "half_step_velocities": -2e6,
        "velocities": 2e6,
        "previous_force": 2e12,
        "tension": -1.0,
        "last_step": -1e-3,
        "omega2": -1.0,
        "time": -0.1,
        "dissipated": -1.0,
    }
    for name, poison in out_of_range.items():
        bad = state.arrays[name].copy()
        bad.flat[0] = poison
        cases.append((name, bad))
    cases.append(("status", np.array([0, 9, 0])))
    cases.append(("status", np.array([0, -1, 0])))
    cases.append(("intact", state.arrays["intact"].astype(np.float64)))
    return cases


def test_every_bad_array_is_refused_by_name_and_changes_nothing() -> None:
    source = busy_batch()
    state = source.snapshot()
    cases = bad_arrays(state)
    assert {name for name, _ in cases} == set(STATE_FIELDS)
    # The target's clusters differ from the state's: a refused restore must not install them.
    target = tg.BatchSimulator(tg.make_cluster("spinning_triangle"), 4)
    target.advance(0.1)
    before = tables(target)
    for name, value in cases:
        with pytest.raises((ValueError, TypeError), match=rf"state\.arrays\['{name}'\]"):
            target.restore(with_array(state, name, value), indices=[3, 1, 0])
        assert tables(target) == before, name
    target.restore(state, indices=[3, 1, 0])  # the state itself is fine
    assert tables(target) != before


@pytest.mark.parametrize(
    "change",
    [
        lambda s: dataclasses.replace(s, arrays={k: v for k, v in s.arrays.items() if k != "time"}),
        lambda s: dataclasses.replace(s, arrays={**s.arrays, "spin": s.arrays["time"]}),
        lambda s: dataclasses.replace(s, arrays=list(s.arrays.values())),
        lambda s: dataclasses.replace(s, clusters=()),
        lambda s: dataclasses.replace(s, clusters=list(s.clusters)),
        lambda s: dataclasses.replace(s, clusters=(s.clusters[0], "a cluster", s.clusters[2])),
        # The last cluster of another topology: before, the first two were installed, then it failed.
        lambda s: dataclasses.replace(s, clusters=(*s.clusters[:2], tg.make_cluster("tetrahedron"))),
        lambda s: dataclasses.replace(s, settings=(0.2, "exact", math.inf, 10_000_000)),
    ],
)
def test_bad_clusters_keys_and_settings_are_refused_and_change_nothing(change: Any) -> None:
    state = busy_batch().snapshot()
    target = tg.BatchSimulator(tg.make_cluster("spinning_triangle"), 3)
    before = tables(target)
    with pytest.raises((ValueError, TypeError), match="state"):
        target.restore(change(state))
    assert tables(target) == before


def test_a_state_built_by_hand_restores_and_continues_like_the_original() -> None:
    source = busy_batch()
    state = source.snapshot()
    by_hand = SimulatorState(
        tuple(state.clusters), {name: np.array(value) for name, value in state.arrays.items()}, state.settings
    )
    target = tg.BatchSimulator(tg.make_cluster("spinning_triangle"), 3)
    target.restore(by_hand)
    force = np.random.default_rng(5).normal(0, 0.3, (3, 3, 3))
    source.advance(0.3, force)
    target.advance(0.3, force)
    assert target.node_table.tobytes() == source.node_table.tobytes()


# ---------------------------------------------------------------------- the task's states
def busy_task() -> tuple[Any, Any]:
    from tether_gym.envs.task import task_from_arguments

    options = dict(impulse_magnitude=0.5, impulse_rate=0.5, thrust_delay=2, thruster_failure_probability=1.0)
    task = task_from_arguments(3, "tetrahedron", **options)
    rngs = [np.random.default_rng(20 + k) for k in range(3)]
    task.reset(rngs, np.arange(3))
    for a in np.random.default_rng(5).uniform(-1, 1, (6, 3, task.action_size)):
        task.step(a, rngs=rngs)
    return task, task.snapshot()


def task_bits(task: Any) -> tuple[bytes, ...]:
    from tether_gym.envs.task import TASK_STATE_FIELDS

    return tables(task.sim) + tuple(task._state_array(name).tobytes() for name in TASK_STATE_FIELDS)


def test_a_task_state_selects_like_a_simulator_state() -> None:
    _, state = busy_task()
    assert state.select(np.array([False, True, True])).num_clusters == 2
    for rows in ([0.0], [True, 2], [3], np.array([1.5])):
        with pytest.raises(ValueError, match="rows"):
            state.select(rows)


def test_a_refused_task_restore_changes_nothing_in_the_simulator_or_the_task() -> None:
    task, state = busy_task()
    assert not any(np.isnan(v).any() for v in state.arrays.values() if v.dtype.kind == "f")  # NaN is never state
    for name, value in state.arrays.items():
        bads = [value.tolist(), value[:1], value.astype(np.float32 if value.dtype != np.float32 else np.float64)]
        if value.dtype.kind == "f":
            nan = value.copy()
            nan.flat[0] = math.nan
            bads.append(nan)
        for bad in bads:
            before = task_bits(task)
            with pytest.raises((ValueError, TypeError), match=rf"state\.arrays\['{name}'\]"):
                task.restore(dataclasses.replace(state, arrays={**state.arrays, name: bad}))
            assert task_bits(task) == before, name
    missing = {k: v for k, v in state.arrays.items() if k != "observation"}
    with pytest.raises(ValueError, match="task arrays"):
        task.restore(dataclasses.replace(state, arrays=missing))
    # The simulator part is checked before anything is written, too.
    bad_simulator = with_array(state.simulator, "time", np.full(3, -1.0))
    before = task_bits(task)
    with pytest.raises(ValueError, match=r"state\.arrays\['time'\]"):
        task.restore(dataclasses.replace(state, simulator=bad_simulator))
    assert task_bits(task) == before
    task.restore(state)


def test_a_selection_larger_than_any_batch_is_refused() -> None:
    from tether_gym.simulator import MAX_BATCH, checked_indices

    with pytest.raises(ValueError, match=f"at most {MAX_BATCH}"):
        checked_indices("rows", np.zeros(MAX_BATCH + 1, dtype=np.int64), 1)
    assert checked_indices("rows", np.zeros(3, dtype=np.int64), 1).tolist() == [0, 0, 0]
