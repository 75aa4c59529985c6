"""Cluster description: validation, presets, immutability, file round trips."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import tether_gym as tg
from tether_gym import Cluster, ClusterError

TRIANGLE = dict(positions=[[0, 0, 0], [10, 0, 0], [0, 10, 0]], masses=5.0, cables=[(0, 1), (1, 2), (0, 2)], EA=1e4)


def make(**changes: object) -> Cluster:
    return Cluster(**{**TRIANGLE, **changes})


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"masses": [5.0, 0.0, 5.0]}, "masses must lie in [1e-06, 1e+09] kg; got 0.0 (satellite 1)"),
        ({"masses": [5.0, -1.0, 5.0]}, "masses must lie in [1e-06"),
        ({"masses": [5.0, np.nan, 5.0]}, "masses contains NaN"),
        ({"positions": [[0, 0, 0], [10, 0, np.inf], [0, 10, 0]]}, "positions contains an infinite value"),
        ({"EA": [1e4, np.nan, 1e4]}, "EA contains NaN"),
        ({"cables": [(0, 1), (1, 1), (0, 2)]}, "joins node 1 to itself"),
        ({"cables": [(0, 1), (1, 0), (0, 2)]}, "both join nodes (0, 1)"),
        ({"cables": [(0, 1), (1, 3), (0, 2)]}, "node indices must be in 0..2"),
        ({"cables": [(0, 1), (-1, 2)]}, "node indices must be in 0..2"),
        ({"cables": [(0, 1.5)]}, "whole node indices"),
        ({"positions": [[0, 0, 0], [0, 0, 0], [0, 10, 0]]}, "positions give cable 0 zero length"),
        ({"EA": [1e4, -1.0, 1e4]}, "EA must lie in [1e-06, 1e+12] N; got -1.0 (cable 1)"),
        ({"N0": -0.5}, "N0 (pretension) must lie in [0, 1e+12] N"),
        ({"damping": -1.0}, "damping must lie in [0, 1e+12] N*s/m"),
        ({"L0": [10.0, 0.0, 10.0]}, "L0 must lie in [1e-06, 1e+09] m; got 0.0 (cable 1)"),
        ({"cables": [(0, 1)]}, "disconnected: satellites [2]"),
        ({"positions": [[0, 0], [1, 0], [0, 1]]}, "shape (n, 3)"),
        ({"masses": [1.0, 2.0]}, "masses must have shape (3,)"),
        ({"EA": [1e4, 1e4]}, "EA must have shape (3,)"),
        ({"cables": [0, 1, 2]}, "shape (m, 2)"),
        ({"cables": []}, "non-empty"),
        ({"breaking_load": 0.0}, "breaking_load must lie in (0, inf]"),
        ({"masses": "heavy"}, "masses must be made of real numbers, not strings"),
        ({"masses": True}, "masses must be made of real numbers, not booleans"),
        ({"EA": [1e4, "1e4", 1e4]}, "EA must be made of real numbers, not strings"),
        ({"cables": [(0, 1), (1, None), (0, 2)]}, "cables must be made of real numbers, not objects"),
        ({"positions": [[0, 0, 0], [1e9, 0, 0], [0, 10, 0]]}, "positions must lie in [0, 1e+08] m"),
        ({"positions": [[0, 0, 0], [1e-7, 0, 0], [0, 10, 0]]}, "its default L0) must lie in [1e-06, 1e+09] m"),
        ({"masses": 1e300}, "masses must lie in [1e-06, 1e+09] kg"),
        ({"EA": 1e300}, "EA must lie in [1e-06, 1e+12] N"),
        ({"breaking_load": [1.0, -np.inf, 1.0]}, "breaking_load must lie in (0, inf]"),
        ({"breaking_load": [1.0, 1e300, 1.0]}, "breaking_load must lie in (0, 1e+12] N, or inf"),
        ({"frame": {"kind": "rotating", "rate": 1e3}}, "frame rate must be a finite number of rad/s within +-100"),
        ({"frame": {"kind": "rotating", "rate": "fast"}}, "frame rate must be a number"),
        ({"name": 3}, "name must be a string"),
    ],
)
def test_invalid_clusters_are_rejected_with_a_clear_message(changes: dict, message: str) -> None:
    with pytest.raises(ClusterError) as info:
        make(**changes)
    assert message in str(info.value)


def test_scalars_broadcast_and_reference_lengths_default_to_the_geometry() -> None:
    c = make(N0=2.0, damping=0.3)
    assert c.masses.shape == (3,) and np.all(c.masses == 5.0)
    assert np.allclose(c.L0, [10.0, math.hypot(10, 10), 10.0])
    assert np.all(c.N0 == 2.0) and np.all(c.damping == 0.3)
    assert np.all(np.isinf(c.breaking_load))


def test_cluster_is_immutable() -> None:
    c = make()
    with pytest.raises(ValueError):
        c.positions[0, 0] = 1.0
    with pytest.raises(AttributeError):
        c.name = "other"  # type: ignore[misc]
    replaced = c.replace(masses=[1.0, 2.0, 3.0])
    assert np.all(c.masses == 5.0) and replaced.masses.tolist() == [1.0, 2.0, 3.0]
    with pytest.raises(ClusterError, match="unknown Cluster field"):
        c.replace(mass=3.0)


def test_split_masses_sum_to_the_assembled_masses() -> None:
    """The Irons-Treharne condition: element masses add up to the node masses."""
    c = tg.make_cluster("hub")
    split = c.masses / c.degree
    assembled = np.zeros(c.num_nodes)
    for i, j in c.cables:
        assembled[i] += split[i]
        assembled[j] += split[j]
    assert np.allclose(assembled, c.masses)
    assert np.allclose(c.inv_split_mass_sum, 1 / split[c.cables[:, 0]] + 1 / split[c.cables[:, 1]])


@pytest.mark.parametrize("name", tg.preset_names())
def test_presets_are_valid_and_sub_step_at_control_rates(name: str) -> None:
    c = tg.make_cluster(name)
    assert c.name == name
    assert np.allclose(c.L0, np.linalg.norm(c.positions[c.cables[:, 1]] - c.positions[c.cables[:, 0]], axis=1))
    sim = tg.Simulator(c)
    # Several sub-steps per control interval of the preset's env id at the default safety factor.
    (interval,) = {task.get("control_interval", 0.1) for preset, _, task in tg.ENV_IDS.values() if preset == name}
    substep = tg.DEFAULT_SAFETY_FACTOR * sim.critical_time_step()
    # A beaded line's step falls as 1/N with its segment count N.
    segments = max((spec.segments for spec in c.tethers), default=1)
    assert 2 <= interval / substep <= 50 * segments
    assert np.all(c.breaking_load > 100.0) and np.all(c.masses[c.satellite_indices] >= 1.0)


def test_tetrahedron_preset_is_regular() -> None:
    c = tg.make_cluster("tetrahedron", edge=50.0)
    lengths = np.linalg.norm(c.positions[c.cables[:, 1]] - c.positions[c.cables[:, 0]], axis=1)
    assert c.num_nodes == 4 and c.num_cables == 6
    assert np.allclose(lengths, 50.0)
    assert np.allclose(c.positions.mean(axis=0), 0.0, atol=1e-12)


def test_preset_overrides_and_errors() -> None:
    c = tg.make_cluster("chain", n=8, EA=3e4)
    assert c.num_nodes == 8 and c.num_cables == 7 and np.all(c.EA == 3e4)
    assert tg.make_cluster("hub", spokes=4, rim=False).num_cables == 4
    assert tg.make_cluster("octahedron").num_cables == 12
    with pytest.raises(ClusterError, match=r"unknown preset 'cube'; choose one of \['tetrahedron'"):
        tg.make_cluster("cube")
    with pytest.raises(ClusterError, match=r"has no parameter\(s\) \['edges'\]"):
        tg.make_cluster("tetrahedron", edges=3)
    with pytest.raises(ClusterError, match="chain needs n >= 2"):
        tg.make_cluster("chain", n=1)


@pytest.mark.parametrize("suffix", [".json", ".toml"])
@pytest.mark.parametrize("name", ["tetrahedron", "hub"])
def test_save_and_load_round_trip(tmp_path: Path, suffix: str, name: str) -> None:
    c = tg.make_cluster(name)
    path = tg.save_cluster(c, tmp_path / f"cluster{suffix}")
    assert tg.load_cluster(path) == c


def test_hand_written_toml_file(tmp_path: Path) -> None:
    path = tmp_path / "mine.toml"
    path.write_text(
        'name = "mine"\npositions = [[0, 0, 0], [20, 0, 0]]\nmasses = [4.0, 8.0]\n'
        "cables = [[0, 1]]\nEA = 2e4\nN0 = 1.0\n"
    )
    c = tg.load_cluster(path)
    assert c.name == "mine" and c.L0.tolist() == [20.0] and c.N0.tolist() == [1.0]


def test_bad_files_get_clear_errors(tmp_path: Path) -> None:
    with pytest.raises(ClusterError, match="no cluster file"):
        tg.load_cluster(tmp_path / "missing.json")
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(ClusterError, match="is not valid JSON"):
        tg.load_cluster(bad)
    extra = tmp_path / "extra.json"
    extra.write_text('{"positions": [[0,0,0],[1,0,0]], "masses": 1, "cables": [[0,1]], "EA": 1, "colour": 2}')
    with pytest.raises(ClusterError, match=r"unknown cluster key\(s\) \['colour'\]"):
        tg.load_cluster(extra)
    with pytest.raises(ClusterError, match="use a .json or .toml"):
        tg.save_cluster(tg.make_cluster("triangle"), tmp_path / "c.yaml")
