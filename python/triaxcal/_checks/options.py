"""Validation of keyword options: one place that says what a bad option was and what is valid.

Every public function checks its options with these helpers before it computes anything. A bad
option raises :class:`~triaxcal.errors.CalibrationError` whose message names the option, the
value given and the valid range, e.g. ``k must be a finite number > 0, got nan``. Nothing is
clipped, rounded or coerced silently: a string is not a number (``"3"`` is refused), a bool is
not a number (``True`` is refused), a float is not a whole number (``2.5`` is refused where a
count of samples is wanted; ``3.0`` is accepted as 3), a complex number is refused.

Array data (readings, time stamps) are checked by :mod:`triaxcal._checks.arrays`.

>>> number(0.5, "k", gt=0)
0.5
>>> number(float("nan"), "k", gt=0)
Traceback (most recent call last):
...
triaxcal.CalibrationError: k must be a finite number > 0, got nan
>>> integer(2**70, "max_iter", ge=1, le=10)
Traceback (most recent call last):
...
triaxcal.CalibrationError: max_iter must be a whole number in [1, 10], got 1180591620717411303424
"""

from __future__ import annotations

import math
import numbers
import os
import re
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..errors import CalibrationError
from .spelling import opt

__all__ = [
    "MAGNITUDE",
    "MAX_SAMPLES",
    "MAX_SEED",
    "choice",
    "flag",
    "instance",
    "integer",
    "intervals",
    "magnitude",
    "mapping",
    "named",
    "number",
    "numbers_list",
    "optional_number",
    "path",
    "samples",
    "seed",
    "text_stream",
    "vector3",
]

#: The magnitudes a reading or a scale-like option (gravity, a radius, a field, an angle, a
#: gain) may have, in whatever unit: 1e-15 to 1e15. Every unit a sensor reads in lies well
#: inside (raw counts of a 32-bit converter stay below 5e9, a field in nT below 1e5, gravity
#: in ug below 1e7), and the squares, products and fourth powers the methods form of such
#: numbers (at most 1e60, at least 1e-60) stay far inside a double's range (1e-308 to 1e308):
#: a value near the edge of a double (1e308, 1e-308) is refused by name instead of
#: overflowing in the middle of a computation.
MAGNITUDE = (1e-15, 1e15)

#: Most samples a duration may stand for (2**53: a double counts them exactly), far beyond any
#: recording; a longer duration is refused by name instead of overflowing a count.
MAX_SAMPLES = 2**53

#: Largest seed of a random generator (numpy takes any whole number >= 0; 2**64 - 1 is what a
#: 64-bit register stores).
MAX_SEED = 2**64 - 1

_IDENTIFIER = re.compile(r"[a-z][a-z0-9_]*\Z")


def named(name: str) -> str:
    """The option ``name`` as the user wrote it (:func:`~triaxcal._checks.spelling.opt`: a
    flag on the command line, the Python name otherwise); a name that is not a plain
    identifier (``intervals[0] start``, ``accel_threshold_g (g)``) is kept as it is.

    >>> named("rate_hz"), named("intervals[0] start")
    ('rate_hz', 'intervals[0] start')
    """
    return opt(name) if _IDENTIFIER.match(name) else name


def _fmt(x: float) -> str:
    return f"{x:g}" if isinstance(x, float) else str(x)


def _range_text(gt: float | None, ge: float | None, lt: float | None, le: float | None) -> str:
    lo = (f"({_fmt(gt)}" if gt is not None else f"[{_fmt(ge)}" if ge is not None else None)
    hi = (f"{_fmt(lt)})" if lt is not None else f"{_fmt(le)}]" if le is not None else None)
    if lo and hi:
        return f"in {lo}, {hi}"
    if lo:
        return f"> {_fmt(gt)}" if gt is not None else f">= {_fmt(ge)}"  # type: ignore[arg-type]
    if hi:
        return f"< {_fmt(lt)}" if lt is not None else f"<= {_fmt(le)}"  # type: ignore[arg-type]
    return ""


