"""Property-based fuzzing of the physics core: clusters, their files, presets and the simulator.

Every input ends in exactly one of two ways:

* a clear error: a :class:`~tether_gym.ClusterError`, ``ValueError`` or ``TypeError`` (or, for an
  integration that cannot be carried out, the project's :class:`~tether_gym.SimulationDiverged`)
  whose message names the offending parameter;
* finite, correct behaviour: a cluster that round-trips bit-exactly through JSON and TOML, a
  simulator state that stays finite.

Nothing else (a bare numpy error, a crash, NaN or inf in the state, a silently changed value) is
allowed.  The example counts keep the file to a few seconds in CI.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

import tether_gym as tg
from tether_gym import Cluster, ClusterError, SimulationDiverged

#: Property-based, with many generated examples per property: the fast suite (-m 'not slow') leaves them out.
pytestmark = pytest.mark.slow

FUZZ = settings(
    max_examples=150,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)

#: The floats that break naive code: signed zeros, subnormals, the extremes, infinities and NaN.
SPECIAL_FLOATS = [
    0.0,
    -0.0,
    5e-324,
    -5e-324,
    2.2250738585072014e-308,
    1e-300,
    1e-7,
    1.0,
    -1.0,
    1e7,
    1e12,
    1e13,
    1e300,
    1.7976931348623157e308,
    -1.7976931348623157e308,
    math.inf,
    -math.inf,
    math.nan,
]

TRIANGLE: dict[str, Any] = dict(
    positions=[[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [0.0, 10.0, 0.0]],
    masses=5.0,
    cables=[(0, 1), (1, 2), (0, 2)],
    EA=1e4,
    N0=0.5,
    damping=0.1,
    breaking_load=500.0,
    axial_damping=0.0,
)
FIELD_SHAPES = {
    "positions": (3, 3),
    "masses": (3,),
    "damping": (3,),
    "EA": (3,),
    "N0": (3,),
    "L0": (3,),
    "breaking_load": (3,),
    "axial_damping": (3,),
}
ACCEPTED = (ClusterError, ValueError, TypeError)

special = st.sampled_from(SPECIAL_FLOATS)
anything_float = st.floats(allow_nan=True, allow_infinity=True) | special
junk = st.one_of(
    st.text(max_size=4),
    st.booleans(),
    st.none(),
    st.complex_numbers(max_magnitude=10),
    st.integers(-(10**400), 10**400),
    st.dictionaries(st.text(max_size=2), st.integers(), max_size=2),
)


def values_for(shape: tuple[int, ...]) -> st.SearchStrategy[Any]:
    """Scalars, arrays of the right shape with special floats, wrong shapes, and junk."""
    size = int(np.prod(shape))
    right = st.lists(anything_float, min_size=size, max_size=size).map(lambda v: np.reshape(v, shape).tolist())
    wrong = st.lists(anything_float, min_size=0, max_size=size + 2).filter(lambda v: len(v) != size)
    mixed = st.lists(st.one_of(anything_float, junk), min_size=size, max_size=size).map(
        lambda v: [v[i : i + shape[-1]] for i in range(0, size, shape[-1])] if len(shape) == 2 else v
    )
    return st.one_of(anything_float, right, wrong, mixed, junk)


def assert_names(error: BaseException, *names: str) -> None:
    message = str(error)
    assert any(name in message for name in names), f"{type(error).__name__}: {message!r} names none of {names}"


def bits(value: Any) -> bytes:
    return np.ascontiguousarray(value, dtype=np.float64).tobytes()


def assert_identical(a: Cluster, b: Cluster) -> None:
    """Equal to the bit (so -0.0 != 0.0 and NaN payloads would differ)."""
    for field in ("positions", "masses", "damping", "EA", "N0", "L0", "breaking_load", "axial_damping"):
        assert bits(getattr(a, field)) == bits(getattr(b, field)), field
    assert np.array_equal(a.cables, b.cables) and a.cables.dtype == b.cables.dtype
    assert a.name == b.name and a.frame.kind == b.frame.kind
    assert bits(a.frame.rate) == bits(b.frame.rate)


# ---------------------------------------------------------------------- construction
@FUZZ
@given(field=st.sampled_from(sorted(FIELD_SHAPES)), data=st.data())
def test_one_bad_field_is_named_or_the_cluster_is_valid(field: str, data: st.DataObject) -> None:
    value = data.draw(values_for(FIELD_SHAPES[field]), label=field)
    try:
        cluster = Cluster(**{**TRIANGLE, field: value})
    except ACCEPTED as error:
        assert_names(error, field, "the distance between a cable's satellites", "zero length", "disconnected")
        return
    stored = getattr(cluster, field)
    finite = np.where(np.isinf(stored), 0.0, stored) if field == "breaking_load" else stored
    assert np.all(np.isfinite(finite)) and np.all(np.isfinite(cluster.stiffness))
    assert np.all(np.isfinite(cluster.inv_split_mass_sum)) and np.all(cluster.inv_split_mass_sum > 0)


@FUZZ
@given(
    cables=st.one_of(
        st.lists(st.tuples(st.integers(-3, 5), st.integers(-3, 5)), max_size=5),
        st.lists(st.lists(st.one_of(st.integers(-2, 4), special, junk), max_size=3), max_size=4),
        junk,
    )
)
def test_bad_cable_lists_are_named(cables: Any) -> None:
    try:
        cluster = Cluster(
            **{**TRIANGLE, "cables": cables, "EA": 1e4, "N0": 0.5, "breaking_load": 500.0, "axial_damping": 0.0}
        )
    except ACCEPTED as error:
        assert_names(error, "cable", "disconnected")
        return
    assert cluster.num_cables >= 2 and np.all(cluster.L0 > 0)


@FUZZ
@given(
    frame=st.one_of(
        st.fixed_dictionaries(
            {"kind": st.sampled_from(["inertial", "hill", "rotating", "warp"]), "rate": st.one_of(anything_float, junk)}
        ),
        st.dictionaries(st.text(max_size=5), st.one_of(anything_float, junk), max_size=3),
        junk,
    )
)
def test_bad_frames_are_named(frame: Any) -> None:
    try:
        cluster = Cluster(**{**TRIANGLE, "frame": frame})
    except ACCEPTED as error:
        assert_names(error, "frame")
        return
    assert math.isfinite(cluster.frame.rate) and np.all(np.isfinite(cluster.frame.tidal))


# ---------------------------------------------------------------------- files
finite_in_range = st.one_of(
    st.sampled_from([0.0, -0.0, 5e-324, -5e-324, 2.2250738585072014e-308, 1e-300, 0.1, 1.0 / 3.0]),
    st.floats(-1e8, 1e8, allow_subnormal=True),
)


@st.composite
def valid_clusters(draw: st.DrawFn) -> Cluster:
    """Valid clusters whose every field holds awkward but legal floats (signed zeros, subnormals,
    extremes within range, unbreakable inf loads, a turning frame)."""
    offsets = draw(st.lists(finite_in_range, min_size=9, max_size=9))
    positions = (
        np.array(TRIANGLE["positions"]) * draw(st.sampled_from([1.0, 1e-3, 1e6])) + np.reshape(offsets, (3, 3)) * 1e-9
    )
    m = st.one_of(st.floats(1e-6, 1e9), st.sampled_from([1e-6, 1e9, 3.0]))
    nonneg = st.one_of(st.sampled_from([0.0, -0.0, 5e-324, 1e12]), st.floats(0.0, 1e12))
    load = st.one_of(st.sampled_from([math.inf, 1e12, 5e-324]), st.floats(1e-300, 1e12))
    frame = draw(
        st.one_of(
            st.none(),
            st.builds(lambda r: {"kind": "rotating", "rate": r}, st.floats(-100, 100)),
            st.builds(lambda r: {"kind": "hill", "rate": r}, st.floats(1e-6, 100)),
        )
    )
    return Cluster(
        positions=positions,
        masses=draw(st.lists(m, min_size=3, max_size=3)),
        cables=TRIANGLE["cables"],
        EA=draw(st.lists(st.floats(1e-6, 1e12), min_size=3, max_size=3)),
        N0=draw(st.lists(nonneg, min_size=3, max_size=3)),
        damping=draw(st.lists(nonneg, min_size=3, max_size=3)),
        L0=draw(st.one_of(st.none(), st.lists(st.floats(1e-6, 1e9), min_size=3, max_size=3))),
        breaking_load=draw(st.lists(load, min_size=3, max_size=3)),
        axial_damping=draw(st.lists(nonneg, min_size=3, max_size=3)),
        frame=frame or tg.Frame.inertial(),
        name=draw(st.text(max_size=12)),
    )


@FUZZ
@given(cluster=valid_clusters(), suffix=st.sampled_from([".json", ".toml"]))
def test_every_field_round_trips_bit_exactly(tmp_path: Path, cluster: Cluster, suffix: str) -> None:
    path = tg.save_cluster(cluster, tmp_path / f"fuzz{suffix}")
    assert_identical(tg.load_cluster(path), cluster)
    if suffix == ".json":
        assert "Infinity" not in path.read_text() and "NaN" not in path.read_text()  # strict JSON


def test_partly_infinite_breaking_loads_survive_a_file(tmp_path: Path) -> None:
    """The case that used to lose data: a mix of unbreakable and breakable cables."""
    cluster = tg.make_cluster("tetrahedron").replace(breaking_load=[math.inf] * 5 + [123.0])
    for suffix in (".json", ".toml"):
        loaded = tg.load_cluster(tg.save_cluster(cluster, tmp_path / f"c{suffix}"))
        assert loaded.breaking_load.tolist() == [math.inf] * 5 + [123.0]


@FUZZ
@given(
    content=st.one_of(
        st.binary(max_size=200),
        st.text(max_size=200).map(str.encode),
        st.dictionaries(
            st.sampled_from(["positions", "masses", "cables", "EA", "N0", "colour"]),
            st.one_of(anything_float, junk, st.lists(anything_float, max_size=3)),
            max_size=6,
        ).map(lambda d: repr(d).encode()),
    ),
    suffix=st.sampled_from([".json", ".toml", ".yaml"]),
)
def test_any_file_content_loads_or_gets_a_cluster_error(tmp_path: Path, content: bytes, suffix: str) -> None:
    path = tmp_path / f"any{suffix}"
    path.write_bytes(content)
    try:
        tg.load_cluster(path)
    except ClusterError as error:
        assert_names(error, str(path), suffix)


# ---------------------------------------------------------------------- presets
@FUZZ
@given(
    name=st.one_of(st.sampled_from(tg.preset_names()), st.text(max_size=6), junk),
    overrides=st.dictionaries(
        st.sampled_from(
            [
                "edge",
                "mass",
                "EA",
                "N0",
                "n",
                "spokes",
                "rim",
                "spin_rate",
                "orbit_rate",
                "spacing",
                "radius",
                "damping_rate",
                "breaking_load",
                "rim_share",
                "axial_damping_ratio",
                "hub_mass",
                "colour",
            ]
        ),
        st.one_of(anything_float, junk, st.integers(-3, 20)),
        max_size=3,
    ),
)
def test_presets_build_or_name_the_argument(name: Any, overrides: dict[str, Any]) -> None:
    try:
        cluster = tg.make_cluster(name, **overrides)
    except ClusterError as error:
        assert_names(error, "preset", *overrides)
        return
    assert np.all(np.isfinite(cluster.positions)) and np.all(np.isfinite(cluster.stiffness))


# ---------------------------------------------------------------------- simulator
@FUZZ
@given(
    cluster=valid_clusters(),
    duration=st.one_of(anything_float, junk, st.floats(1e-9, 1.0)),
    kick=st.floats(-1e3, 1e3),
    force=st.one_of(st.none(), st.floats(-1e13, 1e13), special),
)
def test_advance_stays_finite_or_refuses_clearly(cluster: Cluster, duration: Any, kick: float, force: Any) -> None:
    sim = tg.Simulator(cluster, max_substeps=20_000)
    sim.reset(velocities=np.full((3, 3), kick))
    p = None if force is None else np.full((3, 3), force)
    x, t = sim.positions.copy(), sim.time
    try:
        sim.advance(duration, p)
    except (ValueError, TypeError) as error:
        assert_names(error, "duration", "force")
        assert np.array_equal(sim.positions, x) and sim.time == t  # refused before anything changed
        return
    except SimulationDiverged as error:
        assert_names(error, "max_substeps", "non-finite")
        return
    assert np.all(np.isfinite(sim.positions)) and np.all(np.isfinite(sim.velocities))
    assert sim.time == pytest.approx(float(duration))
    report = sim.energy()
    assert all(math.isfinite(getattr(report, k)) for k in ("kinetic", "strain", "dissipated", "work"))


@FUZZ
@given(
    positions=values_for((4, 3)),
    velocities=st.one_of(st.none(), values_for((4, 3))),
    indices=st.one_of(st.none(), st.lists(st.one_of(st.integers(-2, 3), junk), max_size=3), junk),
)
def test_reset_accepts_or_names_the_argument_and_changes_nothing(positions: Any, velocities: Any, indices: Any) -> None:
    batch = tg.BatchSimulator(tg.make_cluster("tetrahedron"), 2)
    before = (batch.positions.copy(), batch.velocities.copy(), batch.intact.copy(), batch.time.copy())
    shaped = np.asarray(positions, dtype=object)
    if shaped.shape == (4, 3):  # the right shape for one cluster: broadcast to the batch
        positions = [positions, positions]
        velocities = None if velocities is None else [velocities, velocities]
    try:
        batch.reset(positions, velocities, indices=indices)
    except (ValueError, TypeError) as error:
        assert_names(error, "positions", "velocities", "indices", "zero-length cable")
        after = (batch.positions, batch.velocities, batch.intact, batch.time)
        assert all(np.array_equal(a, b) for a, b in zip(before, after, strict=True))
        return
    assume(True)
    assert np.all(np.isfinite(batch.positions)) and np.all(np.isfinite(batch.tension))


@FUZZ
@given(
    options=st.dictionaries(
        st.sampled_from(["safety_factor", "max_step", "max_substeps", "elongation"]),
        st.one_of(anything_float, junk, st.integers(-5, 10**20), st.text(max_size=10)),
        max_size=3,
    ),
    count=st.one_of(st.integers(-2, 4), junk),
)
def test_simulator_options_are_named(options: dict[str, Any], count: Any) -> None:
    try:
        batch = tg.BatchSimulator(tg.make_cluster("triangle"), count, **options)
    except (ValueError, TypeError) as error:
        assert_names(error, "num_clusters", *options)
        return
    stats = batch.advance(0.05)
    assert np.all(np.isfinite(batch.positions)) or np.all(stats.status != 0)


# ---------------------------------------------------------------------- settings, select, restore
@FUZZ
@given(
    safety_factor=st.one_of(anything_float, junk, st.floats(0.0, 1.2)),
    allow=st.one_of(st.booleans(), junk),
    max_step=st.one_of(anything_float, junk),
)
def test_settings_are_named_nan_included_and_the_unstable_range_needs_its_opt_in(
    safety_factor: Any, allow: Any, max_step: Any
) -> None:
    import warnings

    from tether_gym.simulator import MAX_STABLE_SAFETY_FACTOR, UnstableSafetyFactorWarning

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            batch = tg.BatchSimulator(
                tg.make_cluster("triangle"),
                safety_factor=safety_factor,
                max_step=max_step,
                allow_unstable_safety_factor=allow,
            )
        except (ValueError, TypeError) as error:
            assert_names(error, "safety_factor", "max_step", "allow_unstable_safety_factor")
            return
    assert 0.0 < batch.safety_factor <= (1.0 if allow is True else MAX_STABLE_SAFETY_FACTOR)
    assert batch.max_step > 0.0 and not math.isnan(batch.max_step)
    unstable = [w for w in caught if issubclass(w.category, UnstableSafetyFactorWarning)]
    assert len(unstable) == (1 if batch.safety_factor > MAX_STABLE_SAFETY_FACTOR else 0)


@FUZZ
@given(
    rows=st.one_of(
        st.lists(st.integers(-3, 5), max_size=5),
        st.lists(st.booleans(), min_size=0, max_size=5),
        st.lists(st.one_of(st.integers(0, 2), anything_float, junk), max_size=4),
        anything_float,
        junk,
    )
)
def test_select_takes_indices_or_a_mask_or_names_rows(rows: Any) -> None:
    batch = tg.BatchSimulator(tg.make_cluster("triangle"), 3)
    state = batch.snapshot()
    try:
        picked = state.select(rows)
    except ValueError as error:
        assert_names(error, "rows")
        return
    expected = np.flatnonzero(rows) if np.asarray(rows).dtype == np.bool_ else np.asarray(rows, dtype=np.int64)
    assert [id(c) for c in picked.clusters] == [id(state.clusters[int(r)]) for r in expected]
    assert np.array_equal(picked.positions, state.positions[expected])


@FUZZ
@given(
    name=st.sampled_from(sorted(tg.simulator.STATE_FIELDS)),
    value=st.one_of(
        anything_float,
        st.integers(-5, 5),
        st.booleans(),
        junk,
        st.lists(anything_float, min_size=1, max_size=4),
    ),
    whole=st.booleans(),
    row=st.integers(0, 1),
)
def test_restore_checks_every_array_and_changes_nothing_when_it_refuses(
    name: str, value: Any, whole: bool, row: int
) -> None:
    import dataclasses

    source = tg.BatchSimulator(tg.make_cluster("triangle"), 2)
    source.advance(0.1, np.full((2, 3, 3), 0.1))
    state = source.snapshot()
    arrays = dict(state.arrays)
    if whole:  # any value in place of the whole array
        arrays[name] = value
    else:  # one entry of the right array poisoned (when the value fits its dtype)
        poisoned = arrays[name].copy()
        try:
            poisoned[row].flat[0] = value
        except (TypeError, ValueError, OverflowError, IndexError):
            return
        arrays[name] = poisoned
    target = tg.BatchSimulator(tg.make_cluster("triangle", EA=2e3), 3)
    before = [t.tobytes() for t in (target.node_table, target.cable_table, target.cluster_table, target.counter_table)]
    try:
        target.restore(dataclasses.replace(state, arrays=arrays), indices=[2, 0])
    except (ValueError, TypeError) as error:
        assert_names(error, f"state.arrays[{name!r}]")
        after = [
            t.tobytes() for t in (target.node_table, target.cable_table, target.cluster_table, target.counter_table)
        ]
        assert after == before and all(c is target.template for c in target.clusters)
        return
    stats = target.advance(0.1)
    assert np.all(np.isfinite(target.positions[[0, 2]])) or np.all(stats.status[[0, 2]] != 0)


# ---------------------------------------------------------------------- restore: states that agree with themselves
def moving_batch(preset: str, elongation: str, seed: int, steps: int, fragile: bool) -> tg.BatchSimulator:
    """Two clusters of ``preset`` (different masses) pushed about for ``steps`` intervals; with
    ``fragile`` one cable breaks easily."""
    base = tg.make_cluster(preset)
    if fragile:
        base = base.replace(breaking_load=np.where(np.arange(base.num_cables) == 0, 1e-3, base.breaking_load))
    clusters = [base, base.replace(masses=base.masses * 1.3)]
    batch = tg.BatchSimulator(clusters, elongation=elongation)  # type: ignore[arg-type]  # drawn from both
    rng = np.random.default_rng(seed)
    n = base.num_nodes
    batch.reset(base.positions + rng.normal(0, 0.02, (2, n, 3)), rng.normal(0, 0.05, (2, n, 3)))
    for _ in range(steps):
        batch.advance(0.05, rng.normal(0, 0.2, (2, n, 3)))
    return batch


@FUZZ
@given(
    preset=st.sampled_from(tg.preset_names()),
    elongation=st.sampled_from(["exact", "linearised"]),
    seed=st.integers(0, 2**16),
    steps=st.integers(0, 4),
    fragile=st.booleans(),
)
def test_every_snapshot_restores_and_continues_bit_identically(
    preset: str, elongation: str, seed: int, steps: int, fragile: bool
) -> None:
    source = moving_batch(preset, elongation, seed, steps, fragile)
    state = source.snapshot()
    target = tg.BatchSimulator(list(state.clusters[::-1]), elongation=elongation)  # type: ignore[arg-type]
    target.restore(state, indices=[1, 0])
    force = np.full((2, source.num_nodes, 3), 0.1)
    source.advance(0.05, force)
    target.advance(0.05, force)
    for name in ("positions", "velocities", "tension", "status", "time"):
        assert bits(getattr(target, name)[[1, 0]]) == bits(getattr(source, name)), name


@FUZZ
@given(
    preset=st.sampled_from(tg.preset_names()),
    seed=st.integers(0, 2**16),
    steps=st.integers(0, 3),
    fragile=st.booleans(),
    edit=st.sampled_from(["internal_forces", "tension", "omega2", "energy_scale", "initial_energy", "clusters"]),
    entry=st.integers(0, 10**6),
    delta=st.floats(1e-6, 1e6),
)
def test_restore_refuses_arrays_that_contradict_each_other_and_changes_nothing(
    preset: str, seed: int, steps: int, fragile: bool, edit: str, entry: int, delta: float
) -> None:
    import dataclasses

    source = moving_batch(preset, "exact", seed, steps, fragile)
    assume(np.all(source.status == 0))
    state = source.snapshot()
    arrays = dict(state.arrays)
    clusters = state.clusters
    report = source.energy()
    if edit == "clusters":  # the same arrays, told to belong to clusters of other masses
        clusters = tuple(c.replace(masses=c.masses * (1.0 + min(delta, 10.0))) for c in clusters)
    elif edit == "energy_scale":  # below what the books hold
        books = np.maximum.reduce(
            [np.abs(report.initial), report.kinetic + report.strain + np.abs(report.frame_potential)]
        )
        assume(np.all(books > 0.0))
        arrays[edit] = books / (1.0 + delta)
    elif edit == "initial_energy":  # books that no longer balance
        arrays[edit] = arrays[edit] + (1.0 + delta) * source.energy_tolerance * arrays["energy_scale"] + delta
    else:  # one entry of an array that follows from the positions and parameters
        edited = arrays[edit].copy()
        edited.flat[entry % edited.size] += delta * (1.0 + np.abs(edited).max())
        arrays[edit] = edited
    target = tg.BatchSimulator(list(state.clusters))
    target.advance(0.05, np.ones((2, source.num_nodes, 3)))
    before = [t.tobytes() for t in (target.node_table, target.cable_table, target.cluster_table, target.counter_table)]
    objects = list(target.clusters)
    with pytest.raises(ValueError) as caught:
        target.restore(dataclasses.replace(state, clusters=clusters, arrays=arrays))
    assert_names(caught.value, "state.arrays[")
    after = [t.tobytes() for t in (target.node_table, target.cable_table, target.cluster_table, target.counter_table)]
    assert after == before and [id(c) for c in target.clusters] == [id(c) for c in objects]


@FUZZ
@given(
    rows=st.one_of(st.just([]), st.just(()), st.just(range(0)), st.just(np.zeros(0)), st.lists(st.integers(0, 2))),
)
def test_restore_takes_each_cluster_once_and_an_empty_selection_is_one(rows: Any) -> None:
    batch = tg.BatchSimulator(tg.make_cluster("triangle"), 3)
    batch.advance(0.1, np.full((3, 3, 3), 0.1))
    picked = batch.snapshot(rows)
    assert picked.num_clusters == len(rows)
    target = tg.BatchSimulator(tg.make_cluster("triangle"), 3)
    before = target.cluster_table.tobytes()
    try:
        target.restore(picked, indices=rows)
    except ValueError as error:
        assert len(set(np.asarray(rows, dtype=np.int64).tolist())) < len(rows)
        assert_names(error, "indices")
        assert target.cluster_table.tobytes() == before
        return
    assert len(set(np.asarray(rows, dtype=np.int64).tolist())) == len(rows)
    idx = np.asarray(rows, dtype=np.int64)
    assert bits(target.positions[idx]) == bits(batch.positions[idx])


# ---------------------------------------------------------------------- the runaway guard and a common drift
def snapping_pairs(drift: np.ndarray, safety_factor: float, count: int = 16) -> tg.BatchSimulator:
    """``count`` undamped, strongly pretensioned pairs, perturbed, all moving with the common
    velocity ``drift`` (3,) m/s on top, after 10 s at ``safety_factor`` (opt-in above 0.2)."""
    import warnings

    pair = tg.Cluster(positions=[[0, 0, 0], [10, 0, 0]], masses=1.0, cables=[(0, 1)], EA=1e4, N0=1000.0)
    rng = np.random.default_rng(0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        batch = tg.BatchSimulator(pair, count, safety_factor=safety_factor, allow_unstable_safety_factor=True)
    batch.reset(pair.positions + rng.normal(0, 0.05, (count, 2, 3)), rng.normal(0, 0.1, (count, 2, 3)) + drift)
    for _ in range(100):
        batch.advance(0.1)
    return batch


@settings(FUZZ, max_examples=12)
@given(
    speed=st.floats(0.0, 1e4),
    direction=st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1)),
)
def test_a_common_drift_neither_hides_a_runaway_nor_raises_a_false_one(
    speed: float, direction: tuple[float, float, float]
) -> None:
    axis = np.asarray(direction)
    assume(np.linalg.norm(axis) > 0.1)
    drift = speed * axis / np.linalg.norm(axis)
    # A uniform drift is integrated without error, so it must not change the guard's verdict: at
    # safety factor 1 the vibration of every pair runs away (flagged at rest), at 0.1 none does.
    assert np.all(snapping_pairs(drift, 1.0).status == 3)
    assert np.all(snapping_pairs(drift, 0.1).status == 0)


@FUZZ
@given(
    preset=st.sampled_from(tg.preset_names()),
    speed=st.floats(0.0, 1e5),
    axis=st.integers(0, 2),
)
def test_a_cluster_drifting_at_any_speed_is_not_flagged(preset: str, speed: float, axis: int) -> None:
    cluster = tg.make_cluster(preset)
    batch = tg.BatchSimulator(cluster)
    velocities = np.zeros((1, cluster.num_nodes, 3))
    velocities[..., axis] = speed
    batch.reset(cluster.positions[None], velocities)
    for _ in range(10):
        batch.advance(0.2)
    assert batch.status[0] == 0


@FUZZ
@given(rows=st.lists(st.integers(0, 2), min_size=1, max_size=4), shift=st.floats(1e-3, 0.1))
def test_reset_writes_one_state_per_cluster(rows: list[int], shift: float) -> None:
    cluster = tg.make_cluster("triangle")
    batch = tg.BatchSimulator(cluster, 3)
    positions = cluster.positions + shift * np.arange(len(rows))[:, None, None]
    before = batch.node_table.tobytes()
    try:
        batch.reset(positions, indices=rows)
    except ValueError as error:
        assert len(set(rows)) < len(rows)  # refused only for a repeat
        assert_names(error, "indices")
        assert batch.node_table.tobytes() == before
        return
    assert len(set(rows)) == len(rows)
    assert bits(batch.positions[rows]) == bits(positions)


@FUZZ
@given(preset=st.sampled_from(tg.preset_names()), row=st.integers(0, 1), steps=st.integers(0, 3))
def test_a_snapshot_with_a_non_finite_cluster_restores(preset: str, row: int, steps: int) -> None:
    source = moving_batch(preset, "exact", 0, steps, False)
    source.positions_[row, 0] = math.nan  # the writable view: a state the kernels then flag
    source.advance(0.05)
    assert source.status[row] == 1 and source.status[1 - row] == 0
    state = source.snapshot()
    target = tg.BatchSimulator(list(state.clusters))
    target.restore(state)
    assert target.status.tolist() == source.status.tolist()
    force = np.full((2, source.num_nodes, 3), 0.1)
    source.advance(0.05, force)
    target.advance(0.05, force)
    assert bits(target.positions[1 - row]) == bits(source.positions[1 - row])
    assert target.status[row] == 1


# ---------------------------------------------------------------------- beaded lines snapping at the default step
@settings(FUZZ, max_examples=25)
@given(
    segments=st.integers(2, 24),
    line_mass=st.floats(0.05, 10.0),
    stiffness=st.floats(1e3, 1e5),
    slack=st.floats(0.0, 0.03),
    speed=st.floats(0.0, 2.0),
    sag=st.floats(0.0, 10.0),
    damping=st.sampled_from([0.0, 0.1]),
    lumping=st.sampled_from(["half", "none"]),
)
def test_a_snapping_beaded_line_keeps_its_books_at_the_default_safety_factor(
    segments: int,
    line_mass: float,
    stiffness: float,
    slack: float,
    speed: float,
    sag: float,
    damping: float,
    lumping: str,
) -> None:
    """A slack line (shortened chord, a sine sag) whose 50 kg satellites fly apart snaps taut and
    whips its beads; at the default safety factor the runaway guard never trips and the energy
    books hold within 2 % (benchmarks/tether_snaps.py measures at most 0.6 % undamped)."""
    from tether_gym.tethers import Tether, build_cluster

    spec = Tether(
        (0, 1),
        EA=stiffness,
        segments=segments,
        mass=line_mass,
        N0=5.0,
        axial_damping=damping,
        lumping=lumping,  # type: ignore[arg-type]
    )
    line = build_cluster([[0.0, 0.0, 0.0], [100.0, 0.0, 0.0]], 50.0, [spec])
    x0 = line.positions.copy()
    x0[:, 0] *= 1.0 - slack
    x0[:, 1] = sag * np.sin(math.pi * x0[:, 0] / x0[1, 0])
    v0 = np.zeros_like(x0)
    v0[0, 0], v0[1, 0] = -speed, speed
    batch = tg.BatchSimulator(line)
    batch.reset(x0[None], v0[None])
    for _ in range(40):
        batch.advance(0.05)
    assert batch.status[0] == 0
    report = batch.energy()
    scale = max(abs(report.initial[0]), report.kinetic[0] + report.strain[0] + report.dissipated[0])
    assert abs(report.residual[0]) <= 0.02 * scale
