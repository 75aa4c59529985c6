"""The roofline (tether_gym.roofline): its microbenchmark measures, and the limit adds up a
cluster's cables and nodes as its operation count says."""

from __future__ import annotations

import math

import numpy as np

import tether_gym as tg
from tether_gym.roofline import RooflineLimits, _cable_mix, measure_limits, substep_limit_ns


def test_the_limit_of_a_sub_step_adds_its_cables_and_nodes() -> None:
    limits = RooflineLimits(cable_ns=1.0, viscous_cable_ns=2.5, node_ns=3.0, simd=4)
    tetrahedron = tg.make_cluster("tetrahedron")
    assert substep_limit_ns(tetrahedron, limits) == 6 * 1.0 + 4 * 3.0
    beaded = tg.make_cluster("beaded_tetrahedron")
    damped = int(np.count_nonzero(beaded.axial_damping > 0))
    expected = (beaded.num_cables - damped) * 1.0 + damped * 2.5 + beaded.num_nodes * 3.0
    assert substep_limit_ns(beaded, limits) == expected


def test_the_microbenchmark_computes_the_cable_law() -> None:
    """One pass of the cable mix gives the tension-only law's tension and force on known cables:
    one stretched by 1 mm (taut) and one shortened by 10 cm (slack)."""
    xi = np.zeros((3, 2))
    xj = np.array([[100.001, 99.9], [0.0, 0.0], [0.0, 0.0]])
    rest, stiffness, pretension = np.full(2, 100.0), np.full(2, 400.0), np.full(2, 5.0)
    inverse_mass, damping = np.full(2, 0.04), np.zeros(2)
    force, tension, omega2 = np.zeros((3, 2)), np.zeros(2), np.zeros(2)
    velocity = np.zeros((3, 2))
    _cable_mix(xi, xj, rest, stiffness, pretension, inverse_mass, velocity, velocity, damping, force, tension, omega2,
               False, 1)  # fmt: skip
    assert math.isclose(tension[0], 5.0 + 400.0 * 0.001, rel_tol=1e-9)
    assert tension[1] == 0.0 and force[0, 1] == 0.0
    assert math.isclose(force[0, 0], tension[0], rel_tol=1e-12)
    assert math.isclose(omega2[0], 400.0 * 0.04, rel_tol=1e-12)  # EA/L0 beats N/L here


def test_measured_limits_are_positive_and_damping_costs_more() -> None:
    limits = measure_limits(seconds=0.05, repeats=2)
    assert 0 < limits.cable_ns < limits.viscous_cable_ns
    assert limits.node_ns > 0 and limits.simd in (1, 2, 4, 8)
