"""Named clusters with physically plausible magnitudes (SI units).

Defaults use realistic magnitudes: small satellites of 5-100 kg, braided
Dyneema-class tethers (EA of tens of kN, breaking loads of 1-2 kN) of 50-100 m, and light
pretension of a fraction of a newton, which low-thrust cold-gas thrusters can hold.  With these
values the critical step is 0.1-0.15 s, so at the default safety factor every 0.1 s control
interval is integrated in several sub-steps.

Every preset is a function of keyword arguments returning a :class:`~tether_gym.Cluster`;
:func:`make_cluster` looks one up by name and passes keyword overrides through.
"""

from __future__ import annotations

import inspect
import math
from collections.abc import Callable

import numpy as np

from tether_gym.cluster import Cluster, ClusterError

__all__ = ["PRESETS", "make_cluster", "preset_names"]


def tetrahedron(
    edge: float = 100.0,
    mass: float = 10.0,
    EA: float = 50e3,
    N0: float = 0.2,
    damping_rate: float = 0.1,
    breaking_load: float = 1500.0,
) -> Cluster:
    """The paper's example: four satellites at the corners of a regular tetrahedron, six cables.

    Args:
        edge: cable length, m.
        mass: mass of each satellite, kg.
        EA: axial stiffness of each cable, N.
        N0: pretension, N (pulls each satellite toward the centroid with sqrt(6) N0).
        damping_rate: diagonal damping per unit mass, 1/s (C = damping_rate * M).
        breaking_load: cable breaking tension, N.
    """
    base = edge / math.sqrt(3.0)
    height = edge * math.sqrt(2.0 / 3.0)
    positions = np.array(
        [
            [base, 0.0, 0.0],
            [base * math.cos(2 * math.pi / 3), base * math.sin(2 * math.pi / 3), 0.0],
            [base * math.cos(4 * math.pi / 3), base * math.sin(4 * math.pi / 3), 0.0],
            [0.0, 0.0, height],
        ]
    )
    positions -= positions.mean(axis=0)
    cables = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]
    return Cluster(
        positions=positions, masses=mass, cables=cables, EA=EA, N0=N0, damping=damping_rate * mass,
        breaking_load=breaking_load, name="tetrahedron",
    )


def chain(
    n: int = 5,
    spacing: float = 50.0,
    mass: float = 5.0,
    EA: float = 20e3,
    N0: float = 0.1,
    damping_rate: float = 0.1,
    breaking_load: float = 1000.0,
) -> Cluster:
    """``n`` satellites in a straight line along x, each tethered to the next.

    Args:
        n: number of satellites, >= 2.
        spacing: cable length, m.
        mass: mass of each satellite, kg.
        EA: axial stiffness of each cable, N.
        N0: pretension, N.
        damping_rate: diagonal damping per unit mass, 1/s (C = damping_rate * M).
        breaking_load: cable breaking tension, N.
    """
    if not isinstance(n, (int, np.integer)) or n < 2:
        raise ClusterError(f"chain needs n >= 2 satellites (an integer); got n={n!r}")
    positions = np.zeros((n, 3))
    positions[:, 0] = spacing * (np.arange(n) - (n - 1) / 2.0)
    cables = [(i, i + 1) for i in range(n - 1)]
    return Cluster(
        positions=positions, masses=mass, cables=cables, EA=EA, N0=N0, damping=damping_rate * mass,
        breaking_load=breaking_load, name="chain",
    )


def triangle(
    edge: float = 100.0,
    mass: float = 10.0,
    EA: float = 50e3,
    N0: float = 0.2,
    damping_rate: float = 0.1,
    breaking_load: float = 1500.0,
) -> Cluster:
    """Three satellites at the corners of an equilateral triangle in the x-y plane.

    Args:
        edge: cable length, m.
        mass: mass of each satellite, kg.
        EA: axial stiffness of each cable, N.
        N0: pretension, N.
        damping_rate: diagonal damping per unit mass, 1/s (C = damping_rate * M).
        breaking_load: cable breaking tension, N.
    """
    radius = edge / math.sqrt(3.0)
    angles = np.array([0.0, 2 * math.pi / 3, 4 * math.pi / 3])
    positions = np.stack([radius * np.cos(angles), radius * np.sin(angles), np.zeros(3)], axis=1)
    return Cluster(
        positions=positions, masses=mass, cables=[(0, 1), (1, 2), (0, 2)], EA=EA, N0=N0,
        damping=damping_rate * mass, breaking_load=breaking_load, name="triangle",
    )


