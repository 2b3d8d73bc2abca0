"""``triaxcal batch SESSIONS/ --out-dir OUT/``: fit every board of a production run, judge each
one against limits, and write its calibration and a ``summary.csv``.

Input: a folder of session CSVs (one per board, the file name without ``.csv`` is the board id;
``triaxcal capture --out-dir`` names them by serial number), session files given one by one,
or one table holding many boards with ``--by COLUMN`` (CSV with a header, or Parquet). Each
board is fitted exactly as ``triaxcal fit SESSION.csv --poses [options]`` would fit it (pass
``--no-poses`` for tables of points rather than time series), then judged against the limits
below (``triaxcal.fleet.batch`` documents every check).

Output in the folder ``--out-dir``: ``summary.csv`` (one row per board: id, verdict, fail
reasons, coefficients, RMS, coverage, model ...), and per board ``<id>/calibration.json`` (with
the verdict) and, for boards that pass, ``<id>/<prefix>_calibration.h`` and
``<id>/<prefix>_calibration_fixed.h``.
Exit code 1 when any board fails.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import fields
from pathlib import Path
from typing import Any

from ..errors import CalibrationError
from ._help import renamed

HELP = "fit and pass/fail many boards at once (production line); write summary.csv"


def _limits_help() -> str:
    from ..fleet.batch import Limits

    d = Limits()
    return ", ".join(f"{f.name}={getattr(d, f.name):g}" for f in fields(Limits))


def register(subparsers: Any) -> None:
    from ._fit_options import add_fit_options

    p = subparsers.add_parser(
        "batch", help=HELP, description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="limits (defaults): " + _limits_help(),
    )
    p.add_argument("inputs", nargs="+", metavar="SESSIONS",
                   help="a folder of session CSVs, session files, or one table with --by")
    p.add_argument("--out-dir", required=True, metavar="DIR",
                   help="folder for summary.csv and the boards' files")
    renamed(p, "-o", "--out-dir")
    renamed(p, "--output", "--out-dir")
    p.add_argument("--by", metavar="COLUMN", default=None,
                   help="one table of many boards: the column holding the board id "
                        "(e.g. device_id)")
    add_fit_options(p)
    p.add_argument("--no-poses", dest="poses", action="store_false",
                   help="the inputs are points (one reading per row), not time series: do not "
                        "reduce them to still poses")
    p.set_defaults(poses=True)
    p.add_argument("--limit", action="append", default=[], metavar="NAME=VALUE",
                   help="change one limit, e.g. --limit offset_max=0.05 (repeatable)")
    p.add_argument("--limits", metavar="FILE.json", default=None,
                   help="limits from a JSON object {name: value}; --limit overrides it")
    p.add_argument("--prefix", default="triaxcal", help="C prefix of the headers")
    p.add_argument("--jobs", type=int, default=None,
                   help="worker processes (default: one per CPU; at most 1024, and never more "
                        "than there are boards)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def _sources(args: argparse.Namespace) -> list[tuple[str, Any]]:
    from ..fleet.batch import read_grouped_table

    if args.by is not None:
        if len(args.inputs) != 1 or Path(args.inputs[0]).is_dir():
            raise CalibrationError("--by reads one table file: give exactly one file")
        return read_grouped_table(args.inputs[0], args.by)
    out: list[tuple[str, Any]] = []
    for item in args.inputs:
        p = Path(item)
        if p.is_dir():
            files = sorted(q for q in p.iterdir() if q.suffix.lower() in (".csv", ".txt", ".tsv")
                           and q.is_file())
            if not files:
                raise CalibrationError(f"{p} holds no session files (*.csv)")
            out += [(q.stem, q) for q in files]
        elif p.is_file():
            out.append((p.stem, p))
        else:
            raise CalibrationError(f"{p} not found")
    return out


def run(args: argparse.Namespace) -> int:
    from ..fleet.batch import Limits, batch_fit, load_limits, print_counts
    from ._fit_options import fit_request

    limits = load_limits(args.limits) if args.limits else Limits()
    limits = Limits.from_items(args.limit, base=limits)
    request = fit_request(args)
    sources = _sources(args)
    results = batch_fit(sources, request=request, limits=limits, out_dir=args.out_dir,
                        prefix=args.prefix, jobs=args.jobs,
                        progress=None if args.quiet else sys.stderr)
    for r in results:
        if not r.passed:
            print(f"FAIL {r.board_id}: {r.message}")
    print_counts(results)
    print(f"wrote {Path(args.out_dir) / 'summary.csv'}")
    return 1 if any(not r.passed for r in results) else 0
