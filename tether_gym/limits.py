"""The magnitudes tether-gym accepts, in one place (SI units), and the checks that enforce them.

The ranges are generous on purpose: they reach far beyond any tethered-satellite cluster flown or
studied (TiPS: 4 km, YES2: 31.7 km of tether; CubeSats of 1 kg, small satellites of 500 kg; a
1 mm Dyneema line has EA of about 40 kN).  They exist because beyond them the method's arithmetic
breaks down: squared coordinates, energies ``m v^2`` and frequencies ``omega^2 = k (1/m_i + 1/m_j)``
overflow or lose every significant digit, and the critical step becomes so small that no control
interval can be integrated.  Values outside a range are rejected with a message that names the
parameter and the range, instead of producing inf or NaN later.

With every value inside its range the derived quantities stay finite by a wide margin: the
stiffest possible cable (``EA/L0 <= 1e18`` N/m) between the lightest satellites (1e-6 kg) has
``omega^2 <= 1e25`` (rad/s)^2, the largest kinetic energy is ``1e9 kg * (1e6 m/s)^2 = 1e21`` J,
and the largest squared coordinate is 1e16 m^2.
"""

from __future__ import annotations

import math
import numbers
from typing import Any, TypeGuard

import numpy as np

__all__ = [
    "MAX_COORDINATE",
    "MAX_DAMPING",
    "MAX_EA",
    "MAX_FORCE",
    "MAX_FRAME_RATE",
    "MAX_LENGTH",
    "MAX_MASS",
    "MAX_SPEED",
    "MIN_EA",
    "MIN_LENGTH",
    "MIN_BEAD_MASS",
    "MIN_MASS",
    "check_range",
    "check_real",
    "is_real_number",
    "is_whole_number",
    "real_array",
    "short_repr",
    "to_float",
]

#: Largest |coordinate| of a position, m: 1e5 km, a quarter of the way to the Moon.
MAX_COORDINATE = 1e8
#: Satellite masses, kg: from a milligram (a chip-sat is grams) to 1e6 t (the ISS is 420 t).
MIN_MASS = 1e-6
MAX_MASS = 1e9
#: A bead of a tether with mass, kg: a microgram, so that light lines can be meshed finely (a
#: 1 m thread of 1 mg/m in 1000 segments).  Satellites keep MIN_MASS.  The stiffest cable between
#: two such beads has omega^2 <= 1e18 * 2e9 = 2e27 (rad/s)^2, still far from overflow.
MIN_BEAD_MASS = 1e-9
#: Cable reference lengths and node distances, m: from a micrometre to 1e6 km (the longest
#: distance between two positions within MAX_COORDINATE is 3.5e8 m).
MIN_LENGTH = 1e-6
MAX_LENGTH = 1e9
#: Axial stiffness EA of a cable, N: from a micronewton to 1e12 N (a steel bar of 2.5 m radius).
MIN_EA = 1e-6
MAX_EA = 1e12
#: Largest force, N: pretensions, finite breaking loads, external and thruster forces.
MAX_FORCE = 1e12
#: Largest diagonal or axial (Kelvin-Voigt) damping coefficient, N*s/m.
MAX_DAMPING = 1e12
#: Largest |velocity component|, m/s (escape velocity is 1.1e4 m/s).
MAX_SPEED = 1e6
#: Largest |frame rate|, rad/s: orbital rates are 1e-3 and spinning formations turn at 0.01-1.
MAX_FRAME_RATE = 100.0