def _shown(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _is_real(value: Any) -> bool:
    # numbers.Real covers int, float, numpy integer and floating scalars; bool is an int
    # subclass and is refused (True is not a number a user means to pass)
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def number(
    value: Any,
    name: str,
    *,
    gt: float | None = None,
    ge: float | None = None,
    lt: float | None = None,
    le: float | None = None,
    finite: bool = True,
    hint: str = "",
) -> float:
    """Return ``value`` as a float if it is a real number in the range; else raise.

    ``gt``/``ge`` and ``lt``/``le`` are the open/closed bounds; ``finite`` refuses NaN and inf
    (NaN is always refused). ``hint`` is appended to the message (e.g. a typical value).
    """
    name = named(name)
    rng = _range_text(gt, ge, lt, le)
    what = ("a finite number" if finite else "a number") + (f" {rng}" if rng else "")
    tail = f" ({hint})" if hint else ""
    if not _is_real(value):
        raise CalibrationError(f"{name} must be {what}, got {_shown(value)}{tail}")
    try:
        x = float(value)
    except OverflowError:  # an int beyond double precision
        raise CalibrationError(f"{name} must be {what}, got {_shown(value)}{tail}") from None
    ok = not math.isnan(x) and (not finite or math.isfinite(x))
    ok = ok and (gt is None or x > gt) and (ge is None or x >= ge)
    ok = ok and (lt is None or x < lt) and (le is None or x <= le)
    if not ok:
        raise CalibrationError(f"{name} must be {what}, got {_shown(value)}{tail}")
    return x


def optional_number(value: Any, name: str, **kw: Any) -> float | None:
    """``None`` stays ``None``; anything else must pass :func:`number`."""
    return None if value is None else number(value, name, **kw)


def integer(
    value: Any,
    name: str,
    *,
    ge: int | None = None,
    le: int | None = None,
    hint: str = "",
) -> int:
    """Return ``value`` as an int if it is a whole number in ``[ge, le]``; else raise.

    A float with an integral value (``3.0``) is accepted; ``2.5``, ``"3"``, ``True`` are not.
    """
    name = named(name)
    rng = _range_text(None, ge, None, le)
    what = "a whole number" + (f" {rng}" if rng else "")
    tail = f" ({hint})" if hint else ""
    bad = CalibrationError(f"{name} must be {what}, got {_shown(value)}{tail}")
    if not _is_real(value):
        raise bad
    if isinstance(value, numbers.Integral):
        n = int(value)
    else:
        x = float(value)
        if not (math.isfinite(x) and x.is_integer()):
            raise bad
        n = int(x)
    if (ge is not None and n < ge) or (le is not None and n > le):
        raise bad
    return n


def choice(value: Any, name: str, options: Sequence[str]) -> str:
    """Return ``value`` if it is one of the strings ``options``; else raise naming them."""
    if not isinstance(value, str) or value not in options:
        listed = ", ".join(repr(o) for o in options)
        raise CalibrationError(f"{named(name)} must be one of {listed}, got {_shown(value)}")
    return value


def flag(value: Any, name: str) -> bool:
    """Return ``value`` if it is a bool (``True``/``False``); ``"no"`` or ``0`` are refused."""
    if not isinstance(value, (bool, np.bool_)):
        raise CalibrationError(f"{named(name)} must be True or False, got {_shown(value)}")
    return bool(value)


def numbers_list(
    value: Any,
    name: str,
    *,
    min_len: int = 1,
    **bounds: Any,
) -> tuple[float, ...]:
    """A sequence (list, tuple, 1-D array) of at least ``min_len`` numbers, each in range."""
    name = named(name)
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__"):
        raise CalibrationError(
            f"{name} must be a sequence of numbers (at least {min_len}), got {_shown(value)}"
        )
    items = list(np.asarray(value, dtype=object).reshape(-1)) if isinstance(
        value, np.ndarray) else list(value)
    if len(items) < min_len:
        raise CalibrationError(
            f"{name} must hold at least {min_len} number(s), got {len(items)}"
        )
    return tuple(number(v, f"{name}[{i}]", **bounds) for i, v in enumerate(items))


def vector3(value: Any, name: str, *, hint: str = "") -> np.ndarray:
    """Three finite real numbers (a list, tuple or array of shape (3,)) as a float64 array."""
    name = named(name)
    tail = f" ({hint})" if hint else ""
    try:
        arr = np.asarray(value) if not isinstance(value, (str, bytes, Mapping)) else (
            np.asarray([value], dtype=object))
    except (TypeError, ValueError):  # ragged
        arr = np.zeros(0, dtype=object)
    if arr.dtype.kind not in "iuf" or arr.shape != (3,):
        raise CalibrationError(
            f"{name} must be 3 finite real numbers (x, y, z), got {_shown(value)}{tail}"
        )
    out = arr.astype(np.float64)
    if not np.isfinite(out).all():
        raise CalibrationError(
            f"{name} must be 3 finite real numbers (x, y, z), got {out.tolist()}{tail}"
        )
    return out


def intervals(value: Any, name: str, n: int) -> list[tuple[int, int]]:
    """Sample intervals ``[(start, end), ...]`` with ``0 <= start < end <= n``, sorted.

    Each bound must be a whole number; an interval outside the recording, empty or reversed
    is refused (not clipped), and overlapping intervals are refused.
    """
    if isinstance(value, (str, bytes)) or not hasattr(value, "__iter__"):
        raise CalibrationError(
            f"{name} must be a sequence of (start, end) sample indices, got {_shown(value)}"
        )
    out: list[tuple[int, int]] = []
    for i, item in enumerate(value):
        try:
            a, b = item
        except (TypeError, ValueError):
            raise CalibrationError(
                f"{name}[{i}] must be a pair (start, end) of sample indices, got {_shown(item)}"
            ) from None
        a = integer(a, f"{name}[{i}] start", ge=0)
        b = integer(b, f"{name}[{i}] end", ge=0)
        if not (a < b <= n):
            raise CalibrationError(
                f"{name}[{i}] = ({a}, {b}) must satisfy 0 <= start < end <= {n} (the number "
                "of samples; end is exclusive)"
            )
        out.append((a, b))
    out.sort()
    for (a0, b0), (a1, b1) in zip(out[:-1], out[1:]):
        if a1 < b0:
            raise CalibrationError(
                f"{name}: intervals ({a0}, {b0}) and ({a1}, {b1}) overlap; give each sample once"
            )
    return out


def magnitude(value: Any, name: str, *, hint: str = "", signed: bool = False) -> float:
    """A scale-like number (gravity, a radius, a field, an angle) within :data:`MAGNITUDE`:
    positive, or (``signed``) zero or of either sign with its size within it.

    >>> magnitude(9.81, "gravity")
    9.81
    >>> magnitude(1e-308, "gravity")
    Traceback (most recent call last):
    ...
    triaxcal.CalibrationError: gravity must be a finite number in [1e-15, 1e+15], got 1e-308
    """
    lo, hi = MAGNITUDE
    if not signed:
        return number(value, name, ge=lo, le=hi, hint=hint)
    x = number(value, name, ge=-hi, le=hi, hint=hint)
    if x != 0 and abs(x) < lo:
        raise CalibrationError(f"{named(name)} must be 0 or at least {lo:g} in size, got "
                               f"{_shown(value)}" + (f" ({hint})" if hint else ""))
    return x


def samples(seconds: float, rate_hz: float, name: str) -> int:
    """The whole number of samples (rounded) that ``seconds`` last at ``rate_hz``: both already
    checked numbers; a duration of more samples than :data:`MAX_SAMPLES` is refused naming
    the option, instead of overflowing the count.

    >>> samples(2.0, 100.0, "rest_s")
    200
    >>> samples(1e308, 100.0, "rest_s")
    Traceback (most recent call last):
    ...
    triaxcal.CalibrationError: rest_s=1e+308 s at 100 Hz is more samples than any recording \
holds: give a duration within the recording
    """
    n = float(seconds) * float(rate_hz)
    if not (math.isfinite(n) and abs(n) <= MAX_SAMPLES):
        raise CalibrationError(
            f"{named(name)}={float(seconds):g} s at {float(rate_hz):g} Hz is more samples than "
            "any recording holds: give a duration within the recording")
    return int(round(n))


def seed(value: Any, name: str = "seed") -> int:
    """A seed of a random generator: a whole number from 0 to :data:`MAX_SEED`.

    >>> seed(7)
    7
    >>> seed(-1)
    Traceback (most recent call last):
    ...
    triaxcal.CalibrationError: seed must be a whole number in [0, 18446744073709551615], got -1
    """
    return integer(value, name, ge=0, le=MAX_SEED)


def instance(value: Any, types: type | tuple[type, ...], name: str, what: str) -> Any:
    """``value`` if it is an instance of ``types``; else a refusal saying ``what`` to pass
    (``"a Calibration (from Calibration.load or fit_session)"``)."""
    if not isinstance(value, types):
        raise CalibrationError(f"{named(name)} must be {what}, got {_shown(value)}")
    return value


def mapping(value: Any, name: str, *, optional: bool = True) -> dict[str, Any] | None:
    """A mapping with string keys (a copy as a dict), or None when ``optional``."""
    if value is None and optional:
        return None
    if not isinstance(value, Mapping) or not all(isinstance(k, str) for k in value):
        raise CalibrationError(
            f"{named(name)} must be a mapping of names to values (a dict), got {_shown(value)}")
    return dict(value)


def path(value: Any, name: str) -> str | os.PathLike[str]:
    """A file or folder name: a non-empty ``str`` or :class:`os.PathLike`."""
    if not isinstance(value, (str, os.PathLike)) or not os.fspath(value):
        raise CalibrationError(
            f"{named(name)} must be a file name (str or pathlib.Path), got {_shown(value)}")
    return value


def text_stream(value: Any, name: str) -> Any:
    """A text stream (anything with a ``write`` method, like ``sys.stderr``), or None."""
    if value is not None and not callable(getattr(value, "write", None)):
        raise CalibrationError(
            f"{named(name)} must be a text stream such as sys.stderr (or None), got "
            f"{_shown(value)}")
    return value
