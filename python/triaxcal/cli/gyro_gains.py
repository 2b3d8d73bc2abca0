"""triaxcal gyro-gains SESSION --angle 90: gyroscope gains by integrating turns of a known
angle, both ways about every axis (the turn-integration method).

Hold the board still, turn it by --angle degrees about one of its axes (90 on a cube resting
on a table: face to face), hold it still again; clockwise and counter-clockwise about x, y and
z. Each turn between two still periods is integrated (trapezoid rule), assigned to its axis and
direction, and gives gain = |integral| / angle in counts per deg/s. The bias is the mean of
the still periods. The gains **divide**, as in the turn-integration method's (raw - offset) / gain;
the part written holds matrix = diag(1 / gain) (it multiplies) and gives deg/s.

Turns without a pause (--turns whole): two 360 deg turns in a row are one turn of 720 deg,
from the end of the rest at the start to the start of the rest at the end; a recording that
never rests takes its bias from a recording at rest (--bias REST.csv) and is integrated whole.
A recording about one axis (--axes z) calibrates that axis; the others keep the gains of the
gyroscope part already in CAL.json, or take the datasheet's (--counts-per-unit).

Clockwise and counter-clockwise gains of one axis should agree; when they differ by more than
--max-asymmetry percent the command names the axis and the likely cause.

examples:
  triaxcal gyro-gains turns.csv --angle 90 -o cal.json
  triaxcal gyro-gains turns_z.csv --angle 720 --turns whole --axes z --bias rest.csv \\
      --counts-per-unit 16.4 -o cal.json
"""

from __future__ import annotations

import argparse
import math
import re
import sys
from typing import Any

import numpy as np

from ..calibration.parts import part_from_gyro_gains
from ..io.tables import pick_columns, read_table
from ..methods.gyro import WHOLE, gain_warnings, gyro_gains, sample_rate
from ..report.text import coefficient_table
from ._calfile import add_output_options, existing_part, save_part
from ._help import renamed
from ._method_options import add_bias_option, bias_from_args, counts_per_unit, nominal
from ._pose_options import nonnegative_float, positive_float

HELP = ("gyroscope gains from turns of a known angle, both ways about each axis (the original "
        "method's)")


def _turns(text: str) -> str | list[tuple[int, int]] | None:
    t = text.strip().lower()
    if t == "each":
        return None
    if t == WHOLE:
        return WHOLE
    out = []
    for item in t.split(","):
        m = re.fullmatch(r"\s*(\d+)\s*:\s*(\d+)\s*", item)
        if not m:
            raise argparse.ArgumentTypeError(
                f"{text[:40]!r}: give each, whole, or sample intervals START:END[,START:END...]")
        out.append((int(m.group(1)), int(m.group(2))))
    return out


def _axes(text: str) -> str:
    t = text.strip().lower()
    if not t or set(t) - set("xyz") or len(set(t)) != len(t):
        raise argparse.ArgumentTypeError(f"{text[:20]!r}: name the axes turned about, each "
                                         "once, e.g. xyz or z")
    return "".join(a for a in "xyz" if a in t)


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "gyro-gains", help=HELP, description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("data", metavar="SESSION.csv", help="a capture session (or a table of gyro "
                   "readings with a t column)")
    p.add_argument("--angle", type=positive_float, default=90.0, metavar="DEG",
                   help="the angle of every turn, degrees (default 90: a cube; 360 or more is "
                        "better; two 360 deg turns with --turns whole: 720)")
    p.add_argument("--turns", type=_turns, default=None, metavar="each|whole|A:B",
                   help="which samples are the turns: each (default: every gap between two "
                        "still periods), whole (one turn between a rest at the start and one "
                        "at the end; with --bias, the whole recording), or sample intervals "
                        "START:END[,...] (end exclusive)")
    p.add_argument("--axes", type=_axes, default="xyz", metavar="AXES",
                   help="the axes turned about, e.g. z for a recording of turns about z only "
                        "(default xyz)")
    add_bias_option(p, "the still periods of the recording")
    p.add_argument("--columns", default=None,
                   help="the gyro's three columns (default gx,gy,gz by name, or the first three)")
    p.add_argument("--rate-hz", type=positive_float, default=None, metavar="HZ",
                   help="the board's sample rate, the turns integrated at it (for a t column "
                        "that is the host's arrival time of batches). Default: the turns "
                        "integrated over the t column's time stamps, or at its rows per second "
                        "when stamps repeat")
    p.add_argument("--rest", type=positive_float, default=3.0, metavar="S",
                   help="seconds of rest at the start, to learn the noise (default 3)")
    p.add_argument("--counts-per-unit", type=counts_per_unit("gyro"), default=None,
                   metavar="[gyro=]COUNTS[:UNIT]",
                   help="the datasheet gain (131 at +-250 deg/s, 16.4 at +-2000; unit deg/s "
                        "unless given), to judge which turns are partial (default: from the "
                        "larger turns) and for axes neither turned nor in CAL.json")
    renamed(p, "--nominal", "--counts-per-unit")
    p.add_argument("--both-directions", action="store_true",
                   help="fail unless every axis was turned both ways")
    p.add_argument("--max-asymmetry", type=nonnegative_float, default=3.0, metavar="PCT",
                   help="warn when an axis's clockwise and counter-clockwise gains differ by "
                        "more than this (default 3 %%)")
    p.add_argument("--raw-unit", default="counts", help="unit of the readings (counts)")
    add_output_options(p)
    p.set_defaults(func=run)


