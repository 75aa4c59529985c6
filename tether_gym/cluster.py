"""The description of a cluster of tethered satellites: validated on construction, immutable after.

A :class:`Cluster` holds everything the physics needs and nothing about control: node positions,
masses and diagonal damping, the cables with their axial stiffness, reference length,
pretension, axial (Kelvin-Voigt) damping and breaking load, and the frame the positions are
written in (inertial, orbiting or spinning).  Clusters are saved to and loaded from plain JSON or TOML files so
that users can describe their own.
"""

from __future__ import annotations

import dataclasses
import json
import math
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from tether_gym.frames import Frame, FrameError
from tether_gym.limits import (
    MAX_COORDINATE,
    MAX_DAMPING,
    MAX_EA,
    MAX_FORCE,
    MAX_LENGTH,
    MAX_MASS,
    MIN_BEAD_MASS,
    MIN_EA,
    MIN_LENGTH,
    MIN_MASS,
    check_range,
    is_whole_number,
    real_array,
)
from tether_gym.tethers import Tether, TetherError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - exercised on Python 3.10 only
    import tomli as tomllib

__all__ = ["Cluster", "ClusterError", "load_cluster", "save_cluster"]


class ClusterError(ValueError):
    """An invalid cluster description; the message names the problem and how to fix it."""


def _float_array(name: str, value: ArrayLike, shape: tuple[int, ...], what: str, allow_inf: bool = False) -> np.ndarray:
    """Convert ``value`` to a read-only float64 array of ``shape``, broadcasting scalars; anything
    but real numbers (strings, booleans, NaN, and infinities unless ``allow_inf``) is refused."""
    array = real_array(name, value, ClusterError, allow_inf=allow_inf)
    if array.ndim == 0:
        array = np.full(shape, float(array))
    if array.shape != shape:
        raise ClusterError(f"{name} must have shape {shape} ({what}) or be a scalar; got shape {array.shape}")
    array.setflags(write=False)
    return array


def _connected(n_nodes: int, cables: np.ndarray) -> np.ndarray:
    """Boolean mask (n,) of the nodes reachable from node 0 through the cables."""
    neighbours: list[list[int]] = [[] for _ in range(n_nodes)]
    for i, j in cables:
        neighbours[i].append(j)
        neighbours[j].append(i)
    seen = np.zeros(n_nodes, dtype=bool)
    seen[0] = True
    stack = [0]
    while stack:
        node = stack.pop()
        for other in neighbours[node]:
            if not seen[other]:
                seen[other] = True
                stack.append(other)
    return seen


def _tether_layout(tethers: Any, n_nodes: int) -> tuple[tuple[Tether, ...], np.ndarray]:
    """The checked tether specs and the (n,) tether index of each node (-1 for a satellite)."""
    node_tether = np.full(n_nodes, -1, dtype=np.int64)
    if isinstance(tethers, (tuple, list)) and len(tethers) == 0:
        return (), node_tether
    if isinstance(tethers, (str, bytes, Mapping, Tether)) or not isinstance(tethers, Sequence):
        raise ClusterError(f"tethers must be a list of tether specs (tether_gym.tethers.Tether); got {tethers!r:.120}")
    specs: list[Tether] = []
    for t, spec in enumerate(tethers):
        try:
            specs.append(Tether.from_dict(spec))
        except (TetherError, TypeError) as error:
            raise ClusterError(f"tether {t}: {error}") from None
        if specs[-1].L0 is None:
            raise ClusterError(
                f"tether {t} ({specs[-1].label}): L0 is not set; a cluster's tethers carry their reference length "
                "(tether_gym.tethers.build_cluster fills it in)"
            )
    n_beads = sum(spec.num_beads for spec in specs)
    n_satellites = n_nodes - n_beads
    if n_satellites < 2:
        raise ClusterError(
            f"the tethers have {n_beads} beads in all, but the cluster has only {n_nodes} nodes: it needs its "
            "satellites (at least 2) first, then the beads; build it with tether_gym.tethers.build_cluster"
        )
    first = n_satellites
    for t, spec in enumerate(specs):
        node_tether[first : first + spec.num_beads] = t
        first += spec.num_beads
        for end in spec.ends:
            if end >= n_satellites:
                raise ClusterError(
                    f"tether {t} ({spec.label}) ends at node {end}, which is not a satellite: the satellites are "
                    f"nodes 0..{n_satellites - 1} and the beads come after them"
                )
    return tuple(specs), node_tether


