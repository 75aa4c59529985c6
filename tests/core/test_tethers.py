"""Tethers with mass (the lumped-mass line): the spec, its expansion, and the physics against closed forms.

The line of the probe: L = 100 m between two 50 kg satellites, m_t = 2 kg, EA = 40 kN, T = 5 N.
Frequencies are the eigenvalues of the linearised system, whose stiffness is built by central
finite differences of the compiled force kernel (``BatchSimulator.internal_forces``); the
independent peer (scipy's DOP853 on bead equations written here) checks trajectories.
"""

from __future__ import annotations

import inspect
import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

import tether_gym as tg
from tether_gym.analysis import max_frequency
from tether_gym.limits import MIN_BEAD_MASS, MIN_MASS
from tether_gym.tethers import Tether, TetherError, build_cluster, frame_held, static_equilibrium, tether_results

LENGTH, SAT_MASS, LINE_MASS, EA, TENSION = 100.0, 50.0, 2.0, 40e3, 5.0
MU = LINE_MASS / LENGTH  # kg/m
TRANSVERSE_SPEED = math.sqrt(TENSION / MU)  # m/s
AXIAL_SPEED = math.sqrt(EA / MU)  # m/s


def line(segments: int, lumping: str = "half", **options: object) -> tg.Cluster:
    """The probe's line along x, split into ``segments``."""
    spec = Tether((0, 1), EA=EA, segments=segments, mass=LINE_MASS, N0=TENSION, lumping=lumping, **options)  # type: ignore[arg-type]
    return build_cluster([[0.0, 0.0, 0.0], [LENGTH, 0.0, 0.0]], SAT_MASS, [spec])


def stiffness_by_finite_differences(cluster: tg.Cluster) -> np.ndarray:
    """(3n, 3n) ``d f_int / d x`` at the nominal positions, by central differences of the kernel."""
    sim = tg.BatchSimulator(cluster, 1)
    n = cluster.num_nodes
    step = 1e-6 * float(cluster.L0.min())
    probes = np.repeat(cluster.positions[None], 6 * n, axis=0)
    for dof in range(3 * n):
        probes[2 * dof].reshape(-1)[dof] += step
        probes[2 * dof + 1].reshape(-1)[dof] -= step
    forces = sim.internal_forces(probes, np.zeros(6 * n, dtype=np.int64)).reshape(6 * n, 3 * n)
    return ((forces[0::2] - forces[1::2]) / (2 * step)).T


