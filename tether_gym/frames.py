"""Reference frames the dynamics can be written in: inertial, orbiting (Hill), or spinning.

Both non-inertial frames turn at a constant rate ``Omega`` about their z axis, so a satellite at
``r`` with frame velocity ``v`` feels, per unit mass,

    a_frame = -2 Omega z x v  +  diag(T) r

where the first term is the Coriolis acceleration and ``T`` (1/s^2) collects the centrifugal
and, in orbit, the gravity-gradient (tidal) terms:

* **Hill (Clohessy-Wiltshire) frame** of a circular orbit with rate ``n``: x radial (outward),
  y along-track, z orbit normal; ``T = (3 n^2, 0, -n^2)``, giving the HCW equations
  ``x'' - 2 n y' - 3 n^2 x = a_x``, ``y'' + 2 n x' = a_y``, ``z'' + n^2 z = a_z``.
* **Rotating frame** spinning at ``W`` about z in free space: ``T = (W^2, W^2, 0)``, the
  centrifugal acceleration.

The apparent forces are conservative apart from the Coriolis term, which does no work, so the
conserved energy of a free cluster is the Jacobi integral ``T_rel + V_strain + V_frame`` with
``V_frame = -1/2 sum_i m_i r_i . diag(T) r_i`` (:meth:`Frame.potential`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike

from tether_gym.limits import MAX_FRAME_RATE, is_real_number, to_float

__all__ = ["EARTH_GM", "EARTH_RADIUS", "LEO_ORBIT_RATE", "Frame", "FrameError", "circular_orbit_rate"]

#: Earth's gravitational parameter, m^3/s^2.
EARTH_GM = 3.986004418e14
#: Earth's equatorial radius, m.
EARTH_RADIUS = 6.378137e6


def circular_orbit_rate(altitude: float, gm: float = EARTH_GM, body_radius: float = EARTH_RADIUS) -> float:
    """Mean motion ``n = sqrt(GM / a^3)`` of a circular orbit ``altitude`` m above the body, rad/s."""
    if not (is_real_number(altitude) and math.isfinite(to_float(altitude)) and altitude > -body_radius):
        raise ValueError(f"altitude must be a finite height above the body's centre, m; got {altitude!r}")
    return math.sqrt(gm / (body_radius + altitude) ** 3)


#: Orbital rate of a 400 km circular low Earth orbit, rad/s (about 1.13e-3, a 92.6 min period).
LEO_ORBIT_RATE = circular_orbit_rate(400e3)

FrameKind = Literal["inertial", "hill", "rotating"]


class FrameError(ValueError):
    """An invalid frame description; the message names the problem and the fix."""


@dataclasses.dataclass(frozen=True)
class Frame:
    """The frame the cluster's positions and velocities are written in.

    Build one with :meth:`inertial`, :meth:`hill` or :meth:`rotating`.

    Attributes:
        kind: ``"inertial"``, ``"hill"`` (orbiting, rate = orbital rate n) or ``"rotating"``
            (spinning in free space, rate = spin rate W).
        rate: the frame's angular velocity about its z axis, rad/s (0 for inertial).
    """

    kind: FrameKind = "inertial"
    rate: float = 0.0

    def __post_init__(self) -> None:
        if not isinstance(self.kind, str) or self.kind not in ("inertial", "hill", "rotating"):
            raise FrameError(f"frame kind must be 'inertial', 'hill' or 'rotating'; got {self.kind!r}")
        if not is_real_number(self.rate):
            raise FrameError(f"frame rate must be a number of rad/s; got {self.rate!r}")
        rate = to_float(self.rate)
        if not (math.isfinite(rate) and abs(rate) <= MAX_FRAME_RATE):
            raise FrameError(
                f"frame rate must be a finite number of rad/s within +-{MAX_FRAME_RATE:g}; got {self.rate!r}"
            )
        if self.kind == "inertial" and rate != 0.0:
            raise FrameError("an inertial frame does not turn: use Frame.rotating(rate) or Frame.hill(rate)")
        if self.kind == "hill" and rate <= 0.0:
            raise FrameError(f"the Hill frame needs an orbital rate > 0 rad/s (LEO: {LEO_ORBIT_RATE:.3g}); got {rate}")
        object.__setattr__(self, "rate", rate)

    @classmethod
    def inertial(cls) -> Frame:
        """Free space, not rotating: no apparent forces (the paper's setting)."""
        return cls("inertial", 0.0)

    @classmethod
    def hill(cls, orbit_rate: float = LEO_ORBIT_RATE) -> Frame:
        """The Hill (Clohessy-Wiltshire) frame of a circular orbit of rate ``orbit_rate`` rad/s
        (default: 400 km LEO); x radial outward, y along-track, z along the orbit normal."""
        return cls("hill", orbit_rate)

    @classmethod
    def rotating(cls, spin_rate: float) -> Frame:
        """A frame spinning at ``spin_rate`` rad/s about z in free space."""
        return cls("rotating", spin_rate)

    @property
    def tidal(self) -> np.ndarray:
        """(3,) diagonal of the apparent position-dependent acceleration per metre, 1/s^2."""
        w2 = self.rate * self.rate
        if self.kind == "hill":
            return np.array([3.0 * w2, 0.0, -w2])
        if self.kind == "rotating":
            return np.array([w2, w2, 0.0])
        return np.zeros(3)

    @property
    def is_inertial(self) -> bool:
        """True when there are no apparent forces."""
        return self.kind == "inertial"

    def acceleration(self, positions: ArrayLike, velocities: ArrayLike) -> np.ndarray:
        """(..., 3) apparent acceleration ``-2 Omega x v + diag(T) r`` at frame positions (m) and
        velocities (m/s) of shape (..., 3), m/s^2."""
        r = np.asarray(positions, dtype=np.float64)
        v = np.asarray(velocities, dtype=np.float64)
        coriolis = np.stack(
            [2.0 * self.rate * v[..., 1], -2.0 * self.rate * v[..., 0], np.zeros_like(v[..., 2])], axis=-1
        )
        return coriolis + self.tidal * r

    def potential(self, masses: ArrayLike, positions: ArrayLike) -> np.ndarray:
        """Potential of the apparent position-dependent forces, ``-1/2 sum_i m_i r_i . diag(T) r_i``,
        J, for masses (..., n) kg and positions (..., n, 3) m; shape (...)."""
        r = np.asarray(positions, dtype=np.float64)
        return -0.5 * np.einsum("...n,...nd,d->...", np.asarray(masses, dtype=np.float64), r * r, self.tidal)

    def to_dict(self) -> dict[str, Any]:
        """A plain description: ``{"kind": ..., "rate": ...}``."""
        return {"kind": self.kind, "rate": self.rate}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any] | Frame) -> Frame:
        """A frame from :meth:`to_dict` output (or a frame, returned as is)."""
        if isinstance(data, Frame):
            return data
        if not isinstance(data, Mapping):
            raise FrameError(f"a frame is given as {{'kind': ..., 'rate': ...}}; got {data!r}")
        unknown = set(data) - {"kind", "rate"}
        if unknown:
            raise FrameError(f"unknown frame key(s) {sorted(map(str, unknown))}; a frame has 'kind' and 'rate'")
        return cls(**dict(data))
