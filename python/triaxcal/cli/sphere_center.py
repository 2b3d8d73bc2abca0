"""triaxcal sphere-center FILE --radius R [--method descent|grid|fit]: the zero offset as
the centre of a sphere of known radius (the sphere-centre method).

Still readings lie on a sphere of radius R (16384 counts = 1 g for a 16-bit +-2 g
accelerometer) around the unknown offset. descent is its variable-step 26-neighbour
search: from --start (0,0,0), move to the neighbour one --step (1000) away that lowers
the error sum  sum |(x-A)^2 + (y-B)^2 + (z-C)^2 - R^2|, else divide the step by --shrink
(10), down to --min-step (0.01). grid is its brute-force cube search, around the mean
of the readings, --half-width wide at --step, repeated around the best node 20 times
finer down to --min-step (--no-refine: one pass). fit solves least squares of
|p - c| - R for the centre alone (Gauss-Newton). Because R is known, a part of the sphere (a
"wedge") is enough.

The part written holds offset = the centre and, for the accelerometer, matrix = I / R
(R counts = 1 g: --scale-to 1g); for other sensors the offset only, unless --scale-to
says what R is (--scale-to 48uT).
"""

from __future__ import annotations

import argparse
import math
import re
import sys
from typing import Any

import numpy as np

from ..calibration.parts import part_from_center
from ..calibration.request import parse_radius
from ..detect.session import pose_points
from ..errors import CalibrationError
from ..fit.center import CENTER_METHODS, sphere_center
from ..fit.ellipsoid import sphere_error
from ..io.tables import pick_columns, read_table
from ._calfile import add_output_options, save_part
from ._pose_options import add_pose_options, positive_float, settings_from_args

HELP = "zero offset as the centre of a sphere of known radius (variable-step descent)"



def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "sphere-center", help=HELP, description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("data", metavar="FILE", help="readings, one per row (or a session with --poses)")
    p.add_argument("--radius", required=True, metavar="R",
                   help="the sphere's radius in the readings' raw units (16384 counts = 1 g at "
                        "+-2 g, 16 bit)")
    p.add_argument("--method", choices=CENTER_METHODS, default="descent",
                   help="descent (the sphere-centre method's variable-step search, default), "
                        "grid (its cube search), fit (least squares for the centre)")
    p.add_argument("--step", type=positive_float, default=None, metavar="S",
                   help="descent: first step (default 1000); grid: node spacing (default "
                        "half-width / 20)")
    p.add_argument("--min-step", type=positive_float, default=0.01, metavar="S",
                   help="descent, grid: stop when the step falls below this (default 0.01)")
    p.add_argument("--shrink", type=float, default=10.0, metavar="F",
                   help="descent: divide the step by F when no neighbour is better (default 10)")
    p.add_argument("--start", default="0,0,0", metavar="X,Y,Z",
                   help="descent: start point, raw units (default 0,0,0, as the sphere-centre "
                        "method starts)")
    p.add_argument("--half-width", type=positive_float, default=None, metavar="W",
                   help="grid: search the cube mean +- W (default R / 10)")
    p.add_argument("--no-refine", action="store_true",
                   help="grid: one pass at --step; by default the search is repeated around "
                        "the best node, 20 times finer, down to --min-step")
    p.add_argument("--sensor", choices=("accel", "gyro", "mag"), default="accel",
                   help="which sensor the readings are from (default accel)")
    p.add_argument("--columns", default=None,
                   help="three columns by name or zero-based index (default: the sensor's "
                        "named columns, or the first three)")
    p.add_argument("--raw-unit", default="counts", help="unit of the readings (counts)")
    p.add_argument("--scale-to", default=None, metavar="VALUE",
                   help="what R is in calibrated units, e.g. 1g (the accelerometer's default) "
                        "or 48uT; 'none' writes the offset only")
    p.add_argument("--poses", action="store_true",
                   help="reduce a raw time series (a capture session) to still-pose means first")
    add_pose_options(p)
    add_output_options(p)
    p.set_defaults(func=run)