def frequencies(cluster: tg.Cluster, axis: int, fixed_ends: bool) -> np.ndarray:
    """Ascending natural frequencies, Hz, of the motion along ``axis`` (0 axial, 1 transverse),
    with the satellites held (``fixed_ends``) or free."""
    K = stiffness_by_finite_differences(cluster)
    dofs = np.arange(cluster.num_nodes) * 3 + axis
    if fixed_ends:
        dofs = dofs[cluster.is_bead]
    inv_sqrt_mass = 1.0 / np.sqrt(cluster.masses[dofs // 3])
    scaled = K[np.ix_(dofs, dofs)] * inv_sqrt_mass[:, None] * inv_sqrt_mass[None, :]
    omega2 = np.linalg.eigvalsh(0.5 * (scaled + scaled.T))
    return np.sqrt(np.clip(omega2, 0.0, None)) / (2 * math.pi)


def end_mass_roots(count: int) -> np.ndarray:
    """The first ``count`` roots beta = kL/2 of a uniform line between two equal end masses M
    (end-mass ratio r = m_t / (2 M)): antisymmetric modes ``beta tan beta = r``, symmetric modes
    ``tan beta = -beta / r``.  Axial and transverse motion share them, with speeds sqrt(EA/mu)
    and sqrt(T/mu)."""
    r = LINE_MASS / (2 * SAT_MASS)
    tiny = 1e-12
    roots = []
    for j in range(count):
        roots.append(brentq(lambda b: b * math.tan(b) - r, j * math.pi + tiny, j * math.pi + math.pi / 2 - tiny))
        roots.append(brentq(lambda b: math.tan(b) + b / r, j * math.pi + math.pi / 2 + tiny, (j + 1) * math.pi - tiny))
    return np.sort(roots)[:count]


def observed_orders(errors: list[np.ndarray]) -> np.ndarray:
    """Convergence orders log2(e(N) / e(2N)) of errors at N, 2N, 4N, ..."""
    return np.log2(np.array(errors[:-1]) / np.array(errors[1:]))


SEGMENT_COUNTS = [4, 8, 16, 32]


# ---------------------------------------------------------------------------------- closed forms
def test_transverse_modes_with_fixed_ends_converge_at_second_order() -> None:
    exact = np.array([k / (2 * LENGTH) * TRANSVERSE_SPEED for k in (1, 2, 3)])
    errors = [np.abs(frequencies(line(n), 1, fixed_ends=True)[:3] / exact - 1) for n in SEGMENT_COUNTS]
    orders = observed_orders(errors)
    assert np.all(orders > 1.9), orders
    assert errors[-1][0] < 5e-4  # mode 1 at N = 32: 4.0e-4 (1.0e-4 at N = 64)


def test_transverse_modes_with_end_masses_converge_at_second_order() -> None:
    exact = 2 * end_mass_roots(3) / LENGTH * TRANSVERSE_SPEED / (2 * math.pi)
    # The first transverse frequency is the line's translation, zero: modes 1-3 follow it.
    errors = [np.abs(frequencies(line(n), 1, fixed_ends=False)[1:4] / exact - 1) for n in SEGMENT_COUNTS]
    orders = observed_orders(errors)
    assert np.all(orders > 1.9), orders


@pytest.mark.parametrize(("lumping", "low", "high"), [("half", 1.95, 2.05), ("none", 0.95, 1.05)])
def test_first_axial_mode_converges_at_second_order_with_lumping_and_first_without(
    lumping: str, low: float, high: float
) -> None:
    exact = 2 * end_mass_roots(1)[0] / LENGTH * AXIAL_SPEED / (2 * math.pi)
    errors = [
        np.array([abs(frequencies(line(n, lumping), 0, fixed_ends=False)[1] / exact - 1)]) for n in SEGMENT_COUNTS
    ]
    orders = observed_orders(errors)
    assert np.all((low < orders) & (orders < high)), orders


def test_lumping_is_about_a_hundred_times_more_accurate_on_the_axial_mode_at_n_64() -> None:
    exact = 2 * end_mass_roots(1)[0] / LENGTH * AXIAL_SPEED / (2 * math.pi)
    error = {lump: abs(frequencies(line(64, lump), 0, fixed_ends=False)[1] / exact - 1) for lump in ("half", "none")}
    assert error["half"] < 2e-6  # measured 1.6e-6
    assert error["none"] > 50 * error["half"]  # measured 64x


def test_estimated_critical_step_tends_to_the_true_step_from_below() -> None:
    ratios = []
    for n in [2, 4, 8, 16, 32, 64]:
        cluster = line(n)
        estimate = tg.Simulator(cluster).critical_time_step()
        true_step = 2.0 / max_frequency(cluster)
        ratios.append(estimate / true_step)
        if n > 2:  # a segment between two beads sets it: L / (N c_axial), its wave-crossing time
            assert estimate == pytest.approx(LENGTH / (n * AXIAL_SPEED), rel=1e-12)
    ratios_array = np.array(ratios)
    assert np.all(ratios_array <= 1.0 + 1e-12), ratios
    assert np.all(np.diff(ratios_array[1:]) > 0.0), ratios  # from N = 4 on, closer with every doubling
    assert ratios_array[-1] > 0.999


def test_energy_drift_over_100_periods_at_the_default_safety_factor() -> None:
    cluster = line(8)
    sim = tg.Simulator(cluster)
    hold = sim.internal_forces(cluster.positions)  # the pretension, held at the satellites
    x0 = cluster.positions.copy()
    x0[:, 1] = 0.05 * np.sin(math.pi * x0[:, 0] / LENGTH)  # mode 1, small enough to stay taut
    sim.reset(x0)
    vibration = sim.energy().initial - (0.5 * TENSION**2 / cluster.stiffness).sum()
    period = 2 * LENGTH / TRANSVERSE_SPEED
    worst = 0.0
    for _ in range(100):
        sim.advance(period, hold)
        worst = max(worst, abs(sim.energy().residual))
    assert not sim.slack.any()
    assert worst < 1e-5 * vibration  # measured 1.8e-6


# ---------------------------------------------------------------------------------- independent peer
def peer_forces(x: np.ndarray, segments: int) -> tuple[np.ndarray, np.ndarray]:
    """Forces on the nodes of a chain (in order along the line) and the segment tensions, from
    the model's definition: ``max(0, T + EA/L0 (l - L0))`` along each segment."""
    rest = LENGTH / segments
    delta = np.diff(x, axis=0)
    lengths = np.linalg.norm(delta, axis=1)
    tension = np.maximum(TENSION + EA / rest * (lengths - rest), 0.0)
    pull = (tension / lengths)[:, None] * delta
    force = np.zeros_like(x)
    force[:-1] += pull
    force[1:] -= pull
    return force, tension


def peer_run(
    segments: int, x0: np.ndarray, v0: np.ndarray, external: np.ndarray, times: np.ndarray
) -> tuple[np.ndarray, float]:
    """DOP853 on the bead equations: positions (len(times), n, 3) in the cluster's node order,
    and the peak tension (sampled densely)."""
    order = np.r_[0, np.arange(2, segments + 1), 1]  # node indices from satellite 0 to satellite 1
    masses = np.r_[
        SAT_MASS + LINE_MASS / (2 * segments),
        np.full(segments - 1, LINE_MASS / segments),
        SAT_MASS + LINE_MASS / (2 * segments),
    ]
    size = 3 * (segments + 1)
    load = external[order]

    def rhs(_t: float, y: np.ndarray) -> np.ndarray:
        force, _ = peer_forces(y[:size].reshape(-1, 3), segments)
        return np.r_[y[size:], ((force + load) / masses[:, None]).ravel()]

    y0 = np.r_[x0[order].ravel(), v0[order].ravel()]
    solution = solve_ivp(rhs, (0.0, times[-1]), y0, method="DOP853", rtol=1e-10, atol=1e-12, dense_output=True)
    along_line = solution.sol(times)[:size].T.reshape(len(times), segments + 1, 3)
    positions = np.empty_like(along_line)
    positions[:, order] = along_line
    dense = solution.sol(np.linspace(0.0, times[-1], 4001))[:size].T.reshape(-1, segments + 1, 3)
    peak = max(float(peer_forces(x, segments)[1].max()) for x in dense)
    return positions, peak


def test_free_transverse_vibration_matches_the_peer() -> None:
    segments = 8
    cluster = line(segments)
    x0 = cluster.positions.copy()
    x0[:, 1] = 0.05 * np.sin(math.pi * x0[:, 0] / LENGTH)
    v0 = np.zeros_like(x0)
    hold = np.zeros_like(x0)
    hold[0, 0], hold[1, 0] = -TENSION, TENSION  # pretension held at the satellites, written independently
    period = 2 * LENGTH / TRANSVERSE_SPEED
    times = np.array([0.5, 1.0]) * period
    reference, _ = peer_run(segments, x0, v0, hold, times)
    sim = tg.Simulator(cluster)
    sim.reset(x0)
    previous = 0.0
    for k, t in enumerate(times):
        sim.advance(t - previous, hold)
        previous = t
        assert np.abs(sim.positions - reference[k]).max() < 1e-4 * 0.05  # measured 2e-6 m of 0.05 m


def test_snap_of_a_slack_line_matches_the_peer() -> None:
    """A slack line whose satellites fly apart snaps taut, whipping its beads."""
    segments = 8
    cluster = line(segments)
    x0 = cluster.positions.copy()
    x0[:, 0] *= 0.99  # every segment 1 % short: slack
    v0 = np.zeros_like(x0)
    v0[0, 0], v0[1, 0] = -0.5, 0.5
    times = np.array([1.0, 2.0])
    reference, reference_peak = peer_run(segments, x0, v0, np.zeros_like(x0), times)
    sim = tg.Simulator(cluster)
    sim.reset(x0, v0)
    peak, previous = 0.0, 0.0
    for k, t in enumerate(times):
        stats = sim.advance(t - previous)
        previous = t
        peak = max(peak, float(stats.peak_tension.max()))
        # Measured 1.9e-4 m, then 7.4e-3 m after the snaps (1.4e-3 m at safety 0.05, 2.3e-4 m at 0.02).
        assert np.abs(sim.positions - reference[k]).max() < 2e-2
    assert reference_peak > 20 * TENSION  # a real snap
    assert peak == pytest.approx(reference_peak, rel=3e-3)  # measured 1.0e-3 at safety 0.1


# ---------------------------------------------------------------------------------- the massless limit
def test_one_segment_without_lumping_is_the_massless_cable_to_the_bit() -> None:
    """The coarsest line (N = 1: two nodes, no bead) without lumping is the paper's massless
    cable: the same arrays and the same trajectory, bit for bit.  (A line with a bead cannot be:
    the bead's mass enters the equations.)"""
    positions = [[0.0, 0.0, 0.0], [LENGTH, 0.0, 0.0]]
    beaded = build_cluster(
        positions, SAT_MASS, [Tether((0, 1), EA=EA, mass=LINE_MASS, N0=TENSION, lumping="none", axial_damping=3.0)]
    )
    massless = tg.Cluster(positions, SAT_MASS, [[0, 1]], EA=EA, N0=TENSION, axial_damping=3.0)
    plain = beaded.to_dict()
    assert plain.pop("tethers")[0]["segments"] == 1
    assert plain == massless.to_dict()
    x0 = np.array([[0.0, 0.3, 0.0], [LENGTH + 0.2, 0.0, -0.1]])
    v0 = np.array([[0.1, 0.0, 0.2], [-0.3, 0.1, 0.0]])
    runs = []
    for cluster in (beaded, massless):
        sim = tg.Simulator(cluster)
        sim.reset(x0, v0)
        sim.advance(3.0)
        runs.append((sim.positions.copy(), sim.velocities.copy(), sim.tension))
    for a, b in zip(*runs, strict=True):
        assert a.tobytes() == b.tobytes()


def test_segments_in_series_give_back_the_tether_axial_damping() -> None:
    """A line stretched uniformly at rate dL/dt carries the damping force of the massless cable
    with the tether's coefficient in every segment."""
    rate, damping = 0.3, 7.0  # m/s, N*s/m
    beaded = line(5, axial_damping=damping)
    massless = tg.Cluster([[0, 0, 0], [LENGTH, 0, 0]], SAT_MASS, [[0, 1]], EA=EA, N0=TENSION, axial_damping=damping)
    tensions = []
    for cluster in (beaded, massless):
        sim = tg.Simulator(cluster)
        velocities = np.zeros_like(cluster.positions)
        velocities[:, 0] = rate * cluster.positions[:, 0] / LENGTH
        sim.reset(cluster.positions, velocities)
        tensions.append(sim.tension)
    assert tensions[1][0] == pytest.approx(TENSION + damping * rate)
    np.testing.assert_allclose(tensions[0], tensions[1][0], rtol=1e-12)


def test_one_segment_with_lumping_puts_half_the_mass_on_each_satellite() -> None:
    cluster = build_cluster([[0, 0, 0], [LENGTH, 0, 0]], SAT_MASS, [Tether((0, 1), EA=EA, mass=LINE_MASS)])
    assert cluster.masses.tolist() == [SAT_MASS + LINE_MASS / 2] * 2


# ---------------------------------------------------------------------------------- layout and roles
def test_roles_and_layout_of_a_beaded_cluster() -> None:
    cluster = build_cluster(
        [[0, 0, 0], [10, 0, 0], [0, 10, 0]],
        [1.0, 2.0, 3.0],
        [
            Tether((0, 1), EA=1e3, segments=3, mass=0.3),
            Tether((1, 2), EA=1e3),
            Tether((2, 0), EA=1e3, segments=2, mass=0.2, lumping="none", name="back"),
        ],
    )
    assert (cluster.num_nodes, cluster.num_satellites, cluster.num_beads, cluster.num_tethers) == (6, 3, 3, 3)
    assert cluster.satellite_indices.tolist() == [0, 1, 2]
    assert cluster.node_tether.tolist() == [-1, -1, -1, 0, 0, 2]
    assert cluster.is_bead.tolist() == [False, False, False, True, True, True]
    assert cluster.tether_beads(0).tolist() == [3, 4]
    assert cluster.tether_beads(1).tolist() == []
    assert cluster.tether_nodes(2).tolist() == [2, 5, 0]
    assert cluster.tether_cables(0).tolist() == [0, 1, 2]
    assert cluster.tether_cables(2).tolist() == [4, 5]
    assert cluster.cables.tolist() == [[0, 3], [3, 4], [4, 1], [1, 2], [2, 5], [5, 0]]
    np.testing.assert_allclose(cluster.positions[3:5], [[10 / 3, 0, 0], [20 / 3, 0, 0]])
    assert cluster.masses.tolist() == pytest.approx([1.0 + 0.05, 2.0 + 0.05, 3.0, 0.1, 0.1, 0.2])
    assert cluster.node_label(4) == "bead 1 of tether 0 (node 4)"
    assert cluster.node_label(1) == "satellite 1"
    assert "satellites=3" in repr(cluster) and "3 beads" in repr(cluster)
    with pytest.raises(ValueError, match="tether index in 0..2"):
        cluster.tether_beads(3)


def _massless_by_default(name: str) -> bool:
    parameter = inspect.signature(tg.presets.PRESETS[name]).parameters.get("tether_mass")
    return parameter is None or parameter.default == 0.0


@pytest.mark.parametrize("name", [name for name in tg.preset_names() if _massless_by_default(name)])
def test_clusters_without_beads_are_unchanged(name: str) -> None:
    cluster = tg.make_cluster(name)
    assert "tethers" not in cluster.to_dict()
    assert cluster.num_satellites == cluster.num_nodes and cluster.num_beads == 0
    assert cluster.satellite_indices.tolist() == list(range(cluster.num_nodes))
    assert not cluster.is_bead.any()
    with pytest.raises(ValueError, match="no tethers with beads"):
        cluster.tether_cables(0)


@pytest.mark.parametrize("suffix", [".json", ".toml"])
def test_cluster_files_round_trip_the_tether_specs_bit_for_bit(tmp_path: Path, suffix: str) -> None:
    cluster = build_cluster(
        [[0, 0, 0], [LENGTH, 0.1, -0.0], [3.0, 40.0, 1e-7]],
        [SAT_MASS, 7.0, 0.3],
        [
            Tether((0, 1), EA=EA, segments=7, mass=LINE_MASS / 3, N0=TENSION, axial_damping=0.1, name="main"),
            Tether((2, 1), EA=1.5e3, segments=3, mass=1e-3, L0=97.3, breaking_load=123.0, lumping="none"),
        ],
    )
    loaded = tg.load_cluster(tg.save_cluster(cluster, tmp_path / f"line{suffix}"))
    assert loaded == cluster
    assert loaded.tethers == cluster.tethers
    assert json.dumps(loaded.to_dict(), default=str) == json.dumps(cluster.to_dict(), default=str)


def test_light_finely_meshed_lines_are_accepted() -> None:
    """A 1 m thread of 1.2 mg in 1000 segments: beads of 1.2e-9 kg, below a satellite's minimum."""
    cluster = build_cluster([[0, 0, 0], [1, 0, 0]], 1.0, [Tether((0, 1), EA=10.0, segments=1000, mass=1.2e-6)])
    assert cluster.masses[2:].min() == pytest.approx(1.2e-9) and MIN_BEAD_MASS < MIN_MASS


# ---------------------------------------------------------------------------------- results per tether
def test_tether_results_end_and_peak_tension_slack_sag_and_break() -> None:
    cluster = line(4, breaking_load=50.0)
    sim = tg.BatchSimulator(cluster, 3)
    x = np.repeat(cluster.positions[None], 3, axis=0)
    x[1, 3, 1] = 2.0  # the middle bead pulled sideways by 2 m
    x[2, :, 0] *= 0.9  # the whole line 10 % short: slack
    sim.reset(x)
    results = tether_results(cluster, sim.positions, sim.tension, sim.broken)
    assert results.sag[:, 0].tolist() == pytest.approx([0.0, 2.0, 0.0])
    np.testing.assert_allclose(results.end_tension[0, 0], [TENSION, TENSION])
    assert results.peak_tension[1, 0] == pytest.approx(sim.tension[1].max())
    assert results.slack[:, 0].tolist() == [False, False, True]
    assert results.slack_fraction[2, 0] == 1.0
    assert not results.broken.any()
    sim.reset(x[:2] + np.array([-1.0, 0.0, 0.0]) * (np.arange(cluster.num_nodes) == 0)[None, :, None], indices=[0, 1])
    sim.advance(1e-3)
    results = tether_results(cluster, sim.positions, sim.tension, sim.broken)
    assert results.broken[:, 0].tolist() == [True, True, False]  # one broken segment severs the tether
    with pytest.raises(ValueError, match="tension must have shape"):
        tether_results(cluster, sim.positions, sim.tension[:, :2], sim.broken)


# ---------------------------------------------------------------------------------- turning frames
def test_a_radial_tether_in_orbit_is_built_in_equilibrium_along_itself() -> None:
    """The gravity gradient stretches a radial line: the tension peaks at its middle, and the
    built pretension profile balances every bead."""
    frame = tg.Frame.hill()
    spec = Tether((0, 1), EA=EA, segments=8, mass=20.0, N0=1.0)
    cluster = build_cluster([[-500.0, 0, 0], [500.0, 0, 0]], 100.0, [spec], frame=frame)
    profile = cluster.N0
    assert profile.mean() == pytest.approx(1.0, rel=1e-12)
    assert profile.argmax() in (3, 4) and profile[0] == profile.min()
    # Bead k's net load: the segments' pull plus the tidal force, zero to round-off.
    tidal_force = 2.5 * 3 * frame.rate**2 * cluster.positions[cluster.is_bead, 0]  # bead mass 20/8 kg
    assert np.abs(np.diff(profile) + tidal_force).max() < 1e-12
    held = tg.BatchSimulator(cluster, 1).equilibrium_force(cluster.positions[None])[0]
    assert np.abs(held[cluster.is_bead]).max() < 1e-12 * np.abs(tidal_force).max() * 1e3
    assert static_equilibrium(cluster).iterations == 0
    uniform = build_cluster([[-500.0, 0, 0], [500.0, 0, 0]], 100.0, [spec])
    assert (uniform.N0 == 1.0).all()
    with pytest.raises(TetherError, match=r"tether 0 .*raise N0 to at least 0\.00"):
        build_cluster(
            [[-500.0, 0, 0], [500.0, 0, 0]], 100.0, [Tether((0, 1), EA=EA, segments=8, mass=20.0, N0=1e-3)], frame=frame
        )


def test_a_load_across_a_spinning_tether_sags_it_into_the_funicular_parabola() -> None:
    """A tether across the radius of a spinning frame carries the centripetal load q = mu w^2 R
    across it; with its ends held, its beads lie on the parabola of sag q L^2 / (8 H), H the
    tension's component along the chord."""
    spin, radius, length, mu, segments = 0.03, 1000.0, 100.0, 0.02, 16
    spec = Tether((0, 1), EA=EA, segments=segments, mass=mu * length, N0=50.0)
    cluster = build_cluster(
        [[radius, -length / 2, 0], [radius, length / 2, 0]], 100.0, [spec], frame=tg.Frame.rotating(spin)
    )
    equilibrium = static_equilibrium(cluster)
    assert equilibrium.residual < 1e-9 * equilibrium.tension.max()
    nodes = equilibrium.positions[cluster.tether_nodes(0)]
    middle = segments // 2
    delta = nodes[middle + 1] - nodes[middle]
    along_chord = equilibrium.tension[cluster.tether_cables(0)][middle] * abs(delta[1]) / np.linalg.norm(delta)
    offsets = nodes[:, 0] - radius
    y = nodes[:, 1] + length / 2
    parabola = mu * spin**2 * radius * y * (length - y) / (2 * along_chord)
    np.testing.assert_allclose(offsets, parabola, rtol=2e-3, atol=1e-12)  # measured 5.5e-4: q grows with the sag
    results = tether_results(
        cluster, equilibrium.positions[None], equilibrium.tension[None], np.zeros((1, cluster.num_cables), bool)
    )
    assert results.sag[0, 0] == pytest.approx(offsets.max())


# ---------------------------------------------------------------------------------- bad specs
@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"mass": -1.0}, r"tether 'bad': mass must be a number in \[0, "),
        ({"segments": 0}, r"tether 'bad': segments must be a whole number in 1\.\."),
        ({"segments": 2.5}, r"tether 'bad': segments must be a whole number"),
        ({"N0": 50e3}, r"tether 'bad': .*shorter than its pretension stretch"),
        ({"ends": (1, 1)}, r"tether 'bad': both ends are satellite 1"),
        ({"ends": (0,)}, r"tether 'bad': ends must be two satellite indices"),
        ({"segments": 4, "mass": 0.0}, r"tether 'bad': 4 segments need a mass > 0"),
        ({"lumping": "all"}, r"tether 'bad': lumping must be one of"),
        ({"EA": math.nan}, r"tether 'bad': EA must be a number"),
        ({"breaking_load": 0.0}, r"tether 'bad': breaking_load must be a number in \(0, "),
    ],
)
def test_bad_specs_are_refused_naming_the_tether(changes: dict, match: str) -> None:
    fields = {"ends": (0, 1), "EA": EA, "segments": 4, "mass": LINE_MASS, "N0": TENSION, "name": "bad"} | changes
    with pytest.raises(TetherError, match=match):
        Tether(**fields)


