"""The magnetometer in its surroundings, for a fit of a recorded session
(:class:`~triaxcal.calibration.request.FieldOptions`): the field the World Magnetic Model
expects where and when it was recorded, the yaw-only calibration, and the alignment with the
accelerometer."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..conventions.units import UNITS, unit_factor
from ..errors import CalibrationError
from ..methods.field import ExpectedField, expected_field, strength_check
from .alignment import Alignment
from .part import SensorCalibration
from .request import FitRequest

__all__ = ["alignment_for", "expected_for", "field_stats", "measured_strength_ut", "yaw_part"]


def expected_for(request: FitRequest) -> ExpectedField | None:
    """The World Magnetic Model's field where and when the request says the data were recorded
    (None without a location)."""
    loc = request.field.location
    if loc is None:
        return None
    return expected_field(*loc, date=request.field.date)


def measured_strength_ut(part: SensorCalibration) -> float | None:
    """The field strength the raw readings show, in uT: ``radius / cbrt(det(matrix))`` in raw
    units (a yaw-only part: the horizontal circle's radius), converted; None for raw counts
    (no physical scale to compare)."""
    if UNITS.get(part.raw_unit, ("", 0.0))[0] != "mag" or part.radius is None:
        return None
    yaw = part.stats.get("yaw")
    if isinstance(yaw, dict) and yaw.get("raw_horizontal") is not None:
        raw = float(yaw["raw_horizontal"])
    else:
        raw = part.radius / float(np.linalg.det(part.matrix)) ** (1.0 / 3.0)
    return raw * unit_factor(part.raw_unit, "uT")


def field_stats(part: SensorCalibration, expected: ExpectedField) -> tuple[SensorCalibration,
                                                                           list[str]]:
    """``part`` with the expected field recorded and the strength compared (warnings)."""
    measured = measured_strength_ut(part)
    is_yaw = part.model == "yaw"
    want = expected.horizontal_ut if is_yaw else expected.total_ut
    warn = strength_check(measured, want, "horizontal field" if is_yaw else "field")
    stats = dict(part.stats)
    stats["field_strength_ut"] = measured
    warnings = list(stats.get("warnings") or [])
    for w in [warn, *expected.warnings]:
        if w and w not in warnings:
            warnings.append(w)
    stats["warnings"] = warnings
    return part.replace(expected_field=expected, stats=stats), [w for w in [warn] if w]


def _accel_columns(src: Any) -> np.ndarray | None:
    """The accelerometer readings at the same instants as the source's magnetometer."""
    table = getattr(src, "table", None)
    if table is not None and table.names and all(c in table.names for c in ("ax", "ay", "az")):
        return table.data[:, [table.names.index(c) for c in ("ax", "ay", "az")]]
    rec = getattr(src, "recording", None)
    if rec is not None and getattr(rec, "accel", None) is not None:
        return None  # logs: synchronized below
    return None


def _synced(src: Any) -> tuple[np.ndarray, np.ndarray] | None:
    """(mag, accel) at the same instants from a table's columns or a log's streams."""
    acc = _accel_columns(src)
    if acc is not None:
        names = src.table.names
        cols = src.columns
        idx = [names.index(c) if isinstance(c, str) else int(c) for c in cols]
        return src.table.data[:, idx], acc
    rec = getattr(src, "recording", None)
    if rec is not None:
        try:
            _, sync = rec.synchronized(("mag", "accel"))
        except (CalibrationError, KeyError, AttributeError):
            return None
        return np.asarray(sync["mag"]), np.asarray(sync["accel"])
    return None


def yaw_part(src: Any, expected: ExpectedField | None, raw_unit: str, *,
             accel: SensorCalibration | None = None) -> SensorCalibration:
    """The yaw-only fit of ``src``'s magnetometer readings; ``accel`` calibrates the
    accelerometer readings that give the vertical (when the source has them)."""
    from ..methods.yaw import fit_yaw
    from ..quality.coverage import coverage
    from .part import _norm_stats
    from .parts import yaw_part_unjudged

    acc = None
    pair = _synced(src)
    mag = src.points
    if pair is not None:
        mag, acc = pair
        if accel is not None:
            acc = accel.apply(acc)
    y = fit_yaw(mag, accel=acc, field=expected, raw_unit=raw_unit)
    cal = y.apply(mag)
    return yaw_part_unjudged(y, input_sha256=src.sha256, source=str(src.path),
                             extra_stats={"columns": src.columns, "n_input": len(mag),
                                          "coverage_pct": coverage(cal).percent,
                                          "norms": _norm_stats(np.linalg.norm(cal, axis=1))})


def alignment_for(src: Any, mag_part: SensorCalibration, expected: ExpectedField | None, *,
                  accel: SensorCalibration | None, window: int) -> tuple[Alignment, str]:
    """The alignment of the fitted magnetometer part with the accelerometer (``accel``, its
    calibration), from still poses where both were read; and its text."""
    from ..methods.alignment import align_mag_accel

    if accel is None:
        raise CalibrationError(
            "--align needs the accelerometer's calibration: fit it first into the same "
            "calibration file (triaxcal fit DATA --sensor accel --poses -o CAL.json), then the "
            "magnetometer with --align -o CAL.json")
    pair = _synced(src)
    if pair is None:
        raise CalibrationError(
            "--align needs the accelerometer read with the magnetometer: a table with "
            "ax,ay,az beside the magnetometer columns, or a log with both sensors")
    mag, acc = pair
    al = align_mag_accel(mag, acc, mag_cal=mag_part, accel_cal=accel, window=window,
                         expected_inclination_deg=(None if expected is None
                                                   else expected.inclination_deg))
    return Alignment.from_result(al), al.text()
