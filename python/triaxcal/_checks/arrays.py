"""Input validation shared by the public functions: array-likes in, contiguous float64 out;
options checked, never clipped or coerced (a bad one raises :class:`CalibrationError` naming the
option, the value and the valid range)."""

from __future__ import annotations

import math
import numbers
from typing import Any

import numpy as np

from ..errors import CalibrationError, NonFiniteError
from .options import MAGNITUDE, named


def as_points(points: Any, name: str = "points", min_rows: int = 0) -> np.ndarray:
    """Return ``points`` as a C-contiguous float64 array of shape (N, 3).

    Accepts any array-like of real numbers (int16 straight from a sensor is fine). Raises
    :class:`CalibrationError` for wrong shapes or dtypes, with a message saying what to pass.
    NaN and inf are left for the caller (the Rust core names the first bad point).
    """
    return as_samples(points, name, channels="xyz", finite=False, min_rows=min_rows)


def as_samples(
    samples: Any,
    name: str = "samples",
    *,
    channels: str = "xyz",
    finite: bool = True,
    min_rows: int = 0,
) -> np.ndarray:
    """Return ``samples`` as a C-contiguous float64 (N, K) array, one row per reading.

    ``channels="xyz"`` requires exactly 3 columns; ``"xyz+"`` at least 3 (x, y, z first, more
    channels after); ``"any"`` one or more (a 1-D array is one channel). With ``finite``, a NaN
    or inf raises :class:`NonFiniteError` naming the first bad row, and a reading larger in size
    than :data:`~triaxcal._checks.options.MAGNITUDE` allows (1e15: past any unit a sensor reads
    in, and where the squares and fourth powers the methods form would leave a double's range)
    is refused naming it. Every failure is a :class:`CalibrationError` saying what to pass
    instead.
    """
    name = named(name)
    exact = channels == "xyz"
    least = 1 if channels == "any" else 3
    want = "(N, 3), one row of x, y, z per reading" if exact else (
        "(N, K) with K >= 3 channels (x, y, z first)" if least == 3 else
        "(N,) or (N, K), one row per reading"
    )
    try:
        arr = np.asarray(samples)
    except (ValueError, TypeError) as exc:  # ragged lists and the like
        raise CalibrationError(
            f"{name} must be an array of shape {want}; could not convert it ({exc})"
        ) from None
    if arr.dtype.kind not in "iuf":
        raise CalibrationError(
            f"{name} must hold real numbers (integer or float), got dtype {arr.dtype}; "
            "convert text columns with np.asarray(x, dtype=float) first"
        )
    if least == 1 and arr.ndim == 1:
        arr = arr[:, None]
    if arr.ndim != 2 or (arr.shape[1] != 3 if exact else arr.shape[1] < least):
        raise CalibrationError(f"{name} must have shape {want}; got shape {arr.shape}")
    if arr.shape[0] < min_rows:
        raise CalibrationError(f"{name} needs at least {min_rows} rows, got {arr.shape[0]}")
    arr = np.ascontiguousarray(arr, dtype=np.float64)
    if not arr.flags.aligned:
        # a view at an odd byte offset (memory maps, Arrow buffers): the compiled core needs
        # aligned doubles, so copy -- only then
        arr = arr.copy()
    if finite and not np.isfinite(arr).all():
        bad = int(np.flatnonzero(~np.isfinite(arr).all(axis=1))[0])
        raise NonFiniteError(
            f"{name} contains NaN or inf (first at row {bad}): readings must be finite; drop or "
            "repair those rows first"
        )
    if finite and arr.size:
        big = np.abs(arr).max(axis=1) > MAGNITUDE[1]
        if big.any():
            bad = int(np.flatnonzero(big)[0])
            raise CalibrationError(
                f"{name} holds a reading of size {float(np.abs(arr[bad]).max()):.3g} (row {bad}), "
                f"beyond {MAGNITUDE[1]:g} in any unit a sensor reads in: give the readings in "
                "their own unit (counts, g, m/s^2, deg/s, uT)"
            )
    return arr


def lengths(rows: np.ndarray) -> np.ndarray:
    """The Euclidean length of each row, without overflow or underflow for any finite rows
    (each row is scaled by a power of two first, which is exact); a length beyond the largest
    double is inf.

    >>> lengths(np.array([[3e300, 4e300, 0.0], [3.0, 4.0, 0.0]])).tolist()
    [5e+300, 5.0]
    """
    big = np.abs(rows).max(axis=1) if rows.size else np.zeros(len(rows))
    _, e = np.frexp(big)
    with np.errstate(over="ignore"):
        return np.linalg.norm(np.ldexp(rows, -e[:, None]), axis=1) * np.ldexp(1.0, e)


