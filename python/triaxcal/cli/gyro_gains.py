"""triaxcal gyro-gains SESSION --angle 90: gyroscope gains by integrating turns of a known
angle, both ways about every axis (gyro-integration-calibration.txt).

Hold the board still, turn it by --angle degrees about one of its axes (90 on a cube resting
on a table: face to face), hold it still again; clockwise and counter-clockwise about x, y and
z. Each turn between two still periods is integrated (trapezoid rule), assigned to its axis and
direction, and gives gain = |integral| / angle in counts per deg/s. The bias is the mean of
the still periods. The gains **divide**, as in the seed's (raw - offset) / gain; the part
written holds matrix = diag(1 / gain) (it multiplies) and gives deg/s.

Clockwise and counter-clockwise gains of one axis should agree; when they differ by more than
--max-asymmetry percent the command names the axis and the likely cause.
"""

from __future__ import annotations

import argparse
import math
import sys
from typing import Any

import numpy as np

from ..calibration.parts import part_from_gyro_gains
from ..errors import CalibrationError
from ..io.tables import pick_columns, read_table
from ..methods.gyro import gyro_gains
from ._calfile import add_output_options, file_sha256, save_part

HELP = "gyroscope gains from turns of a known angle, both ways about each axis (the seed's)"

#: int16 full scale: a raw reading this close to it is taken as saturated.
SATURATION = 32767 * 0.995


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "gyro-gains", help=HELP, description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("data", metavar="SESSION.csv", help="a capture session (or a table of gyro "
                   "readings with a t column)")
    p.add_argument("--angle", type=float, default=90.0, metavar="DEG",
                   help="the angle of every turn, degrees (default 90: a cube; 360 or more is "
                        "better)")
    p.add_argument("--columns", default=None,
                   help="the gyro's three columns (default gx,gy,gz by name, or the first three)")
    p.add_argument("--rate-hz", type=float, default=None, metavar="HZ",
                   help="the board's sample rate (default: rows per second of the t column)")
    p.add_argument("--rest", type=float, default=3.0, metavar="S",
                   help="seconds of rest at the start, to learn the noise (default 3)")
    p.add_argument("--nominal", type=float, default=None, metavar="COUNTS_PER_DPS",
                   help="the datasheet gain (131 at +-250 deg/s, 16.4 at +-2000), to judge "
                        "which turns are partial (default: from the larger turns)")
    p.add_argument("--both-directions", action="store_true",
                   help="fail unless every axis was turned both ways")
    p.add_argument("--max-asymmetry", type=float, default=3.0, metavar="PCT",
                   help="warn when an axis's clockwise and counter-clockwise gains differ by "
                        "more than this (default 3 %%)")
    p.add_argument("--raw-unit", default="counts", help="unit of the readings (counts)")
    add_output_options(p)
    p.set_defaults(func=run)


def _rate(table: Any, rate_hz: float | None) -> float:
    if rate_hz is not None:
        if not (math.isfinite(rate_hz) and rate_hz > 0):
            raise CalibrationError(f"--rate-hz must be > 0, got {rate_hz}")
        return float(rate_hz)
    names = table.names or ()
    if "t" not in names:
        raise CalibrationError(f"{table.path} has no t column: pass --rate-hz")
    t = table.data[:, names.index("t")]
    span = float(t[-1] - t[0]) if len(t) > 1 else 0.0
    if not span > 0:
        raise CalibrationError(f"the t column of {table.path} does not advance: pass --rate-hz")
    return (len(t) - 1) / span


def _cause(axis: str, cw: float, ccw: float, peaks: dict[str, float], angle: float) -> str:
    """The likely reason why an axis's two directions disagree."""
    sat = [d for d, v in peaks.items() if v >= SATURATION]
    if sat:
        return (f"the {' and '.join(sat)} turn saturated the gyro (|raw| reached "
                f"{max(peaks.values()):.0f}): turn more slowly or choose a larger range")
    mean = 0.5 * (cw + ccw)
    return (f"the turns were probably not the same angle both ways (at the mean gain the "
            f"clockwise ones measure {angle * cw / mean:.1f} deg, the counter-clockwise ones "
            f"{angle * ccw / mean:.1f}): turn against a fixed stop, e.g. from one face of a cube "
            "to the next on a flat table; a bias that drifted between the turns does this too "
            "(hold still longer, or fit the temperature drift)")


def run(args: argparse.Namespace) -> int:
    table = read_table(args.data)
    cols = pick_columns(table, args.columns, "gyro")
    g = table.data[:, cols]
    rate = _rate(table, args.rate_hz)
    res = gyro_gains(g, angle_deg=args.angle, rate_hz=rate, rest_s=args.rest,
                     require_both_directions=args.both_directions,
                     nominal_counts_per_dps=args.nominal)
    u = args.raw_unit
    out = sys.stdout
    print(f"gyro gains from {len(res.rotations)} turns of {res.angle_deg:g} deg "
          f"({rate:.6g} samples/s); gain in {u} per deg/s, divides", file=out)
    print(f"  {'axis':<5} {'clockwise':>10} {'counter-cw':>11} {'mean':>10} {'apart':>7}  "
          f"bias ({u})", file=out)
    warnings = []
    for i, ax in enumerate("xyz"):
        cw, ccw = float(res.gain_cw_counts_per_dps[i]), float(res.gain_ccw_counts_per_dps[i])
        apart = abs(float(res.asymmetry[i])) * 100 if math.isfinite(res.asymmetry[i]) else None
        def fmt(v: float) -> str:
            return f"{v:10.4f}" if math.isfinite(v) else f"{'-':>10}"

        print(f"  {ax:<5} {fmt(cw)} {fmt(ccw):>11} {fmt(float(res.gain_counts_per_dps[i]))} "
              f"{'' if apart is None else f'{apart:6.2f}%':>7}  {res.offset[i]:.2f}", file=out)
        if apart is not None and apart > args.max_asymmetry:
            peaks: dict[str, float] = {}
            for r in res.rotations:
                if r.axis == i:
                    d = "counter-clockwise" if r.direction == "ccw" else "clockwise"
                    peaks[d] = max(peaks.get(d, 0.0), float(np.abs(g[r.start:r.end, i]).max()))
            why = _cause(ax, cw, ccw, peaks, args.angle)
            warnings.append(f"{ax}: clockwise {cw:.4g} and counter-clockwise {ccw:.4g} {u} per "
                            f"deg/s differ by {apart:.1f} %: {why}")
    for m in res.missing:
        ax, d = m.split()
        warnings.append(f"no {'counter-clockwise' if d == 'ccw' else 'clockwise'} turn about "
                        f"{ax}: its gain is from one direction only")
    for rej in res.rejected:
        print(f"  (not used: samples {rej.start}-{rej.end}, {rej.reason}: {rej.detail})",
              file=out)
    for w in warnings:
        print(f"warning: {w}", file=out)
    part = part_from_gyro_gains(res, raw_unit=u, stats={"rate_hz": rate, "warnings": warnings},
                                source=str(table.path), input_sha256=file_sha256(table.path),
                                force=args.force)
    verb = save_part(args, "gyro", part)
    print(f"{verb} {args.output}: gyro ({u} -> deg/s, gains from turns of {res.angle_deg:g} deg)",
          file=out)
    return 0
