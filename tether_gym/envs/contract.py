"""The named contract between the task kernels, the task, the environments and the controllers.

Everything a reader of a task's results needs by name is defined here, once:

* :class:`Scalar`: the columns of :attr:`DampingTask.scalars <tether_gym.envs.DampingTask.scalars>`
  (the reward, its terms and the energies), also the keys of ``info``;
* :class:`EndReason`: the codes of ``DampingTask.end_reason``, whose lower-case names are
  ``info["end_reason"]``;
* :class:`RewardWeights`: the reward's weights as the kernels apply them;
* :class:`ObservationLayout`: the named slices of the observation vector, for a cluster's number
  of observed satellites and cables.

The compiled kernels read the same definitions (as plain ints); no other module writes a column
number, a reason code or an observation offset.
"""

from __future__ import annotations

import dataclasses
import enum

import numpy as np

__all__ = [
    "END_REASONS",
    "OBSERVATION_BLOCKS",
    "SCALARS",
    "TETHER_DIRECTIONS",
    "TETHER_FEATURES",
    "TETHER_FEATURE_MEANINGS",
    "TETHER_MODES",
    "EndReason",
    "ObservationBlock",
    "ObservationLayout",
    "RewardWeights",
    "Scalar",
]


class Scalar(enum.IntEnum):
    """Columns of the task's per-cluster scalar results, ``DampingTask.scalars[:, Scalar.X]``.

    The lower-case names are the keys of ``info``: ``reward = reward_vibration +
    reward_propellant + reward_slack + reward_failure``; energies in J, ``max_deviation`` in m,
    ``slack_fraction`` in [0, 1].
    """

    REWARD = 0
    REWARD_VIBRATION = 1
    REWARD_PROPELLANT = 2
    REWARD_SLACK = 3
    REWARD_FAILURE = 4
    VIBRATION_ENERGY = 5
    MAX_DEVIATION = 6
    SLACK_FRACTION = 7
    KINETIC_ENERGY = 8
    STRAIN_ENERGY = 9
    FRAME_POTENTIAL = 10

    @property
    def key(self) -> str:
        """The ``info`` key of this quantity (its lower-case name)."""
        return self.name.lower()


#: The scalar columns' names, in column order.
SCALARS: tuple[str, ...] = tuple(column.key for column in Scalar)

#: The reward terms that add up to the reward, in column order.
REWARD_TERMS: tuple[Scalar, ...] = (
    Scalar.REWARD_VIBRATION,
    Scalar.REWARD_PROPELLANT,
    Scalar.REWARD_SLACK,
    Scalar.REWARD_FAILURE,
)
#: Their ``info`` keys (computed once: an enum property costs a microsecond, per step).
REWARD_TERM_KEYS: tuple[str, ...] = tuple(term.key for term in REWARD_TERMS)


class EndReason(enum.IntEnum):
    """Why a cluster's episode ended (``DampingTask.end_reason``); anything but ``RUNNING``
    terminates it.  ``info["end_reason"]`` is the lower-case name."""

    RUNNING = 0
    FORMATION_LOST = 1  # a satellite farther than max_deviation from its nominal place
    CABLE_BROKEN = 2  # a cable's tension passed its breaking load (with cable_failure="terminate")
    NUMERICS_DIVERGED = 3  # non-finite state, energy runaway, sub-step budget exhausted, or the reward ran away

    @property
    def label(self) -> str:
        """The name reported in ``info["end_reason"]``."""
        return self.name.lower()


#: ``info["end_reason"]`` names, indexed by the codes of :class:`EndReason`.
END_REASONS: tuple[str, ...] = tuple(reason.label for reason in EndReason)


@dataclasses.dataclass(frozen=True)
class RewardWeights:
    """The reward's weights as the kernels apply them (SI units).

    ``reward_vibration = -vibration * E_vib``, ``reward_propellant = -propellant * impulse``,
    ``reward_slack = -slack * slack_fraction`` and ``reward_failure = -failure`` on a failure.

    Attributes:
        vibration: per J: the configured ``vibration_weight`` over the task's energy scale.
        propellant: per N*s: ``propellant_weight`` over the impulse of full thrust on every
            thruster for one control interval.
        slack: per fraction of slack cables.
        failure: the one-off penalty of a failure.
    """

    vibration: float
    propellant: float
    slack: float
    failure: float


