"""Named clusters with physically plausible magnitudes (SI units).

Defaults use realistic magnitudes: small satellites of 5-100 kg, braided
Dyneema-class tethers (EA of tens of kN, breaking loads of 1-2 kN) of 50-100 m, and light
pretension of a fraction of a newton, which low-thrust cold-gas thrusters can hold.  With these
values the critical step is 0.1-0.15 s, so at the default safety factor every 0.1 s control
interval is integrated in several sub-steps.

The presets ``radial_chain``, ``spinning_triangle`` and ``spinning_hub`` live in turning frames
(:class:`~tether_gym.frames.Frame`), where the gravity gradient or the spin, not thrust, holds the
cables taut: their pretensions are set so that the nominal shape is an equilibrium of the frame.
They damp through the cables (Kelvin-Voigt, ``axial_damping_ratio``) rather than the paper's
diagonal damping, which would act on velocities relative to the turning frame.

Every preset is a function of keyword arguments returning a :class:`~tether_gym.Cluster`;
:func:`make_cluster` looks one up by name and passes keyword overrides through.
"""

from __future__ import annotations

import functools
import inspect
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np
from numpy.typing import ArrayLike

from tether_gym.cluster import Cluster, ClusterError
from tether_gym.frames import LEO_ORBIT_RATE, Frame, FrameError
from tether_gym.limits import is_real_number, is_whole_number, short_repr, to_float
from tether_gym.tethers import Tether, TetherError, build_cluster, frame_held

__all__ = ["MAX_SATELLITES", "PRESETS", "TetherSpec", "make_cluster", "preset_names"]

#: Largest satellite count a preset builds (``n``, ``spokes``): far beyond any studied formation,
#: small enough that a cluster's arrays fit in memory many times over.
MAX_SATELLITES = 10_000

PresetBuilder = TypeVar("PresetBuilder", bound=Callable[..., Cluster])


def _check_preset_argument(preset: str, name: str, value: object, default: object) -> None:
    """Raise ``ClusterError`` if ``value`` is not of the kind of ``default``: a bool for a flag, a
    whole number in 1..MAX_SATELLITES for a count, a real number for a magnitude."""
    if isinstance(default, bool):
        if not isinstance(value, (bool, np.bool_)):
            raise ClusterError(f"preset {preset!r}: {name} must be True or False; got {short_repr(value)}")
    elif isinstance(default, int):
        if not (is_whole_number(value) and 1 <= value <= MAX_SATELLITES):
            raise ClusterError(
                f"preset {preset!r}: {name} must be a whole number in 1..{MAX_SATELLITES}; got {value!r}"
            )
    elif isinstance(default, float):
        if not is_real_number(value):
            raise ClusterError(f"preset {preset!r}: {name} must be a real number; got {short_repr(value)}")
        if abs(to_float(value)) == math.inf and not (name == "breaking_load" and to_float(value) > 0):
            raise ClusterError(
                f"preset {preset!r}: {name} must be finite (only breaking_load may be inf); got {short_repr(value)}"
            )


def _preset(builder: PresetBuilder) -> PresetBuilder:
    """Check a preset's arguments against the kinds of its defaults before it runs, and name the
    preset and its arguments in any error the cluster it builds raises (a cluster-level message
    such as "positions must lie in ..." then says which argument put them there)."""
    signature = inspect.signature(builder)

    @functools.wraps(builder)
    def checked(*args: object, **kwargs: object) -> Cluster:
        try:
            bound = signature.bind(*args, **kwargs)
        except TypeError as error:
            raise ClusterError(
                f"preset {builder.__name__!r}: {error}; its parameters are {list(signature.parameters)}"
            ) from None
        for name, value in bound.arguments.items():
            _check_preset_argument(builder.__name__, name, value, signature.parameters[name].default)
        try:
            with np.errstate(over="ignore", invalid="ignore"):  # the cluster's own checks name the result
                return builder(*args, **kwargs)
        except (ClusterError, FrameError) as error:
            given = ", ".join(f"{key}={short_repr(value, 40)}" for key, value in bound.arguments.items())
            raise ClusterError(f"preset {builder.__name__}({given}): {error}") from None

    return checked  # type: ignore[return-value]