def _fmt(v: float) -> str:
    return f"{v:10.4f}" if math.isfinite(v) else f"{'-':>10}"


def run(args: argparse.Namespace) -> int:
    table = read_table(args.data)
    cols = pick_columns(table, args.columns, "gyro")
    g = table.data[:, cols]
    t = table.data[:, table.names.index("t")] if table.names and "t" in table.names else None
    rate = sample_rate(t, args.rate_hz)
    # the recording's own clock when it has one that advances every row; else a uniform rate
    stamps = t if args.rate_hz is None and t is not None and bool(np.all(np.diff(t) > 0)) \
        else None
    offset, bias_stats = bias_from_args(args, args.columns)
    per_dps = nominal(args.counts_per_unit, "deg/s")
    res = gyro_gains(g, angle_deg=args.angle, t=stamps,
                     rate_hz=None if stamps is not None else rate, rest_s=args.rest,
                     require_both_directions=args.both_directions,
                     nominal_counts_per_dps=per_dps, offset=offset, turns=args.turns,
                     axes=args.axes)
    u = args.raw_unit
    out = sys.stdout
    print(f"gyro gains from {len(res.rotations)} turns of {res.angle_deg:g} deg "
          f"({rate:.6g} samples/s); gain in {u} per deg/s, divides", file=out)
    print(f"  {'axis':<5} {'clockwise':>10} {'counter-cw':>11} {'mean':>10} {'apart':>7}  "
          f"bias ({u})", file=out)
    for i, ax in enumerate("xyz"):
        asym = float(res.asymmetry[i])
        apart = f"{abs(asym) * 100:6.2f}%" if math.isfinite(asym) else ""
        print(f"  {ax:<5} {_fmt(float(res.gain_cw_counts_per_dps[i]))} "
              f"{_fmt(float(res.gain_ccw_counts_per_dps[i])):>11} "
              f"{_fmt(float(res.gain_counts_per_dps[i]))} {apart:>7}  {res.offset[i]:.2f}",
              file=out)
    for rej in res.rejected:
        print(f"  (not used: samples {rej.start}-{rej.end}, {rej.reason}: {rej.detail})",
              file=out)
    warnings = gain_warnings(res, g, max_asymmetry_pct=args.max_asymmetry, raw_unit=u)
    for w in warnings:
        print(f"warning: {w}", file=out)
    stats: dict[str, Any] = {"rate_hz": rate, "time_stamps": stamps is not None,
                             "warnings": warnings, **bias_stats}
    if args.turns is not None:
        stats["turns"] = args.turns if isinstance(args.turns, str) else [list(x) for x in
                                                                          args.turns]
    if args.axes != "xyz":
        stats["axes"] = args.axes
    base = existing_part(args.output, "gyro", args.new) if args.axes != "xyz" else None
    part = part_from_gyro_gains(res, base, raw_unit=u, nominal_counts_per_dps=per_dps,
                                stats=stats, source=str(table.path), input_sha256=table.sha256,
                                force=args.force)
    for line in coefficient_table(part, "gyro"):
        print(f"  {line}", file=out)
    verb = save_part(args, "gyro", part)
    kept = ", ".join(f"{a} from the {w}" for a, w in zip("xyz", part.stats["gain_from"])
                     if w != "turns")
    print(f"{verb} {args.output}: gyro ({u} -> deg/s, gains from turns of {res.angle_deg:g} "
          f"deg{'; ' + kept if kept else ''})", file=out)
    return 0