@dataclasses.dataclass(frozen=True)
class ObservationBlock:
    """One named part of the observation vector.

    Attributes:
        name: the :class:`ObservationLayout` attribute holding its slice.
        per: ``"satellite"`` (three entries, x y z, per observed satellite) or ``"cable"`` (one
            entry per cable).
        meaning: what the entries are.
        unit: their unit: ``D`` the initial displacement, ``V`` the initial velocity, ``1`` none.
    """

    name: str
    per: str
    meaning: str
    unit: str

    def width(self, satellites: int, cables: int) -> int:
        """Entries of this block for ``satellites`` observed satellites and ``cables`` cables."""
        return 3 * satellites if self.per == "satellite" else cables


#: Transverse sine modes of each tether with beads that the reset noise excites and the
#: observation reports.
TETHER_MODES = 3

#: The two directions across a tether in which its modal amplitudes are observed (see
#: :data:`TETHER_FEATURES`): with ``e`` the unit chord from ``ends[0]`` to ``ends[1]`` now, and
#: ``r`` the z axis (the x axis for a tether whose nominal chord is within 45 degrees of z),
#: ``lateral = (r x e) / |r x e|`` and ``normal = e x lateral``.  For a chord in the xy plane,
#: ``lateral`` is the chord turned +90 degrees about z and ``normal`` is +z.
TETHER_DIRECTIONS: tuple[str, ...] = ("lateral", "normal")

#: The entries of each tether's observation block (clusters with tethers only), in order, with
#: their units: the tether's elongation (length along its beads minus its ``L0``, D), the tension
#: of its first and last segment (in units of its pretension ``N0``), the fraction of its segments
#: that are slack (1), and its first ``TETHER_MODES`` transverse modal amplitudes, each signed, in
#: the two directions of :data:`TETHER_DIRECTIONS` (mode-major: ``mode_1_lateral``,
#: ``mode_1_normal``, ``mode_2_lateral``, ...): ``(2/N) sum_j (u_j . d) sin(k pi j / N)``, ``u_j``
#: bead j's offset across the chord and ``d`` the direction (D).
TETHER_FEATURES: tuple[str, ...] = (
    "elongation",
    "tension_start",
    "tension_end",
    "slack_fraction",
    *(f"mode_{k}_{direction}" for k in range(1, TETHER_MODES + 1) for direction in TETHER_DIRECTIONS),
)

#: Each entry of :data:`TETHER_FEATURES`: (meaning, unit), for the docs' observation tables.
TETHER_FEATURE_MEANINGS: dict[str, tuple[str, str]] = {
    "elongation": ("length along its beads minus its ``L0``", "D"),
    "tension_start": ("tension of its first segment (at ``ends[0]``) / its pretension ``N0``", "1"),
    "tension_end": ("tension of its last segment (at ``ends[1]``) / its pretension ``N0``", "1"),
    "slack_fraction": ("fraction of its segments that are slack", "1"),
    **{
        f"mode_{k}_{direction}": (f"signed amplitude of its transverse sine mode {k} along ``{direction}``", "D")
        for k in range(1, TETHER_MODES + 1)
        for direction in TETHER_DIRECTIONS
    },
}

#: The observation vector, in order.  The last block is present only with ``observe_tensions``.
#: Clusters with tethers (beads) add, after these, ``len(TETHER_FEATURES)`` entries per tether
#: (:attr:`ObservationLayout.tether`); their segments are not among the ``cable`` entries.
OBSERVATION_BLOCKS: tuple[ObservationBlock, ...] = (
    ObservationBlock(
        "displacement", "satellite", "displacement of each observed satellite from its nominal place", "D"
    ),
    ObservationBlock(
        "velocity", "satellite", "velocity of each observed satellite relative to the centre of mass", "V"
    ),
    ObservationBlock("elongation", "cable", "cable elongation ``L - L0``", "D"),
    ObservationBlock("tension_ratio", "cable", "cable tension / breaking load (only with ``observe_tensions``)", "1"),
)


