"""The options of ``fit`` that ``report`` and ``batch`` also take, parsed into one
:class:`~triaxcal.calibration.request.FitRequest` (validated there, once)."""

from __future__ import annotations

import argparse
import math
from typing import Any

from ..calibration.request import (
    FIT_METHODS,
    MAX_BOOTSTRAP,
    OUTLIER_RULES,
    FieldOptions,
    FitRequest,
    SourceOptions,
)
from ..conventions.names import SENSORS
from ..errors import CalibrationError
from ..fit.ellipsoid import MODELS
from ..io.akm import asa_factors
from ._pose_options import add_pose_options, settings_from_args

__all__ = ["add_field_options", "add_fit_options", "add_source_options", "fit_request",
           "parse_fix"]

_DEFAULT = FitRequest()


def _asa(text: str) -> tuple[int, int, int]:
    parts = [s.strip() for s in text.split(",")]
    try:
        vals = tuple(int(s, 0) for s in parts)
        asa_factors(vals)
    except (ValueError, CalibrationError):
        raise argparse.ArgumentTypeError(
            f"--asa {text[:40]!r}: give the three fuse-ROM bytes, e.g. 176,177,165 (0..255, "
            "decimal or 0x..)"
        ) from None
    return vals  # type: ignore[return-value]


def _bootstrap(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text[:40]!r}") from None
    if not 0 <= n <= MAX_BOOTSTRAP:
        raise argparse.ArgumentTypeError(f"expected 0 to {MAX_BOOTSTRAP} resamples, got {n}")
    return n


def _nonnegative(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text[:40]!r}") from None
    if not v >= 0:
        raise argparse.ArgumentTypeError(f"expected a number >= 0, got {text[:40]!r}")
    return v


def _rounds(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text[:40]!r}") from None
    if not 0 <= n <= 1000:
        raise argparse.ArgumentTypeError(f"expected 0 to 1000 rounds, got {n}")
    return n


def _instance(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text[:40]!r}") from None
    if not 0 <= n <= 255:
        raise argparse.ArgumentTypeError(f"expected 0 to 255, got {n}")
    return n


def add_source_options(p: argparse.ArgumentParser) -> None:
    """``--instance``, ``--topic``, ``--undo-autopilot-cal`` (logs only)."""
    p.add_argument("--instance", type=_instance, default=None, metavar="N",
                   help="log: which sensor -- PX4 per-sensor topics sensor_accel/gyro/mag "
                        "instance N (default: sensor_combined, vehicle_magnetometer); "
                        "ArduPilot IMU/MAG (0), IMU2/MAG2 (1), ...")
    p.add_argument("--topic", action="append", default=None, metavar="NAME",
                   help="ROS bag: the sensor_msgs/Imu and/or MagneticField topic to read "
                        "(repeat, or comma-separate, when the bag has several)")
    p.add_argument("--undo-autopilot-cal", action="store_true",
                   help="autopilot log: remove the calibration the autopilot applied (its "
                        "CAL_* / COMPASS_* / INS_* parameters, with its own equation) so the "
                        "fit sees the raw sensor")


