"""The central-difference integrator against closed-form answers and its own defining equations."""

from __future__ import annotations

import math

import numpy as np
import pytest

import tether_gym as tg
from tests.helpers import pair, reference_internal_forces, separation

#: Some checks run the scheme at its linear limit (safety factor up to 1, the step set by max_step)
#: on purpose: the opt-in warns, which is expected here.
pytestmark = pytest.mark.filterwarnings("ignore::tether_gym.simulator.UnstableSafetyFactorWarning")


def tetrahedron_ics(cluster: tg.Cluster, rng: np.random.Generator, amplitude: float, speed: float):
    x0 = cluster.positions + amplitude * rng.standard_normal(cluster.positions.shape)
    v0 = speed * rng.standard_normal(cluster.positions.shape)
    return x0, v0


def test_internal_forces_match_an_independent_implementation() -> None:
    rng = np.random.default_rng(1)
    for name in tg.preset_names():
        c = tg.make_cluster(name)
        sim = tg.Simulator(c)
        for _ in range(5):
            x = c.positions + rng.normal(0.0, 0.5, c.positions.shape)
            np.testing.assert_allclose(sim.internal_forces(x), reference_internal_forces(c, x), rtol=1e-12, atol=1e-9)


def test_half_step_form_equals_the_papers_three_level_form_at_constant_step() -> None:
    """Eqs. (7)-(9) with the uniformly accelerated start, against the simulator's half-step form."""
    c = tg.make_cluster("tetrahedron", damping_rate=0.3)
    h = 0.01
    sim = tg.Simulator(c, max_step=h)
    rng = np.random.default_rng(2)
    x0, v0 = tetrahedron_ics(c, rng, 0.3, 0.5)
    p = 0.3 * rng.standard_normal(x0.shape)
    sim.reset(x0, v0)
    m = c.masses[:, None]
    cd = c.damping[:, None]
    a0 = (p - reference_internal_forces(c, x0) - cd * v0) / m
    previous, current = x0, x0 + h * v0 + 0.5 * h * h * a0
    sim.advance(h, p)
    np.testing.assert_allclose(sim.positions, current, rtol=0, atol=1e-12)
    k_hat = m / h**2 + cd / (2 * h)
    slack_seen = False
    for _ in range(400):
        p_hat = (
            p + 2 * m / h**2 * current - (m / h**2 - cd / (2 * h)) * previous - reference_internal_forces(c, current)
        )
        previous, current = current, p_hat / k_hat
        sim.advance(h, p)
        slack_seen |= bool(sim.slack.any())
        np.testing.assert_allclose(sim.positions, current, rtol=0, atol=1e-9)
    assert slack_seen  # the comparison covered the tension-only cut-off


def test_preloaded_pair_oscillates_at_the_central_difference_frequency() -> None:
    """Held apart by opposite thrust F: stretch F/k, and the discrete frequency is omega_h exactly."""
    m1, m2, EA, L = 10.0, 30.0, 5e4, 100.0
    k = EA / L
    omega = math.sqrt(k * (1 / m1 + 1 / m2))
    h = 1.0 / omega  # omega h = 1: the discrete frequency is 4.7 % above omega
    c = pair(m1, m2, L, EA)
    sim = tg.Simulator(c, safety_factor=1.0, max_step=h, allow_unstable_safety_factor=True)
    F = 5.0
    p = np.array([[-F, 0, 0], [F, 0, 0]])
    # Equilibrium: stretch F/k (check: zero net force there).
    x_eq = c.positions + np.array([[-F / k * m2 / (m1 + m2), 0, 0], [F / k * m1 / (m1 + m2), 0, 0]])
    np.testing.assert_allclose(sim.internal_forces(x_eq), p, atol=1e-10)
    sim.reset(x_eq + np.array([[0.0, 0, 0], [1e-3, 0, 0]]))
    stretch = []
    for _ in range(3000):
        sim.advance(h, p)
        stretch.append(separation(sim.positions) - L - F / k)
    y = np.array(stretch)
    assert y.min() < -9e-4 and y.max() > 9e-4 and np.all(sim.tension > 0)
    # A sampled sinusoid satisfies y[n+1] + y[n-1] = 2 cos(theta) y[n], with theta = omega_h h.
    cos_theta = np.dot(y[1:-1], y[2:] + y[:-2]) / (2 * np.dot(y[1:-1], y[1:-1]))
    omega_h = 2 / h * math.asin(omega * h / 2)
    assert math.acos(cos_theta) / h == pytest.approx(omega_h, rel=1e-9)
    assert abs(math.acos(cos_theta) / h / omega - 1) > 0.04