def _node_label(node: int, n_satellites: int, tethers: tuple[Tether, ...]) -> str:
    """``"satellite i"``, or ``"bead k of tether t"`` (k from 0 at the tether's first end)."""
    if node < n_satellites:
        return f"satellite {node}"
    first = n_satellites
    for t, spec in enumerate(tethers):
        if node < first + spec.num_beads:
            return f"bead {node - first} of tether {t} (node {node})"
        first += spec.num_beads
    return f"node {node}"


def _check_nodes(
    name: str,
    values: np.ndarray,
    low: float,
    high: float,
    unit: str,
    n_satellites: int,
    tethers: tuple[Tether, ...],
    *,
    where: str = "satellite",
    bead_low: float | None = None,
) -> None:
    """:func:`check_range` over per-node ``values`` ((n,) or (n, 3)); the satellites are checked
    first, as before beads existed, and a bead out of range is named as a bead of its tether
    (beads may be as light as ``bead_low``)."""
    check_range(name, values[:n_satellites], low, high, unit, error=ClusterError, where=where)
    beads = values[n_satellites:]
    if beads.shape[0] == 0:
        return
    bead_min = low if bead_low is None else bead_low
    bad = (beads < bead_min) | (beads > high) | np.isnan(beads)
    if bad.any():
        index = tuple(int(i) for i in np.argwhere(bad)[0])
        label = _node_label(n_satellites + index[0], n_satellites, tethers)
        axis = f", axis {index[1]}" if len(index) > 1 else ""
        raise ClusterError(f"{name} must lie in [{bead_min:g}, {high:g}] {unit}; got {beads[index]} ({label}{axis})")


def _check_tether_cables(tethers: tuple[Tether, ...], cables: np.ndarray, n_satellites: int, n_nodes: int) -> None:
    """Refuse cables that do not hold each tether's segments, in order, after the plain cables,
    or plain cables that touch a bead."""
    if not tethers:
        return
    n_segments = sum(spec.segments for spec in tethers)
    n_plain = cables.shape[0] - n_segments
    if n_plain < 0:
        raise ClusterError(
            f"the tethers have {n_segments} segments in all, but the cluster has only {cables.shape[0]} cables; "
            "the last cables must be the tethers' segments (build it with tether_gym.tethers.build_cluster)"
        )
    touching = np.flatnonzero((cables[:n_plain] >= n_satellites).any(axis=1))
    if touching.size:
        c = int(touching[0])
        node = int(cables[c].max())
        raise ClusterError(
            f"cable {c} is not a tether segment but joins {_node_label(node, n_satellites, tethers)}; "
            "a bead is joined only to its neighbours along its tether"
        )
    bead, cable = n_satellites, n_plain
    for t, spec in enumerate(tethers):
        chain = [spec.ends[0], *range(bead, bead + spec.num_beads), spec.ends[1]]
        expected = np.array([chain[:-1], chain[1:]], dtype=np.int64).T
        found = cables[cable : cable + spec.segments]
        if not np.array_equal(found, expected):
            raise ClusterError(
                f"tether {t} ({spec.label}): cables {cable}..{cable + spec.segments - 1} must be its segments "
                f"{expected.tolist()} (from satellite {spec.ends[0]} through its beads to satellite {spec.ends[1]}); "
                f"got {found.tolist()}"
            )
        bead += spec.num_beads
        cable += spec.segments


