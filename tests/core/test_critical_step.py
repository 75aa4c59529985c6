"""The critical-step estimate (paper, section 4) against the true largest frequency."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import tether_gym as tg
from tether_gym.analysis import max_frequency, normal_modes, tangent_stiffness


def random_cluster(seed: int, n: int, extra_cable_probability: float) -> tuple[tg.Cluster, np.ndarray]:
    """A random connected cluster (mass ratios up to 1:100, slack and taut cables) and a perturbed
    configuration of it."""
    rng = np.random.default_rng(seed)
    while True:
        positions = rng.uniform(-50.0, 50.0, (n, 3))
        gaps = np.linalg.norm(positions[:, None] - positions[None], axis=-1) + 1e9 * np.eye(n)
        if gaps.min() > 5.0:
            break
    cables = {(int(rng.integers(k)), k) for k in range(1, n)}  # a random spanning tree
    cables |= {(i, j) for i in range(n) for j in range(i + 1, n) if rng.random() < extra_cable_probability}
    cables_list = sorted(cables)
    lengths = np.array([np.linalg.norm(positions[j] - positions[i]) for i, j in cables_list])
    cluster = tg.Cluster(
        positions=positions,
        masses=10.0 ** rng.uniform(0.0, 2.0, n),
        cables=cables_list,
        EA=10.0 ** rng.uniform(3.0, 5.0, len(cables_list)),
        N0=rng.uniform(0.0, 50.0, len(cables_list)) * (rng.random(len(cables_list)) < 0.5),
        L0=lengths * rng.uniform(0.97, 1.03, len(cables_list)),
    )
    return cluster, positions + rng.normal(0.0, 1.0, positions.shape)


def estimates(cluster: tg.Cluster, x: np.ndarray) -> tuple[float, float]:
    sim = tg.Simulator(cluster)
    sim.reset(x)
    return sim.critical_time_step("closed-form"), sim.critical_time_step("finite-difference")


@settings(max_examples=150, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(2, 8), extra=st.floats(0.0, 0.8))
def test_estimate_never_exceeds_the_true_critical_step(seed: int, n: int, extra: float) -> None:
    cluster, x = random_cluster(seed, n, extra)
    closed_form, finite_difference = estimates(cluster, x)
    true_taut = 2.0 / max_frequency(cluster, x, taut_branch=True)
    actual_omega = max_frequency(cluster, x, taut_branch=False)
    assert closed_form <= true_taut * (1 + 1e-9)
    assert actual_omega == 0.0 or closed_form <= 2.0 / actual_omega * (1 + 1e-9)
    # The paper's column-L1 reference bounds the same element eigenvalue from above.
    assert finite_difference <= closed_form * (1 + 1e-6)


def test_estimate_is_not_wastefully_small() -> None:
    """Median estimate / truth over random clusters; docs/verification.md quotes these ratios."""
    ratios_cf, ratios_fd = [], []
    for seed in range(200):
        cluster, x = random_cluster(seed, 2 + seed % 7, 0.4)
        closed_form, finite_difference = estimates(cluster, x)
        true_step = 2.0 / max_frequency(cluster, x, taut_branch=True)
        ratios_cf.append(closed_form / true_step)
        ratios_fd.append(finite_difference / true_step)
    assert max(ratios_cf) <= 1 + 1e-9
    assert np.median(ratios_cf) > 0.6 and np.min(ratios_cf) > 0.2
    assert np.median(ratios_fd) > 0.5
    for name in tg.preset_names():
        c = tg.make_cluster(name)
        ratio = estimates(c, c.positions)[0] * max_frequency(c) / 2
        assert 0.6 < ratio <= 1.0, name


def test_tetrahedron_reference_values() -> None:
    """Equal masses, N0 = 0: omega^2 = 0 (x6), k/m (x2), 2k/m (x3), 4k/m; the m/3-split bound is 6k/m."""
    c = tg.make_cluster("tetrahedron", N0=0.0)
    k, m = c.stiffness[0], c.masses[0]
    omega2, modes = normal_modes(c, taut_branch=True)  # N0 = 0: every cable on the verge of slack
    np.testing.assert_allclose(omega2 / (k / m), [0] * 6 + [1, 1, 2, 2, 2, 4], atol=1e-9)
    np.testing.assert_allclose(modes.T @ np.diag(np.repeat(c.masses, 3)) @ modes, np.eye(12), atol=1e-9)
    closed_form, finite_difference = estimates(c, c.positions)
    assert closed_form == pytest.approx(2 / math.sqrt(6 * k / m), rel=1e-12)
    # Column-L1 overestimates a cable's eigenvalue by up to 1.37 depending on its direction.
    assert 1.0 <= (closed_form / finite_difference) ** 2 <= 1.37
    # The trap the mass split avoids: full node masses per cable give a step twice too large.
    omega_full_mass = math.sqrt(k * (1 / m + 1 / m))
    assert 2 / omega_full_mass > 2 / math.sqrt(4 * k / m) * 1.4


def test_closed_form_is_the_exact_element_eigenvalue() -> None:
    """The fast path equals the largest eigenvalue of the finite-difference element matrix."""
    cluster, x = random_cluster(11, 5, 0.5)
    sim = tg.BatchSimulator(cluster, 1)
    sim.reset(x[None])
    split = cluster.masses / cluster.degree
    for c, (i, j) in enumerate(cluster.cables):
        sub = tg.Cluster(
            positions=cluster.positions[[i, j]],
            masses=[split[i], split[j]],
            cables=[(0, 1)],
            EA=cluster.EA[c],
            N0=cluster.N0[c],
            L0=cluster.L0[c],
        )
        element_omega2 = max_frequency(sub, x[[i, j]], taut_branch=True) ** 2
        bound = sim.element_omega2_finite_difference()[0, c]
        assert element_omega2 <= bound * (1 + 1e-6)
        single = tg.Simulator(sub)
        single.reset(x[[i, j]])
        assert (2 / single.critical_time_step()) ** 2 == pytest.approx(element_omega2, rel=1e-9)


def test_slack_cables_still_limit_the_step() -> None:
    c = tg.make_cluster("triangle")
    sim = tg.Simulator(c)
    taut_step = sim.critical_time_step()
    shrunk = c.positions * 0.9  # every cable slack
    sim.reset(shrunk)
    assert sim.slack.all()
    assert np.allclose(tangent_stiffness(c, shrunk), 0.0)
    assert sim.critical_time_step() == pytest.approx(taut_step, rel=1e-12)
    assert math.isfinite(sim.critical_time_step("finite-difference"))


@pytest.mark.parametrize("length", [80.0, 10.0, 0.1])
def test_finite_difference_reference_treats_short_slack_cables_as_just_taut(length: float) -> None:
    """A slack cable far shorter than L0 must not look stiffer than a taut one."""
    c = tg.Cluster(positions=[[0, 0, 0], [100, 0, 0]], masses=[10.0, 10.0], cables=[(0, 1)], EA=5e4, N0=5.0)
    sim = tg.Simulator(c)
    sim.reset([[0, 0, 0], [length, 0, 0]])
    assert sim.slack.all()
    assert sim.critical_time_step("finite-difference") == pytest.approx(sim.critical_time_step(), rel=1e-6)
