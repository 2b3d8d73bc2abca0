"""triaxcal imu SESSION --rate-hz HZ -o CAL.json: accelerometer and gyroscope from still poses
joined by turns by hand, no rig (Tedaldi, Pretto and Menegatti 2014, imu_tk:
:func:`triaxcal.calibrate_imu`).

Lay the board still for a while (--rest seconds at least; the detector learns its noise
there), then hold it still in many orientations (at least 9, better 30-40, a few seconds
each), turning it by hand between them. The accelerometer is fitted to the still poses
(ellipsoid of radius --gravity); the gyroscope's matrix so that the turns, integrated, carry
the gravity direction of one pose into the next. Both sensors sampled together: one table
with both (t,ax,ay,az,gx,gy,gz,...), or an accelerometer file and a gyroscope file row for row
(imu_tk's xsens_acc.mat and xsens_gyro.mat: t x y z each, no header).

Both parts are written: the accelerometer in the unit of --gravity, the gyroscope in rad/s,
each (raw - offset) @ matrix.T with the matrix multiplying; both pass the validity gate or
neither is written. The gyroscope's rest reading depends on the acceleration it feels (its
g-sensitivity, fitted unless --no-g-sensitivity); it is printed and stored in the gyroscope
part's stats, and the part itself does not apply it.

examples:
  triaxcal imu session.csv --gravity 1g -o cal.json
  triaxcal imu xsens_acc.mat xsens_gyro.mat --time-column 0 --accel-columns 1,2,3 \\
      --gyro-columns 1,2,3 --rate-hz 100 --gravity 9.81744 -o cal.json
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from ..calibration.parts import part_from_imu
from ..errors import CalibrationError
from ..io.tables import read_table
from ..methods.gyro import sample_rate
from ..methods.imu import calibrate_imu
from ..report.text import coefficient_table
from ._calfile import add_output_options, save_parts
from ._method_options import (
    add_bias_option,
    add_triad_options,
    bias_from_args,
    gravity_type,
    time_column,
    triad_columns,
)
from ._pose_options import nonnegative_float, positive_float, positive_int

HELP = "accelerometer and gyroscope from still poses and turns by hand (Tedaldi, imu_tk)"


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "imu", help=HELP, description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("data", metavar="SESSION",
                   help="both sensors' readings, or the accelerometer's with GYRO_DATA")
    p.add_argument("gyro_data", metavar="GYRO_DATA", nargs="?", default=None,
                   help="the gyroscope's readings, row for row with SESSION (optional)")
    p.add_argument("--rate-hz", type=positive_float, default=None, metavar="HZ",
                   help="the sample rate, for the still detector's windows (default: rows per "
                        "second of the time stamps)")
    p.add_argument("--time-column", default=None, metavar="NAME|INDEX",
                   help="the time stamps (s) the turns are integrated over (default: a column "
                        "named t; without one, uniform at --rate-hz)")
    p.add_argument("--gravity", type=gravity_type, default=(9.80665, "m/s^2"), metavar="G",
                   help="local gravity with its unit, the accelerometer's calibrated unit: "
                        "9.80665m/s^2 (default), 9.81744 (imu_tk's), or 1g")
    p.add_argument("--rest", type=positive_float, default=3.0, metavar="S",
                   help="seconds still at the start, from which the detector learns the noise "
                        "(default 3; longer is better)")
    p.add_argument("--min-still", type=nonnegative_float, default=1.0, metavar="S",
                   help="shortest still pose, seconds (default 1)")
    p.add_argument("--accel-model", choices=("auto", "full", "axis"), default="auto",
                   help="the accelerometer's matrix: full (symmetric 3x3), axis (three gains), "
                        "auto (full unless the poses do not determine it, e.g. only the six "
                        "faces; default)")
    p.add_argument("--no-g-sensitivity", action="store_true",
                   help="one constant gyro bias (imu_tk's) instead of a bias that depends on "
                        "the acceleration")
    add_bias_option(p, "the still poses")
    p.add_argument("--max-iter", type=positive_int, default=50, metavar="N",
                   help="most Levenberg-Marquardt iterations of the gyro fit (default 50)")
    add_triad_options(p)
    add_output_options(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    table = read_table(args.data)
    acc = table.data[:, triad_columns(table, args.accel_columns, "accel")]
    t = time_column(table, args.time_column)
    gtable = table
    if args.gyro_data is not None:
        gtable = read_table(args.gyro_data)
        if len(gtable.data) != len(table.data):
            raise CalibrationError(
                f"{args.data} has {len(table.data)} rows, {args.gyro_data} {len(gtable.data)}: "
                "the two sensors must be sampled together, row for row")
        tg = time_column(gtable, args.time_column)
        if t is not None and tg is not None and not np.array_equal(t, tg):
            raise CalibrationError(f"the time stamps of {args.data} and {args.gyro_data} "
                                   "differ: the two sensors must be sampled together")
    gyro = gtable.data[:, triad_columns(gtable, args.gyro_columns, "gyro")]
    rate = sample_rate(t, args.rate_hz)
    gravity, unit = args.gravity
    offset, bias_stats = bias_from_args(args, args.gyro_columns, "gyro_columns")
    res = calibrate_imu(acc, gyro, rate_hz=rate, gravity=gravity, t=t, rest_s=args.rest,
                        min_still_s=args.min_still, accel_model=args.accel_model,
                        gyro_offset=offset, gyro_g_sensitivity=not args.no_g_sensitivity,
                        max_iter=args.max_iter)
    stats = {"rate_hz": rate, "time_stamps": t is not None, **bias_stats}
    if gtable is not table:  # the source is the accelerometer's file; the gyroscope's here
        stats["gyro_source"] = {"path": str(gtable.path), "sha256": gtable.sha256}
    parts = part_from_imu(res, gravity=gravity, unit=unit, accel_raw_unit=args.accel_raw_unit,
                          gyro_raw_unit=args.gyro_raw_unit, stats=stats, source=str(table.path),
                          input_sha256=table.sha256, force=args.force)
    out = sys.stdout
    print(f"Tedaldi calibration from {len(res.intervals)} still poses and {res.n_moves} turns "
          f"({len(acc)} rows at {rate:.6g} samples/s; still threshold k = {res.k:g})", file=out)
    print(f"  accelerometer: model {res.accel_model}, residual RMS {res.accel_rms:.4g} {unit}; "
          f"gyroscope: gravity directions after the turns {res.gyro_rms_deg:.3g} deg RMS "
          f"({res.gyro_rms_deg_before:.3g} deg with the nominal scale only), "
          f"{res.gyro_iterations} iterations", file=out)
    print("  gains           accel " + "  ".join(
        f"{a} {v:.6g}" for a, v in zip("xyz", res.accel.gains)) + f" {args.accel_raw_unit} per "
        f"{unit};  gyro " + "  ".join(f"{a} {v:.6g}" for a, v in zip("xyz", res.gyro.gains))
        + f" {args.gyro_raw_unit} per rad/s", file=out)
    for sensor, part in parts.items():
        for line in coefficient_table(part, sensor):
            print(f"  {line}", file=out)
    if res.gyro_g_sensitivity.any():
        k = np.abs(res.gyro_g_sensitivity).max()
        print(f"  gyro g-sensitivity: up to {k:.4g} {args.gyro_raw_unit} per {unit}, stored in "
              "the gyro part's stats, not applied by it", file=out)
    verb = save_parts(args, parts)
    print(f"{verb} {args.output}: accel ({args.accel_raw_unit} -> {unit}) and gyro "
          f"({args.gyro_raw_unit} -> rad/s), Tedaldi", file=out)
    return 0