@dataclass(frozen=True)
class TetherSpec:
    """The cables of a preset, all alike, and the damping of its satellites: the block of
    arguments that every preset takes the same way."""

    EA: ArrayLike
    """Axial stiffness of each cable, N (a scalar, or one per cable)."""
    N0: ArrayLike
    """Pretension of each cable, N (a scalar, or one per cable)."""
    damping_rate: float
    """Diagonal damping per unit mass, 1/s: each satellite's damping is ``damping_rate`` times its
    mass (C = damping_rate * M)."""
    breaking_load: ArrayLike
    """Cable breaking tension, N (a scalar, or one per cable)."""

    tether_mass: float = 0.0
    """Mass of each tether, kg (0: massless cables, the paper's model)."""
    segments: int = 1
    """Segments each tether is split into (``segments - 1`` beads carry its mass; 1: no beads)."""

    def cluster(
        self, name: str, positions: ArrayLike, cables: ArrayLike, masses: float | np.ndarray, **options: Any
    ) -> Cluster:
        """The preset's :class:`Cluster`: satellites at ``positions`` ((n, 3), m) of ``masses`` (kg,
        a scalar or (n,)) joined by ``cables`` ((m, 2) satellite indices) of this spec;
        ``options`` are further :class:`Cluster` fields (``axial_damping``, ``frame``).  With a
        ``tether_mass`` > 0 every cable is a :class:`~tether_gym.tethers.Tether` of that mass in
        ``segments`` segments, expanded by :func:`~tether_gym.tethers.build_cluster` (the
        satellites' diagonal damping stays ``damping_rate`` times their own masses, before the
        tethers' lumped mass is added).  In a turning frame the tethers are then put on the
        funicular of the frame's load and tensioned so that the frame alone holds the satellites
        (:func:`~tether_gym.tethers.frame_held`)."""
        if self.tether_mass != 0.0 or self.segments != 1:
            return self._beaded_cluster(name, positions, cables, masses, **options)
        return Cluster(
            positions=positions,
            masses=masses,
            cables=cables,
            EA=self.EA,
            N0=self.N0,
            damping=self.damping_rate * masses,
            breaking_load=self.breaking_load,
            name=name,
            **options,
        )

    def _beaded_cluster(
        self, name: str, positions: ArrayLike, cables: ArrayLike, masses: float | np.ndarray, **options: Any
    ) -> Cluster:
        """The cluster with every cable a tether of ``tether_mass`` kg in ``segments`` segments."""
        mass = to_float(self.tether_mass)
        if not mass >= 0.0:
            raise ClusterError(f"tether_mass must be >= 0 kg (the mass of each tether); got {short_repr(mass)}")
        if mass == 0.0:
            raise ClusterError(
                f"segments={self.segments} needs tether_mass > 0 kg (its beads carry the tether's mass); give "
                "tether_mass, or leave segments=1 for massless cables"
            )
        ends = np.asarray(cables, dtype=np.int64).reshape(-1, 2)
        count = ends.shape[0]
        sat_positions = np.asarray(positions, dtype=np.float64)
        sat_masses = np.broadcast_to(np.asarray(masses, dtype=np.float64), (sat_positions.shape[0],))
        per_cable = {
            key: np.broadcast_to(np.asarray(value, dtype=np.float64), (count,))
            for key, value in (
                ("EA", self.EA),
                ("N0", self.N0),
                ("breaking_load", self.breaking_load),
                ("axial_damping", options.pop("axial_damping", 0.0)),
            )
        }
        frame = options.pop("frame", None)
        if options:
            raise TypeError(f"unexpected cluster options {sorted(options)}")
        try:
            tethers = [
                Tether(
                    ends=(int(a), int(b)),
                    EA=float(per_cable["EA"][c]),
                    segments=self.segments,
                    mass=mass,
                    N0=float(per_cable["N0"][c]),
                    axial_damping=float(per_cable["axial_damping"][c]),
                    breaking_load=float(per_cable["breaking_load"][c]),
                )
                for c, (a, b) in enumerate(ends)
            ]
            cluster = build_cluster(
                sat_positions, sat_masses, tethers, damping=self.damping_rate * sat_masses, name=name
            )
            if frame is None or frame.is_inertial:
                return cluster
            # In a turning frame the frame's load alone holds the formation, its lines included: the
            # lines hang on the funicular of their own load, tensioned so that the bias thrust is 0.
            return frame_held(cluster.replace(frame=frame))
        except TetherError as error:
            raise ClusterError(f"tether_mass={short_repr(mass)}, segments={self.segments}: {error}") from None