def test_slack_taut_bounce_matches_the_closed_form() -> None:
    m1, m2, EA, L0, v0 = 10.0, 30.0, 5e4, 100.0, 0.5
    k, mu = EA / L0, m1 * m2 / (m1 + m2)
    c = pair(m1, m2, L0 - 0.1, EA, L0=L0)
    sim = tg.Simulator(c, safety_factor=0.05)
    sim.reset(velocities=[[-v0 * m2 / (m1 + m2), 0, 0], [v0 * m1 / (m1 + m2), 0, 0]])
    dt = 2e-4
    times, tension, relative_speed = [], [], []
    while sim.time < 1.5:
        sim.advance(dt)
        times.append(sim.time)
        tension.append(sim.tension[0])
        relative_speed.append(sim.velocities[1, 0] - sim.velocities[0, 0])
    tension_arr = np.array(tension)
    taut = np.flatnonzero(tension_arr > 0)
    assert taut.size and taut[-1] < len(times) - 1  # one taut phase, over before the end
    taut_duration = (taut[-1] - taut[0] + 1) * dt
    assert taut_duration == pytest.approx(math.pi / math.sqrt(k / mu), abs=2 * dt)
    assert tension_arr.max() == pytest.approx(v0 * math.sqrt(k * mu), rel=2e-3)
    assert relative_speed[-1] == pytest.approx(-v0, rel=1e-3)


def test_spinning_pair_equilibrium_and_radial_frequency() -> None:
    m, EA, L0, N0, W = 10.0, 5e4, 100.0, 1.0, 0.5
    k, mu = EA / L0, m / 2
    L_eq = (k * L0 - N0) / (k - mu * W**2)
    c = pair(m, m, L0, EA, N0=N0)

    def spin_state(length: float) -> tuple[np.ndarray, np.ndarray]:
        x = np.array([[-length / 2, 0, 0], [length / 2, 0, 0]])
        v = np.array([[0, -W * L_eq / 2, 0], [0, W * L_eq / 2, 0]]) * (L_eq / length)  # same angular momentum
        return x, v

    sim = tg.Simulator(c, safety_factor=0.05)
    sim.reset(*spin_state(L_eq))
    for _ in range(100):
        sim.advance(0.1)
        assert separation(sim.positions) == pytest.approx(L_eq, rel=1e-7)  # O(h^2) orbit error
    assert sim.tension[0] == pytest.approx(mu * W**2 * L_eq, rel=1e-6)

    sim.reset(*spin_state(L_eq + 0.01))
    dt, lengths = 0.01, []
    for _ in range(6000):
        sim.advance(dt)
        lengths.append(separation(sim.positions))
    y = np.array(lengths) - np.mean(lengths)
    up = np.flatnonzero((y[:-1] < 0) & (y[1:] >= 0))
    crossing = (up + (-y[up] / (y[up + 1] - y[up]))) * dt
    omega_measured = 2 * math.pi / np.mean(np.diff(crossing))
    omega_r = math.sqrt(k / mu + 3 * W**2)
    h = sim.batch.safety_factor * sim.critical_time_step()
    assert h == pytest.approx(dt)  # one sub-step per interval, so the dispersion below is exact
    omega_r_discrete = 2 / h * math.asin(omega_r * h / 2)
    assert omega_measured == pytest.approx(omega_r_discrete, rel=3e-5)
    assert abs(omega_measured / (2 / h * math.asin(math.sqrt(k / mu) * h / 2)) - 1) > 3e-3  # spin term resolved


def max_energy_error(step: float) -> float:
    """Largest |E(t) - E0| of an undamped, always-taut tetrahedron over 20 s at a fixed step, J."""
    c = tg.make_cluster("tetrahedron", N0=20.0, damping_rate=0.0)
    sim = tg.Simulator(c, safety_factor=1.0, max_step=step, allow_unstable_safety_factor=True)
    bias = sim.internal_forces(c.positions)
    x0, v0 = tetrahedron_ics(c, np.random.default_rng(3), 0.004, 0.02)
    sim.reset(x0, v0)
    worst = 0.0
    for _ in range(200):
        sim.advance(0.1, bias)
        assert not sim.slack.any()
        worst = max(worst, abs(sim.energy().residual))
    return worst


