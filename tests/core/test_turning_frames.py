"""Closed-form checks of the turning frames, the Kelvin-Voigt cables and cable breaking."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg
from scipy.integrate import solve_ivp

import tether_gym as tg
from tether_gym import Cluster, Frame
from tether_gym.simulator import BatchSimulator

#: Some checks run the scheme at its linear limit (safety factor up to 1, the step set by max_step)
#: on purpose: the opt-in warns, which is expected here.
pytestmark = pytest.mark.filterwarnings("ignore::tether_gym.simulator.UnstableSafetyFactorWarning")


def pair(frame: Frame, length: float = 100.0, masses: tuple[float, float] = (10.0, 30.0), **fields: object) -> Cluster:
    """Two satellites on the x axis, centre of mass at the origin."""
    m1, m2 = masses
    x1 = -length * m2 / (m1 + m2)
    positions = [[x1, 0.0, 0.0], [x1 + length, 0.0, 0.0]]
    return Cluster(positions=positions, masses=list(masses), cables=[(0, 1)], frame=frame, **fields)


def test_radial_pair_settles_at_the_gravity_gradient_tension() -> None:
    n = 0.01  # rad/s: a fast "orbit" keeps the test short; the law is the same at LEO rates
    # Cable damping only: diagonal damping relative to the Hill frame destabilises the centre of
    # mass (next test).
    cluster = pair(Frame.hill(n), EA=2e3, N0=0.0, axial_damping=20.0)
    sim = tg.Simulator(cluster)
    assert sim.tension[0] == 0.0  # it starts unstretched
    for _ in range(300):
        sim.advance(1.0)
    mu = 10.0 * 30.0 / 40.0
    length = float(np.linalg.norm(sim.positions[1] - sim.positions[0]))
    # The axial ringing has died out (e-folding 0.75 s); what is left is a libration of 1e-4 m/s
    # excited by the Coriolis force while the cable stretched, which shifts the tension by 1e-4.
    assert np.abs(sim.velocities).max() < 1e-3
    assert sim.tension[0] == pytest.approx(3 * n**2 * mu * length, rel=1e-3)


def test_damping_relative_to_the_hill_frame_destabilises_the_centre_of_mass() -> None:
    """Kelvin-Tait-Chetaev: the radial direction is unstable in the tidal potential and held only
    gyroscopically; dissipation relative to the frame undoes that.  The centre of mass must
    follow the damped HCW equations exactly (matrix exponential of the linear system)."""
    n, alpha = 0.01, 0.05
    masses = np.array([10.0, 30.0])
    cluster = Cluster(
        positions=[[-7.5, 0.0, 0.0], [2.5, 0.0, 0.0]],
        masses=masses,
        cables=[(0, 1)],
        EA=1e3,
        N0=0.0,
        damping=alpha * masses,
        frame=Frame.hill(n),
    )  # centre of mass at the origin
    A = np.array([[0, 0, 1, 0], [0, 0, 0, 1], [3 * n**2, 0, -alpha, 2 * n], [0, 0, -2 * n, -alpha]])
    growth = np.linalg.eigvals(A).real.max()
    assert growth > 0
    sim = tg.Simulator(cluster, max_step=0.05)
    start = cluster.positions + [1.0, 0.0, 0.0]
    sim.reset(start)
    state0 = np.array([1.0, 0.0, 0.0, 0.0])  # the centre of mass: x, y, x', y'
    com = lambda x: (masses[:, None] * x).sum(axis=0) / masses.sum()  # noqa: E731
    for k in range(1, 11):
        sim.advance(100.0)
        exact = scipy.linalg.expm(A * 100.0 * k) @ state0
        np.testing.assert_allclose(com(sim.positions)[:2], exact[:2], rtol=0, atol=2e-4 * np.abs(exact[:2]).max())
    assert np.abs(exact[:2]).max() > 2.0  # it grew


def test_radial_chain_preset_is_held_by_the_gravity_gradient() -> None:
    cluster = tg.make_cluster("radial_chain", n=2, spacing=400.0, mass=20.0)
    n = tg.LEO_ORBIT_RATE
    assert cluster.N0[0] == pytest.approx(3 * n**2 * 10.0 * 400.0, rel=1e-12)
    sim = BatchSimulator(cluster, 1)
    assert np.abs(sim.equilibrium_force(cluster.positions[None])).max() < 1e-12 * cluster.N0[0]
    three = tg.make_cluster("radial_chain")  # outer masses pull 3 n^2 m L each
    assert three.N0 == pytest.approx([3 * n**2 * 50.0 * 500.0] * 2, rel=1e-12)


def hcw(n: float, x0: np.ndarray, v0: np.ndarray, t: float) -> np.ndarray:
    """Closed-form Clohessy-Wiltshire position at time t (x radial, y along-track, z normal)."""
    s, c = math.sin(n * t), math.cos(n * t)
    x, y, z = x0
    vx, vy, vz = v0
    return np.array(
        [
            (4 - 3 * c) * x + s / n * vx + 2 / n * (1 - c) * vy,
            6 * (s - n * t) * x + y - 2 / n * (1 - c) * vx + (4 * s - 3 * n * t) / n * vy,
            c * z + s / n * vz,
        ]
    )


def test_free_motion_in_the_hill_frame_follows_the_hcw_solution_at_second_order() -> None:
    n = 0.01
    x0 = np.array([[3.0, -2.0, 1.0], [-4.0, 5.0, -2.0]])
    v0 = np.array([[0.02, -0.05, 0.03], [-0.01, 0.04, -0.02]])
    # A cable far longer than the satellites ever get apart: always slack, so both move freely.
    cluster = Cluster(positions=x0, masses=[5.0, 8.0], cables=[(0, 1)], EA=1.0, L0=1e3, frame=Frame.hill(n))
    errors = []
    for max_step in (2.0, 1.0, 0.5):
        sim = tg.Simulator(cluster, max_step=max_step)
        sim.reset(x0, v0)
        worst = 0.0
        for k in range(1, 7):
            sim.advance(100.0)  # 600 s, about one orbit
            exact = np.stack([hcw(n, x0[i], v0[i], 100.0 * k) for i in range(2)])
            worst = max(worst, float(np.abs(sim.positions - exact).max()))
        assert np.all(sim.tension == 0)
        errors.append(worst)
    ratios = [errors[0] / errors[1], errors[1] / errors[2]]
    assert errors[-1] < 1e-2  # metres, on motions of about 100 m
    assert all(3.5 < r < 4.5 for r in ratios), (errors, ratios)


@pytest.mark.parametrize("spin", [0.05, 0.3])
def test_spinning_pair_equilibrium_and_radial_frequency(spin: float) -> None:
    EA, L0, N0, masses = 5e3, 100.0, 2.0, (10.0, 30.0)
    k, mu = EA / L0, masses[0] * masses[1] / sum(masses)
    length = (k * L0 - N0) / (k - mu * spin**2)
    cluster = pair(Frame.rotating(spin), length=length, masses=masses, EA=EA, L0=L0, N0=N0)
    sim = tg.Simulator(cluster, max_step=0.002)
    assert np.abs(sim.batch.equilibrium_force(cluster.positions[None])).max() < 1e-12 * k * L0
    assert sim.tension[0] == pytest.approx(mu * spin**2 * length, rel=1e-12)
    sim.advance(20.0)
    assert np.abs(sim.positions - cluster.positions).max() < 1e-9
    # A small radial stretch oscillates at omega_r^2 = k / mu + 3 W^2 (Coriolis couples the
    # tangential motion in).  Find the period from the zero crossings of L - L_eq.
    stretched = cluster.positions * (1 + 1e-4)
    sim.reset(stretched)
    times, offsets = [], []
    for _ in range(6000):
        sim.advance(0.002)
        times.append(sim.time)
        offsets.append(float(np.linalg.norm(sim.positions[1] - sim.positions[0])) - length)
    y, t = np.array(offsets), np.array(times)
    up = np.flatnonzero((y[:-1] < 0) & (y[1:] >= 0))  # upward crossings: immune to a shifted mean
    crossings = t[up] - y[up] * (t[up + 1] - t[up]) / (y[up + 1] - y[up])
    period = float(np.mean(np.diff(crossings)))
    expected = 2 * math.pi / math.sqrt(k / mu + 3 * spin**2)
    assert period == pytest.approx(expected, rel=5e-5)  # the step's dispersion is 1e-6 here


def test_jacobi_energy_holds_in_a_spinning_frame_with_snapping_cables() -> None:
    cluster = tg.make_cluster("spinning_triangle", axial_damping_ratio=0.0, spin_rate=0.2)
    rng = np.random.default_rng(4)
    residuals = []
    for safety in (0.1, 0.05):
        sim = tg.Simulator(cluster, safety_factor=safety)
        sim.reset(cluster.positions + 0.02 * rng.standard_normal((3, 3)), 0.05 * rng.standard_normal((3, 3)))
        rng = np.random.default_rng(4)
        slack_seen = False
        worst = 0.0
        for _ in range(200):
            sim.advance(0.1)
            slack_seen |= bool(sim.slack.any())
            report = sim.energy()
            worst = max(worst, abs(report.residual))
        assert slack_seen
        scale = abs(sim.energy().initial) + abs(sim.energy().frame_potential)
        residuals.append(worst / scale)
    assert residuals[0] < 1e-3
    assert residuals[1] < residuals[0]


#: Opposite thrusts of 5 N holding a pair with 5 N of pretension at its reference length.
HOLD = np.array([[-5.0, 0.0, 0.0], [5.0, 0.0, 0.0]])


def test_axial_damping_decay_rate_and_its_critical_step() -> None:
    masses, EA, L0, c_ax = (10.0, 30.0), 5e3, 100.0, 15.0
    k, mu = EA / L0, 7.5
    cluster = pair(Frame.inertial(), masses=masses, EA=EA, L0=L0, N0=5.0, axial_damping=c_ax)
    omega = math.sqrt(k / mu)
    xi = c_ax / (2 * mu * omega)
    sim = tg.Simulator(cluster)
    assert sim.critical_time_step() == pytest.approx(2 / omega * (math.sqrt(1 + xi**2) - xi), rel=1e-12)
    # The paper's finite-difference bound (column L1 norms) is conservative for unequal masses.
    assert sim.critical_time_step() * 0.8 < sim.critical_time_step("finite-difference") <= sim.critical_time_step()
    # The stretch follows the damped oscillator mu y'' + c y' + k y = 0 from rest.
    sim = tg.Simulator(cluster, max_step=1e-3)
    y0 = 0.02
    sim.reset(cluster.positions * (1 + y0 / L0))
    decay, damped = c_ax / (2 * mu), omega * math.sqrt(1 - xi**2)
    worst = 0.0
    for _ in range(800):
        sim.advance(0.01, HOLD)
        t = sim.time
        exact = y0 * math.exp(-decay * t) * (math.cos(damped * t) + decay / damped * math.sin(damped * t))
        worst = max(worst, abs(float(np.linalg.norm(sim.positions[1] - sim.positions[0])) - L0 - exact))
        assert sim.tension[0] > 0  # stayed taut: the linear closed form applies
    # The lagged stretching rate costs O(h): 1e-3 s steps against a 2.6 s period.
    assert worst < 2e-3 * y0


def lagged_damping_radius(omega: float, xi: float, h: float) -> float:
    """Spectral radius of u+ = u + h v+, v+ = v + h (-omega^2 u - 2 xi omega v): the explicit scheme
    with the damping force on the lagged velocity, as the integrator treats axial damping."""
    a = -h * omega**2
    b = 1.0 - 2.0 * h * xi * omega
    step = np.array([[1.0 + h * a, h * b], [a, b]])
    return float(np.abs(np.linalg.eigvals(step)).max())


def test_the_lagged_damping_step_correction_is_needed_and_enough() -> None:
    masses, EA, L0 = (10.0, 10.0), 5e3, 100.0
    mu, k = 5.0, EA / L0
    omega = math.sqrt(k / mu)
    xi = 0.5
    c_ax = 2 * xi * mu * omega
    limit = 2 / omega * (math.sqrt(1 + xi**2) - xi)
    assert lagged_damping_radius(omega, xi, 0.98 * 2 / omega) > 1.05  # undamped limit: unstable
    assert lagged_damping_radius(omega, xi, 0.98 * limit) < 1.0
    cluster = pair(Frame.inertial(), masses=masses, EA=EA, L0=L0, N0=5.0, axial_damping=c_ax)
    sim = tg.Simulator(cluster, safety_factor=0.98, allow_unstable_safety_factor=True)
    sim.reset(cluster.positions * (1 + 1e-3))
    start = abs(float(np.linalg.norm(sim.positions[1] - sim.positions[0])) - L0)
    for _ in range(50):
        sim.advance(0.5, HOLD)
    assert abs(float(np.linalg.norm(sim.positions[1] - sim.positions[0])) - L0) < 1e-3 * start


def test_a_breaking_cable_stays_broken_and_spares_the_rest_of_the_batch() -> None:
    cluster = tg.make_cluster("triangle", breaking_load=20.0)
    pull = np.zeros((3, 3))
    pull[0] = 30.0 * cluster.positions[0] / np.linalg.norm(cluster.positions[0])  # N, outward
    batch = BatchSimulator([cluster, cluster], safety_factor=0.1)
    alone = tg.Simulator(cluster)
    force = np.stack([pull, np.zeros((3, 3))])
    broke = False
    for _ in range(100):
        stats = batch.advance(0.1, force)
        alone.advance(0.1)
        np.testing.assert_array_equal(batch.positions[1], alone.positions)  # the neighbour is untouched
        if batch.broken[0].any():
            if broke:
                assert np.all(batch.tension[0][batch.broken[0]] == 0)
            broke = True
            assert np.any(stats.peak_tension[0][batch.broken[0]] > 20.0) or np.all(
                batch.tension[0][batch.broken[0]] == 0
            )
    assert broke and not batch.broken[1].any()
    broken_cables = batch.broken[0].copy()
    report = batch.energy()
    assert abs(report.residual[0]) < 1e-3 * report.work[0]  # released strain energy is booked
    assert report.dissipated[0] > 0
    batch.reset(batch.reference)
    assert not batch.broken.any() and broken_cables.any()


def spinning_reference(cluster: Cluster, x0: np.ndarray, v0: np.ndarray, times: np.ndarray) -> np.ndarray:
    """DOP853 (rtol 1e-11) on an independent numpy model of the same physics in the spinning frame:
    tension-only Kelvin-Voigt cables plus the Coriolis and centrifugal accelerations."""
    spin = cluster.frame.rate
    i, j = cluster.cables[:, 0], cluster.cables[:, 1]
    n = cluster.num_nodes

    def rhs(_t: float, y: np.ndarray) -> np.ndarray:
        x, v = y[: 3 * n].reshape(n, 3), y[3 * n :].reshape(n, 3)
        delta = x[j] - x[i]
        length = np.linalg.norm(delta, axis=1)
        e = delta / length[:, None]
        elastic = cluster.N0 + cluster.stiffness * (length - cluster.L0)
        rate = np.einsum("cd,cd->c", v[j] - v[i], e)
        tension = np.where(elastic > 0, np.maximum(elastic + cluster.axial_damping * rate, 0.0), 0.0)
        force = np.zeros((n, 3))
        np.add.at(force, i, tension[:, None] * e)
        np.add.at(force, j, -tension[:, None] * e)
        apparent = np.stack(
            [spin**2 * x[:, 0] + 2 * spin * v[:, 1], spin**2 * x[:, 1] - 2 * spin * v[:, 0], np.zeros(n)], axis=1
        )
        return np.concatenate([v.ravel(), (force / cluster.masses[:, None] + apparent).ravel()])

    solution = solve_ivp(
        rhs,
        (0.0, times[-1]),
        np.concatenate([x0.ravel(), v0.ravel()]),
        method="DOP853",
        t_eval=times,
        rtol=1e-11,
        atol=1e-11,
    )
    assert solution.success
    return solution.y[: 3 * n].T.reshape(-1, n, 3)


def test_spinning_triangle_matches_a_dop853_reference() -> None:
    cluster = tg.make_cluster("spinning_triangle", spin_rate=0.3)  # 27 N of centrifugal tension
    rng = np.random.default_rng(11)
    x0 = cluster.positions + rng.normal(0.0, 0.05, (3, 3))
    v0 = rng.normal(0.0, 0.5, (3, 3))
    interval = 0.02
    times = interval * np.arange(1, 251)
    reference = spinning_reference(cluster, x0, v0, times)
    scale = np.abs(reference - cluster.positions).max()
    errors = []
    for safety in (0.1, 0.05, 0.025):
        sim = tg.Simulator(cluster, safety_factor=safety)
        sim.reset(x0, v0)
        worst, slack_steps = 0.0, 0
        for x_ref in reference:
            sim.advance(interval)
            worst = max(worst, float(np.abs(sim.positions - x_ref).max()))
            slack_steps += int(sim.slack.any())
        assert slack_steps > 20  # cables go slack and snap taut during the comparison
        errors.append(worst / scale)
    assert errors[0] < 0.01, errors  # within 1 % of the displacement scale at the default step
    assert errors[1] < 0.6 * errors[0] and errors[2] < 0.6 * errors[1], errors
