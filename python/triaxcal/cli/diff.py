"""``triaxcal diff OLD.json NEW.json`` (or ``triaxcal diff CAL.json``: the calibration against
the one it replaced): per coefficient the change, the change in standard errors, and a verdict
-- the same calibration, a real change, or a suspicious one (see :mod:`triaxcal.calibration.diff`).

Exit code, for production scripts: 0 when every change is within ``--threshold`` standard
errors, 3 for a real change, 4 for a suspicious one (1 for an error such as a missing file).
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from ..calibration.diff import compare, compare_with_previous
from ..calibration.file import SENSORS, Calibration
from ._help import renamed


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "diff",
        help="what changed between two calibrations, in standard errors; non-zero exit on change",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("old", metavar="OLD.json", help="the earlier calibration (or the only one)")
    p.add_argument("new", metavar="NEW.json", nargs="?", default=None,
                   help="the later calibration (default: OLD.json against its 'previous')")
    p.add_argument("--sensor", choices=SENSORS, action="append", default=None,
                   help="compare only this part (repeat for several; default: all in both)")
    p.add_argument("--threshold", type=float, default=3.0,
                   help="a change beyond this many standard errors is real (default 3)")
    p.add_argument("--max-gain-change", type=float, default=0.05,
                   help="a gain changing by more than this fraction is suspicious (0.05)")
    p.add_argument("--max-offset-change", type=float, default=0.25,
                   help="an offset moving by more than this fraction of the radius is "
                        "suspicious (0.25)")
    p.add_argument("--format", choices=("text", "json"), default="text",
                   help="print the comparison as text or as JSON")
    renamed(p, "--json", "--format json")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    kw: dict[str, Any] = {"threshold": args.threshold, "max_gain_change": args.max_gain_change,
                          "max_offset_change": args.max_offset_change}
    sensors = tuple(dict.fromkeys(args.sensor)) if args.sensor else None
    if args.new is None:
        d = compare_with_previous(Calibration.load(args.old), sensors=sensors, **kw)
    else:
        old, new = Calibration.load(args.old), Calibration.load(args.new)
        d = compare(old, new, sensors=sensors, **kw)
    text = json.dumps(d.to_dict(), indent=2) if args.format == "json" else d.text()
    sys.stdout.write(text + "\n")
    return d.exit_code