def test_undamped_energy_error_is_second_order() -> None:
    errors = [max_energy_error(0.1 / steps) for steps in (2, 4, 8)]
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert np.all((ratios > 3.5) & (ratios < 4.7)), (errors, ratios)


def momenta(sim: tg.Simulator) -> tuple[np.ndarray, np.ndarray]:
    m = sim.cluster.masses[:, None]
    return (m * sim.velocities).sum(axis=0), np.cross(sim.positions, m * sim.velocities).sum(axis=0)


def test_momentum_is_conserved_to_round_off_without_damping() -> None:
    c = tg.make_cluster("octahedron", damping_rate=0.0)
    sim = tg.Simulator(c)
    x0, v0 = tetrahedron_ics(c, np.random.default_rng(4), 1.0, 1.0)
    sim.reset(x0, v0)
    P0, J0 = momenta(sim)
    slack = 0
    for _ in range(300):
        sim.advance(0.1)
        slack += sim.slack.sum()
        P, J = momenta(sim)
        np.testing.assert_allclose(P, P0, rtol=0, atol=1e-11)
        np.testing.assert_allclose(J, J0, rtol=0, atol=1e-8)
    assert slack > 0


def test_momentum_decays_exponentially_with_mass_proportional_damping() -> None:
    alpha = 0.4
    c = tg.make_cluster("tetrahedron", damping_rate=alpha)
    sim = tg.Simulator(c)
    x0, v0 = tetrahedron_ics(c, np.random.default_rng(5), 0.5, 1.0)
    v0 += np.array([0.3, -0.2, 0.1])  # rigid drift
    sim.reset(x0, v0)
    P0, _ = momenta(sim)
    for _ in range(50):
        sim.advance(0.1)
        P, _ = momenta(sim)
        np.testing.assert_allclose(P, P0 * math.exp(-alpha * sim.time), rtol=1e-4)


@pytest.mark.parametrize("zeta", [0.0, 0.5, 2.0, 10.0])
def test_centred_damping_keeps_the_undamped_stability_limit(zeta: float) -> None:
    """Damping on the centred velocity leaves the limit at omega h = 2, however heavy it is.

    Lagged damping would cut the limit to (sqrt(1 + zeta^2) - zeta) 2/omega, i.e. below the step
    used here for zeta >= 0.5, and the run would blow up.
    """
    m, EA, L = 10.0, 5e4, 100.0
    k = EA / L
    omega = math.sqrt(2 * k / m)
    c_node = 2 * zeta * omega * m / 2  # relative-motion damping ratio zeta
    c = pair(m, m, L, EA, N0=50.0, damping=c_node)
    sim = tg.Simulator(c, safety_factor=0.98, allow_unstable_safety_factor=True)
    bias = sim.internal_forces(c.positions)
    sim.reset(c.positions + np.array([[0, 0, 0], [0.05, 0, 0]]))
    start = sim.energy().strain
    for _ in range(200):
        sim.advance(0.1, bias)
    assert np.all(np.abs(sim.positions - c.positions) < 0.06)
    assert sim.energy().strain <= start + 1e-9


def test_interval_ends_exactly_and_sub_steps_follow_the_critical_step() -> None:
    soft = tg.Simulator(tg.make_cluster("tetrahedron", EA=2e4))
    stiff = tg.Simulator(tg.make_cluster("tetrahedron", EA=8e4))
    counts = []
    for sim in (soft, stiff):
        sim.reset(velocities=np.full((4, 3), 0.1))
        for _ in range(7):
            stats = sim.advance(0.1, record_steps=64)
        counts.append(int(stats.substeps[0]))
        sizes = stats.step_sizes[0, : stats.substeps[0]]
        assert sizes.sum() == pytest.approx(0.1, rel=1e-14)
        assert sizes.max() <= sim.batch.safety_factor * sim.critical_time_step() * (1 + 1e-9)
        assert sim.time == pytest.approx(0.7, rel=1e-15)
    assert counts[1] >= 2 * counts[0] - 1  # 4x stiffer: about 2x more sub-steps