@_preset
def tetrahedron(
    edge: float = 100.0,
    mass: float = 10.0,
    EA: float = 50e3,
    N0: float = 0.2,
    damping_rate: float = 0.1,
    breaking_load: float = 1500.0,
    tether_mass: float = 0.0,
    segments: int = 1,
) -> Cluster:
    """The paper's example: four satellites at the corners of a regular tetrahedron, six cables.

    Args:
        edge: cable length, m.
        mass: mass of each satellite, kg.
        EA: axial stiffness of each cable, N.
        N0: pretension, N (pulls each satellite toward the centroid with sqrt(6) N0).
        damping_rate: diagonal damping per unit mass, 1/s (C = damping_rate * M).
        breaking_load: cable breaking tension, N.
        tether_mass: mass of each tether, kg (0: massless cables; > 0: every cable becomes a
            :class:`~tether_gym.tethers.Tether` of this mass whose beads and lumped end mass carry it).
        segments: segments of each tether with mass (``segments - 1`` beads each; 1: no beads).
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
    return TetherSpec(
        EA=EA, tether_mass=tether_mass, segments=segments, N0=N0, damping_rate=damping_rate, breaking_load=breaking_load
    ).cluster("tetrahedron", positions, cables, mass)


@_preset
def chain(
    n: int = 5,
    spacing: float = 50.0,
    mass: float = 5.0,
    EA: float = 20e3,
    N0: float = 0.1,
    damping_rate: float = 0.1,
    breaking_load: float = 1000.0,
    tether_mass: float = 0.0,
    segments: int = 1,
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
        tether_mass: mass of each tether, kg (0: massless cables; > 0: every cable becomes a
            :class:`~tether_gym.tethers.Tether` of this mass whose beads and lumped end mass carry it).
        segments: segments of each tether with mass (``segments - 1`` beads each; 1: no beads).
    """
    if not isinstance(n, (int, np.integer)) or n < 2:
        raise ClusterError(f"chain needs n >= 2 satellites (an integer); got n={n!r}")
    positions = np.zeros((n, 3))
    positions[:, 0] = spacing * (np.arange(n) - (n - 1) / 2.0)
    cables = [(i, i + 1) for i in range(n - 1)]
    return TetherSpec(
        EA=EA, tether_mass=tether_mass, segments=segments, N0=N0, damping_rate=damping_rate, breaking_load=breaking_load
    ).cluster("chain", positions, cables, mass)


@_preset
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
    return TetherSpec(EA=EA, N0=N0, damping_rate=damping_rate, breaking_load=breaking_load).cluster(
        "triangle", positions, [(0, 1), (1, 2), (0, 2)], mass
    )


@_preset
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
    positions = half * np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=float)
    cables = [(i, j) for i in range(6) for j in range(i + 1, 6) if not np.allclose(positions[i], -positions[j])]
    return TetherSpec(EA=EA, N0=N0, damping_rate=damping_rate, breaking_load=breaking_load).cluster(
        "octahedron", positions, cables, mass
    )


@_preset
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
    return TetherSpec(EA=EA, N0=N0, damping_rate=damping_rate, breaking_load=breaking_load).cluster(
        "hub", positions, cables, masses
    )