def test_bad_expansions_are_refused_naming_the_tether() -> None:
    satellites = [[0, 0, 0], [LENGTH, 0, 0]]
    good = Tether((0, 1), EA=EA, segments=4, mass=LINE_MASS)
    with pytest.raises(
        TetherError, match=r"tether 1 \(tether between satellites 0 and 2\) ends at satellite 2, but there are 2"
    ):
        build_cluster(satellites, SAT_MASS, [good, Tether((0, 2), EA=EA)])
    with pytest.raises(TetherError, match=r"tether 0 .*beads of 1e-10 kg are lighter than the 1e-09 kg"):
        build_cluster(satellites, SAT_MASS, [Tether((0, 1), EA=EA, segments=10, mass=1e-9)])
    with pytest.raises(TetherError, match=r"tether 0: unknown tether key\(s\) \['mas'\]"):
        build_cluster(satellites, SAT_MASS, [{"ends": [0, 1], "EA": EA, "mas": 1.0}])
    with pytest.raises(TetherError, match="non-empty sequence of Tether specs"):
        build_cluster(satellites, SAT_MASS, good)  # type: ignore[arg-type]


def test_cluster_errors_name_a_bead_as_a_bead_of_its_tether() -> None:
    data = line(4).to_dict()
    data["masses"][3] = 0.0  # node 3 is the second bead
    with pytest.raises(tg.ClusterError, match=r"masses must lie in \[1e-09, .*\(bead 1 of tether 0 \(node 3\)\)"):
        tg.Cluster.from_dict(data)
    data = line(4).to_dict()
    data["positions"][4][2] = math.inf
    with pytest.raises(tg.ClusterError, match="positions contains an infinite value"):
        tg.Cluster.from_dict(data)
    data = line(4).to_dict()
    data["positions"][4][2] = 2e8
    with pytest.raises(tg.ClusterError, match=r"\(bead 2 of tether 0 \(node 4\), axis 2\)"):
        tg.Cluster.from_dict(data)
    data = line(4).to_dict()
    data["tethers"][0]["ends"] = [0, 2]
    with pytest.raises(tg.ClusterError, match=r"tether 0 .*ends at node 2, which is not a satellite"):
        tg.Cluster.from_dict(data)
    data = line(4).to_dict()
    data["cables"][1] = [3, 2]
    with pytest.raises(tg.ClusterError, match=r"tether 0 .*cables 0\.\.3 must be its segments"):
        tg.Cluster.from_dict(data)
    data = line(4).to_dict()
    data["positions"][3] = data["positions"][2]
    with pytest.raises(tg.ClusterError, match=r"cable 1 zero length: bead 0 of tether 0 \(node 2\) and bead 1"):
        tg.Cluster.from_dict(data)
    data = line(4).to_dict()
    data["tethers"][0]["segments"] = 9
    with pytest.raises(tg.ClusterError, match="the tethers have 8 beads in all, but the cluster has only 5 nodes"):
        tg.Cluster.from_dict(data)