def test_batched_equals_one_by_one_to_the_bit() -> None:
    rng = np.random.default_rng(6)
    base = tg.make_cluster("hub")
    clusters = [
        base.replace(masses=base.masses * rng.uniform(0.5, 2.0, base.num_nodes), EA=base.EA * rng.uniform(0.5, 2.0))
        for _ in range(20)
    ]
    x0 = np.stack([c.positions + rng.normal(0, 1.0, c.positions.shape) for c in clusters])
    v0 = rng.normal(0, 1.0, x0.shape)
    forces = rng.normal(0, 0.5, (30,) + x0.shape)
    batch = tg.BatchSimulator(clusters)  # B = 20 uses the multi-threaded kernel
    batch.reset(x0, v0)
    singles = [tg.Simulator(c) for c in clusters]
    for b, sim in enumerate(singles):
        sim.reset(x0[b], v0[b])
    for p in forces:
        stats = batch.advance(0.1, p)
        for b, sim in enumerate(singles):
            single_stats = sim.advance(0.1, p[b])
            assert single_stats.substeps[0] == stats.substeps[b]
    for b, sim in enumerate(singles):
        assert np.array_equal(sim.positions, batch.positions[b])
        assert np.array_equal(sim.velocities, batch.velocities[b])
        assert sim.energy().residual == batch.energy().residual[b]
    # Same inputs, same bits: a second batch run reproduces the first.
    again = tg.BatchSimulator(clusters)
    again.reset(x0, v0)
    for p in forces:
        again.advance(0.1, p)
    assert np.array_equal(again.positions, batch.positions)


def test_a_diverging_cluster_is_frozen_and_flagged_without_disturbing_the_batch() -> None:
    c = tg.make_cluster("triangle")
    x0 = np.stack([c.positions] * 3)
    v0 = np.zeros_like(x0)
    v0[:, 0, 0] = 0.5
    batch = tg.BatchSimulator(c, 3)
    batch.reset(x0, v0)
    # Validated inputs cannot overflow any more (reset refuses speeds past tether_gym.limits), so
    # cluster 1's state is poisoned directly: it overflows within the first sub-step.
    batch._v_half[1] = 1e307
    alone = tg.BatchSimulator(c, 1)
    alone.reset(x0[:1], v0[:1])
    stats = batch.advance(0.1)
    alone.advance(0.1)
    assert stats.status.tolist() == [0, 1, 0] and stats.diverged.tolist() == [False, True, False]
    frozen = batch.positions[1].copy()
    for _ in range(5):
        stats = batch.advance(0.1)
        alone.advance(0.1)
        assert stats.substeps[1] == 0 and stats.status[1] == 1
    assert np.array_equal(batch.positions[1], frozen, equal_nan=True)
    assert np.array_equal(batch.positions[0], alone.positions[0])
    assert np.array_equal(batch.positions[2], alone.positions[0])
    batch.reset(x0[1:2], v0[:1], indices=[1])  # a reset revives it
    assert batch.advance(0.1).status.tolist() == [0, 0, 0]


def test_sub_step_limit_flags_the_cluster_before_it_steps() -> None:
    batch = tg.BatchSimulator(tg.make_cluster("triangle"), 2, max_substeps=50)
    batch.reset(batch.positions + 0.01)
    before = (batch.positions.copy(), batch.velocities.copy(), batch.time.copy())
    stats = batch.advance(6.0)  # needs about 215 sub-steps
    assert stats.status.tolist() == [2, 2] and stats.substeps.tolist() == [0, 0]
    assert all(
        np.array_equal(a, b) for a, b in zip(before, (batch.positions, batch.velocities, batch.time), strict=True)
    )
    # Not frozen: the refusal left the clusters as they were, and a shorter interval goes through.
    stats = batch.advance(0.1)
    assert stats.status.tolist() == [0, 0] and (stats.substeps > 0).all()


@pytest.mark.parametrize("duration", [1e6, 1e300, np.finfo(float).max])
def test_durations_beyond_the_sub_step_budget_never_take_a_giant_step(duration: float) -> None:
    """The sub-step count once overflowed its integer for huge durations, and the cluster took
    the whole duration in one step; now it is flagged and left untouched."""
    sim = tg.Simulator(tg.make_cluster("triangle"))
    sim.reset(sim.cluster.positions + 0.01)
    x = sim.positions.copy()
    with pytest.raises(tg.SimulationDiverged, match="max_substeps"):
        sim.advance(duration)
    assert np.array_equal(sim.positions, x) and sim.time == 0.0


