"""Input validation shared by the public functions: array-likes in, contiguous float64 out."""

from __future__ import annotations

from typing import Any

import numpy as np

from .errors import CalibrationError, NonFiniteError


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
    channels after). With ``finite``, a NaN or inf raises :class:`NonFiniteError` naming the
    first bad row. Every failure is a :class:`CalibrationError` saying what to pass instead.
    """
    exact = channels == "xyz"
    want = "(N, 3), one row of x, y, z per reading" if exact else (
        "(N, K) with K >= 3 channels (x, y, z first)"
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
    if arr.ndim != 2 or (arr.shape[1] != 3 if exact else arr.shape[1] < 3):
        raise CalibrationError(f"{name} must have shape {want}; got shape {arr.shape}")
    if arr.shape[0] < min_rows:
        raise CalibrationError(f"{name} needs at least {min_rows} rows, got {arr.shape[0]}")
    arr = np.ascontiguousarray(arr, dtype=np.float64)
    if not arr.flags.aligned:  # e.g. unpickled from a network buffer: the core needs aligned
        arr = arr.copy()
    if finite and not np.isfinite(arr).all():
        bad = int(np.flatnonzero(~np.isfinite(arr).all(axis=1))[0])
        raise NonFiniteError(
            f"{name} contains NaN or inf (first at row {bad}); drop or repair those rows first"
        )
    return arr


def as_vector(value: Any, name: str) -> tuple[float, float, float]:
    """Return a finite 3-vector (a scalar is repeated on all three axes)."""
    arr = np.asarray(value, dtype=np.float64)
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
    try:
        r = float(radius)
    except (TypeError, ValueError):
        raise CalibrationError(
            f"radius must be a number (1.0 for g, 9.80665 for m/s^2, the field in uT), got "
            f"{radius!r}"
        ) from None
    if not (np.isfinite(r) and r > 0):
        raise CalibrationError(f"radius must be a finite number greater than zero, got {r}")
    return r