# ---------------------------------------------------------------------------------- properties
PROPERTY = settings(max_examples=60, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])


@st.composite
def tethered_clusters(draw: st.DrawFn) -> tuple[np.ndarray, np.ndarray, list[Tether]]:
    """Satellites on a circle, joined in a chain and by other tethers between distinct pairs, of
    random mass, mesh and lumping."""
    count = draw(st.integers(2, 4))
    angles = 2 * math.pi * np.arange(count) / count
    positions = 30.0 * np.stack([np.cos(angles), np.sin(angles), np.zeros(count)], axis=1)
    masses = np.array(draw(st.lists(st.floats(1e-3, 1e3), min_size=count, max_size=count)))
    chain = [(k - 1, k) for k in range(1, count)]  # keeps the cluster connected
    others = [(i, j) for i in range(count) for j in range(i + 2, count)]
    chosen = chain + (draw(st.lists(st.sampled_from(others), unique=True)) if others else [])
    tethers = []
    for i, j in chosen:
        ends = (i, j) if draw(st.booleans()) else (j, i)
        tethers.append(
            Tether(
                ends,
                EA=draw(st.floats(1.0, 1e6)),
                segments=draw(st.integers(1, 9)),
                mass=draw(st.floats(1e-3, 10.0)),
                N0=draw(st.floats(0.0, 0.5)),
                lumping=draw(st.sampled_from(["half", "none"])),
                breaking_load=draw(st.sampled_from([math.inf, 1e3])),
            )
        )
    return positions, masses, tethers