def _axial_damping(cables: np.ndarray, masses: np.ndarray, stiffness: np.ndarray, ratio: float) -> np.ndarray:
    """(m,) Kelvin-Voigt coefficients, N*s/m, giving each cable the damping ratio ``ratio`` of the
    axial oscillation of its two end masses alone: ``c = 2 ratio sqrt(k mu)``, mu the reduced mass."""
    if not (math.isfinite(ratio) and ratio >= 0):
        raise ClusterError(f"axial_damping_ratio must be a finite number >= 0; got {ratio!r}")
    m_i, m_j = masses[cables[:, 0]], masses[cables[:, 1]]
    return 2.0 * ratio * np.sqrt(stiffness * m_i * m_j / (m_i + m_j))


def _positive(name: str, value: float, unit: str) -> float:
    if not (isinstance(value, (int, float, np.floating)) and math.isfinite(value) and value > 0):
        raise ClusterError(f"{name} must be a finite number > 0 {unit}; got {short_repr(value)}")
    return float(value)


@_preset
def radial_chain(
    n: int = 3,
    spacing: float = 500.0,
    mass: float = 50.0,
    EA: float = 20e3,
    orbit_rate: float = LEO_ORBIT_RATE,
    axial_damping_ratio: float = 0.05,
    damping_rate: float = 0.0,
    breaking_load: float = 1000.0,
    tether_mass: float = 0.0,
    segments: int = 1,
) -> Cluster:
    """``n`` satellites in a straight line along the local vertical of a circular orbit, in the Hill
    frame, held taut by the gravity gradient alone (no thrust).

    At rest in the Hill frame, satellite k at radial offset ``x_k`` (centre of mass at the origin)
    feels the tidal force ``3 n^2 m x_k``; cable k carries the pull of everything outboard of it,
    ``N_k = 3 n^2 sum_{i > k} m_i x_i`` (for two satellites ``3 n^2 mu L``).  The pretension of
    each cable is that tension at the nominal spacing, so the nominal line is an equilibrium.
    The defaults (50 kg satellites 500 m apart in 400 km LEO) give about 0.1 N: such tethers are
    barely taut, and slack easily.

    With ``tether_mass > 0`` the lines hang on the funicular of the frame's load on their own
    mass and their pretensions are set so that the frame alone still holds the satellites
    (:func:`~tether_gym.tethers.frame_held`: zero bias thrust, a line's pretension being its
    mean segment tension).

    Args:
        n: number of satellites, >= 2.
        spacing: cable length, m.
        mass: mass of each satellite, kg.
        EA: axial stiffness of each cable, N.
        orbit_rate: orbital rate n of the circular orbit, rad/s (default 400 km LEO).
        axial_damping_ratio: Kelvin-Voigt damping of each cable, as the damping ratio of its
            end masses' axial oscillation.
        damping_rate: diagonal damping per unit mass (relative to the Hill frame), 1/s.
        breaking_load: cable breaking tension, N.
        tether_mass: mass of each tether, kg (0: massless cables; > 0: every cable becomes a
            :class:`~tether_gym.tethers.Tether` of this mass whose beads and lumped end mass carry it).
        segments: segments of each tether with mass (``segments - 1`` beads each; 1: no beads).
    """
    if not isinstance(n, (int, np.integer)) or n < 2:
        raise ClusterError(f"radial_chain needs n >= 2 satellites (an integer); got n={n!r}")
    spacing = _positive("spacing", spacing, "m")
    mass = _positive("mass", mass, "kg")
    frame = Frame.hill(_positive("orbit_rate", orbit_rate, "rad/s"))
    positions = np.zeros((n, 3))
    positions[:, 0] = spacing * (np.arange(n) - (n - 1) / 2.0)
    masses = np.full(n, mass)
    tidal_force = masses * frame.tidal[0] * positions[:, 0]  # (n,) N, outward above the centre
    tension = np.array([tidal_force[k + 1 :].sum() for k in range(n - 1)])
    cables = np.array([(k, k + 1) for k in range(n - 1)])
    stiffness = _positive("EA", EA, "N") / spacing
    return TetherSpec(
        EA=EA,
        tether_mass=tether_mass,
        segments=segments,
        N0=tension,
        damping_rate=damping_rate,
        breaking_load=breaking_load,
    ).cluster(
        "radial_chain",
        positions,
        cables,
        masses,
        axial_damping=_axial_damping(cables, masses, np.full(n - 1, stiffness), axial_damping_ratio),
        frame=frame,
    )


