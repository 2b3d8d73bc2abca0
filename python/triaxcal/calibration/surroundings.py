"""``fit`` options for the magnetometer's surroundings: the expected field from the location
(``--radius wmm --location LAT,LON[,ALT_M] [--date YYYY-MM-DD]``), the yaw-only calibration
(``--yaw-only``) and the alignment with the accelerometer (``--align``)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np

from ..conventions.units import UNITS, unit_factor
from ..errors import CalibrationError
from ..methods.field import ExpectedField, expected_field, parse_location, strength_check
from .file import Alignment, Calibration, SensorCalibration

__all__ = ["add_field_options", "alignment_for", "expected_from_args", "measured_strength_ut",
           "yaw_part"]


def add_field_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("the expected field, yaw-only calibration, alignment (magnetometer)")
    g.add_argument("--location", default=None, metavar="LAT,LON[,ALT_M]",
                   help="where the data were recorded (deg, deg, m above the WGS 84 ellipsoid): "
                        "the World Magnetic Model's field there is recorded, compared with the "
                        "fit and, with --radius wmm, used as the radius (needs triaxcal[geo])")
    g.add_argument("--date", default=None, metavar="YYYY-MM-DD",
                   help="date of the recording for the World Magnetic Model (default: today)")
    g.add_argument("--yaw-only", action="store_true",
                   help="magnetometer turned about the vertical only (boat, car, rover): fit "
                        "the horizontal ellipse; the vertical offset from the --location's "
                        "field and the accelerometer columns (ax,ay,az) when present")
    g.add_argument("--align", action="store_true",
                   help="magnetometer: also find its rotation into the accelerometer's frame "
                        "from still poses where both were read (the accelerometer part must "
                        "be in -o CAL.json already)")


def expected_from_args(args: argparse.Namespace, sensor: str) -> ExpectedField | None:
    """The WMM field for ``--location`` / ``--date`` (None without a location)."""
    radius_wmm = isinstance(args.radius, str) and args.radius.strip().lower() == "wmm"
    loc = getattr(args, "location", None)
    if getattr(args, "date", None) and not loc:
        raise CalibrationError("--date needs --location LAT,LON[,ALT_M]")
    if radius_wmm and not loc:
        raise CalibrationError("--radius wmm needs --location LAT,LON[,ALT_M] (and --date "
                               "YYYY-MM-DD of the recording; default today)")
    if loc is None:
        return None
    if sensor != "mag":
        raise CalibrationError(f"--location gives the magnetic field; it applies to --sensor "
                               f"mag, not {sensor}")
    lat, lon, alt = parse_location(loc)
    return expected_field(lat, lon, alt, date=args.date)


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


def yaw_part(args: argparse.Namespace, src: Any, expected: ExpectedField | None,
             raw_unit: str) -> SensorCalibration:
    """The ``--yaw-only`` fit of ``src``'s magnetometer readings."""
    from ..methods.yaw import fit_yaw

    if args.poses:
        raise CalibrationError("--yaw-only fits the turning readings themselves: drop --poses")
    accel = None
    pair = _synced(src)
    mag = src.points
    if pair is not None:
        mag, accel = pair
        acal = _accel_part(args)
        if acal is not None:
            accel = acal.apply(accel)
    from ..quality.coverage import coverage
    from .file import _norm_stats

    y = fit_yaw(mag, accel=accel, field=expected, raw_unit=raw_unit)
    cal = y.apply(mag)
    return y.part(input_sha256=src.sha256, source=str(src.path),
                  extra_stats={"columns": src.columns, "n_input": len(mag),
                               "coverage_pct": coverage(cal).percent,
                               "norms": _norm_stats(np.linalg.norm(cal, axis=1))})


def _accel_part(args: argparse.Namespace) -> SensorCalibration | None:
    path = Path(args.output)
    if path.exists() and not args.new:
        try:
            return Calibration.load(path).accel
        except CalibrationError:
            return None
    return None


def alignment_for(args: argparse.Namespace, src: Any, mag_part: SensorCalibration,
                  expected: ExpectedField | None) -> tuple[Alignment, str]:
    """The ``--align`` result for the fitted magnetometer part, and its text."""
    from ..methods.alignment import align_mag_accel

    path = Path(args.output)
    accel_part = _accel_part(args)
    if accel_part is None:
        raise CalibrationError(
            f"--align needs the accelerometer's calibration in {path}: fit it first "
            f"(triaxcal fit DATA --sensor accel --poses -o {path}), then the magnetometer")
    pair = _synced(src)
    if pair is None:
        raise CalibrationError(
            "--align needs the accelerometer read with the magnetometer: a table with "
            "ax,ay,az beside the magnetometer columns, or a log with both sensors")
    if args.poses:
        raise CalibrationError("--align finds the still poses itself: drop --poses")
    mag, acc = pair
    al = align_mag_accel(mag, acc, mag_cal=mag_part, accel_cal=accel_part, window=args.window,
                         expected_inclination_deg=(None if expected is None
                                                   else expected.inclination_deg))
    return Alignment.from_result(al), al.text()
