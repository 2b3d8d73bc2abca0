"""Fitting one sensor of a recorded session the way ``triaxcal fit`` does, from the fit
command's options (an :class:`argparse.Namespace` from :func:`add_fit_options`, or
:func:`triaxcal.fleet.batch.fit_options`): reading the session or log, pose detection, the
robust fit with model choice, units and plausibility, the Earth's field, and the checks that
refuse a fit which is not a calibration (:func:`undetermined`). ``triaxcal fit``, ``report``,
``batch`` and the live page share it.
"""

from __future__ import annotations

import argparse
import math
import re
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..conventions.units import UNITS, implausible_radius, unit_factor
from ..detect.options import add_pose_options
from ..errors import CalibrationError
from ..fit.ellipsoid import MODELS
from ..io.akm import apply_asa, asa_factors
from ..io.tables import SENSOR_COLUMNS, Table, pick_columns, read_table
from ..methods.field import ExpectedField
from ..quality.coverage import coverage, coverage_warning
from .file import SENSORS, SensorCalibration
from .parts import fold_asa
from .source import (
    Source,
    add_source_options,
    autopilot_stats,
    load_source,
    table_source,
)
from .surroundings import (
    expected_from_args,
    field_stats,
    yaw_part,
)

__all__ = ["SENSOR_COLUMNS", "Table", "parse_radius", "pick_columns", "read_table"]

#: Default radius per sensor when --radius is not given (None: keep the data's own scale).
DEFAULT_RADIUS = {"accel": (1.0, "g"), "gyro": None, "mag": None}

_UNITS_EXACT = ("g", "mg", "m/s^2", "uT", "nT", "mT", "gauss", "mG", "deg/s", "rad/s", "counts")
_UNIT_ALIASES = {"m/s2": "m/s^2", "mps2": "m/s^2", "ut": "uT", "µt": "uT", "dps": "deg/s",
                 "lsb": "counts", "G": "gauss"}

#: A fit is not written when its calibrated directions all lie within a cap this small
#: (length of their mean unit vector: 0 for readings all round the sphere, 1 for one point;
#: 0.9 is a cap of about 37 deg radius) ...
MAX_MEAN_DIRECTION = 0.9
#: ... or in a band this thin (smallest eigenvalue of mean(d d^T): 1/3 for readings all
#: round the sphere or the six faces, 0 for a ring about one axis).
MIN_DIRECTION_SPREAD = 0.02

#: What to record instead, per sensor, when a fit is refused.
RECORD_INSTEAD = {
    "accel": "hold the board still in many orientations -- at least each of the six faces "
             "up in turn, better 20 or more spread over the sphere (triaxcal capture says "
             "which way to turn next) -- and fit the still poses with --poses",
    "mag": "turn the board slowly through every orientation (upside down and onto each "
           "side, e.g. figure eights), away from steel, magnets and currents",
    "gyro": "a sphere fit of gyroscope readings needs turns at one constant rate about many "
            "axes (a turntable); for the gyroscope bias record the board lying still and use "
            "triaxcal.gyro_bias, for its gains record turns of known angle (e.g. 360 deg "
            "about each axis, both ways) and use triaxcal.gyro_gains",
}


def parse_radius(text: str, sensor: str) -> tuple[float, str]:
    """``"1g"`` -> (1.0, "g"); ``"48uT"`` -> (48.0, "uT"); a bare number gets a unit by size.

    Bare numbers: accelerometer 0.5..2 -> g, 5..15 -> m/s^2, else counts; magnetometer
    10..100 -> uT, else counts; gyroscope -> deg/s.

    >>> (parse_radius("1g", "accel"), parse_radius("9.80665", "accel"),
    ...  parse_radius("16384", "accel"))
    ((1.0, 'g'), (9.80665, 'm/s^2'), (16384.0, 'counts'))
    >>> parse_radius("48uT", "mag")
    (48.0, 'uT')
    """
    m = re.fullmatch(r"\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([^\s\d].*)?\s*", text)
    if not m:
        raise CalibrationError(
            f"--radius {text!r}: give a number with an optional unit, e.g. 1g, 9.80665, 48uT, "
            "16384"
        )
    value = float(m.group(1))
    if not value > 0:
        raise CalibrationError(f"--radius must be greater than zero, got {text!r}")
    suffix = (m.group(2) or "").strip()
    if suffix:
        unit = (suffix if suffix in _UNITS_EXACT
                else _UNIT_ALIASES.get(suffix) or _UNIT_ALIASES.get(suffix.lower()))
        if unit is None:
            raise CalibrationError(
                f"--radius {text!r}: unknown unit {suffix!r}; use one of {_UNITS_EXACT}"
            )
        return value, unit
    if sensor == "accel":
        return value, "g" if 0.5 <= value <= 2 else "m/s^2" if 5 <= value <= 15 else "counts"
    if sensor == "mag":
        return value, "uT" if 10 <= value <= 100 else "counts"
    return value, "deg/s"