def test_single_simulator_raises_on_divergence() -> None:
    sim = tg.Simulator(tg.make_cluster("triangle"), max_substeps=10)
    with pytest.raises(tg.SimulationDiverged, match="max_substeps=10"):
        sim.advance(5.0)


def test_linearised_elongation_strains_cables_under_rigid_rotation() -> None:
    c = tg.make_cluster("triangle", N0=1.0)
    angle = math.radians(30)
    rotation = np.array([[math.cos(angle), -math.sin(angle), 0], [math.sin(angle), math.cos(angle), 0], [0, 0, 1]])
    rotated = c.positions @ rotation.T
    exact = tg.Simulator(c)
    linearised = tg.Simulator(c, elongation="linearised")
    exact.reset(rotated)
    linearised.reset(rotated)
    np.testing.assert_allclose(exact.tension, 1.0, rtol=1e-9)
    expected = 1.0 + c.stiffness * c.L0 * (1 - math.cos(angle))  # dL = L - L0 cos(angle)
    np.testing.assert_allclose(linearised.tension, expected, rtol=1e-9)
    # At the nominal configuration both models agree.
    exact.reset()
    linearised.reset()
    np.testing.assert_array_equal(exact.tension, linearised.tension)


def test_energy_report_at_reset_and_strain_energy_formula() -> None:
    c = pair(N0=2.0)
    sim = tg.Simulator(c)
    sim.reset(c.positions + np.array([[0, 0, 0], [0.1, 0, 0]]), np.array([[1.0, 0, 0], [0, 2.0, 0]]))
    report = sim.energy()
    k = c.stiffness[0]
    assert report.strain == pytest.approx((2.0 + k * 0.1) ** 2 / (2 * k))
    assert report.kinetic == pytest.approx(0.5 * 10 * 1 + 0.5 * 30 * 4)
    assert report.residual == 0.0 and report.work == 0.0 and report.dissipated == 0.0


def worst_energy_balance_residual(**step_options: float) -> float:
    """Largest |residual| / E0 over 10 s of a damped, randomly forced tetrahedron with slack."""
    c = tg.make_cluster("tetrahedron", damping_rate=0.5)
    sim = tg.Simulator(c, **step_options)
    rng = np.random.default_rng(7)
    x0, v0 = tetrahedron_ics(c, rng, 0.5, 1.0)
    sim.reset(x0, v0)
    bias = sim.internal_forces(c.positions)
    worst, slack = 0.0, 0
    for _ in range(100):
        sim.advance(0.1, bias + rng.normal(0, 0.5, (4, 3)))
        slack += sim.slack.sum()
        report = sim.energy()
        worst = max(worst, abs(report.residual) / report.initial)
    assert report.work != 0.0 and report.dissipated > 0.5 * report.initial and slack > 0
    return worst


def test_work_and_dissipation_close_the_energy_balance_at_second_order() -> None:
    residuals = [
        worst_energy_balance_residual(safety_factor=1.0, max_step=0.1 / n, allow_unstable_safety_factor=True)
        for n in (4, 8, 16)
    ]
    ratios = np.array(residuals[:-1]) / np.array(residuals[1:])
    assert np.all((ratios > 3.0) & (ratios < 5.0)), (residuals, ratios)
    assert worst_energy_balance_residual() < 5e-3  # default safety factor


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda s: s.advance(0.0), "duration must be a finite number of seconds > 0"),
        (lambda s: s.advance(-1.0), "duration must be"),
        (lambda s: s.advance(float("nan")), "duration must be"),
        (lambda s: s.advance("soon"), "duration must be a finite number of seconds"),
        (lambda s: s.advance(0.1, np.zeros((3, 3))), r"force must have shape \(4, 3\)"),
        (lambda s: s.advance(0.1, np.full((4, 3), np.nan)), "force contains NaN"),
        (lambda s: s.advance(0.1, np.full((4, 3), 1e13)), r"force must lie in \[0, 1e\+12\] N"),
        (lambda s: s.advance(0.1, [["a"] * 3] * 4), "force must be made of real numbers"),
        (lambda s: s.advance(0.1, record_steps=-1), "record_steps must be a whole number"),
        (lambda s: s.advance(True), "duration must be a finite number"),
        (lambda s: s.reset(velocities=np.full((4, 3), 1e7)), r"velocities must lie in \[0, 1e\+06\] m/s"),
        (
            lambda s: s.critical_time_step("finite-difference") and s.batch.element_omega2_finite_difference(0.0),
            "relative_perturbation must lie in",
        ),
        (lambda s: s.reset(np.zeros((4, 2))), r"positions must have shape \(4, 3\)"),
        (lambda s: s.reset(velocities=np.full((4, 3), np.inf)), "velocities contains an infinite value"),
        (lambda s: s.reset(np.zeros((4, 3))), "zero-length cable"),
        (lambda s: s.critical_time_step("magic"), "method must be"),
    ],
)
def test_bad_simulator_input_gets_a_clear_error(call, message: str) -> None:
    sim = tg.Simulator(tg.make_cluster("tetrahedron"))
    with pytest.raises(ValueError, match=message):
        call(sim)


