"""Tethers that have mass: a tether spec expanded into beads and segments (the lumped-mass line).

A :class:`Tether` describes one line between two satellites: its total mass, its axial
stiffness, pretension, reference length, damping and breaking load, and the number of segments
``N`` it is split into.  :func:`build_cluster` expands satellites and tethers into a
:class:`~tether_gym.cluster.Cluster` whose nodes are the satellites followed by the beads of each
tether, and whose cables are the tethers' segments; the cluster keeps the specs, knows which node
is a satellite and which a bead of which tether, and writes the specs to its files.

The expansion of a tether of mass ``m_t``, reference length ``L`` and ``N`` segments:

* ``N - 1`` beads on the straight chord between the end satellites, equally spaced;
* each segment has reference length ``L / N``, the tether's ``EA``, ``N0`` and breaking load
  (a line in series: the same force in every segment), and ``N`` times the tether's
  Kelvin-Voigt coefficient (``N`` dashpots in series give back the tether's coefficient);
* lumping ``"half"`` (default, the standard lumped-mass line): each bead carries ``m_t / N`` and
  each end satellite gains half a segment's mass, ``m_t / (2 N)``; the frequencies then converge
  at second order in ``N``.  Lumping ``"none"``: the beads share the whole mass (``m_t / (N - 1)``
  each) and the satellites gain nothing; the axial mode converges at first order only.  With
  ``N = 1`` and ``"none"`` the tether is the massless cable of the paper, bit for bit.

A segment that breaks severs its tether (:attr:`TetherResults.broken`): the line no longer joins
its satellites, and the beads on either side stay attached to their own end as loose debris.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike

from tether_gym.frames import Frame
from tether_gym.limits import (
    MAX_DAMPING,
    MAX_EA,
    MAX_FORCE,
    MAX_LENGTH,
    MAX_MASS,
    MIN_BEAD_MASS,
    MIN_EA,
    MIN_LENGTH,
    is_real_number,
    is_whole_number,
    short_repr,
    to_float,
)

__all__ = [
    "LUMPING_RULES",
    "MAX_SEGMENTS",
    "Tether",
    "TetherError",
    "StaticEquilibrium",
    "TetherResults",
    "build_cluster",
    "frame_held",
    "static_equilibrium",
    "tether_results",
]

#: The lumping rules: ``"half"`` puts half a segment's mass on each end satellite; ``"none"``
#: spreads the whole mass over the beads.
LUMPING_RULES = ("half", "none")
#: Most segments in one tether: 10^4 beads already make the step 10^4 times smaller than the
#: massless cable's, and the cost per simulated second grows as N^2.
MAX_SEGMENTS = 10_000

Lumping = Literal["half", "none"]


class TetherError(ValueError):
    """An invalid tether spec; the message names the tether and how to fix it."""


@dataclasses.dataclass(frozen=True)
class Tether:
    """One tether between two satellites, split into ``segments`` lumped-mass segments.

    Args:
        ends: ``(a, b)`` the indices of the two satellites it joins (beads run from ``a`` to ``b``).
        EA: axial stiffness, N, > 0 (the same in every segment).
        segments: number of segments N >= 1; N - 1 beads carry the mass.
        mass: total mass of the line, kg, >= 0 (> 0 when N > 1: a bead needs mass).  The mass
            per reference length is ``mass / L0``.
        N0: pretension, N, >= 0 and < EA (else a segment would be shorter than its stretch).  In a
            turning frame, the mean pretension of its segments: :func:`build_cluster` varies it
            along the line so that the frame's load along the line is in equilibrium.
        L0: reference (unstretched-plus-pretension) length of the whole tether, m; ``None``: the
            distance between its satellites, filled in by :func:`build_cluster`.
        axial_damping: Kelvin-Voigt coefficient of the whole tether, N*s/m, >= 0.
        breaking_load: tension at which a segment breaks, N, > 0 (default inf: unbreakable).
        lumping: ``"half"`` (default) or ``"none"``; see the module docstring.
        name: an optional label used in messages.
    """

    ends: tuple[int, int]
    EA: float
    segments: int = 1
    mass: float = 0.0
    N0: float = 0.0
    L0: float | None = None
    axial_damping: float = 0.0
    breaking_load: float = math.inf
    lumping: Lumping = "half"
    name: str = ""

    def __post_init__(self) -> None:
        ends = self.ends
        if (
            not isinstance(ends, (tuple, list))
            or len(ends) != 2
            or not all(is_whole_number(e) and e >= 0 for e in ends)
        ):
            raise TetherError(
                f"{self.label}: ends must be two satellite indices (a, b), whole numbers >= 0; got {short_repr(ends)}"
            )
        ends = (int(ends[0]), int(ends[1]))
        if ends[0] == ends[1]:
            raise TetherError(
                f"{self.label}: both ends are satellite {ends[0]}; a tether joins two distinct satellites"
            )
        object.__setattr__(self, "ends", ends)
        if not is_whole_number(self.segments) or not 1 <= self.segments <= MAX_SEGMENTS:
            raise TetherError(
                f"{self.label}: segments must be a whole number in 1..{MAX_SEGMENTS}; got {short_repr(self.segments)}"
            )
        object.__setattr__(self, "segments", int(self.segments))
        self._set_number("EA", MIN_EA, MAX_EA, "N")
        self._set_number("mass", 0.0, MAX_MASS, "kg")
        self._set_number("N0", 0.0, MAX_FORCE, "N")
        if self.L0 is not None:
            self._set_number("L0", MIN_LENGTH, MAX_LENGTH, "m")
        self._set_number("axial_damping", 0.0, MAX_DAMPING, "N*s/m")
        if isinstance(self.breaking_load, str) and self.breaking_load.strip().lower().lstrip("+") in (
            "inf",
            "infinity",
        ):
            object.__setattr__(self, "breaking_load", math.inf)  # strict JSON's spelling of an unbreakable tether
        if not (is_real_number(self.breaking_load) and to_float(self.breaking_load) == math.inf):
            self._set_number("breaking_load", 0.0, MAX_FORCE, "N (or inf: unbreakable)", low_inclusive=False)
        object.__setattr__(self, "breaking_load", float(self.breaking_load))
        if self.lumping not in LUMPING_RULES:
            raise TetherError(f"{self.label}: lumping must be one of {LUMPING_RULES}; got {short_repr(self.lumping)}")
        if not isinstance(self.name, str):
            raise TetherError(f"{self.label}: name must be a string; got {short_repr(self.name)}")
        if self.segments > 1 and self.mass == 0.0:
            raise TetherError(
                f"{self.label}: {self.segments} segments need a mass > 0 (its beads carry it); give the tether "
                "its mass in kg, or segments=1 for a massless cable"
            )
        if self.N0 >= self.EA:
            raise TetherError(
                f"{self.label}: pretension N0={self.N0:g} N is not below EA={self.EA:g} N, so each segment would be "
                "shorter than its pretension stretch (unstretched length L0 * (1 - N0/EA) <= 0); lower N0 or raise EA"
            )

    def _set_number(self, field: str, low: float, high: float, unit: str, *, low_inclusive: bool = True) -> None:
        value = getattr(self, field)
        number = to_float(value) if is_real_number(value) else math.nan
        inside = (number >= low if low_inclusive else number > low) and number <= high
        if not inside:
            bracket = "[" if low_inclusive else "("
            raise TetherError(
                f"{self.label}: {field} must be a number in {bracket}{low:g}, {high:g}] {unit}; got {short_repr(value)}"
            )
        object.__setattr__(self, field, number)

    @property
    def label(self) -> str:
        """How messages name this tether: ``tether 'name'`` or ``tether between satellites a and b``."""
        if isinstance(self.name, str) and self.name:
            return f"tether {self.name!r}"
        ends = self.ends
        if isinstance(ends, (tuple, list)) and len(ends) == 2:
            return f"tether between satellites {ends[0]} and {ends[1]}"
        return "tether"

    @property
    def num_beads(self) -> int:
        """N - 1."""
        return self.segments - 1

    @property
    def bead_mass(self) -> float:
        """Mass of each bead, kg (0 when the tether has no beads)."""
        if self.segments == 1:
            return 0.0
        return self.mass / self.segments if self.lumping == "half" else self.mass / (self.segments - 1)

    @property
    def end_mass(self) -> float:
        """Mass added to each end satellite, kg: ``m_t / (2 N)`` with ``"half"`` lumping, else 0."""
        return self.mass / (2 * self.segments) if self.lumping == "half" else 0.0

    def to_dict(self) -> dict[str, Any]:
        """Every field as plain values (the ends as a list), for cluster files."""
        if self.L0 is None:
            raise TetherError(f"{self.label}: only a tether with its L0 set can be written (build_cluster sets it)")
        return {
            "ends": list(self.ends),
            "EA": self.EA,
            "segments": self.segments,
            "mass": self.mass,
            "N0": self.N0,
            "L0": self.L0,
            "axial_damping": self.axial_damping,
            "breaking_load": self.breaking_load,
            "lumping": self.lumping,
            "name": self.name,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Tether:
        """A tether from :meth:`to_dict` output (unknown keys are an error)."""
        if isinstance(data, Tether):
            return data
        if not isinstance(data, Mapping):
            raise TetherError(f"a tether is a mapping of field names to values; got {type(data).__name__}")
        fields = {f.name for f in dataclasses.fields(cls)}
        unknown = set(data) - fields
        if unknown:
            raise TetherError(f"unknown tether key(s) {sorted(map(str, unknown))}; allowed keys are {sorted(fields)}")
        missing = {"ends", "EA"} - set(data)
        if missing:
            raise TetherError(f"a tether lacks required key(s) {sorted(missing)}")
        values = dict(data)
        if isinstance(values["ends"], list):
            values["ends"] = tuple(values["ends"])
        return cls(**values)

    def segment_parameters(self, length: float) -> dict[str, float]:
        """Each segment's cable parameters for a tether of reference length ``length`` (m):
        ``L0`` (m), ``EA`` (N), ``N0`` (N), ``axial_damping`` (N*s/m), ``breaking_load`` (N)."""
        return {
            "L0": length / self.segments,
            "EA": self.EA,
            "N0": self.N0,
            "axial_damping": self.axial_damping * self.segments,
            "breaking_load": self.breaking_load,
        }


def build_cluster(
    positions: ArrayLike,
    masses: ArrayLike,
    tethers: Sequence[Tether],
    *,
    damping: ArrayLike = 0.0,
    frame: Frame | None = None,
    name: str = "custom",
) -> Any:
    """A :class:`~tether_gym.cluster.Cluster` of satellites joined by tethers with beads.

    Args:
        positions: (S, 3) satellite positions, m.
        masses: (S,) or scalar satellite masses, kg (before the tethers' lumped mass is added).
        tethers: the tethers; tether ``t``'s beads are nodes ``S + sum_{u<t} (N_u - 1) + k`` for
            ``k = 0 .. N_t - 2``, from ``ends[0]`` to ``ends[1]``, and its segments are the cables
            ``sum_{u<t} N_u + k``, ``k = 0 .. N_t - 1``, in the same order.
        damping: (S,) or scalar diagonal damping of the satellites, N*s/m; beads have none (a
            line's physical damping is its axial damping).
        frame: the frame of ``positions`` (default inertial).  In a Hill or rotating frame each
            tether's segment pretensions vary along the line by the frame's load on its beads
            along the chord (gravity gradient, centripetal load), about a mean of the spec's
            ``N0``, so that the straight line is in equilibrium along itself; a load across the
            line is left to :func:`static_equilibrium`, which finds the sagged shape.
        name: the cluster's label.

    Returns:
        The cluster, holding the tether specs with each ``L0`` filled in (a tether's ``L0=None``
        becomes the distance between its satellites).  Bad specs raise :class:`TetherError`
        naming the tether by its index.
    """
    from tether_gym.cluster import Cluster, ClusterError
    from tether_gym.limits import real_array

    sat_positions = real_array("positions", positions, ClusterError)
    if sat_positions.ndim != 2 or sat_positions.shape[1] != 3 or sat_positions.shape[0] < 2:
        raise ClusterError(f"positions must have shape (S, 3) with S >= 2 satellites; got shape {sat_positions.shape}")
    S = sat_positions.shape[0]
    sat_masses = real_array("masses", masses, ClusterError)
    if sat_masses.ndim == 0:
        sat_masses = np.full(S, float(sat_masses))
    if sat_masses.shape != (S,):
        raise ClusterError(f"masses must have shape ({S},) (kg per satellite) or be a scalar; got {sat_masses.shape}")
    sat_damping = real_array("damping", damping, ClusterError)
    if sat_damping.ndim == 0:
        sat_damping = np.full(S, float(sat_damping))
    if sat_damping.shape != (S,):
        raise ClusterError(
            f"damping must have shape ({S},) (N*s/m per satellite) or be a scalar; got {sat_damping.shape}"
        )
    if isinstance(tethers, (Tether, Mapping)) or not isinstance(tethers, Sequence) or len(tethers) == 0:
        raise TetherError("tethers must be a non-empty sequence of Tether specs")

    node_positions = [sat_positions]
    node_masses = [sat_masses.copy()]
    cables: list[tuple[int, int]] = []
    columns: dict[str, list[float]] = {key: [] for key in ("L0", "EA", "N0", "axial_damping", "breaking_load")}
    resolved: list[Tether] = []
    next_bead = S
    for t, spec in enumerate(tethers):
        spec = _indexed(t, spec)
        a, b = spec.ends
        if max(a, b) >= S:
            raise TetherError(
                f"tether {t} ({spec.label}) ends at satellite {max(a, b)}, but there are {S} satellites (0..{S - 1})"
            )
        chord = sat_positions[b] - sat_positions[a]
        spec, params = _resolved(t, spec, float(np.linalg.norm(chord)) if spec.L0 is None else spec.L0)
        beads = list(range(next_bead, next_bead + spec.num_beads))
        next_bead += spec.num_beads
        fractions = np.arange(1, spec.segments)[:, None] / spec.segments
        bead_positions = sat_positions[a] + fractions * chord
        node_positions.append(bead_positions)
        node_masses.append(np.full(spec.num_beads, spec.bead_mass))
        node_masses[0][a] += spec.end_mass
        node_masses[0][b] += spec.end_mass
        pretension = np.full(spec.segments, spec.N0)
        if frame is not None and not frame.is_inertial and spec.num_beads:
            pretension = _pretension_profile(t, spec, frame, bead_positions, chord)
        chain = [a, *beads, b]
        for k in range(spec.segments):
            cables.append((chain[k], chain[k + 1]))
            for key, value in params.items():
                columns[key].append(float(pretension[k]) if key == "N0" else value)
        resolved.append(spec)

    n_beads = next_bead - S
    all_damping = np.concatenate([sat_damping, np.zeros(n_beads)])
    return Cluster(
        positions=np.concatenate(node_positions),
        masses=np.concatenate(node_masses),
        cables=np.array(cables, dtype=np.int64).reshape(-1, 2),
        damping=all_damping,
        frame=Frame.inertial() if frame is None else frame,
        name=name,
        tethers=tuple(resolved),
        **{key: np.array(values) for key, values in columns.items()},
    )


def _resolved(t: int, spec: Tether, length: float) -> tuple[Tether, dict[str, float]]:
    """Tether ``t`` with its reference length ``length`` (m) filled in, and its segments'
    parameters; a mesh the limits refuse raises :class:`TetherError` naming the tether."""
    if not MIN_LENGTH <= length <= MAX_LENGTH:
        raise TetherError(
            f"tether {t} ({spec.label}): its length {length:g} m (the distance between its satellites) must lie "
            f"in [{MIN_LENGTH:g}, {MAX_LENGTH:g}] m; move its satellites apart or give L0"
        )
    spec = dataclasses.replace(spec, L0=length)
    params = spec.segment_parameters(length)
    if params["L0"] < MIN_LENGTH:
        raise TetherError(
            f"tether {t} ({spec.label}): {spec.segments} segments of {length:g} m are {params['L0']:g} m each, "
            f"shorter than the {MIN_LENGTH:g} m minimum; use fewer segments"
        )
    if spec.segments > 1 and spec.bead_mass < MIN_BEAD_MASS:
        raise TetherError(
            f"tether {t} ({spec.label}): beads of {spec.bead_mass:g} kg are lighter than the {MIN_BEAD_MASS:g} kg "
            "minimum; use fewer segments or a heavier tether"
        )
    if params["axial_damping"] > MAX_DAMPING:
        raise TetherError(
            f"tether {t} ({spec.label}): axial_damping * segments = {params['axial_damping']:g} N*s/m exceeds "
            f"{MAX_DAMPING:g}; lower the damping or the segment count"
        )
    return spec, params


def _pretension_profile(
    t: int, spec: Tether, frame: Frame, bead_positions: np.ndarray, chord: np.ndarray
) -> np.ndarray:
    """(N,) segment pretensions, N, of a straight tether in equilibrium along itself under the
    frame's load ``m_b diag(T) x`` on its beads, with mean ``spec.N0``.

    Bead k sits between segments k - 1 and k: ``N_k - N_{k-1} + F_k . e = 0`` along the chord
    direction ``e``."""
    direction = chord / np.linalg.norm(chord)
    load = spec.bead_mass * (bead_positions * frame.tidal) @ direction  # (N-1,) N, along e
    steps = np.concatenate([[0.0], -np.cumsum(load)])
    profile = spec.N0 + (steps - steps.mean())
    if profile.min() < 0.0 or profile.max() >= spec.EA:
        raise TetherError(
            f"tether {t} ({spec.label}): the frame's load along the line varies its tension by "
            f"{np.ptp(profile):.4g} N about N0={spec.N0:g} N, which takes a segment's pretension out of [0, EA); "
            f"raise N0 to at least {spec.N0 - profile.min():.4g} N (or keep it below EA)"
        )
    return profile


def _indexed(t: int, spec: Any) -> Tether:
    """``spec`` as a :class:`Tether`, with any error prefixed by the tether's index."""
    if isinstance(spec, Tether):
        return spec
    try:
        return Tether.from_dict(spec)
    except TetherError as error:
        raise TetherError(f"tether {t}: {error}") from None
    except TypeError as error:
        raise TetherError(f"tether {t}: {error}") from None


@dataclasses.dataclass(frozen=True)
class TetherResults:
    """Per-tether quantities of B clusters at their current state; arrays are (B, T).

    Attributes:
        end_tension: (B, T, 2) tension of the first and last segment, N: the pulls the tether
            exerts on its satellites ``ends[0]`` and ``ends[1]``.
        peak_tension: (B, T) largest segment tension along the line, N.
        slack: (B, T) bool: some segment carries no tension, so the line does not pull end to end.
        slack_fraction: (B, T) fraction of its segments that are slack.
        sag: (B, T) largest distance of a bead from the chord between the end satellites, m (0
            without beads).
        broken: (B, T) bool: some segment broke since the reset; one broken segment severs the
            tether, which then joins its satellites no more.
    """

    end_tension: np.ndarray
    peak_tension: np.ndarray
    slack: np.ndarray
    slack_fraction: np.ndarray
    sag: np.ndarray
    broken: np.ndarray


def tether_results(cluster: Any, positions: ArrayLike, tension: ArrayLike, broken: ArrayLike) -> TetherResults:
    """Per-tether results of a cluster with tethers from node and cable arrays.

    Args:
        cluster: the :class:`~tether_gym.cluster.Cluster` (with ``tethers``).
        positions: (B, n, 3) node positions, m (e.g. ``BatchSimulator.positions``).
        tension: (B, m) cable tensions, N (``BatchSimulator.tension``).
        broken: (B, m) bool, broken cables (``BatchSimulator.broken``).
    """
    x = np.asarray(positions, dtype=np.float64)
    tension_array = np.asarray(tension, dtype=np.float64)
    broken_array = np.asarray(broken, dtype=bool)
    n, m = cluster.num_nodes, cluster.num_cables
    if x.ndim != 3 or x.shape[1:] != (n, 3):
        raise ValueError(f"positions must have shape (B, {n}, 3); got {x.shape}")
    B = x.shape[0]
    for what, array in (("tension", tension_array), ("broken", broken_array)):
        if array.shape != (B, m):
            raise ValueError(f"{what} must have shape ({B}, {m}) (B clusters, m cables); got {array.shape}")
    T = cluster.num_tethers
    end_tension = np.zeros((B, T, 2))
    peak, slack_fraction, sag = np.zeros((B, T)), np.zeros((B, T)), np.zeros((B, T))
    severed = np.zeros((B, T), dtype=bool)
    for t, spec in enumerate(cluster.tethers):
        segments = cluster.tether_cables(t)
        line = tension_array[:, segments]
        end_tension[:, t, 0], end_tension[:, t, 1] = line[:, 0], line[:, -1]
        peak[:, t] = line.max(axis=1)
        slack_fraction[:, t] = (line <= 0.0).mean(axis=1)
        severed[:, t] = broken_array[:, segments].any(axis=1)
        beads = cluster.tether_beads(t)
        if beads.size:
            a, b = spec.ends
            start = x[:, a, None, :]
            chord = x[:, b, None, :] - start
            offset = x[:, beads, :] - start
            along = (offset * chord).sum(axis=2) / np.maximum((chord * chord).sum(axis=2), 1e-300)
            across = offset - along[:, :, None] * chord
            sag[:, t] = np.linalg.norm(across, axis=2).max(axis=1)
    return TetherResults(
        end_tension=end_tension,
        peak_tension=peak,
        slack=slack_fraction > 0.0,
        slack_fraction=slack_fraction,
        sag=sag,
        broken=severed,
    )


@dataclasses.dataclass(frozen=True)
class StaticEquilibrium:
    """The static equilibrium of a cluster's beads with its satellites held.

    Attributes:
        positions: (n, 3) node positions, m: the satellites where they were held, the beads in
            equilibrium (the nominal shape of the tethers, sagged by any load across them).
        tension: (m,) cable tensions there, N: each tether's tension profile.
        residual: largest force left on a bead, N.
        iterations: Newton iterations taken.
    """

    positions: np.ndarray
    tension: np.ndarray
    residual: float
    iterations: int


def static_equilibrium(
    cluster: Any, positions: ArrayLike | None = None, *, tolerance: float = 1e-10, max_iterations: int = 50
) -> StaticEquilibrium:
    """Solve for the beads' equilibrium in the cluster's frame, the satellites held at ``positions``.

    Newton's method on the beads' net force ``f_int(x) - M diag(T) x`` (the simulator's
    :meth:`~tether_gym.BatchSimulator.equilibrium_force`, from the compiled force kernel), with the
    tangent stiffness of :func:`tether_gym.analysis.tangent_stiffness` (taut branch) plus the
    frame's stiffness as the Jacobian.

    Args:
        cluster: a :class:`~tether_gym.cluster.Cluster`.
        positions: (n, 3) start, m (default: the cluster's positions); its satellites stay there.
        tolerance: stop when the largest force on a bead is below ``tolerance`` times the largest
            segment tension (N/N).
        max_iterations: Newton iterations allowed.

    Raises:
        ValueError: no convergence in ``max_iterations`` (e.g. a slack tether, whose beads have
            no equilibrium: raise its pretension).
    """
    from tether_gym.analysis import frame_stiffness, tangent_stiffness
    from tether_gym.simulator import BatchSimulator

    x = np.array(cluster.positions if positions is None else positions, dtype=np.float64)
    if x.shape != cluster.positions.shape or not np.isfinite(x).all():
        raise ValueError(f"positions must be a finite array of shape {cluster.positions.shape}; got {x.shape}")
    if not is_real_number(tolerance) or not 0.0 < to_float(tolerance) < 1.0:
        raise ValueError(f"tolerance must be a number in (0, 1); got {tolerance!r}")
    if not is_whole_number(max_iterations) or max_iterations < 1:
        raise ValueError(f"max_iterations must be a whole number >= 1; got {max_iterations!r}")
    beads = np.flatnonzero(cluster.is_bead)
    dofs = (3 * beads[:, None] + np.arange(3)[None, :]).ravel()
    sim = BatchSimulator(cluster, 1)
    frame_part = frame_stiffness(cluster)
    residual = math.inf
    for iteration in range(int(max_iterations) + 1):
        sim.reset(x[None])
        force = sim.equilibrium_force(x[None])[0]
        scale = max(float(sim.tension[0].max()), 1e-300)
        residual = float(np.abs(force[beads]).max()) if beads.size else 0.0
        if residual <= tolerance * scale:
            return StaticEquilibrium(x, sim.tension[0].copy(), residual, iteration)
        if iteration == max_iterations:
            break
        jacobian = (tangent_stiffness(cluster, x, taut_branch=True) + frame_part)[np.ix_(dofs, dofs)]
        step = np.linalg.lstsq(jacobian, -force[beads].ravel(), rcond=None)[0]
        x[beads] += step.reshape(-1, 3)
    raise ValueError(
        f"static_equilibrium did not converge in {max_iterations} iterations: a force of {residual:.3g} N is left "
        "on a bead; a slack tether has no equilibrium (raise its N0), or allow more iterations"
    )


def _funicular(
    t: int, spec: Tether, start: np.ndarray, end: np.ndarray, tidal: np.ndarray, level: float
) -> tuple[np.ndarray, np.ndarray]:
    """Tether ``t``'s lumped line in equilibrium under the frame's load ``m_b diag(tidal) x`` on
    its beads, between satellites held at ``start`` and ``end`` (m), with equal segment lengths
    and mean segment tension ``level`` (N).

    Returns ``(nodes, forces)``: (N + 1, 3) the line's nodes from ``start`` to ``end``, m, and
    (N, 3) each segment's pull ``T_k e_k`` on its first node, N.  Newton's method on the first
    segment's pull and the segment length, with a finite-difference Jacobian (4 unknowns).
    """
    N, bead_mass = spec.segments, spec.bead_mass
    chord = end - start
    length = float(np.linalg.norm(chord))

    def line(unknowns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        nodes, forces = np.empty((N + 1, 3)), np.empty((N, 3))
        nodes[0], force, step = start, unknowns[:3].copy(), unknowns[3]
        for k in range(N):
            forces[k] = force
            nodes[k + 1] = nodes[k] + step * force / np.linalg.norm(force)
            force = force - bead_mass * tidal * nodes[k + 1]  # bead k+1: F_k = F_{k-1} - m_b diag(T) x
        return nodes, forces

    def residual(unknowns: np.ndarray) -> np.ndarray:
        nodes, forces = line(unknowns)
        miss = (nodes[-1] - end) / length
        return np.append(miss, np.linalg.norm(forces, axis=1).mean() / level - 1.0)

    straight = start + (np.arange(1, N) / N)[:, None] * chord
    load = (bead_mass * tidal * straight).sum(axis=0)
    unknowns = np.append(level * chord / length + 0.5 * load, length / N)
    scale = np.array([level, level, level, length / N])
    for _ in range(60):
        error = residual(unknowns)
        if np.abs(error).max() <= 1e-14:
            break
        jacobian = np.empty((4, 4))
        for j in range(4):
            shifted = unknowns.copy()
            shifted[j] += 1e-7 * scale[j]
            jacobian[:, j] = (residual(shifted) - error) / (1e-7 * scale[j])
        step = np.linalg.lstsq(jacobian, error, rcond=None)[0]
        # Backtrack: far from the solution a full step can fold the line past its funicular.
        for _ in range(30):
            trial = unknowns - step
            if np.abs(trial[:3]).max() > 0.0 and trial[3] > 0.0:
                trial_error = residual(trial)
                if np.isfinite(trial_error).all() and np.abs(trial_error).max() < np.abs(error).max():
                    break
            step = 0.5 * step
        unknowns = trial
    else:
        raise TetherError(
            f"tether {t} ({spec.label}): no equilibrium shape at a mean tension of {level:.4g} N under the frame's "
            "load on its mass (the line would sag without bound); raise its pretension or lower its mass"
        )
    nodes, forces = line(unknowns)
    nodes[-1] = end
    return nodes, forces


def _starting_levels(tethers: Sequence[Tether], x: np.ndarray, tidal: np.ndarray) -> np.ndarray:
    """(T,) the tethers' pretensions, N, where :func:`frame_held` starts: each spec's ``N0``, or
    for a line without pretension the frame's load on its own mass (it needs some tension to hang)."""
    levels = np.array([spec.N0 for spec in tethers], dtype=np.float64)
    for t, spec in enumerate(tethers):
        if levels[t] <= 0.0:
            a, b = spec.ends
            beads = x[a] + (np.arange(1, spec.segments) / spec.segments)[:, None] * (x[b] - x[a])
            own_load = float(np.linalg.norm((spec.bead_mass * tidal * beads).sum(axis=0)))
            levels[t] = max(own_load, 1e-6 * max(float(levels.max()), 1e-300))
    return levels


def _damped_step(
    name: str, count: int, levels: np.ndarray, change: np.ndarray, hang: Callable[[int, float], Any]
) -> np.ndarray:
    """``levels - change`` (N), the change halved until every one of the ``count`` lines has a
    funicular (``hang(t, level)`` raises :class:`TetherError` for a line too slack for its own
    load) and keeps some tension."""
    for _ in range(30):
        trial = levels - change
        if (trial > 0.0).all():
            try:
                for t in range(count):
                    hang(t, trial[t])
                return trial
            except TetherError:
                pass
        change = 0.5 * change
    raise TetherError(
        f"the frame's load cannot hold the satellites of cluster {name!r} on their tethers alone: no tension "
        "level lets every line hang in the frame's load (lighter lines or a slower turn)"
    )


def frame_held(cluster: Any, *, tolerance: float = 1e-12, max_iterations: int = 40) -> Any:
    """The cluster with its tethers shaped and tensioned so that its frame's load alone holds it.

    In a turning frame (Hill, spinning) the frame's load ``m diag(T) x`` pulls on the satellites
    and on the tethers' beads.  Each tether is put on the funicular of the load on its own mass
    (its beads in static equilibrium, segments of equal length; a rim line of a spinning formation
    bows outward), and each segment's ``L0`` and ``N0`` become its length and tension on that
    shape, so the nominal shape is in equilibrium at the segments' reference lengths.  A tether's
    pretension (its spec's ``N0``) is then its mean segment tension along the funicular; the
    pretensions are the cluster's own ones plus the smallest (least-squares) change that lets the
    frame's load alone hold every satellite, including the satellites' share of their tethers'
    load, so the bias thrust ``f_int(nominal)`` of the satellites vanishes to round-off wherever
    the frame alone can hold the shape.  The satellites stay where they are; plain cables keep
    their ``N0``.  Without beads or in an inertial frame the cluster is returned unchanged.

    Args:
        cluster: a :class:`~tether_gym.cluster.Cluster` from :func:`build_cluster`.
        tolerance: stop when the largest force left on a satellite is below ``tolerance`` times the
            largest load of the frame on one (N/N).
        max_iterations: Gauss-Newton iterations on the pretensions.

    Raises:
        TetherError: no tension level lets a tether hang in the frame's load (naming it), or the
            frame cannot hold the satellites (the shape needs thrust: not a turning-frame formation).
    """
    if not cluster.num_beads or cluster.frame.is_inertial:
        return cluster
    tidal = cluster.frame.tidal
    S, tethers = cluster.num_satellites, cluster.tethers
    x = cluster.positions
    masses = cluster.masses[:S]
    frame_load = masses[:, None] * tidal * x[:S]  # (S, 3) N
    plain = cluster.num_cables - sum(spec.segments for spec in tethers)
    for c in range(plain):
        i, j = cluster.cables[c]
        pull = cluster.N0[c] * (x[j] - x[i]) / np.linalg.norm(x[j] - x[i])
        frame_load[i] += pull
        frame_load[j] -= pull
    scale = max(float(np.abs(masses[:, None] * tidal * x[:S]).max()), 1e-300)

    def end_forces(t: int, level: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        a, b = tethers[t].ends
        nodes, forces = _funicular(t, tethers[t], x[a], x[b], tidal, level)
        return nodes, forces, np.stack([forces[0], -forces[-1]])

    levels = _starting_levels(tethers, x, tidal)
    weights = levels.copy()  # changes are measured relative to each line's own pretension
    # Each step aims at the least total change from the starting levels (relative to each) that
    # zeroes the linearised forces: where the formation is statically indeterminate (the spinning
    # hub's spokes and rim) this picks one answer, independent of the path and of the mesh.
    for iteration in range(max_iterations + 1):
        net = frame_load.copy()
        slopes = np.zeros((3 * S, len(tethers)))
        for t, spec in enumerate(tethers):
            a, b = spec.ends
            pulls = end_forces(t, levels[t])[2]
            net[a] += pulls[0]
            net[b] += pulls[1]
            h = 1e-7 * max(levels[t], 1e-3)
            slope = (end_forces(t, levels[t] + h)[2] - pulls) / h
            slopes[3 * a : 3 * a + 3, t] = slope[0]
            slopes[3 * b : 3 * b + 3, t] = slope[1]
        target = slopes @ (levels - weights) - net.ravel()
        # rcond: a self-stress of the formation is an exact null direction, which the
        # finite-difference slopes blur to singular values of about 1e-10 of the largest.
        deviation = weights * np.linalg.lstsq(slopes * weights, target, rcond=1e-7)[0]
        change = levels - (weights + deviation)
        if np.abs(net).max() <= tolerance * scale and np.abs(change / weights).max() <= 1e-9:
            break
        if iteration == max_iterations:
            raise TetherError(
                f"the frame's load cannot hold the satellites of cluster {cluster.name!r} on their tethers alone: "
                f"a force of {np.abs(net).max():.3g} N is left on a satellite after {max_iterations} iterations "
                "(a shape the frame does not hold needs thrust)"
            )
        levels = _damped_step(cluster.name, len(tethers), levels, change, end_forces)
    positions = x.copy()
    L0, N0 = cluster.L0.copy(), cluster.N0.copy()
    specs = []
    for t, spec in enumerate(tethers):
        nodes, forces, _ = end_forces(t, levels[t])
        positions[cluster.tether_beads(t)] = nodes[1:-1]
        segments = cluster.tether_cables(t)
        L0[segments] = np.linalg.norm(np.diff(nodes, axis=0), axis=1)
        N0[segments] = np.linalg.norm(forces, axis=1)
        if N0[segments].max() >= spec.EA:
            raise TetherError(
                f"tether {t} ({spec.label}): holding its satellites in the frame needs {N0[segments].max():.4g} N, "
                f"not below its EA={spec.EA:g} N; raise EA or lower the load"
            )
        specs.append(dataclasses.replace(spec, N0=float(levels[t]), L0=float(L0[segments].sum())))
    return cluster.replace(positions=positions, L0=L0, N0=N0, tethers=tuple(specs))