# --------------------------------------------------------------------------------------------
# The fit pipeline, shared with `triaxcal report`


def _asa(text: str) -> tuple[int, int, int]:
    parts = [s.strip() for s in text.split(",")]
    try:
        vals = tuple(int(s, 0) for s in parts)
        asa_factors(vals)
    except (ValueError, CalibrationError):
        raise argparse.ArgumentTypeError(
            f"--asa {text!r}: give the three fuse-ROM bytes, e.g. 176,177,165 (0..255, "
            "decimal or 0x..)"
        ) from None
    return vals  # type: ignore[return-value]


def add_fit_options(p: argparse.ArgumentParser) -> None:
    """The options of ``fit`` that ``report`` also takes for a session file."""
    p.add_argument("--sensor", choices=SENSORS, default=None,
                   help="which sensor the columns hold (default: accel)")
    p.add_argument("--columns", default=None,
                   help="three columns by name or zero-based index: ax,ay,az or 0,1,2 "
                        "(default: the sensor's named columns, or the first three)")
    p.add_argument("--model", choices=(*MODELS, "auto"), default="auto",
                   help="sphere (offset + 1 scale), axis (+ 3 gains), full (+ cross-axis / soft "
                        "iron), auto: chosen by BIC (default)")
    p.add_argument("--radius", default=None,
                   help="magnitude of calibrated readings with unit: 1g (accel default), "
                        "9.80665 (m/s^2), 48uT, 16384 (counts); a value no sensor on Earth "
                        "reads (e.g. 48mT for a magnetometer) gives a warning. Default for "
                        "gyro/mag: the data's own")
    p.add_argument("--unit", default=None,
                   help="calibrated unit to record (default: from --radius)")
    p.add_argument("--raw-unit", default=None,
                   help="unit of the raw readings (default: counts; a log's own unit)")
    p.add_argument("--sigma", type=float, default=2.0,
                   help="reject readings whose length is more than SIGMA standard deviations "
                        "from the mean (Magneto's rule), iterated; 0 disables (default 2)")
    p.add_argument("--rounds", type=int, default=10,
                   help="most reject-and-refit rounds; 1 = a single pass like Magneto "
                        "(default 10)")
    p.add_argument("--reject-on", choices=("calibrated", "raw"), default="calibrated",
                   help="judge the first round on calibrated lengths (default) or raw lengths "
                        "(exactly Magneto's rule)")
    p.add_argument("--poses", action="store_true",
                   help="reduce a raw time series (a capture session) to still-pose means first")
    p.add_argument("--asa", type=_asa, default=None, metavar="X,Y,Z",
                   help="magnetometer: the fuse-ROM sensitivity bytes ASAX,ASAY,ASAZ of an "
                        "AK8963 (AK8975, AK09911, AK09912), applied before fitting as "
                        "k = (ASA - 128) / 256 + 1; the part still takes the register counts")
    p.add_argument("--bootstrap", type=int, default=0, metavar="N",
                   help="also compute 95 %% bootstrap intervals of every coefficient from N "
                        "refits (e.g. 1000, fixed seed), stored in the calibration, shown by "
                        "report and used by diff")
    p.add_argument("--fix", action="append", default=[], metavar="NAME=VALUE",
                   help="hold a parameter at a value instead of fitting it (repeatable): "
                        "offset_x/y/z in raw units, gain_x/y/z (or gain for the sphere model) "
                        "in calibrated units per raw unit -- with --radius 16384 a gain of 1 "
                        "means unchanged counts, as in the seed's spreadsheet (--fix gain_z=1)")
    add_pose_options(p)
    p.add_argument("--skip-bad-lines", action="store_true",
                   help="skip lines of the data file that are not a row of numbers (and count "
                        "them) instead of stopping at the first one")
    add_source_options(p)