@PROPERTY
@given(tethered_clusters())
def test_expansion_conserves_mass_and_length_and_round_trips(case: tuple[np.ndarray, np.ndarray, list[Tether]]) -> None:
    positions, masses, tethers = case
    cluster = build_cluster(positions, masses, tethers)
    kept = sum(spec.mass for spec in cluster.tethers if spec.lumping == "half" or spec.segments > 1)
    assert cluster.masses.sum() == pytest.approx(masses.sum() + kept, rel=1e-12)
    assert cluster.num_satellites == len(masses)
    for t, spec in enumerate(cluster.tethers):
        nodes, segments = cluster.tether_nodes(t), cluster.tether_cables(t)
        assert cluster.cables[segments].tolist() == np.stack([nodes[:-1], nodes[1:]], axis=1).tolist()
        assert (cluster.node_tether[nodes[1:-1]] == t).all()
        assert cluster.L0[segments].sum() == pytest.approx(spec.L0, rel=1e-12)
        assert spec.L0 == pytest.approx(np.linalg.norm(positions[spec.ends[1]] - positions[spec.ends[0]]))
    assert tg.Cluster.from_dict(json.loads(json.dumps(cluster.to_dict()))) == cluster


BAD_VALUES = {
    "mass": [-1.0, math.nan, math.inf, "2", True, None],
    "segments": [0, -3, 1.5, 10**6, "4", None],
    "EA": [0.0, -5.0, math.nan, "big"],
    "N0": [-1.0, math.nan],
    "L0": [0.0, -1.0, math.inf],
    "axial_damping": [-0.1, math.nan],
    "breaking_load": [0.0, -1.0, math.nan, "none"],
    "lumping": ["All", 0, None],
    "ends": [(0, 0), (0, -1), (0, 1.0), "01", None, (0, 1, 2)],
    "name": [3],
}