def test_bad_simulator_arguments() -> None:
    c = tg.make_cluster("tetrahedron")
    with pytest.raises(ValueError, match=r"safety_factor \(a fraction of the critical step\) must lie in \(0, 1\]"):
        tg.Simulator(c, safety_factor=1.5)
    with pytest.raises(ValueError, match="elongation must be"):
        tg.Simulator(c, elongation="small")
    with pytest.raises(TypeError, match="Simulator takes a Cluster"):
        tg.Simulator("tetrahedron")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="different topology"):
        tg.BatchSimulator([c, tg.make_cluster("triangle")])
    with pytest.raises(ValueError, match="num_clusters must be a whole number"):
        tg.BatchSimulator(c, 0)
    batch = tg.BatchSimulator(c, 2)
    with pytest.raises(ValueError, match="cluster indices must be in 0..1"):
        batch.reset(c.positions[None], indices=[2])
    with pytest.raises(ValueError, match="active must be a boolean array"):
        batch.advance(0.1, active=[1, 0])
    with pytest.raises(ValueError, match="safety_factor"):
        tg.Simulator(c, safety_factor="small")
    with pytest.raises(ValueError, match="max_substeps must be a whole number"):
        tg.Simulator(c, max_substeps=10**30)
    with pytest.raises(ValueError, match="num_clusters must be a whole number"):
        tg.BatchSimulator(c, True)


def test_refused_updates_leave_the_batch_unchanged() -> None:
    """Validate first, then change state: a refused call must not half-apply."""
    c = tg.make_cluster("tetrahedron")
    batch = tg.BatchSimulator(c, 3)
    batch.reset(np.stack([c.positions + 0.01 * k for k in range(3)]))
    batch.advance(0.3)
    snapshot = {
        name: np.copy(getattr(batch, name)) for name in vars(batch) if isinstance(getattr(batch, name), np.ndarray)
    }
    clusters = list(batch.clusters)
    other = c.replace(masses=20.0)
    for call in (
        lambda: batch.set_cluster(3, other),
        lambda: batch.set_cluster(-1, other),
        lambda: batch.set_cluster(0, "tetrahedron"),  # type: ignore[arg-type]
        lambda: batch.set_cluster(0, tg.make_cluster("triangle")),
        lambda: batch.reset(np.stack([c.positions, c.positions, np.zeros((4, 3))])),  # third has zero-length cables
        lambda: batch.reset(np.stack([c.positions] * 3), np.full((3, 4, 3), 1e9)),
        lambda: batch.advance(0.1, np.full((3, 4, 3), np.inf)),
    ):
        with pytest.raises((ValueError, TypeError)):
            call()
        assert batch.clusters == clusters
        for name, value in snapshot.items():
            assert np.array_equal(getattr(batch, name), value, equal_nan=True), name