def parse_fix(items: list[str] | None) -> dict[str, float] | None:
    """``["gain_z=1", ...]`` from ``--fix`` to ``{"gain_z": 1.0}`` (None when empty)."""
    if not items:
        return None
    out: dict[str, float] = {}
    for item in items:
        name, sep, value = item.partition("=")
        try:
            number = float(value)
        except ValueError:
            number = math.nan
        if not sep or not name.strip() or not math.isfinite(number):
            raise CalibrationError(
                f"--fix {item!r}: give NAME=VALUE with a finite number, e.g. --fix gain_z=1"
            )
        out[name.strip()] = number
    return out


@dataclass
class FitOutcome:
    """Everything ``fit`` and ``report`` need after fitting a file."""

    part: SensorCalibration
    points: np.ndarray
    sensor: str
    rejected: np.ndarray
    reason: str | None
    table: Table | None
    source: Source | None = None
    #: Things to tell the user about the input (skipped lines, an implausible radius).
    notes: list[str] = field(default_factory=list)
    expected: ExpectedField | None = None


def fit_file(args: argparse.Namespace, *, table: Table | None = None) -> FitOutcome:
    """Read ``args.data`` (or take ``table``, already read), pick columns, optionally reduce
    to poses, fit robustly."""
    from ..fit.select import fit_robust

    sensor = args.sensor or "accel"
    notes: list[str] = []
    expected = expected_from_args(args, sensor)
    if (getattr(args, "yaw_only", False) or getattr(args, "align", False)) and sensor != "mag":
        raise CalibrationError("--yaw-only and --align apply to --sensor mag")
    src = load_source(args.data, sensor, args) if table is None else table_source(
        table, sensor, args)
    table, pts = src.table, src.points
    if table is not None:
        notes += [f"note: {n}" for n in table.notes]
    raw_unit = args.raw_unit or src.raw_unit or "counts"
    if getattr(args, "yaw_only", False):
        if args.radius is not None and args.radius.strip().lower() != "wmm":
            raise CalibrationError("--yaw-only takes the field from --location (the World "
                                   "Magnetic Model); drop --radius")
        part = yaw_part(args, src, expected, raw_unit)
        if expected is not None:
            part, _ = field_stats(part, expected)
        return FitOutcome(part=part, points=pts, sensor=sensor,
                          rejected=np.zeros(0, dtype=np.int64), reason=None, table=table,
                          source=src, expected=expected)
    if expected is not None and args.radius is not None and args.radius.strip().lower() == "wmm":
        unit = args.unit or "uT"
        radius = expected.total_ut * unit_factor("uT", unit)
    elif args.radius is not None:
        radius, unit = parse_radius(args.radius, sensor)
        warn = implausible_radius(sensor, radius, unit)
        if warn:
            notes.append(f"warning: {warn}")
    elif DEFAULT_RADIUS[sensor] is not None:
        radius, unit = DEFAULT_RADIUS[sensor]  # type: ignore[misc]
    else:
        radius, unit = None, raw_unit
    if args.unit:
        unit = args.unit
    if args.rounds < 0:
        raise CalibrationError("--rounds must be >= 0")
    fitted = pts
    if getattr(args, "asa", None) is not None:
        if sensor != "mag":
            raise CalibrationError("--asa is the magnetometer's sensitivity adjustment: use it "
                                   "with --sensor mag")
        fitted = apply_asa(pts, args.asa)  # adjusted before fitting, folded back below
    rob = fit_robust(fitted, model=args.model, radius=radius, sigma=args.sigma,
                     max_rounds=args.rounds, lengths=args.reject_on,
                     fixed=parse_fix(getattr(args, "fix", None)))
    extra: dict[str, Any] = {
        "columns": src.columns,
        "poses": bool(args.poses),
        "n_input": len(pts),
        "sigma": float(args.sigma),
        "rejection_rounds": int(rob.rounds),
    }
    if table is not None and table.skipped:
        extra["lines_skipped"] = int(table.skipped)
    if rob.model_reason:
        extra["model_reason"] = rob.model_reason
    extra.update(src.extra)
    extra.update(autopilot_stats(src, sensor))
    part = SensorCalibration.from_fit(
        rob.fit, raw_unit=raw_unit, unit=unit, points=fitted[rob.inliers],
        rejected=rob.rejected, input_sha256=src.sha256, source=str(src.path),
        extra_stats=extra,
    )
    if fitted is not pts:  # the part takes the register counts the chip reports
        part = fold_asa(part, args.asa)
    stats = dict(part.stats)
    cov = coverage(part.apply(pts))  # of the session: every reading, outliers too
    stats["coverage_pct"] = cov.percent
    low = coverage_warning(cov, sensor)
    if radius is None and part.radius is not None and UNITS.get(unit, ("",))[0] == sensor:
        odd = implausible_radius(sensor, part.radius, unit)
        if odd:
            notes.append(f"warning: fitted radius: {odd}")
    stats["warnings"] = [*stats.get("warnings", []), *([low] if low else []),
                         *(n[len("warning: "):] for n in notes if n.startswith("warning: "))]
    if getattr(args, "bootstrap", 0):
        from ..methods.bootstrap import bootstrap

        if fitted is not pts:
            raise CalibrationError("--bootstrap with --asa is not supported: the intervals "
                                   "would describe the ASA-adjusted coefficients")
        ci = bootstrap(fitted[rob.inliers], fit=rob.fit, radius=radius, n_boot=args.bootstrap,
                       raw_unit=raw_unit, unit=unit)
        stats["intervals"] = ci.as_dict()
        stats["warnings"] = list(stats.get("warnings", [])) + ci.warnings()
    part = SensorCalibration(**{**_fields(part), "stats": stats})
    if expected is not None:
        part, _ = field_stats(part, expected)
    return FitOutcome(part=part, points=pts, sensor=sensor, rejected=rob.rejected,
                      reason=rob.model_reason, table=table, source=src, notes=notes,
                      expected=expected)