@_preset
def spinning_triangle(
    edge: float = 100.0,
    mass: float = 10.0,
    EA: float = 50e3,
    spin_rate: float = 0.06,
    axial_damping_ratio: float = 0.05,
    damping_rate: float = 0.0,
    breaking_load: float = 1500.0,
    tether_mass: float = 0.0,
    segments: int = 1,
) -> Cluster:
    """Three satellites in an equilateral triangle spinning about its normal (z), seen in the frame
    that spins with it.  Spin holds the cables taut: each satellite, at radius ``edge/sqrt(3)``,
    needs the centripetal force ``m W^2 edge / sqrt(3)``, which its two cables supply with the
    tension ``N = m W^2 edge / 3`` (1.2 N by default, a 105 s spin period).

    With ``tether_mass > 0`` the lines hang on the funicular of the frame's load on their own
    mass and their pretensions are set so that the frame alone still holds the satellites
    (:func:`~tether_gym.tethers.frame_held`: zero bias thrust, a line's pretension being its
    mean segment tension).

    Args:
        edge: cable length, m.
        mass: mass of each satellite, kg.
        EA: axial stiffness of each cable, N.
        spin_rate: spin rate W of the formation (and frame) about z, rad/s.
        axial_damping_ratio: Kelvin-Voigt damping of each cable, as the damping ratio of its
            end masses' axial oscillation.
        damping_rate: diagonal damping per unit mass (relative to the spinning frame), 1/s.
        breaking_load: cable breaking tension, N.
        tether_mass: mass of each tether, kg (0: massless cables; > 0: every cable becomes a
            :class:`~tether_gym.tethers.Tether` of this mass whose beads and lumped end mass carry it).
        segments: segments of each tether with mass (``segments - 1`` beads each; 1: no beads).
    """
    edge = _positive("edge", edge, "m")
    mass = _positive("mass", mass, "kg")
    frame = Frame.rotating(_positive("spin_rate", spin_rate, "rad/s"))
    radius = edge / math.sqrt(3.0)
    angles = np.array([0.0, 2 * math.pi / 3, 4 * math.pi / 3])
    positions = np.stack([radius * np.cos(angles), radius * np.sin(angles), np.zeros(3)], axis=1)
    cables = np.array([(0, 1), (1, 2), (0, 2)])
    masses = np.full(3, mass)
    stiffness = np.full(3, _positive("EA", EA, "N") / edge)
    return TetherSpec(
        EA=EA,
        tether_mass=tether_mass,
        segments=segments,
        N0=mass * frame.rate**2 * edge / 3.0,
        damping_rate=damping_rate,
        breaking_load=breaking_load,
    ).cluster(
        "spinning_triangle",
        positions,
        cables,
        masses,
        axial_damping=_axial_damping(cables, masses, stiffness, axial_damping_ratio),
        frame=frame,
    )


