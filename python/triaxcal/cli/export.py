"""``triaxcal export CAL.json --format {c,c-fixed,json,motioncal} [--prefix NAME] -o FILE``.

``c``: C99 header with float coefficients and ``<prefix>_<sensor>_apply``; ``c-fixed``: the
same with integers only (Q7.24 matrix, ``<prefix>_<sensor>_apply_q``); ``json``: the
calibration file, validated and rewritten; ``motioncal``: the 68-byte PJRC MotionCal packet.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from ..calibration import Calibration
from ..errors import CalibrationError
from ..export import DEVICE_COUNTS_PER_UNIT, EXPORT_FORMATS, export
from ..io.files import check_output


def _scale(text: str) -> tuple[str, tuple[float, str]]:
    try:
        sensor, rest = text.split("=", 1)
        value, _, unit = rest.partition(":")
        sensor = sensor.strip()
        if sensor not in DEVICE_COUNTS_PER_UNIT:
            raise ValueError
        return sensor, (float(value), unit.strip() or DEVICE_COUNTS_PER_UNIT[sensor][1])
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{text!r}: use SENSOR=COUNTS[:UNIT], e.g. accel=16384:g, gyro=131:deg/s, mag=10:uT"
        ) from None


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "export",
        help="write a calibration as a C header, fixed-point header, JSON or MotionCal packet",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("calibration", metavar="CAL.json",
                   help="calibration file written by triaxcal fit (or Calibration.save)")
    p.add_argument("--format", required=True, choices=EXPORT_FORMATS, dest="fmt",
                   help="c: C99 header, float; c-fixed: C99 header, integers only (Q7.24); "
                        "json: the calibration file, validated and rewritten; motioncal: the "
                        "68-byte PJRC MotionCal packet")
    p.add_argument("--prefix", default="triaxcal",
                   help="C identifier prefix: imu gives IMU_ACCEL_OFFSET_X, imu_accel_apply")
    p.add_argument("--counts-per-unit", type=_scale, action="append", default=[],
                   metavar="SENSOR=COUNTS[:UNIT]",
                   help="motioncal: the board driver's scale (default accel=16384:g, "
                        "gyro=131:deg/s, mag=10:uT)")
    p.add_argument("-o", "--output", required=True, metavar="FILE",
                   help="file to write (replaced whole; its folder must exist)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    out = check_output(args.output, "export")
    cal = Calibration.load(args.calibration)
    if out.resolve() == Path(args.calibration).resolve():
        raise CalibrationError("-o must differ from the calibration file")
    export(cal, args.fmt, out, prefix=args.prefix,
           counts_per_unit=dict(args.counts_per_unit) or None)
    size = out.stat().st_size if out.is_file() else None
    print(f"wrote {out} ({args.fmt}" + (f", {size} bytes" if size is not None else "")
          + f"; sensors: {', '.join(cal.sensors)})")
    return 0
