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
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from tether_gym.frames import Frame, FrameError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - exercised on Python 3.10 only
    import tomli as tomllib

__all__ = ["Cluster", "ClusterError", "load_cluster", "save_cluster"]


class ClusterError(ValueError):
    """An invalid cluster description; the message names the problem and how to fix it."""


def _float_array(name: str, value: ArrayLike, shape: tuple[int, ...], what: str) -> np.ndarray:
    """Convert ``value`` to a read-only float64 array of ``shape``, broadcasting scalars."""
    try:
        array = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise ClusterError(f"{name} must be numeric ({what}); got {value!r}: {error}") from None
    if array.ndim == 0:
        array = np.full(shape, float(array))
    if array.shape != shape:
        raise ClusterError(
            f"{name} must have shape {shape} ({what}) or be a scalar; got shape {array.shape}"
        )
    if not np.all(np.isfinite(array)):
        bad = np.argwhere(~np.isfinite(array))[0]
        raise ClusterError(
            f"{name} contains a non-finite value (NaN or inf) at index {tuple(int(i) for i in bad)}; "
            "every entry must be a finite number"
        )
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
    """

    positions: np.ndarray
    masses: np.ndarray
    cables: np.ndarray
    EA: np.ndarray
    N0: np.ndarray = 0.0  # type: ignore[assignment]
    damping: np.ndarray = 0.0  # type: ignore[assignment]
    L0: np.ndarray | None = None
    breaking_load: np.ndarray = math.inf  # type: ignore[assignment]
    axial_damping: np.ndarray = 0.0  # type: ignore[assignment]
    frame: Frame = dataclasses.field(default_factory=Frame.inertial)
    name: str = "custom"

    def __post_init__(self) -> None:
        try:
            positions = np.array(self.positions, dtype=np.float64)
        except (TypeError, ValueError) as error:
            raise ClusterError(f"positions must be an (n, 3) array of numbers in m: {error}") from None
        if positions.ndim != 2 or positions.shape[1] != 3 or positions.shape[0] < 2:
            raise ClusterError(
                f"positions must have shape (n, 3) with n >= 2 satellites; got shape {positions.shape}"
            )
        n_nodes = positions.shape[0]
        positions = _float_array("positions", positions, (n_nodes, 3), "node positions in m")
        masses = _float_array("masses", self.masses, (n_nodes,), "kg per satellite")
        if np.any(masses <= 0.0):
            i = int(np.argmax(masses <= 0.0))
            raise ClusterError(f"masses must be > 0 kg; satellite {i} has mass {masses[i]}")
        damping = _float_array("damping", self.damping, (n_nodes,), "N*s/m per satellite")
        if np.any(damping < 0.0):
            i = int(np.argmax(damping < 0.0))
            raise ClusterError(f"damping must be >= 0 N*s/m; satellite {i} has {damping[i]}")

        try:
            cables = np.array(self.cables, dtype=np.float64)
        except (TypeError, ValueError) as error:
            raise ClusterError(f"cables must be a list of (i, j) node-index pairs: {error}") from None
        if cables.ndim != 2 or cables.shape[1] != 2 or cables.shape[0] < 1:
            raise ClusterError(
                "cables must be a non-empty list of (i, j) node-index pairs, shape (m, 2); "
                f"got shape {cables.shape}"
            )
        if not np.all(np.isfinite(cables)) or np.any(cables != np.round(cables)):
            raise ClusterError("cables must hold whole node indices (integers)")
        cables = cables.astype(np.int64)
        for c, (i, j) in enumerate(cables.tolist()):
            if not (0 <= i < n_nodes and 0 <= j < n_nodes):
                raise ClusterError(
                    f"cable {c} joins nodes ({i}, {j}), but node indices must be in 0..{n_nodes - 1} "
                    f"for {n_nodes} satellites"
                )
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

        lengths = np.linalg.norm(positions[cables[:, 1]] - positions[cables[:, 0]], axis=1)
        if np.any(lengths <= 0.0):
            c = int(np.argmax(lengths <= 0.0))
            raise ClusterError(
                f"cable {c} has zero length: nodes {tuple(int(k) for k in cables[c])} share the same "
                "position; give every satellite a distinct position"
            )
        reachable = _connected(n_nodes, cables)
        if not np.all(reachable):
            loose = [int(k) for k in np.flatnonzero(~reachable)]
            raise ClusterError(
                f"the cluster is disconnected: satellites {loose} are not linked to satellite 0 by "
                "any chain of cables; add cables or simulate the parts as separate clusters"
            )

        EA = _float_array("EA", self.EA, (n_cables,), "axial stiffness in N per cable")
        if np.any(EA <= 0.0):
            c = int(np.argmax(EA <= 0.0))
            raise ClusterError(f"EA must be > 0 N; cable {c} has EA = {EA[c]}")
        N0 = _float_array("N0", self.N0, (n_cables,), "pretension in N per cable")
        if np.any(N0 < 0.0):
            c = int(np.argmax(N0 < 0.0))
            raise ClusterError(f"N0 (pretension) must be >= 0 N; cable {c} has N0 = {N0[c]}")
        if self.L0 is None:
            L0 = lengths.copy()
            L0.setflags(write=False)
        else:
            L0 = _float_array("L0", self.L0, (n_cables,), "reference length in m per cable")
            if np.any(L0 <= 0.0):
                c = int(np.argmax(L0 <= 0.0))
                raise ClusterError(f"L0 must be > 0 m; cable {c} has L0 = {L0[c]}")
        breaking = np.array(self.breaking_load, dtype=np.float64)
        if breaking.ndim == 0:
            breaking = np.full(n_cables, float(breaking))
        if breaking.shape != (n_cables,) or np.any(np.isnan(breaking)) or np.any(breaking <= 0.0):
            raise ClusterError(
                f"breaking_load must be a scalar or shape ({n_cables},) of values > 0 N (inf for "
                f"unbreakable); got {self.breaking_load!r}"
            )
        breaking.setflags(write=False)
        axial_damping = _float_array("axial_damping", self.axial_damping, (n_cables,), "N*s/m per cable")
        if np.any(axial_damping < 0.0):
            c = int(np.argmax(axial_damping < 0.0))
            raise ClusterError(f"axial_damping must be >= 0 N*s/m; cable {c} has {axial_damping[c]}")
        try:
            frame = Frame.from_dict(self.frame)
        except (FrameError, TypeError) as error:
            raise ClusterError(f"invalid frame: {error}") from None
        if not isinstance(self.name, str):
            raise ClusterError(f"name must be a string; got {self.name!r}")

        for field, value in (
            ("positions", positions), ("masses", masses), ("cables", cables), ("EA", EA),
            ("N0", N0), ("damping", damping), ("L0", L0), ("breaking_load", breaking),
            ("axial_damping", axial_damping), ("frame", frame),
        ):
            object.__setattr__(self, field, value)

    # ------------------------------------------------------------------ derived quantities
    @property
    def num_nodes(self) -> int:
        """Number of satellites n."""
        return int(self.positions.shape[0])

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
                f"unknown Cluster field(s) {sorted(unknown)}; fields are "
                f"{[f.name for f in dataclasses.fields(self)]}"
            )
        return dataclasses.replace(self, **changes)

    # ------------------------------------------------------------------ (de)serialisation
    def to_dict(self) -> dict[str, Any]:
        """A plain, JSON- and TOML-friendly description (lists of floats, SI units)."""
        data: dict[str, Any] = {
            "name": self.name,
            "positions": self.positions.tolist(),
            "masses": self.masses.tolist(),
            "damping": self.damping.tolist(),
            "cables": self.cables.tolist(),
            "EA": self.EA.tolist(),
            "L0": self.L0.tolist(),
            "N0": self.N0.tolist(),
        }
        if np.all(np.isfinite(self.breaking_load)):
            data["breaking_load"] = self.breaking_load.tolist()
        if np.any(self.axial_damping > 0.0):
            data["axial_damping"] = self.axial_damping.tolist()
        if not self.frame.is_inertial:
            data["frame"] = self.frame.to_dict()
        return data

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Cluster:
        """Build a cluster from :meth:`to_dict` output (unknown keys are an error)."""
        fields = {f.name for f in dataclasses.fields(cls)}
        unknown = set(data) - fields
        if unknown:
            raise ClusterError(f"unknown cluster key(s) {sorted(unknown)}; allowed keys are {sorted(fields)}")
        missing = {"positions", "masses", "cables", "EA"} - set(data)
        if missing:
            raise ClusterError(f"cluster description lacks required key(s) {sorted(missing)}")
        return cls(**dict(data))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Cluster):
            return NotImplemented
        return self.name == other.name and self.frame == other.frame and all(
            np.array_equal(getattr(self, f), getattr(other, f))
            for f in ("positions", "masses", "cables", "EA", "N0", "damping", "L0", "breaking_load", "axial_damping")
        )

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        frame = "" if self.frame.is_inertial else f", frame={self.frame.kind} at {self.frame.rate:.4g} rad/s"
        return (
            f"Cluster(name={self.name!r}, satellites={self.num_nodes}, cables={self.num_cables}, "
            f"mass={self.masses.sum():.4g} kg{frame})"
        )


def save_cluster(cluster: Cluster, path: str | Path) -> Path:
    """Write ``cluster`` to ``path`` as JSON (``.json``) or TOML (``.toml``); returns the path."""
    path = Path(path)
    data = cluster.to_dict()
    if path.suffix == ".json":
        path.write_text(json.dumps(data, indent=2) + "\n")
    elif path.suffix == ".toml":
        import tomli_w

        path.write_text(tomli_w.dumps(data))
    else:
        raise ClusterError(f"cannot save a cluster as {path.suffix!r}; use a .json or .toml file name")
    return path


def load_cluster(path: str | Path) -> Cluster:
    """Read a cluster written by :func:`save_cluster` (or by hand) from a JSON or TOML file."""
    path = Path(path)
    if not path.is_file():
        raise ClusterError(f"no cluster file at {str(path)!r}")
    text = path.read_text()
    try:
        if path.suffix == ".json":
            data = json.loads(text)
        elif path.suffix == ".toml":
            data = tomllib.loads(text)
        else:
            raise ClusterError(f"cannot read a cluster from {path.suffix!r}; use a .json or .toml file")
    except (json.JSONDecodeError, tomllib.TOMLDecodeError) as error:
        raise ClusterError(f"{path} is not valid {path.suffix[1:].upper()}: {error}") from None
    if not isinstance(data, Mapping):
        raise ClusterError(f"{path} must hold a table/object of cluster fields")
    return Cluster.from_dict(data)