@dataclasses.dataclass(frozen=True)
class ObservationLayout:
    """Where each part of the observation vector lies, for ``satellites`` observed satellites and
    ``cables`` cables (see :data:`OBSERVATION_BLOCKS`); everything is in the cluster frame
    (origin at the centre of mass), in units of the task's length and speed scales.

    Attributes:
        satellites: s, the number of observed satellites.
        cables: c, the number of cables observed one by one (a cluster's plain cables: a
            tether's segments are observed per tether).
        tensions: whether the tension ratios are observed.
        tethers: t, the number of tethers with a spec (0: none, and no tether block).
        displacement, velocity: slices of 3 s entries each, satellite k's x, y, z at 3 k + d.
        elongation: slice of c entries, one per cable.
        tension_ratio: slice of c entries, or an empty slice at the end without tensions.
        commands: the number of command entries (``thrust_delay`` x action size with
            ``observe_commands``, else 0).
        tether: slice of ``len(TETHER_FEATURES)`` t entries after the cable blocks, tether k's
            feature f at ``len(TETHER_FEATURES) k + f`` (empty without tethers).
        command: slice of the ``commands`` entries at the end: the commands given but not
            acting yet, oldest (the next to act) first, each an action in [-1, 1] (empty
            without ``observe_commands``).
        size: the observation's length.
    """

    satellites: int
    cables: int
    tensions: bool
    tethers: int = 0
    commands: int = 0
    displacement: slice = dataclasses.field(init=False)
    velocity: slice = dataclasses.field(init=False)
    elongation: slice = dataclasses.field(init=False)
    tension_ratio: slice = dataclasses.field(init=False)
    tether: slice = dataclasses.field(init=False)
    command: slice = dataclasses.field(init=False)
    size: int = dataclasses.field(init=False)

    def __post_init__(self) -> None:
        start = 0
        for block in OBSERVATION_BLOCKS:
            present = block.name != "tension_ratio" or self.tensions
            stop = start + (block.width(self.satellites, self.cables) if present else 0)
            object.__setattr__(self, block.name, slice(start, stop))
            start = stop
        stop = start + len(TETHER_FEATURES) * self.tethers
        object.__setattr__(self, "tether", slice(start, stop))
        object.__setattr__(self, "command", slice(stop, stop + self.commands))
        object.__setattr__(self, "size", stop + self.commands)

    def satellite_values(self, observation: np.ndarray, block: str) -> np.ndarray:
        """The ``"displacement"`` or ``"velocity"`` entries of (..., size) observations, as
        (..., s, 3) (in observation units)."""
        part = observation[..., getattr(self, block)]
        return part.reshape(part.shape[:-1] + (self.satellites, 3))

    @staticmethod
    def symbolic_table() -> str:
        """The layout as a Markdown table of index ranges in s (observed satellites) and c
        (cables): the env docstrings' Observation Space table."""
        rows = ["| index | observation | unit |", "|---|---|---|"]
        satellites = cables = 0  # the start of each block, as multiples of s and c
        for block in OBSERVATION_BLOCKS:
            width = (3, 0) if block.per == "satellite" else (0, 1)
            end = (satellites + width[0], cables + width[1])
            rows.append(
                f"| {_symbolic(satellites, cables, 0)} .. {_symbolic(*end, -1)} | {block.meaning} | {block.unit} |"
            )
            satellites, cables = end
        return "\n".join(rows)

    @staticmethod
    def symbolic_tether_table() -> str:
        """The tether block as a Markdown table: with ``t`` tethers that have mass, after the
        ``P`` entries of :meth:`symbolic_table`, tether k's feature f is entry
        ``P + len(TETHER_FEATURES) k + f``; the env docstrings' table of that block."""
        width = len(TETHER_FEATURES)
        rows = ["| index | observation of tether k (k = 0 .. t-1) | unit |", "|---|---|---|"]
        for f, name in enumerate(TETHER_FEATURES):
            meaning, unit = TETHER_FEATURE_MEANINGS[name]
            rows.append(f"| P+{width}k{f'+{f}' if f else ''} | `{name}`: {meaning} | {unit} |")
        return "\n".join(rows)


def _symbolic(satellites: int, cables: int, constant: int) -> str:
    """``a s + b c + k`` written compactly, e.g. ``6s+c-1``."""
    terms = [f"{'' if a == 1 else a}{name}" for a, name in ((satellites, "s"), (cables, "c")) if a]
    text = "+".join(terms)
    if constant or not text:
        text += f"{constant:+d}" if text else str(constant)
    return text
