"""triaxcal turntable FILE... --rpm RPM --bias REST -o CAL.json: the gyroscope's matrix from a
turntable (a record player) turning at known speeds (:func:`triaxcal.fit_turntable`).

Put the board on the turntable in one orientation after another (tilted differently each
time, at least 6 for the full matrix, 3 for per-axis scales) and record it turning: each
orientation gives a plateau of constant rate whose true size is the table's speed. One
recording per speed, --rpm in the same order (one --rpm for all of them). The bias comes from
a recording of the board at rest (--bias REST, or three numbers X,Y,Z in raw units).

The plateaus are found and fitted in the readings' own unit: the speeds are turned into it
(--raw-unit rad/s or deg/s; for counts, --counts-per-unit gives the datasheet's scale). The
part written is (raw - bias) @ matrix.T in --unit (default: the readings' rate unit, else
rad/s), the matrix multiplying; the command prints each speed's plateaus as measured before
and after.

example (freeIMUCal's Gear VR controller, gyro in rad/s, 100 samples/s at rest):
  triaxcal turntable 33RPMgyr.txt 45RPMgyr.txt --rpm 100/3 --rpm 45 --bias 0RPMgyr.txt \\
      --rate-hz 100 --rest 10 --raw-unit rad/s -o cal.json
"""

from __future__ import annotations

import argparse
import math
import sys

from ..calibration.parts import part_from_turntable
from ..conventions.units import UNITS, unit_factor
from ..errors import CalibrationError
from ..io.tables import pick_columns, read_table
from ..methods.turntable import fit_turntable
from ..report.text import coefficient_table
from ._calfile import add_output_options, save_part
from ._method_options import add_bias_option, bias_from_args, counts_per_unit, nominal
from ._pose_options import positive_float, positive_int

HELP = "the gyroscope's matrix from turntable recordings at known speeds"

#: One revolution per minute in the units a part may take.
PER_RPM = {"rad/s": 2.0 * math.pi / 60.0, "deg/s": 6.0}


def _rpm(text: str) -> float:
    try:
        if "/" in text:
            a, b = text.split("/", 1)
            v = float(a) / float(b)
        else:
            v = float(text)
    except (ValueError, ZeroDivisionError):
        v = math.nan
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"{text[:40]!r}: give the speed in revolutions per "
                                         "minute, e.g. 45 or 100/3 (33 1/3)")
    return v


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "turntable", help=HELP, description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("data", nargs="+", metavar="FILE", help="gyro readings, one file per speed")
    p.add_argument("--rpm", type=_rpm, action="append", required=True, metavar="RPM",
                   help="the table's speed for each file, in order (repeat; one for all)")
    add_bias_option(p)
    p.add_argument("--rate-hz", type=positive_float, default=None, metavar="HZ",
                   help="the sample rate, to find the still part of --bias REST (default: its "
                        "t column; without either, the whole file)")
    p.add_argument("--rest", type=positive_float, default=3.0, metavar="S",
                   help="seconds still at the start of --bias REST (default 3)")
    p.add_argument("--model", choices=("full", "axis"), default="full",
                   help="full (symmetric 3x3, default) or axis (three scales)")
    p.add_argument("--window", type=positive_int, default=50, metavar="N",
                   help="samples per averaging window of the plateau detection (default 50)")
    p.add_argument("--unit", choices=tuple(PER_RPM), default=None,
                   help="calibrated unit (default: the readings' rate unit, else rad/s)")
    p.add_argument("--counts-per-unit", type=counts_per_unit("gyro"), default=None,
                   metavar="[gyro=]COUNTS[:UNIT]",
                   help="readings in counts: the datasheet's scale (131 counts per deg/s at "
                        "+-250 deg/s), to find the plateaus in counts")
    p.add_argument("--columns", default=None,
                   help="the gyro's three columns (default gx,gy,gz by name, or the only three)")
    p.add_argument("--raw-unit", default="counts",
                   help="unit of the readings (default counts; rad/s or deg/s for a sensor "
                        "that reports them)")
    add_output_options(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    rpm = args.rpm * len(args.data) if len(args.rpm) == 1 else args.rpm
    if len(rpm) != len(args.data):
        raise CalibrationError(f"{len(args.data)} files and {len(args.rpm)} --rpm: give one "
                               "speed per file, in the same order (or one for all)")
    tables = [read_table(f) for f in args.data]
    recs = [t.data[:, pick_columns(t, args.columns, "gyro")] for t in tables]
    offset, bias_stats = bias_from_args(args, args.columns)
    raw_rate = UNITS.get(args.raw_unit, ("",))[0] == "gyro"
    unit = args.unit or (args.raw_unit if args.raw_unit in PER_RPM else "rad/s")
    if raw_rate:  # raw per unit: 1 deg/s reads unit_factor("deg/s", raw) raw units
        raw_per_unit = unit_factor(unit, args.raw_unit)
    else:
        per = nominal(args.counts_per_unit, unit)
        if per is None:
            raise CalibrationError(
                f"readings in {args.raw_unit}: give the gyro's scale to find the plateaus in "
                "them, --counts-per-unit COUNTS[:UNIT] (e.g. 131:deg/s), or --raw-unit rad/s "
                "or deg/s for a gyro that reports a rate")
        raw_per_unit = per
    # the fit in the readings' unit (where the plateaus are found), then the matrix in `unit`
    fit = fit_turntable(recs, [r * PER_RPM[unit] * raw_per_unit for r in rpm], offset=offset,
                        model=args.model, window=args.window)
    stats = {"rpm": rpm, "files": [{"path": str(t.path), "sha256": t.sha256} for t in tables],
             "raw_per_unit": raw_per_unit, **bias_stats}
    one = len(tables) == 1
    part = part_from_turntable(fit, unit=unit, raw_unit=args.raw_unit, scale=1 / raw_per_unit,
                               stats=stats,
                               source=str(tables[0].path) if one else None,
                               input_sha256=tables[0].sha256 if one else None,
                               force=args.force)
    out = sys.stdout
    print(f"turntable fit ({args.model}) from {sum(fit.n_plateaus)} plateaus; speeds as "
          f"measured, {unit}:", file=out)
    for t, r, n, raw, cal, err in zip(tables, rpm, fit.n_plateaus, fit.raw_measured,
                                      fit.measured, fit.rel_error):
        print(f"  {t.path.name}: {r:.6g} rpm = {r * PER_RPM[unit]:.6g}, {n} plateaus: "
              f"{raw / raw_per_unit:.6g} before, {cal / raw_per_unit:.6g} after "
              f"({100 * err:+.3f} %)", file=out)
    print(f"  RMS of the plateaus' calibrated speeds: {100 * fit.rms_rel:.3f} % of the table's",
          file=out)
    for line in coefficient_table(part, "gyro"):
        print(f"  {line}", file=out)
    verb = save_part(args, "gyro", part)
    print(f"{verb} {args.output}: gyro ({args.raw_unit} -> {unit}, turntable)", file=out)
    return 0