def _cable_lengths(
    positions: np.ndarray, cables: np.ndarray, n_satellites: int, tethers: tuple[Tether, ...]
) -> np.ndarray:
    """(m,) distances between each cable's nodes, m; a zero length or a disconnected cluster is
    refused, naming the nodes (a bead as a bead of its tether)."""
    lengths = np.linalg.norm(positions[cables[:, 1]] - positions[cables[:, 0]], axis=1)
    if np.any(lengths <= 0.0):
        c = int(np.argmax(lengths <= 0.0))
        if tethers:
            i, j = (_node_label(int(k), n_satellites, tethers) for k in cables[c])
            raise ClusterError(
                f"positions give cable {c} zero length: {i} and {j} share the same position; "
                "give every node a distinct position"
            )
        raise ClusterError(
            f"positions give cable {c} zero length: nodes {tuple(int(k) for k in cables[c])} share the "
            "same position; give every satellite a distinct position"
        )
    reachable = _connected(positions.shape[0], cables)
    if not np.all(reachable):
        # A bead is always linked to its tether's satellites: only satellites can be cut off.
        loose = [int(k) for k in np.flatnonzero(~reachable[:n_satellites])]
        raise ClusterError(
            f"the cluster is disconnected: satellites {loose} are not linked to satellite 0 by "
            "any chain of cables; add cables or simulate the parts as separate clusters"
        )
    return lengths