@PROPERTY
@given(
    st.sampled_from(sorted(BAD_VALUES)).flatmap(lambda key: st.tuples(st.just(key), st.sampled_from(BAD_VALUES[key])))
)
def test_any_bad_field_is_refused_naming_the_tether_and_the_field(bad: tuple[str, object]) -> None:
    field, value = bad
    fields: dict = {"ends": (0, 1), "EA": EA, "segments": 4, "mass": LINE_MASS, "N0": TENSION, "name": "probe"}
    fields[field] = value
    with pytest.raises(TetherError) as error:
        Tether(**fields)
    message = str(error.value)
    assert message.startswith("tether") and (field in message or field == "name")


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    preset=st.sampled_from(["spinning_triangle", "spinning_hub", "radial_chain"]),
    tether_mass=st.floats(0.01, 5.0),
    segments=st.integers(2, 24),
    rate_factor=st.floats(0.5, 2.0),
)
def test_fuzz_the_frame_alone_holds_beaded_turning_frame_presets(
    preset: str, tether_mass: float, segments: int, rate_factor: float
) -> None:
    """Any mass, mesh and rate: no force is left on any node of the nominal shape (the frame's
    load alone holds satellites and beads), each segment is at its reference length and
    pretension, and a tether's spec gives its mean tension and its length along the beads."""
    rate = {"spinning_triangle": ("spin_rate", 0.06), "spinning_hub": ("spin_rate", 0.05)}.get(
        preset, ("orbit_rate", 0.00113)
    )
    cluster = tg.make_cluster(preset, tether_mass=tether_mass, segments=segments, **{rate[0]: rate[1] * rate_factor})
    S = cluster.num_satellites
    load = np.abs(cluster.masses[:S, None] * cluster.frame.tidal * cluster.positions[:S]).max()
    force = tg.BatchSimulator(cluster, 1).equilibrium_force(cluster.positions[None])[0]
    assert np.abs(force).max() <= 1e-10 * load
    lengths = np.linalg.norm(np.diff(cluster.positions[cluster.cables], axis=1)[:, 0], axis=1)
    np.testing.assert_allclose(lengths, cluster.L0, rtol=1e-12)
    for t, spec in enumerate(cluster.tethers):
        segments_of_t = cluster.tether_cables(t)
        assert spec.N0 == pytest.approx(cluster.N0[segments_of_t].mean(), rel=1e-9)
        assert spec.L0 == pytest.approx(cluster.L0[segments_of_t].sum(), rel=1e-12)