def octahedron(
    edge: float = 100.0,
    mass: float = 10.0,
    EA: float = 50e3,
    N0: float = 0.2,
    damping_rate: float = 0.1,
    breaking_load: float = 1500.0,
) -> Cluster:
    """Six satellites at the vertices of a regular octahedron, twelve cables along its edges.

    Args:
        edge: cable length, m.
        mass: mass of each satellite, kg.
        EA: axial stiffness of each cable, N.
        N0: pretension, N.
        damping_rate: diagonal damping per unit mass, 1/s (C = damping_rate * M).
        breaking_load: cable breaking tension, N.
    """
    half = edge / math.sqrt(2.0)
    positions = half * np.array(
        [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=float
    )
    cables = [
        (i, j)
        for i in range(6)
        for j in range(i + 1, 6)
        if not np.allclose(positions[i], -positions[j])
    ]
    return Cluster(
        positions=positions, masses=mass, cables=cables, EA=EA, N0=N0, damping=damping_rate * mass,
        breaking_load=breaking_load, name="octahedron",
    )


def hub(
    spokes: int = 6,
    radius: float = 100.0,
    hub_mass: float = 100.0,
    mass: float = 10.0,
    EA: float = 50e3,
    N0: float = 0.2,
    rim: bool = True,
    damping_rate: float = 0.1,
    breaking_load: float = 1500.0,
) -> Cluster:
    """A heavy hub satellite (node 0) with ``spokes`` lighter satellites around it in the x-y plane.

    Each satellite is tethered to the hub; with ``rim=True`` neighbours are also tethered to each
    other, closing a wheel.  The 10:1 mass ratio exercises the mass-aware critical-step estimate.

    Args:
        spokes: number of outer satellites, >= 2 (>= 3 with a rim).
        radius: spoke length, m.
        hub_mass: mass of the hub, kg.
        mass: mass of each outer satellite, kg.
        EA: axial stiffness of every cable, N.
        N0: pretension of every cable, N.
        rim: also tether neighbouring outer satellites.
        damping_rate: diagonal damping per unit mass (C = damping_rate * M), 1/s.
        breaking_load: cable breaking tension, N.
    """
    if not isinstance(spokes, (int, np.integer)) or spokes < (3 if rim else 2):
        raise ClusterError(f"hub needs spokes >= {3 if rim else 2} (an integer); got spokes={spokes!r}")
    angles = 2 * math.pi * np.arange(spokes) / spokes
    outer = np.stack([radius * np.cos(angles), radius * np.sin(angles), np.zeros(spokes)], axis=1)
    positions = np.vstack([np.zeros((1, 3)), outer])
    cables = [(0, k + 1) for k in range(spokes)]
    if rim:
        cables += [(k + 1, (k + 1) % spokes + 1) for k in range(spokes)]
    masses = np.concatenate([[hub_mass], np.full(spokes, mass)])
    return Cluster(
        positions=positions, masses=masses, cables=cables, EA=EA, N0=N0,
        damping=damping_rate * masses, breaking_load=breaking_load, name="hub",
    )


PRESETS: dict[str, Callable[..., Cluster]] = {
    "tetrahedron": tetrahedron,
    "chain": chain,
    "triangle": triangle,
    "octahedron": octahedron,
    "hub": hub,
}


def preset_names() -> list[str]:
    """Names accepted by :func:`make_cluster`."""
    return list(PRESETS)


def make_cluster(name: str, **overrides: object) -> Cluster:
    """Build the preset cluster ``name`` with keyword overrides of its parameters.

    Example: ``make_cluster("chain", n=8, EA=30e3)``.  Unknown names or parameters raise a
    :class:`ClusterError` that lists what is accepted.
    """
    if name not in PRESETS:
        raise ClusterError(f"unknown preset {name!r}; choose one of {preset_names()}")
    builder = PRESETS[name]
    accepted = list(inspect.signature(builder).parameters)
    unknown = sorted(set(overrides) - set(accepted))
    if unknown:
        raise ClusterError(f"preset {name!r} has no parameter(s) {unknown}; its parameters are {accepted}")
    return builder(**overrides)