@_preset
def spinning_hub(
    spokes: int = 6,
    radius: float = 100.0,
    hub_mass: float = 100.0,
    mass: float = 10.0,
    EA: float = 50e3,
    spin_rate: float = 0.05,
    rim_share: float = 0.25,
    axial_damping_ratio: float = 0.05,
    damping_rate: float = 0.0,
    breaking_load: float = 1500.0,
    tether_mass: float = 0.0,
    segments: int = 1,
) -> Cluster:
    """A hub satellite (node 0) with ``spokes`` satellites on a wheel around it, spinning about z,
    seen in the frame that spins with it.  Each outer satellite needs the centripetal force
    ``m W^2 R``; a share ``rim_share`` of it comes from the two rim cables to its neighbours
    (tension ``rim_share m W^2 R / (2 sin(pi / spokes))``), the rest from its spoke.  With the
    defaults the spokes carry 1.9 N and the rim cables 0.6 N; the spin period is 126 s.

    With ``tether_mass > 0`` the lines hang on the funicular of the frame's load on their own
    mass and their pretensions are set so that the frame alone still holds the satellites
    (:func:`~tether_gym.tethers.frame_held`: zero bias thrust, a line's pretension being its
    mean segment tension).

    Args:
        spokes: number of outer satellites, >= 3.
        radius: spoke length, m.
        hub_mass: mass of the hub, kg.
        mass: mass of each outer satellite, kg.
        EA: axial stiffness of every cable, N.
        spin_rate: spin rate W about z, rad/s.
        rim_share: fraction of the centripetal load carried by the rim, in [0, 1) (0: rim cables
            just taut, with no pretension).
        axial_damping_ratio: Kelvin-Voigt damping of each cable, as the damping ratio of its
            end masses' axial oscillation.
        damping_rate: diagonal damping per unit mass (relative to the spinning frame), 1/s.
        breaking_load: cable breaking tension, N.
        tether_mass: mass of each tether, kg (0: massless cables; > 0: every cable becomes a
            :class:`~tether_gym.tethers.Tether` of this mass whose beads and lumped end mass carry it).
        segments: segments of each tether with mass (``segments - 1`` beads each; 1: no beads).
    """
    if not isinstance(spokes, (int, np.integer)) or spokes < 3:
        raise ClusterError(f"spinning_hub needs spokes >= 3 (an integer); got spokes={spokes!r}")
    if not (isinstance(rim_share, (int, float)) and 0.0 <= rim_share < 1.0):
        raise ClusterError(f"rim_share must be a fraction in [0, 1); got {rim_share!r}")
    radius = _positive("radius", radius, "m")
    frame = Frame.rotating(_positive("spin_rate", spin_rate, "rad/s"))
    angles = 2 * math.pi * np.arange(spokes) / spokes
    outer = np.stack([radius * np.cos(angles), radius * np.sin(angles), np.zeros(spokes)], axis=1)
    positions = np.vstack([np.zeros((1, 3)), outer])
    cables = np.array([(0, k + 1) for k in range(spokes)] + [(k + 1, (k + 1) % spokes + 1) for k in range(spokes)])
    masses = np.concatenate([[_positive("hub_mass", hub_mass, "kg")], np.full(spokes, _positive("mass", mass, "kg"))])
    centripetal = mass * frame.rate**2 * radius
    rim_tension = rim_share * centripetal / (2.0 * math.sin(math.pi / spokes))
    tension = np.concatenate([np.full(spokes, (1.0 - rim_share) * centripetal), np.full(spokes, rim_tension)])
    lengths = np.linalg.norm(positions[cables[:, 1]] - positions[cables[:, 0]], axis=1)
    return TetherSpec(
        EA=EA,
        tether_mass=tether_mass,
        segments=segments,
        N0=tension,
        damping_rate=damping_rate,
        breaking_load=breaking_load,
    ).cluster(
        "spinning_hub",
        positions,
        cables,
        masses,
        axial_damping=_axial_damping(cables, masses, _positive("EA", EA, "N") / lengths, axial_damping_ratio),
        frame=frame,
    )


#: The line of the beaded ids: 2 kg per tether, 8 segments.  Eight segments put the lowest
#: transverse mode within 0.7 % of the continuous line and the first axial mode within 0.1 %
#: (``tether_gym.analysis.tether_mode_errors``), at about 30 times the massless id's cost per
#: control step; 16 segments would cut those errors fourfold, at a cost that grows as N^2.
BEADED_TETHER_MASS = 2.0
BEADED_SEGMENTS = 8


