"""triaxcal ferraris SESSION --rate-hz HZ -o CAL.json: accelerometer and gyroscope from six
static faces and three full turns, in closed form (Ferraris et al. 1995, as imucal computes it:
:func:`triaxcal.ferraris`).

The session holds nine sections: x_p, x_a, y_p, y_a, z_p, z_a (still, that axis pointing up,
_p, then down, _a) and x_rot, y_rot, z_rot (a full turn about that axis; the sense is read
from the data). Either

* a file whose rows carry their section first (imucal's annotated_session.csv:
  part,samples,acc_x,...,gyr_z), or a line naming the section before its rows; or
* a continuous recording and --sections LIST.json, where each section starts and ends
  (imucal's example_ferraris_session_list.json: {"x_p": {"start": 0, "end": 1028}, ...};
  rows from 0, end exclusive).

Both parts are written: the accelerometer in the unit of --gravity, the gyroscope in rad/s,
each (raw - offset) @ matrix.T with the matrix multiplying; both pass the validity gate or
neither is written. The gyroscope's sensitivity to acceleration (imucal's K_ga) is printed and
stored in the gyroscope part's stats; the part itself does not apply it.

examples:
  triaxcal ferraris annotated_session.csv --rate-hz 204.8 -o cal.json
  triaxcal ferraris example_ferraris_session.csv --sections example_ferraris_session_list.json \\
      --rate-hz 102.4 --accel-raw-unit m/s^2 --gyro-raw-unit deg/s -o cal.json
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

import numpy as np

from ..calibration.parts import part_from_ferraris
from ..io.sections import FERRARIS_SECTIONS, read_section_list, read_sections
from ..io.tables import read_table
from ..methods.gyro import sample_rate
from ..methods.static import ferraris
from ..report.text import coefficient_table
from ._calfile import add_output_options, save_parts
from ._method_options import add_triad_options, gravity_type, time_column, triad_columns
from ._pose_options import positive_float

HELP = "accelerometer and gyroscope from six faces and three turns (Ferraris, as imucal)"


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "ferraris", help=HELP, description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("data", metavar="SESSION",
                   help="the labelled session, or a continuous recording with --sections")
    p.add_argument("--sections", default=None, metavar="LIST.json",
                   help="where each section of a continuous recording starts and ends (JSON)")
    p.add_argument("--rate-hz", type=positive_float, default=None, metavar="HZ",
                   help="the sample rate (default: rows per second of a t column)")
    p.add_argument("--gravity", type=gravity_type, default=(9.81, "m/s^2"), metavar="G",
                   help="local gravity with its unit, the accelerometer's calibrated unit: "
                        "9.81m/s^2 (default, imucal's) or 1g")
    p.add_argument("--angle", type=positive_float, default=360.0, metavar="DEG",
                   help="the size of each turn, degrees (default 360)")
    add_triad_options(p)
    add_output_options(p)
    p.set_defaults(func=run)


def _sections(args: argparse.Namespace) -> tuple[Any, dict[str, tuple[np.ndarray, np.ndarray]],
                                                  np.ndarray | None, str]:
    """The table (all rows), the sections as (acc, gyro) and the time stamps, and the sha."""
    if args.sections is not None:
        table = read_table(args.data)
        where = read_section_list(args.sections, FERRARIS_SECTIONS, len(table.data))
        rows = {k: slice(a, b) for k, (a, b) in where.items()}
        data = table.data
    else:
        labelled = read_sections(args.data, FERRARIS_SECTIONS, what="Ferraris session",
                                 hint="label the rows x_p, x_a, y_p, y_a, z_p, z_a, x_rot, "
                                      "y_rot, z_rot, or give --sections LIST.json")
        table = labelled.table()
        data, rows, start = table.data, {}, 0
        for k, v in labelled.groups.items():
            rows[k] = slice(start, start + len(v))
            start += len(v)
    a_cols = triad_columns(table, args.accel_columns, "accel")
    g_cols = triad_columns(table, args.gyro_columns, "gyro")
    sec = {k: (data[rows[k], a_cols], data[rows[k], g_cols]) for k in FERRARIS_SECTIONS}
    return table, sec, time_column(table, None), table.sha256


def run(args: argparse.Namespace) -> int:
    table, sec, t, sha = _sections(args)
    rate = sample_rate(t, args.rate_hz)
    gravity, unit = args.gravity
    fer = ferraris(sec, rate_hz=rate, gravity=gravity, angle_deg=args.angle)
    stats = {"rate_hz": rate, "angle_deg": args.angle,
             "sections": {k: len(v[0]) for k, v in sec.items()}}
    if args.sections is not None:
        stats["section_list"] = str(args.sections)
    parts = part_from_ferraris(fer, gravity=gravity, unit=unit,
                               accel_raw_unit=args.accel_raw_unit,
                               gyro_raw_unit=args.gyro_raw_unit, stats=stats,
                               source=str(table.path), input_sha256=sha, force=args.force)
    out = sys.stdout
    a_u, g_u = args.accel_raw_unit, args.gyro_raw_unit
    turned = ", ".join(f"{a} {'counter-clockwise' if s > 0 else 'clockwise'}"
                       for a, s in zip("xyz", fer.rotation_sign))
    print(f"Ferraris calibration from six faces and three turns of {args.angle:g} deg "
          f"({sum(len(v[0]) for v in sec.values())} rows at {rate:.6g} samples/s; turned "
          f"{turned})", file=out)
    print("  sensitivity     accel " + "  ".join(
        f"{a} {v:.6g}" for a, v in zip("xyz", fer.accel_counts_per_g)) + f" {a_u} per g;  gyro "
        + "  ".join(f"{a} {v:.6g}" for a, v in zip("xyz", fer.gyro_counts_per_dps))
        + f" {g_u} per deg/s", file=out)
    for sensor, part in parts.items():
        for line in coefficient_table(part, sensor):
            print(f"  {line}", file=out)
    k = np.abs(fer.g_sensitivity).max()
    print(f"  gyro g-sensitivity (imucal's K_ga): up to {k:.4g} {g_u} per {unit}, stored in "
          "the gyro part's stats, not applied by it", file=out)
    verb = save_parts(args, parts)
    print(f"{verb} {args.output}: accel ({a_u} -> {unit}) and gyro ({g_u} -> rad/s), Ferraris",
          file=out)
    return 0