@dataclasses.dataclass(frozen=True, eq=False)
class Cluster:
    """A cluster of point-mass satellites joined by massless, linear-elastic, tension-only cables.

    Cable ``c`` joining nodes ``i, j`` carries the axial force
    ``N = max(0, N0 + EA/L0 * dL + c_ax * dL')`` while taut (``N0 + EA/L0 dL > 0``) and none
    while slack, with ``dL = |x_j - x_i| - L0``; once its tension passes ``breaking_load`` it
    breaks and carries nothing until the simulator is reset.  Scalars are broadcast to every node or
    cable.  All arrays are stored as read-only float64 (int64 for ``cables``).

    Args:
        positions: (n, 3) nominal node positions, m.  They are the reference configuration: the
            default cable lengths, and the reference of the paper's linearised elongation.
        masses: (n,) or scalar node masses, kg, all > 0.
        cables: (m, 2) pairs of node indices; no self-loops, no duplicates, every node connected.
        EA: (m,) or scalar axial stiffness (Young's modulus times area), N, > 0.
        N0: (m,) or scalar pretension, N, >= 0 (default 0).
        damping: (n,) or scalar diagonal damping coefficient per node, N*s/m, >= 0 (default 0).
        L0: (m,) or scalar reference (unstretched-plus-pretension) length, m, > 0; default: the
            distance between the cable's nodes in ``positions``.
        breaking_load: (m,) or scalar tension at which a cable breaks, N, > 0 (default inf).
        axial_damping: (m,) or scalar Kelvin-Voigt damping ``c_ax`` of each cable, N*s/m, >= 0
            (default 0): the physical alternative to the paper's diagonal damping, acting only
            on the cable's stretching rate, and only while it is taut.
        frame: the :class:`~tether_gym.frames.Frame` of ``positions`` and of the motion (default
            inertial); a Hill or rotating frame adds Coriolis, centrifugal and tidal forces.
        name: a short label.
        tethers: the :class:`~tether_gym.tethers.Tether` specs of the tethers with beads (default
            none: every node is a satellite).  With tethers, the first ``S = n - sum(N_t - 1)``
            nodes are the satellites, then come the beads of tether 0 from its ``ends[0]`` to its
            ``ends[1]``, then those of tether 1, ...; the last ``sum(N_t)`` cables are the
            tethers' segments in the same order (plain cables come first).  Build such clusters
            with :func:`tether_gym.tethers.build_cluster`.
    """

    # Each field is stored as an array (see __post_init__); the constructor takes anything array-like.
    positions: np.ndarray
    masses: np.ndarray
    cables: np.ndarray
    EA: np.ndarray
    N0: np.ndarray = 0.0  # type: ignore[assignment]
    damping: np.ndarray = 0.0  # type: ignore[assignment]
    L0: np.ndarray = None  # type: ignore[assignment]  # None: the distances in positions
    breaking_load: np.ndarray = math.inf  # type: ignore[assignment]
    axial_damping: np.ndarray = 0.0  # type: ignore[assignment]
    frame: Frame = dataclasses.field(default_factory=Frame.inertial)
    name: str = "custom"

    tethers: tuple[Tether, ...] = ()

    if TYPE_CHECKING:  # the signature type checkers see; at run time the dataclass's own

        def __init__(
            self,
            positions: ArrayLike,
            masses: ArrayLike,
            cables: ArrayLike,
            EA: ArrayLike,
            N0: ArrayLike = 0.0,
            damping: ArrayLike = 0.0,
            L0: ArrayLike | None = None,
            breaking_load: ArrayLike = math.inf,
            axial_damping: ArrayLike = 0.0,
            frame: Frame = ...,
            name: str = "custom",
            tethers: Sequence[Tether | Mapping[str, Any]] = (),
        ) -> None: ...

    def __post_init__(self) -> None:
        positions = real_array("positions", self.positions, ClusterError)
        if positions.ndim != 2 or positions.shape[1] != 3 or positions.shape[0] < 2:
            raise ClusterError(f"positions must have shape (n, 3) with n >= 2 satellites; got shape {positions.shape}")
        n_nodes = positions.shape[0]
        tethers, node_tether = _tether_layout(self.tethers, n_nodes)
        n_satellites = n_nodes - int((node_tether >= 0).sum())
        positions = _float_array("positions", positions, (n_nodes, 3), "node positions in m")
        _check_nodes(
            "positions",
            np.abs(positions),
            0.0,
            MAX_COORDINATE,
            "m (absolute value)",
            n_satellites,
            tethers,
            where="satellite, axis",
        )
        masses = _float_array("masses", self.masses, (n_nodes,), "kg per satellite")
        _check_nodes("masses", masses, MIN_MASS, MAX_MASS, "kg", n_satellites, tethers, bead_low=MIN_BEAD_MASS)
        damping = _float_array("damping", self.damping, (n_nodes,), "N*s/m per satellite")
        _check_nodes("damping", damping, 0.0, MAX_DAMPING, "N*s/m", n_satellites, tethers)

        cables = real_array("cables", self.cables, ClusterError)
        if cables.ndim != 2 or cables.shape[1] != 2 or cables.shape[0] < 1:
            raise ClusterError(
                f"cables must be a non-empty list of (i, j) node-index pairs, shape (m, 2); got shape {cables.shape}"
            )
        if np.any(cables != np.round(cables)):
            raise ClusterError("cables must hold whole node indices (integers)")
        outside = (cables < 0) | (cables >= n_nodes)
        if outside.any():
            c = int(np.argwhere(outside)[0, 0])
            raise ClusterError(
                f"cable {c} joins nodes {tuple(cables[c].tolist())}, but node indices must be in "
                f"0..{n_nodes - 1} for {n_nodes} satellites"
            )
        cables = cables.astype(np.int64)
        for c, (i, j) in enumerate(cables.tolist()):
            if i == j:
                raise ClusterError(f"cable {c} joins node {i} to itself; a cable needs two distinct nodes")
        seen: dict[tuple[int, int], int] = {}
        for c, (i, j) in enumerate(cables.tolist()):
            key = (min(i, j), max(i, j))
            if key in seen:
                raise ClusterError(
                    f"cables {seen[key]} and {c} both join nodes {key}; remove the duplicate "
                    "(model a stronger tether with a larger EA instead)"
                )
            seen[key] = c
        cables.setflags(write=False)
        n_cables = cables.shape[0]
        _check_tether_cables(tethers, cables, n_satellites, n_nodes)

        lengths = _cable_lengths(positions, cables, n_satellites, tethers)

        EA = _float_array("EA", self.EA, (n_cables,), "axial stiffness in N per cable")
        check_range("EA", EA, MIN_EA, MAX_EA, "N", error=ClusterError, where="cable")
        N0 = _float_array("N0", self.N0, (n_cables,), "pretension in N per cable")
        check_range("N0 (pretension)", N0, 0.0, MAX_FORCE, "N", error=ClusterError, where="cable")
        if self.L0 is None:
            check_range(
                "the distance between a cable's satellites (its default L0)",
                lengths,
                MIN_LENGTH,
                MAX_LENGTH,
                "m",
                error=ClusterError,
                where="cable",
            )
            L0 = lengths.copy()
            L0.setflags(write=False)
        else:
            L0 = _float_array("L0", self.L0, (n_cables,), "reference length in m per cable")
            check_range("L0", L0, MIN_LENGTH, MAX_LENGTH, "m", error=ClusterError, where="cable")
        breaking = _float_array(
            "breaking_load",
            self.breaking_load,
            (n_cables,),
            "tension in N per cable, inf for unbreakable",
            allow_inf=True,
        )
        check_range(
            "breaking_load",
            breaking,
            0.0,
            math.inf,
            "N (inf: unbreakable)",
            low_inclusive=False,
            error=ClusterError,
            where="cable",
        )
        finite_breaking = np.where(np.isinf(breaking), MAX_FORCE, breaking)
        check_range(
            "breaking_load",
            finite_breaking,
            0.0,
            MAX_FORCE,
            "N, or inf for unbreakable",
            low_inclusive=False,
            error=ClusterError,
            where="cable",
        )
        axial_damping = _float_array("axial_damping", self.axial_damping, (n_cables,), "N*s/m per cable")
        check_range("axial_damping", axial_damping, 0.0, MAX_DAMPING, "N*s/m", error=ClusterError, where="cable")
        try:
            frame = Frame.from_dict(self.frame)
        except (FrameError, TypeError) as error:
            raise ClusterError(f"invalid frame: {error}") from None
        if not isinstance(self.name, str):
            raise ClusterError(f"name must be a string; got {self.name!r}")

        for field, value in (
            ("positions", positions),
            ("masses", masses),
            ("damping", damping),
            ("cables", cables),
            ("EA", EA),
            ("N0", N0),
            ("L0", L0),
            ("breaking_load", breaking),
            ("axial_damping", axial_damping),
            ("frame", frame),
            ("tethers", tethers),
        ):
            object.__setattr__(self, field, value)
        object.__setattr__(self, "_node_tether", node_tether)
        object.__setattr__(self, "_num_satellites", n_satellites)

    # ------------------------------------------------------------------ derived quantities
    @property
    def num_nodes(self) -> int:
        """Number of satellites n."""
        return int(self.positions.shape[0])

    @property
    def num_satellites(self) -> int:
        """Number of satellites S: the nodes that carry thrusters; ``num_nodes`` without beads."""
        return int(self._num_satellites)  # type: ignore[attr-defined]

    @property
    def satellite_indices(self) -> np.ndarray:
        """(S,) node indices of the satellites: ``0 .. S - 1`` (the beads come after them)."""
        return np.arange(self.num_satellites)

    @property
    def num_beads(self) -> int:
        """Number of beads, n - S."""
        return self.num_nodes - self.num_satellites

    @property
    def num_tethers(self) -> int:
        """Number of tethers with a spec (0 for a cluster of plain cables)."""
        return len(self.tethers)

    @property
    def node_tether(self) -> np.ndarray:
        """(n,) int: the tether each node is a bead of, -1 for a satellite (a copy)."""
        return self._node_tether.copy()  # type: ignore[attr-defined]

    @property
    def is_bead(self) -> np.ndarray:
        """(n,) bool: True for beads, False for satellites."""
        return self._node_tether >= 0  # type: ignore[attr-defined]

    def _tether_index(self, tether: int) -> int:
        if not is_whole_number(tether) or not 0 <= tether < self.num_tethers:
            raise ValueError(
                f"tether must be a tether index in 0..{self.num_tethers - 1}; got {tether!r}"
                if self.num_tethers
                else f"this cluster has no tethers with beads (asked for tether {tether!r})"
            )
        return int(tether)

    def tether_beads(self, tether: int) -> np.ndarray:
        """(N_t - 1,) node indices of the beads of tether ``tether``, from its ``ends[0]`` to ``ends[1]``."""
        t = self._tether_index(tether)
        first = self.num_satellites + sum(spec.num_beads for spec in self.tethers[:t])
        return np.arange(first, first + self.tethers[t].num_beads)

    def tether_nodes(self, tether: int) -> np.ndarray:
        """(N_t + 1,) node indices along tether ``tether``: its first satellite, its beads, its second satellite."""
        t = self._tether_index(tether)
        a, b = self.tethers[t].ends
        return np.concatenate([[a], self.tether_beads(t), [b]]).astype(np.int64)

    def tether_cables(self, tether: int) -> np.ndarray:
        """(N_t,) cable indices of the segments of tether ``tether``, in order from ``ends[0]``."""
        t = self._tether_index(tether)
        first = self.num_cables - sum(spec.segments for spec in self.tethers[t:])
        return np.arange(first, first + self.tethers[t].segments)

    def node_label(self, node: int) -> str:
        """How messages name node ``node``: ``"satellite i"`` or ``"bead k of tether t (node i)"``."""
        return _node_label(int(node), self.num_satellites, self.tethers)

    @property
    def num_cables(self) -> int:
        """Number of cables m."""
        return int(self.cables.shape[0])

    @property
    def stiffness(self) -> np.ndarray:
        """(m,) axial spring constant EA / L0 of each cable, N/m."""
        return self.EA / self.L0

    @property
    def degree(self) -> np.ndarray:
        """(n,) number of cables meeting at each node."""
        return np.bincount(self.cables.ravel(), minlength=self.num_nodes)

    @property
    def inv_split_mass_sum(self) -> np.ndarray:
        """(m,) ``1/m_i^e + 1/m_j^e`` in 1/kg, with each node's mass split equally among its cables.

        The split makes the element mass matrices sum to the assembled one, the condition under
        which the largest element frequency bounds the system's (Irons-Treharne).
        """
        split = self.masses / self.degree
        return 1.0 / split[self.cables[:, 0]] + 1.0 / split[self.cables[:, 1]]

    def replace(self, **changes: Any) -> Cluster:
        """A new, validated cluster with some fields changed (``dataclasses.replace``)."""
        unknown = set(changes) - {f.name for f in dataclasses.fields(self)}
        if unknown:
            raise ClusterError(
                f"unknown Cluster field(s) {sorted(unknown)}; fields are {[f.name for f in dataclasses.fields(self)]}"
            )
        return dataclasses.replace(self, **changes)

    # ------------------------------------------------------------------ (de)serialisation
    def to_dict(self) -> dict[str, Any]:
        """Every field as plain Python values (lists of floats, SI units), for JSON and TOML.

        Nothing is left out, not even fields at their defaults, so that a cluster written and read
        back is equal to the original bit for bit (``-0.0`` and unbreakable ``inf`` loads included).
        """
        return {
            "name": self.name,
            "positions": self.positions.tolist(),
            "masses": self.masses.tolist(),
            "damping": self.damping.tolist(),
            "cables": self.cables.tolist(),
            "EA": self.EA.tolist(),
            "L0": self.L0.tolist(),
            "N0": self.N0.tolist(),
            "breaking_load": self.breaking_load.tolist(),
            "axial_damping": self.axial_damping.tolist(),
            "frame": self.frame.to_dict(),
        } | ({"tethers": [spec.to_dict() for spec in self.tethers]} if self.tethers else {})

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Cluster:
        """Build a cluster from :meth:`to_dict` output (unknown keys are an error)."""
        if not isinstance(data, Mapping):
            raise ClusterError(
                f"a cluster description is a mapping of field names to values; got {type(data).__name__}"
            )
        fields = {f.name for f in dataclasses.fields(cls)}
        unknown = set(data) - fields
        if unknown:
            raise ClusterError(f"unknown cluster key(s) {sorted(map(str, unknown))}; allowed keys are {sorted(fields)}")
        missing = {"positions", "masses", "cables", "EA"} - set(data)
        if missing:
            raise ClusterError(f"cluster description lacks required key(s) {sorted(missing)}")
        return cls(**dict(data))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Cluster):
            return NotImplemented
        return (
            self.name == other.name
            and self.frame == other.frame
            and self.tethers == other.tethers
            and all(
                np.array_equal(getattr(self, f), getattr(other, f))
                for f in (
                    "positions",
                    "masses",
                    "cables",
                    "EA",
                    "N0",
                    "damping",
                    "L0",
                    "breaking_load",
                    "axial_damping",
                )
            )
        )

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        frame = "" if self.frame.is_inertial else f", frame={self.frame.kind} at {self.frame.rate:.4g} rad/s"
        beads = f", tethers={self.num_tethers} with {self.num_beads} beads" if self.tethers else ""
        return (
            f"Cluster(name={self.name!r}, satellites={self.num_satellites}, cables={self.num_cables}{beads}, "
            f"mass={self.masses.sum():.4g} kg{frame})"
        )


