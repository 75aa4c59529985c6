"""Exact snapshots of the simulator and the task: a restored cluster continues bit-identically.

This is the public API that planning (the ``mpc`` reference controller) and search build on:
snapshot a cluster, try candidate actions in other clusters of a batch, restore.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest

import tether_gym as tg
from tether_gym.envs.task import TASK_STATE_FIELDS, TaskConfig, task_from_arguments
from tether_gym.simulator import STATE_FIELDS


def state_of(batch: tg.BatchSimulator, index: int) -> list[np.ndarray]:
    return [getattr(batch, attribute)[index].copy() for attribute in STATE_FIELDS.values()]


def identical(a: list[np.ndarray], b: list[np.ndarray]) -> bool:
    return all(x.tobytes() == y.tobytes() for x, y in zip(a, b, strict=True))


def busy_batch(count: int) -> tg.BatchSimulator:
    """Clusters that differ in their parameters, snap slack and taut, and break cables: every
    kind of state the integrator keeps."""
    base = tg.make_cluster("spinning_triangle").replace(breaking_load=[1e9, 1e9, 3.0])
    clusters = [base.replace(masses=base.masses * (1 + 0.1 * k)) for k in range(count)]
    batch = tg.BatchSimulator(clusters)
    rng = np.random.default_rng(3)
    batch.reset(base.positions + rng.normal(0, 0.05, (count, 3, 3)), rng.normal(0, 0.2, (count, 3, 3)))
    for _ in range(7):
        batch.advance(0.1, rng.normal(0, 0.3, (count, 3, 3)))
    return batch


def forces(steps: int, count: int, seed: int = 11) -> np.ndarray:
    return np.random.default_rng(seed).normal(0, 0.5, (steps, count, 3, 3))


def test_a_restored_batch_continues_bit_identically() -> None:
    batch = busy_batch(3)
    saved = batch.snapshot()
    pushes = forces(25, 3)
    for p in pushes:
        batch.advance(0.1, p)
    reference = [state_of(batch, b) for b in range(3)]
    assert batch.broken.any()  # the continuation breaks a cable: intact flags are state too
    batch.restore(saved)
    for p in pushes:
        batch.advance(0.1, p)
    assert all(identical(state_of(batch, b), reference[b]) for b in range(3))


def test_states_move_between_batches_and_clone() -> None:
    source = busy_batch(3)
    saved = source.snapshot([2, 0])
    pushes = forces(15, 3)
    for p in pushes:
        source.advance(0.1, p)
    # Into another batch, other slots: parameters travel with the state.
    target = tg.BatchSimulator(tg.make_cluster("spinning_triangle"), 5)
    target.restore(saved, indices=[4, 1])
    moved = np.zeros((15, 5, 3, 3))
    moved[:, 4], moved[:, 1] = pushes[:, 2], pushes[:, 0]
    for p in moved:
        target.advance(0.1, p)
    assert identical(state_of(target, 4), state_of(source, 2)) and identical(state_of(target, 1), state_of(source, 0))
    assert target.clusters[4] is source.clusters[2]
    # One cluster cloned into four: all follow the original.
    clones = tg.BatchSimulator(tg.make_cluster("spinning_triangle"), 4)
    clones.restore(
        saved.__class__(saved.clusters[:1], {k: v[:1] for k, v in saved.arrays.items()}, saved.settings),
        indices=np.arange(4),
    )
    for p in pushes:
        clones.advance(0.1, np.repeat(p[2:3], 4, axis=0))
    assert all(identical(state_of(clones, b), state_of(source, 2)) for b in range(4))


def test_a_snapshot_is_a_read_only_copy() -> None:
    batch = busy_batch(2)
    saved = batch.snapshot()
    before = saved.positions.copy()
    batch.advance(0.1)
    assert np.array_equal(saved.positions, before)
    with pytest.raises(ValueError):
        saved.positions[0, 0, 0] = 1.0
    assert set(saved.arrays) == set(STATE_FIELDS)


def test_refused_restores_change_nothing() -> None:
    batch = busy_batch(2)
    saved = batch.snapshot()
    batch.advance(0.3)
    before = [state_of(batch, b) for b in range(2)]
    other_settings = tg.BatchSimulator(tg.make_cluster("spinning_triangle"), 2, safety_factor=0.2).snapshot()
    other_topology = tg.BatchSimulator(tg.make_cluster("tetrahedron"), 2).snapshot()
    for state, indices, message in (
        (other_settings, None, "settings"),
        (other_topology, None, "topology"),
        (saved, [0, 1, 1], "cannot fill"),
        (saved, [0, 5], "indices must be in 0..1"),
        ("state", None, "SimulatorState"),
    ):
        with pytest.raises((ValueError, TypeError), match=message):
            batch.restore(state, indices)  # type: ignore[arg-type]
        assert all(identical(state_of(batch, b), before[b]) for b in range(2))


def step_task(task, actions: np.ndarray, rngs: list[np.random.Generator]) -> list[np.ndarray]:
    task.step(actions, rngs=rngs)
    arrays = task.info_arrays()
    return [task.observation.copy(), task.scalars.copy(), task.end_reason.copy()] + [
        np.asarray(arrays[key]).copy() for key in ("thrust", "disturbance", "thruster_ok", "propellant_used", "time")
    ]


def test_a_restored_task_continues_bit_identically_with_every_fault_on() -> None:
    """Delay line, thruster failure, kicks, periodic force, thrust noise, randomisation and cable
    breaking: the task's own state must travel with the simulator's."""
    options = dict(
        randomize={"masses": 0.2, "EA": 0.2},
        impulse_magnitude=0.5,
        impulse_rate=0.5,
        periodic_amplitude=0.2,
        thrust_noise=0.1,
        thrust_delay=2,
        thruster_failure_probability=1.0,
        thruster_failure_window=(0.2, 0.6),
        cable_failure="continue",
    )
    task = task_from_arguments(3, "tetrahedron", **options)
    rngs = [np.random.default_rng(20 + k) for k in range(3)]
    task.reset(rngs, np.arange(3))
    actions = np.random.default_rng(5).uniform(-1, 1, (30, 3, task.action_size))
    for a in actions[:8]:
        task.step(a, rngs=rngs)
    saved = task.snapshot()
    saved_rngs = copy.deepcopy(rngs)
    reference = [step_task(task, a, rngs) for a in actions[8:]]

    other = task_from_arguments(4, "tetrahedron", **options)
    other.reset([np.random.default_rng(99)] * 4, np.arange(4))
    other.restore(saved, indices=[3, 0, 2])
    other_rngs = [saved_rngs[1], np.random.default_rng(0), saved_rngs[2], saved_rngs[0]]
    for a, expected in zip(actions[8:], reference, strict=True):
        moved = np.zeros((4, task.action_size))
        moved[3], moved[0], moved[2] = a[0], a[1], a[2]
        got = step_task(other, moved, other_rngs)
        for g, e in zip(got, expected, strict=True):
            assert g[[3, 0, 2]].tobytes() == e.tobytes()
    assert set(saved.arrays) == set(TASK_STATE_FIELDS)


def test_task_restore_refuses_another_task_or_difficulty() -> None:
    task = task_from_arguments(2, "tetrahedron")
    task.reset([np.random.default_rng(0)] * 2, np.arange(2))
    saved = task.snapshot()
    with pytest.raises(ValueError, match="another cluster or TaskConfig"):
        task_from_arguments(2, "tetrahedron", propellant_weight=0.5).restore(saved)
    harder = task_from_arguments(2, "tetrahedron")
    harder.set_difficulty(0.5)
    with pytest.raises(ValueError, match="set_difficulty"):
        harder.restore(saved)
    assert TaskConfig() == saved.config