def real_array(name: str, value: Any, error: type[Exception] = ValueError, allow_inf: bool = False) -> np.ndarray:
    """``value`` as a float64 array, refusing anything that is not made of real numbers.

    Python and numpy integers and floats are accepted, in scalars, sequences and arrays.  Strings,
    booleans, ``None``, complex numbers and ragged nestings raise ``error`` naming ``name``; so
    does NaN, and so does an infinity unless ``allow_inf`` (then the strings ``"inf"`` and
    ``"Infinity"`` are read as +inf too, the spelling of an unbounded value in strict JSON files).
    """
    if isinstance(value, np.ndarray) and value.dtype.kind in "iuf":
        array = value.astype(np.float64)
    else:
        if allow_inf:
            value = _read_infinities(value)
        try:
            raw = np.asarray(value)
        except (TypeError, ValueError) as exc:
            raise error(f"{name} must be a number or an array of numbers; got {short_repr(value)} ({exc})") from None
        if raw.dtype.kind == "O" and all(is_real_number(item) for item in raw.ravel()):
            # Python integers too large for int64 land here; they are numbers all the same.
            try:
                raw = raw.astype(np.float64)
            except OverflowError:
                raise error(f"{name} holds an integer too large for a float; got {short_repr(value)}") from None
        if raw.dtype.kind in "iuf" and isinstance(value, (list, tuple)) and _holds_bool(value):
            raise error(f"{name} must be made of real numbers, not booleans; got {short_repr(value)}")
        if raw.dtype.kind not in "iuf":
            kind = {"b": "booleans", "U": "strings", "S": "bytes", "c": "complex numbers"}.get(
                raw.dtype.kind, "objects"
            )
            raise error(f"{name} must be made of real numbers, not {kind}; got {short_repr(value)}")
        array = raw.astype(np.float64)
    if np.isnan(array).any():
        raise error(f"{name} contains NaN; every entry must be a number")
    if not allow_inf and np.isinf(array).any():
        raise error(f"{name} contains an infinite value; every entry must be finite")
    return array


def short_repr(value: Any, limit: int = 120) -> str:
    """``repr(value)``, cut to ``limit`` characters for an error message."""
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _holds_bool(value: Any) -> bool:
    """True if a nested list/tuple holds a boolean anywhere (numpy would read it as 0 or 1)."""
    if isinstance(value, (bool, np.bool_)):
        return True
    if isinstance(value, (list, tuple)):
        return any(_holds_bool(item) for item in value)
    return False


def _read_infinities(value: Any) -> Any:
    """``value`` with the strings "inf"/"+inf"/"Infinity" (any case) replaced by ``math.inf``."""
    if isinstance(value, str):
        return math.inf if value.strip().lower().lstrip("+") in ("inf", "infinity") else value
    if isinstance(value, (list, tuple)):
        return [_read_infinities(item) for item in value]
    return value


def check_range(
    name: str,
    values: np.ndarray | np.floating[Any],
    low: float,
    high: float,
    unit: str,
    *,
    low_inclusive: bool = True,
    error: type[Exception] = ValueError,
    where: str = "entry",
) -> None:
    """Raise ``error`` naming ``name``, the first offending ``where`` (e.g. "cable") and the
    accepted range when any of ``values`` lies outside ``[low, high]`` (``(low, high]`` when not
    ``low_inclusive``).  NaN is outside every range: both comparisons with NaN are false, so
    it is looked for on its own."""
    too_low = values < low if low_inclusive else values <= low
    bad = too_low | (values > high) | np.isnan(values)
    if bad.any():
        index = tuple(int(i) for i in np.argwhere(bad)[0]) if values.ndim else ()
        at = f" ({where} {index[0] if len(index) == 1 else index})" if index else ""
        bracket = "[" if low_inclusive else "("
        unit = f" {unit}" if unit else ""
        got = np.asarray(values)[index] if index else values
        raise error(f"{name} must lie in {bracket}{low:g}, {high:g}]{unit}; got {got}{at}")


def to_float(value: Any) -> float:
    """A real number as a float; a Python integer beyond the float range becomes +-inf (where
    ``float()`` would raise ``OverflowError``), so that range checks can refuse it by name."""
    try:
        return float(value)
    except OverflowError:
        return math.inf if value > 0 else -math.inf


def is_whole_number(value: Any) -> TypeGuard[int | np.integer[Any]]:
    """True for a Python or numpy integer that is not a boolean."""
    return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))


def is_real_number(value: Any) -> bool:
    """True for a real, non-boolean number (int, float, numpy scalar)."""
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def check_real(name: str, value: object, low: float, high: float, unit: str, *, low_inclusive: bool = False) -> float:
    """``value`` as a float, or a ``ValueError`` naming ``name`` unless it is a real number in
    ``(low, high]`` (``[low, high]`` with ``low_inclusive``)."""
    if not is_real_number(value):
        raise ValueError(f"{name} must be a number ({unit}); got {value!r}")
    number = to_float(value)
    check_range(name, np.float64(number), low, high, unit, low_inclusive=low_inclusive)
    return number