def add_fit_options(p: argparse.ArgumentParser) -> None:
    """The options of ``fit`` that ``report`` and ``batch`` also take."""
    p.add_argument("--sensor", choices=SENSORS, default=None,
                   help="which sensor the columns hold (default: accel)")
    p.add_argument("--method", choices=FIT_METHODS, default=_DEFAULT.method,
                   help="ellipsoid: fit the readings alone (default); attitude: a flight log's "
                        "compass against the Earth's field turned by the logged attitude (ATT, "
                        "vehicle_attitude), with battery-current or throttle interference "
                        "(COMPASS_MOT); the field from the log's GPS / EKF origin or --location, "
                        "else fitted")
    p.add_argument("--columns", default=None,
                   help="three columns by name or zero-based index: ax,ay,az or 0,1,2 "
                        "(default: the sensor's named columns, or the first three)")
    p.add_argument("--model", choices=(*MODELS, "auto"), default=_DEFAULT.model,
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
    p.add_argument("--outliers", choices=OUTLIER_RULES, default=None,
                   help="outlier rule on the calibrated lengths: robust (modified z-score above "
                        "3.5, Iglewicz & Hoaglin: keeps clean data, drops gross errors), sigma "
                        "(more than --sigma standard deviations from the mean, iterated; drops "
                        "about 5 %% of clean data at 2), magneto (exactly Magneto's: one pass "
                        "of 2 sigma on raw lengths), none. Default: robust, or sigma when "
                        "--sigma is given")
    p.add_argument("--sigma", type=_nonnegative, default=None,
                   help=f"the sigma rule's threshold in standard deviations of the lengths; 0 "
                        f"disables rejection (default {_DEFAULT.sigma:g})")
    p.add_argument("--rounds", type=_rounds, default=_DEFAULT.rounds,
                   help="most reject-and-refit rounds; 1 = a single pass like Magneto "
                        "(default %(default)s)")
    p.add_argument("--reject-on", choices=("calibrated", "raw"), default=_DEFAULT.reject_on,
                   help="judge the first round on calibrated lengths (default) or raw lengths "
                        "(exactly Magneto's rule)")
    p.add_argument("--poses", action="store_true",
                   help="reduce a raw time series (a capture session) to still-pose means first")
    p.add_argument("--asa", type=_asa, default=None, metavar="X,Y,Z",
                   help="magnetometer: the fuse-ROM sensitivity bytes ASAX,ASAY,ASAZ of an "
                        "AK8963 (AK8975, AK09911, AK09912), applied before fitting as "
                        "k = (ASA - 128) / 256 + 1; the part still takes the register counts")
    p.add_argument("--bootstrap", type=_bootstrap, default=0, metavar="N",
                   help="also compute 95 %% bootstrap intervals of every coefficient from N "
                        f"refits (e.g. 1000, fixed seed; at most {MAX_BOOTSTRAP}), stored in the "
                        "calibration, shown by report and used by diff")
    p.add_argument("--fix", action="append", default=[], metavar="NAME=VALUE",
                   help="hold a parameter at a value instead of fitting it (repeatable): "
                        "offset_x/y/z in raw units, gain_x/y/z (or gain for the sphere model) "
                        "in calibrated units per raw unit -- with --radius 16384 a gain of 1 "
                        "means unchanged counts, as in the spreadsheet method (--fix gain_z=1)")
    add_pose_options(p)
    p.add_argument("--skip-bad-lines", action="store_true",
                   help="skip lines of the data file that are not a row of numbers (and count "
                        "them) instead of stopping at the first one")
    add_source_options(p)


def add_field_options(p: argparse.ArgumentParser) -> None:
    """``--location``, ``--date``, ``--yaw-only``, ``--align`` (the magnetometer)."""
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


def parse_fix(items: list[str] | None) -> dict[str, float]:
    """``["gain_z=1", ...]`` from ``--fix`` to ``{"gain_z": 1.0}``."""
    out: dict[str, float] = {}
    for item in items or []:
        name, sep, value = item.partition("=")
        try:
            number = float(value)
        except ValueError:
            number = math.nan
        if not sep or not name.strip() or not math.isfinite(number):
            raise CalibrationError(
                f"--fix {item[:60]!r}: give NAME=VALUE with a finite number, e.g. --fix gain_z=1"
            )
        out[name.strip()] = number
    return out


def _rule(args: Any) -> str:
    """``--outliers``, or the sigma rule when only ``--sigma`` was given."""
    if args.outliers is not None:
        return str(args.outliers)
    return "sigma" if args.sigma is not None else _DEFAULT.outliers


def fit_request(args: Any, **overrides: Any) -> FitRequest:
    """The :class:`~triaxcal.calibration.request.FitRequest` the parsed options describe."""
    source = SourceOptions(
        columns=getattr(args, "columns", None),
        poses=bool(getattr(args, "poses", False)),
        detection=settings_from_args(args),
        instance=getattr(args, "instance", None),
        topics=tuple(args.topic) if getattr(args, "topic", None) else None,
        undo_autopilot_cal=bool(getattr(args, "undo_autopilot_cal", False)),
        skip_bad_lines=bool(getattr(args, "skip_bad_lines", False)),
    )
    field = FieldOptions(
        location=getattr(args, "location", None),
        date=getattr(args, "date", None),
        yaw_only=bool(getattr(args, "yaw_only", False)),
        align=bool(getattr(args, "align", False)),
    )
    kw: dict[str, Any] = dict(
        sensor=args.sensor or "accel", model=args.model, radius=args.radius, unit=args.unit,
        raw_unit=args.raw_unit, outliers=_rule(args),
        sigma=_DEFAULT.sigma if args.sigma is None else args.sigma, rounds=args.rounds,
        reject_on=args.reject_on,
        asa=args.asa, bootstrap=getattr(args, "bootstrap", 0),
        fixed=parse_fix(getattr(args, "fix", None)), source=source, field=field,
        method=getattr(args, "method", None) or _DEFAULT.method,
    )
    kw.update(overrides)
    return FitRequest(**kw)