def fit_table(table: Table, args: argparse.Namespace) -> FitOutcome:
    """:func:`fit_file` on a table already read (``triaxcal batch`` fits each board so)."""
    return fit_file(args, table=table)


def _fields(part: SensorCalibration) -> dict[str, Any]:
    return {k: getattr(part, k) for k in ("offset", "matrix", "raw_unit", "unit", "radius",
                                          "model", "temperature", "stats", "input_sha256",
                                          "source", "previous", "expected_field", "alignment")}


def undetermined(part: SensorCalibration, points: Any) -> list[str]:
    """Why a fit must not be written as a calibration: it did not converge, or its readings
    cover too little of the sphere (a small cap or a thin band) to determine its model.

    Returns the reasons in words (empty when the fit is usable).
    """
    why = []
    s = part.stats
    if s.get("converged") is False:
        why.append(f"the fit did not converge ({s.get('iterations', '?')} iterations)")
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    d = part.apply(pts)
    n = np.linalg.norm(d, axis=1)
    d = d[n > 0] / n[n > 0, None]
    if len(d):
        mean = d.mean(axis=0)
        m = float(np.linalg.norm(mean))
        spread = float(np.linalg.eigvalsh(d.T @ d / len(d))[0])
        if m > MAX_MEAN_DIRECTION:
            cap = float(np.degrees(np.arccos(np.clip(d @ (mean / m), -1, 1))).max())
            why.append(
                f"the readings all point within {cap:.0f} deg of one direction "
                f"(coverage {s.get('coverage_pct', 0):.0f} % of the sphere), too little to "
                f"determine the {part.model} model"
            )
        elif spread < MIN_DIRECTION_SPREAD:
            why.append(
                f"the readings lie in a thin band round one axis (spread {spread:.3f}; 0.33 "
                f"for readings all round the sphere), too little to determine the "
                f"{part.model} model"
            )
    return why
