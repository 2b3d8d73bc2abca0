"""``triaxcal fit SESSION.csv|LOG --sensor {accel,gyro,mag} [--columns ...] [--model ...]
[--radius ...] -o CAL.json``: fit one sensor's readings and write (or update) a calibration file.

Input: a session CSV from ``triaxcal capture`` (header ``t,ax,ay,az,...``) or any table of
numbers -- comma, semicolon, tab or space separated, with or without a header row (detected),
read by :func:`triaxcal.io.tables.read_table`; or a log: PX4 ``.ulg``, ArduPilot ``.bin``, ROS
``.bag`` / ``.db3`` / ``.mcap`` (``--instance``, ``--topic``, ``--undo-autopilot-cal``; the raw
unit is the log's). ``--columns`` picks three columns by name or zero-based index
(``ax,ay,az`` or ``0,1,2``); by default the sensor's named columns, or the first three of a
headerless file. ``--poses`` first reduces a raw time series to still-pose means, a pose
ending when any sensor says the board moved, exactly as ``triaxcal capture`` counted them
(:func:`triaxcal.detect.session.session_poses`). Outliers are rejected by the iterated
2-sigma rule on vector lengths (``--sigma 0`` disables).

Every fit passes the validity gate (:mod:`triaxcal.calibration.gate`): a fit that did not
converge, whose readings do not lie on an ellipsoid, cover too little of the sphere for its
model or carry only directions, or whose gains or offset no sensor has, is not written: the
command exits with status 2 and says why and what to record instead. ``--force`` writes it
anyway, marked ``"valid": false`` with the reasons. The coefficients are printed as a table.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

from ..calibration.session import fit_to_file
from ..io.files import check_output
from ..report.text import fit_lines
from ._fit_options import add_field_options, add_fit_options, fit_request


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "fit",
        help="fit one sensor's readings and write a calibration file",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("data", metavar="SESSION.csv|LOG",
                   help="session CSV, any numeric table, or a log (.ulg, .bin, .bag, .db3, .mcap)")
    add_fit_options(p)
    p.add_argument("-o", "--output", required=True, metavar="CAL.json",
                   help="calibration file to write; an existing one keeps its other sensors")
    p.add_argument("--new", action="store_true",
                   help="overwrite CAL.json instead of adding this sensor to it (the replaced "
                        "calibration of this sensor is still kept in its 'previous' summary)")
    p.add_argument("--sensor-id", default=None, help="board / sensor id to record")
    p.add_argument("--force", action="store_true",
                   help="write the calibration even when the validity gate refuses it (it did "
                        "not converge, its readings cover too little of the sphere, its "
                        "residual or coefficients are implausible): it is marked \"valid\": "
                        "false with the reasons, and every export refuses it unless forced too")
    add_field_options(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    path = check_output(args.output, "calibration file")
    saved = fit_to_file(args.data, fit_request(args), path, new=args.new,
                        sensor_id=args.sensor_id, force=args.force)
    for n in saved.outcome.notes:
        if n.startswith("note: "):  # warnings are printed with the fit's below
            print(f"  {n}", file=sys.stderr)
    print("\n".join(fit_lines(saved)))
    return 0