def test_frame_held_rim_line_sags_as_the_funicular_and_leaves_free_space_alone() -> None:
    """A spinning triangle's rim line bows outward by about the parabola's q L^2 / (8 H), with q
    the centripetal load per length at the chord's radius and H the line's tension; in free space
    frame_held returns the cluster itself."""
    cluster = tg.make_cluster("spinning_triangle", tether_mass=1.0, segments=32)
    spec = cluster.tethers[0]
    a, b = spec.ends
    midpoint = 0.5 * (cluster.positions[a] + cluster.positions[b])
    chord = float(np.linalg.norm(cluster.positions[b] - cluster.positions[a]))
    q = spec.mass / spec.L0 * cluster.frame.rate**2 * float(np.linalg.norm(midpoint))
    m = cluster.num_cables
    sag = float(tether_results(cluster, cluster.positions[None], cluster.N0[None], np.zeros((1, m), bool)).sag[0, 0])
    middle = cluster.tether_beads(0)[len(cluster.tether_beads(0)) // 2]
    assert np.linalg.norm(cluster.positions[middle]) > np.linalg.norm(midpoint)  # it bows outward
    assert sag == pytest.approx(q * chord**2 / (8.0 * spec.N0), rel=0.05)
    free = tg.make_cluster("chain", tether_mass=1.0, segments=4)
    assert frame_held(free) is free


def test_frame_held_picks_one_answer_for_an_indeterminate_formation() -> None:
    """The spinning hub's spokes and rim can share the load in many ways; frame_held's choice
    (the least change from the massless pretensions) converges with the mesh and grows with the
    lines' mass, instead of wandering along the self-stress with round-off."""

    def levels(mass: float, segments: int) -> np.ndarray:
        cluster = tg.make_cluster("spinning_hub", tether_mass=mass, segments=segments)
        return np.array([spec.N0 for spec in cluster.tethers])

    coarse, fine = levels(1.0, 8), levels(1.0, 32)
    np.testing.assert_allclose(coarse, fine, rtol=2e-3)
    massless = tg.make_cluster("spinning_hub").N0
    lighter, heavier = levels(0.2, 8), levels(1.0, 8)
    assert (massless < lighter).all() and (lighter < heavier).all()


def test_tether_mode_errors_match_the_kernel_frequencies_and_the_closed_forms() -> None:
    """The ids' pages state these errors: they are the kernel's frequencies (by finite differences,
    above) against the closed forms written in this file, and fall at second order."""
    from tether_gym.analysis import tether_mode_errors

    string = np.array([k / (2 * LENGTH) * TRANSVERSE_SPEED for k in (1, 2, 3)])
    bar = 2 * end_mass_roots(1)[0] / LENGTH * AXIAL_SPEED / (2 * math.pi)
    previous = None
    for n in (8, 16):
        (errors,) = tether_mode_errors(line(n))
        assert (errors.tether, errors.segments, errors.tension) == (0, n, pytest.approx(TENSION))
        np.testing.assert_allclose(errors.transverse_hz, string, rtol=1e-12)
        assert errors.axial_hz == pytest.approx(bar, rel=1e-10)
        expected = frequencies(line(n), 1, fixed_ends=True)[:3] / string - 1
        np.testing.assert_allclose(errors.transverse_error, expected, rtol=1e-5)
        axial = frequencies(line(n), 0, fixed_ends=False)[1] / bar - 1
        assert errors.axial_error == pytest.approx(axial, rel=1e-5)
        if previous is not None:
            ratios = previous / np.abs([*errors.transverse_error, errors.axial_error])
            assert np.all((3.8 < ratios) & (ratios < 4.2)), ratios
        previous = np.abs([*errors.transverse_error, errors.axial_error])
    # Other tethers' lumped shares do not move a tether's end masses: the closed form is the
    # bare satellites'.
    beaded = tg.presets.make_cluster("beaded_tetrahedron")
    axial = [e.axial_hz for e in tether_mode_errors(beaded)]
    np.testing.assert_allclose(axial, axial[0], rtol=1e-14)
    assert tether_mode_errors(tg.presets.make_cluster("tetrahedron")) == []


def test_simulator_names_the_coincident_nodes_of_a_zero_length_segment() -> None:
    cluster = tg.presets.make_cluster("beaded_chain")
    sim = tg.BatchSimulator(cluster, 2)
    positions = np.repeat(cluster.positions[None], 2, axis=0)
    positions[1, 6] = positions[1, 5]
    expected = r"cluster\(s\) \[1\] give a zero-length cable: cable 1 joins bead 0 of tether 0 \(node 5\) and bead 1"
    with pytest.raises(ValueError, match=expected):
        sim.reset(positions)
    with pytest.raises(ValueError, match=expected):
        sim.internal_forces(positions, np.array([0, 1]))


def snap_peak(segments: int, safety_factor: float, axial_damping: float) -> float:
    """The largest segment tension, N, over the first 2 s of the probe's line started straight and
    1 % slack, its satellites flying apart at 0.5 m/s each, so that it snaps taut after about 1 s
    (``segments=0``: the massless cable)."""
    if segments == 0:
        spec = Tether((0, 1), EA=EA, N0=TENSION, axial_damping=axial_damping)
        cluster = build_cluster([[0.0, 0.0, 0.0], [LENGTH, 0.0, 0.0]], SAT_MASS, [spec])
    else:
        cluster = line(segments, axial_damping=axial_damping)
    sim = tg.BatchSimulator(cluster, 1, safety_factor=safety_factor)
    positions = cluster.positions.copy()
    positions[:, 0] *= 0.99
    velocities = np.zeros_like(positions)
    velocities[0, 0], velocities[1, 0] = -0.5, 0.5
    sim.reset(positions[None], velocities[None])
    return max(float(sim.advance(0.01).peak_tension.max()) for _ in range(200))


def test_peak_tension_through_a_snap_converges_as_the_mesh_is_refined_and_the_step_falls() -> None:
    """With a Kelvin-Voigt damping fixed for all N (5 % on the highest segment mode at N = 16:
    material damping, the physical regularisation of the snap's front), the first snap's peak
    converges: each doubling of N moves it less, and at N = 32-64 neither the mesh nor the step
    moves it by 1 %. Undamped, the lumped line's front overshoots more as N grows, by less and
    less (benchmarks/tether_snaps.py and the Verification page have the full study)."""
    damping = 0.05 * math.sqrt(EA * LINE_MASS / LENGTH) / 16  # N*s/m, the whole tether's
    counts = [4, 8, 16, 32, 64]
    fine = np.array([snap_peak(n, 0.025, damping) for n in counts])
    changes = np.abs(np.diff(fine)) / fine[1:]  # measured 15, 6.3, 3.7 and 0.5 %
    assert np.all(np.diff(changes) < 0), changes
    assert changes[-1] < 0.01
    for n in (32, 64):
        coarse = snap_peak(n, 0.1, damping)
        assert abs(coarse / fine[counts.index(n)] - 1) < 0.01  # measured 0.5 % and 0.4 %
    # Within 10 % of the massless cable's (the line's own momentum adds to the pull).
    massless = snap_peak(0, 0.025, damping)
    assert 1.0 < fine[-1] / massless < 1.1, (fine[-1], massless)
    undamped = np.array([snap_peak(n, 0.1, 0.0) for n in counts])
    assert np.all(np.diff(undamped) > 0) and np.all(np.diff(np.diff(undamped)) < 0), undamped