def as_matrix3(value: Any, name: str) -> np.ndarray:
    """A finite 3x3 matrix (nested lists or an array) as float64, its entries within
    :data:`~triaxcal._checks.options.MAGNITUDE` in size."""
    name = named(name)
    try:
        arr = np.asarray(value) if not isinstance(value, (str, bytes, dict)) else None
    except (TypeError, ValueError):
        arr = None
    if arr is None or arr.dtype.kind not in "iuf" or arr.shape != (3, 3):
        raise CalibrationError(f"{name} must be a 3x3 matrix of real numbers, got "
                               f"{_shown(value)}")
    out = arr.astype(np.float64)
    if not (np.isfinite(out).all() and np.abs(out).max() <= MAGNITUDE[1]):
        raise CalibrationError(f"{name} must hold finite numbers no larger than "
                               f"{MAGNITUDE[1]:g}, got {out.tolist()}")
    return out


def finite_result(values: dict[str, Any], what: str, why: str) -> None:
    """Refuse a result whose named values are not all finite: ``what`` (the method) could not
    compute them from these data, ``why`` says what to do."""
    bad = [k for k, v in values.items()
           if not np.isfinite(np.asarray(v, dtype=np.float64)).all()]
    if bad:
        raise CalibrationError(f"{what}: {', '.join(bad)} came out infinite or undefined: "
                               f"{why}")


def _shown(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def as_vector(value: Any, name: str) -> tuple[float, float, float]:
    """Return a finite 3-vector (a scalar is repeated on all three axes)."""
    name = named(name)
    try:
        arr = np.asarray(value) if not isinstance(value, (str, bytes, dict)) else None
    except (TypeError, ValueError):
        arr = None
    if arr is None or arr.dtype.kind not in "iuf":
        raise CalibrationError(f"{name} must be a number or 3 numbers, got {_shown(value)}")
    arr = arr.astype(np.float64)
    if arr.ndim == 0:
        arr = np.repeat(arr, 3)
    if arr.shape != (3,):
        raise CalibrationError(f"{name} must be a number or 3 numbers, got shape {arr.shape}")
    if not np.isfinite(arr).all():
        raise NonFiniteError(f"{name} must be finite, got {arr.tolist()}")
    return (float(arr[0]), float(arr[1]), float(arr[2]))


def as_radius(radius: Any) -> float | None:
    """Return ``radius`` as a positive float, or None (the data's own scale)."""
    if radius is None:
        return None
    return require_radius(radius)


def require_radius(radius: Any) -> float:
    """Return ``radius`` as a positive float; it must be given."""
    if radius is None:
        raise CalibrationError("radius is required: the magnitude calibrated readings must have")
    if not _is_real(radius):
        raise CalibrationError(
            f"radius must be a number (1.0 for g, 9.80665 for m/s^2, the field in uT), got "
            f"{radius!r}"
        )
    r = _float(radius)
    if not (math.isfinite(r) and r > 0):
        raise CalibrationError(f"radius must be a finite number greater than zero, got {r}")
    return r


def _is_real(value: Any) -> bool:
    """A real number: int, float or a numpy real scalar -- not a bool, a string or complex."""
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def _float(value: Any) -> float:
    """``float(value)`` of a real number; an int too large for a float is an infinity (so that
    the range check refuses it with its message rather than an OverflowError)."""
    try:
        return float(value)
    except OverflowError:
        return math.inf if value > 0 else -math.inf


def as_count(value: Any, name: str, *, lo: int = 0, hi: int) -> int:
    """Return ``value`` as an int in ``[lo, hi]``; whole numbers only (no bool, no float)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise CalibrationError(f"{name} must be a whole number from {lo} to {hi}, got {value!r}")
    v = int(value)
    if not lo <= v <= hi:
        raise CalibrationError(f"{name} must be a whole number from {lo} to {hi}, got {v}")
    return v


def as_real(
    value: Any,
    name: str,
    *,
    lo: float = -math.inf,
    hi: float = math.inf,
    lo_open: bool = False,
    hi_open: bool = False,
    allow_inf: bool = False,
) -> float:
    """Return ``value`` as a float in the given range (closed unless ``*_open``); NaN is never
    valid, infinities only with ``allow_inf``."""
    left = "(" if lo_open else "["
    right = ")" if hi_open else "]"
    what = f"a number in {left}{lo:g}, {hi:g}{right}"
    if not _is_real(value):
        raise CalibrationError(f"{name} must be {what}, got {value!r}")
    v = _float(value)
    ok = not math.isnan(v) and (allow_inf or math.isfinite(v))
    ok = ok and (v > lo if lo_open else v >= lo) and (v < hi if hi_open else v <= hi)
    if not ok:
        raise CalibrationError(f"{name} must be {what}, got {v!r}")
    return v


def as_flag(value: Any, name: str) -> bool:
    """Return ``value`` as a bool; only True or False (or numpy's) are accepted."""
    if not isinstance(value, (bool, np.bool_)):
        raise CalibrationError(f"{name} must be True or False, got {value!r}")
    return bool(value)


def as_choice(value: Any, name: str, choices: tuple[str, ...]) -> str:
    """Return ``value`` if it is one of ``choices``."""
    if not isinstance(value, str) or value not in choices:
        raise CalibrationError(
            f"{name} must be one of {', '.join(repr(c) for c in choices)}, got {value!r}"
        )
    return value
