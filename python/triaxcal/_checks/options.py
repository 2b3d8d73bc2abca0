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
from collections.abc import Sequence
from typing import Any

import numpy as np

from ..errors import CalibrationError

__all__ = [
    "choice",
    "flag",
    "integer",
    "intervals",
    "number",
    "numbers_list",
    "optional_number",
    "vector3",
]


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
        raise CalibrationError(f"{name} must be one of {listed}, got {_shown(value)}")
    return value


def flag(value: Any, name: str) -> bool:
    """Return ``value`` if it is a bool (``True``/``False``); ``"no"`` or ``0`` are refused."""
    if not isinstance(value, (bool, np.bool_)):
        raise CalibrationError(f"{name} must be True or False, got {_shown(value)}")
    return bool(value)


def numbers_list(
    value: Any,
    name: str,
    *,
    min_len: int = 1,
    **bounds: Any,
) -> tuple[float, ...]:
    """A sequence (list, tuple, 1-D array) of at least ``min_len`` numbers, each in range."""
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
    tail = f" ({hint})" if hint else ""
    arr = np.asarray(value) if not isinstance(value, (str, bytes)) else np.asarray([value])
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