def _vector(text: str, what: str) -> np.ndarray:
    parts = [s for s in re.split(r"[,\s]+", text.strip()) if s]
    try:
        v = np.array([float(s) for s in parts])
    except ValueError:
        raise CalibrationError(f"{what} must be three numbers X,Y,Z, got {text!r}") from None
    if v.shape != (3,) or not np.isfinite(v).all():
        raise CalibrationError(f"{what} must be three finite numbers X,Y,Z, got {text!r}")
    return v


def _raw_radius(text: str, raw_unit: str) -> float:
    m = re.fullmatch(r"\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(\S*)\s*", text)
    if not m:
        raise CalibrationError(f"--radius {text!r}: give a number in raw units, e.g. 16384")
    r = float(m.group(1))
    unit = m.group(2)
    if unit and unit != raw_unit:
        raise CalibrationError(
            f"--radius {text!r}: the search runs in the readings' raw units ({raw_unit}); give "
            f"R in them (16384 counts = 1 g at +-2 g) and say what it is with --scale-to"
        )
    if not (math.isfinite(r) and r > 0):
        raise CalibrationError(f"--radius must be > 0, got {text!r}")
    return r


def _scale_to(text: str | None, sensor: str) -> tuple[float, str] | None:
    if text is None:
        return (1.0, "g") if sensor == "accel" else None
    if text.strip().lower() == "none":
        return None
    value, unit = parse_radius(text, sensor)
    if unit == "counts":
        raise CalibrationError(f"--scale-to {text!r}: give a unit, e.g. 1g or 48uT")
    return value, unit


def run(args: argparse.Namespace) -> int:
    table = read_table(args.data)
    cols = pick_columns(table, args.columns, args.sensor)
    stats: dict[str, Any] = {"columns": [table.names[c] if table.names else c for c in cols]}
    if args.poses:
        pts, pose_stats = pose_points(table, cols, settings_from_args(args))
        stats.update(pose_stats)
    else:
        pts = table.data[:, cols]
    if len(pts) < 4:
        raise CalibrationError(f"{len(pts)} readings: a centre needs at least 4 (better 10+)")
    r = _raw_radius(args.radius, args.raw_unit)
    found = sphere_center(pts, r, method=args.method, step=args.step, min_step=args.min_step,
                          shrink=args.shrink, start=_vector(args.start, "--start"),
                          half_width=args.half_width, refine=not args.no_refine)
    c, info = found.center, found.info
    resid = np.linalg.norm(pts - c, axis=1) - r
    rms = float(np.sqrt(np.mean(resid**2)))
    err = sphere_error(pts, c, r)
    stats.update(info)
    stats.update({"n": len(pts), "error_sum": err, "rms_raw": rms})
    scale = _scale_to(args.scale_to, args.sensor)
    part = part_from_center(c, r, raw_unit=args.raw_unit, method=args.method,
                            unit=None if scale is None else scale[1],
                            scale_to=None if scale is None else scale[0], stats=stats,
                            source=str(table.path), input_sha256=table.sha256,
                            force=args.force)
    verb = save_part(args, args.sensor, part)
    u = args.raw_unit
    mean = pts.mean(axis=0)
    out = sys.stdout
    print(f"{args.sensor} centre by {args.method} (R = {r:g} {u}, {len(pts)} readings): "
          f"{c[0]:.2f} {c[1]:.2f} {c[2]:.2f} {u}", file=out)
    print(f"  error sum {err:.6g} {u}^2, RMS of |p - c| - R {rms:.4g} {u}"
          + (f", {info['iterations']} {'passes' if args.method == 'grid' else 'steps'}, "
             f"{info['evaluations']} error sums" if "evaluations" in info else ""), file=out)
    print(f"  (the plain mean of the readings would say {mean[0]:.2f} {mean[1]:.2f} "
          f"{mean[2]:.2f} {u})", file=out)
    what = (f"offset, {scale[0]:g} {scale[1]} = {r:g} {u}" if scale is not None
            else "offset only")
    print(f"{verb} {args.output}: {args.sensor} ({what})", file=out)
    return 0