@pytest.mark.parametrize("safety_factor", [0.05, 0.2, 0.7])
def test_every_force_switch_delivers_its_exact_impulse(safety_factor: float) -> None:
    """Zero-order hold: a thrust held for an interval gives exactly force x duration of momentum.

    A slack cable (L0 longer than the satellites' separation) leaves the satellites free, so the
    velocity after a sequence of thrust pulses has a closed form, whatever the sub-steps.
    """
    c = tg.Cluster(positions=[[0, 0, 0], [100, 0, 0]], masses=[10.0, 4.0], cables=[(0, 1)], EA=1e3, L0=300.0)
    sim = tg.Simulator(c, safety_factor=safety_factor, allow_unstable_safety_factor=True)
    pulses = [(0.1, 1.0), (0.07, 0.0), (0.1, -2.5), (0.3, 0.5), (0.1, 0.0)]
    expected = 0.0
    for duration, thrust in pulses:
        sim.advance(duration, [[thrust, 0, 0], [0, 0, 0]])
        expected += thrust * duration / 10.0
        assert sim.velocities[0, 0] == pytest.approx(expected, rel=1e-12, abs=1e-15)
    assert sim.slack.all()


def test_internal_forces_of_selected_clusters_use_their_own_parameters() -> None:
    base = tg.make_cluster("triangle")
    clusters = [base, base.replace(EA=base.EA * 3), base.replace(N0=5.0)]
    batch = tg.BatchSimulator(clusters)
    x = np.stack([c.positions * 1.001 for c in clusters])
    everything = batch.internal_forces(x)
    chosen = batch.internal_forces(x[[2, 1]], indices=[2, 1])
    assert np.array_equal(chosen, everything[[2, 1]])
    assert not np.allclose(everything[0], everything[1])


@pytest.mark.parametrize("damping", [0.5, 10.0, 1e3])
def test_heavily_damped_free_masses_follow_the_exact_exponential_decay(damping: float) -> None:
    """Free masses with diagonal damping: ``v(t) = v0 exp(-c t / m)`` and
    ``x(t) = x0 + v0 (m / c) (1 - exp(-c t / m))``.

    The one cable is slack and so soft (EA = 1 uN, L0 = 1 km between satellites 10 m apart) that
    it limits the step to over an hour: only the damping time scale m/c does.  Stepped past
    2 m/c, the centred update would reverse the velocities; the sub-step respects
    ``safety_factor * 2 m/c`` instead, so they decay monotonically, to second-order accuracy.
    """
    masses = np.array([1.0, 3.0])
    c = tg.Cluster(
        positions=[[0, 0, 0], [10, 0, 0]], masses=masses, cables=[(0, 1)], EA=1e-6, L0=1e3, damping=damping * masses
    )  # c/m = damping for both
    v0 = np.array([[0.3, -0.2, 0.1], [-0.1, 0.05, 0.2]])
    interval = 1.0 / damping  # ten intervals span ten time constants
    errors = []
    for safety in (0.1, 0.05):
        sim = tg.Simulator(c, safety_factor=safety)
        sim.reset(velocities=v0)
        previous = v0.copy()
        worst = 0.0
        for k in range(1, 11):
            stats = sim.advance(interval)
            assert stats.step_max[0] <= safety * 2.0 / damping * (1 + 1e-12)
            t = k * interval
            decay = math.exp(-damping * t)
            assert np.all(np.sign(sim.velocities) == np.sign(v0)) and np.all(np.abs(sim.velocities) < np.abs(previous))
            previous = sim.velocities.copy()
            exact_v = v0 * decay
            exact_x = c.positions + v0 / damping * (1.0 - decay)
            worst = max(worst, float(np.abs(sim.velocities - exact_v).max() / np.abs(v0).max()))
            assert np.allclose(sim.positions, exact_x, rtol=0, atol=0.01 * np.abs(v0).max() / damping)
        errors.append(worst)
    assert errors[0] < 0.01
    assert 3.0 < errors[0] / errors[1] < 5.0, errors  # second order in the step


def test_damping_never_reverses_a_velocity_once_every_cable_broke() -> None:
    """With every cable broken nothing limits the step but the damping time scale."""
    c = tg.Cluster(
        positions=[[0, 0, 0], [10, 0, 0]], masses=1.0, cables=[(0, 1)], EA=1e4, L0=9.9, breaking_load=1e-3, damping=50.0
    )
    sim = tg.Simulator(c)
    sim.reset(velocities=[[1.0, 0, 0], [0, 1.0, 0]])
    sim.advance(0.01)
    assert sim.batch.broken.all()
    for _ in range(20):
        before = sim.velocities.copy()
        sim.advance(1.0)
        moving = before != 0.0
        assert np.all(np.sign(sim.velocities[moving]) == np.sign(before[moving]))