@_preset
def beaded_tetrahedron(
    edge: float = 100.0,
    mass: float = 10.0,
    EA: float = 50e3,
    N0: float = 0.2,
    damping_rate: float = 0.1,
    breaking_load: float = 1500.0,
    tether_mass: float = BEADED_TETHER_MASS,
    segments: int = BEADED_SEGMENTS,
) -> Cluster:
    """The paper's tetrahedron with tethers of mass: each 100 m line weighs 2 kg (a fifth of a
    satellite) and is split into 8 segments, 7 beads each.

    Its transverse waves travel at ``sqrt(N0 / mu)`` = 3.2 m/s, so a line's lowest mode has a
    period of about 63 s, twice an episode: a sagging line is slow mass the satellites drag.

    Args:
        edge: tether length, m.
        mass: mass of each satellite, kg (before the tethers' lumped end mass is added).
        EA: axial stiffness of each tether, N.
        N0: pretension, N.
        damping_rate: diagonal damping per unit mass of the satellites, 1/s (the beads have none).
        breaking_load: segment breaking tension, N.
        tether_mass: mass of each tether, kg.
        segments: segments of each tether (``segments - 1`` beads each).
    """
    return tetrahedron(edge, mass, EA, N0, damping_rate, breaking_load, tether_mass, segments).replace(
        name="beaded_tetrahedron"
    )


@_preset
def beaded_chain(
    n: int = 5,
    spacing: float = 50.0,
    mass: float = 5.0,
    EA: float = 20e3,
    N0: float = 0.1,
    damping_rate: float = 0.1,
    breaking_load: float = 1000.0,
    tether_mass: float = BEADED_TETHER_MASS,
    segments: int = BEADED_SEGMENTS,
) -> Cluster:
    """The chain with tethers of mass: each 50 m line weighs 2 kg and is split into 8 segments,
    7 beads each, so the lines carry a third of the chain's mass.

    Its transverse waves travel at ``sqrt(N0 / mu)`` = 1.6 m/s: a line's lowest mode has a period
    of about 63 s, twice an episode.

    Args:
        n: number of satellites, >= 2.
        spacing: tether length, m.
        mass: mass of each satellite, kg (before the tethers' lumped end mass is added).
        EA: axial stiffness of each tether, N.
        N0: pretension, N.
        damping_rate: diagonal damping per unit mass of the satellites, 1/s (the beads have none).
        breaking_load: segment breaking tension, N.
        tether_mass: mass of each tether, kg.
        segments: segments of each tether (``segments - 1`` beads each).
    """
    return chain(n, spacing, mass, EA, N0, damping_rate, breaking_load, tether_mass, segments).replace(
        name="beaded_chain"
    )


PRESETS: dict[str, Callable[..., Cluster]] = {
    "tetrahedron": tetrahedron,
    "chain": chain,
    "triangle": triangle,
    "octahedron": octahedron,
    "hub": hub,
    "radial_chain": radial_chain,
    "spinning_triangle": spinning_triangle,
    "spinning_hub": spinning_hub,
    "beaded_tetrahedron": beaded_tetrahedron,
    "beaded_chain": beaded_chain,
}


def preset_names() -> list[str]:
    """Names accepted by :func:`make_cluster`."""
    return list(PRESETS)


def make_cluster(name: str, **overrides: object) -> Cluster:
    """Build the preset cluster ``name`` with keyword overrides of its parameters.

    Example: ``make_cluster("chain", n=8, EA=30e3)``.  Unknown names or parameters raise a
    :class:`ClusterError` that lists what is accepted.
    """
    if not isinstance(name, str) or name not in PRESETS:
        raise ClusterError(f"unknown preset {name!r}; choose one of {preset_names()}")
    builder = PRESETS[name]
    accepted = list(inspect.signature(builder).parameters)
    unknown = sorted(map(str, set(overrides) - set(accepted)))
    if unknown:
        raise ClusterError(f"preset {name!r} has no parameter(s) {unknown}; its parameters are {accepted}")
    return builder(**overrides)