#: Cluster files larger than this are refused: a cluster of 10^4 satellites fits in a few MB.
MAX_FILE_BYTES = 64 * 2**20


def _strict_json(data: Any) -> Any:
    """``data`` with every infinite float written as the string ``"inf"``: strict JSON has no
    infinity, and only breaking loads may be infinite (NaN never reaches a file)."""
    if isinstance(data, float) and math.isinf(data):
        return "inf" if data > 0 else "-inf"
    if isinstance(data, list):
        return [_strict_json(item) for item in data]
    if isinstance(data, dict):
        return {key: _strict_json(value) for key, value in data.items()}
    return data


def save_cluster(cluster: Cluster, path: str | Path) -> Path:
    """Write ``cluster`` to ``path`` as JSON (``.json``) or TOML (``.toml``); returns the path.

    Every field is written, and floats are written with the shortest repr that reads back to the
    same bits, so :func:`load_cluster` returns a cluster equal to ``cluster`` bit for bit.  JSON
    files are strict JSON (an unbreakable cable's load is the string ``"inf"``).
    """
    if not isinstance(cluster, Cluster):
        raise TypeError(f"save_cluster takes a Cluster; got {type(cluster).__name__}")
    path = Path(path)
    data = cluster.to_dict()
    if path.suffix == ".json":
        text = json.dumps(_strict_json(data), indent=2, allow_nan=False) + "\n"
    elif path.suffix == ".toml":
        import tomli_w

        text = tomli_w.dumps(data)
    else:
        raise ClusterError(f"cannot save a cluster as {path.suffix!r}; use a .json or .toml file name")
    path.write_text(text, encoding="utf-8")
    return path


def load_cluster(path: str | Path) -> Cluster:
    """Read a cluster written by :func:`save_cluster` (or by hand) from a UTF-8 JSON or TOML file.

    Any problem with the file (missing, not UTF-8, not JSON/TOML, unknown or missing keys, values
    that are not numbers or out of range) raises :class:`ClusterError` naming the file and the
    field.  Loading never runs code: both formats are plain data.
    """
    path = Path(path)
    if path.suffix not in (".json", ".toml"):
        raise ClusterError(f"cannot read a cluster from {path.suffix!r}; use a .json or .toml file")
    if not path.is_file():
        raise ClusterError(f"no cluster file at {str(path)!r}")
    if path.stat().st_size > MAX_FILE_BYTES:
        raise ClusterError(f"{path} is {path.stat().st_size} bytes; cluster files are limited to {MAX_FILE_BYTES}")
    try:
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as error:
        raise ClusterError(f"{path} is not UTF-8 text ({error}); save cluster files as UTF-8") from None
    try:
        data = json.loads(text) if path.suffix == ".json" else tomllib.loads(text)
    except (json.JSONDecodeError, tomllib.TOMLDecodeError, RecursionError) as error:
        raise ClusterError(f"{path} is not valid {path.suffix[1:].upper()}: {error}") from None
    if not isinstance(data, Mapping):
        raise ClusterError(f"{path} must hold a table/object of cluster fields")
    try:
        return Cluster.from_dict(data)
    except ClusterError as error:
        raise ClusterError(f"{path}: {error}") from None
