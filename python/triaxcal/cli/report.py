"""``triaxcal report SESSION.csv|LOG|CAL.json [--plot FIG.png] [-o REPORT.json]``: how good is a
calibration?

With a session / data file: fit it as ``triaxcal fit`` would (same options) and report. With a
calibration file: report each part on its input data -- the file named in the calibration
(as recorded, or next to CAL.json, and checked against the stored SHA-256) or
the one given with ``--data``; without data, the statistics stored at fit time. A part that
is not a fit of readings to a sphere (e.g. a gyroscope bias) is always reported from its
stored statistics.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

from ..calibration.file import Calibration
from ..calibration.flight import flight_source
from ..calibration.gate import check_part
from ..calibration.part import SensorCalibration
from ..calibration.request import FitRequest, SourceOptions
from ..calibration.session import fit_session
from ..calibration.source import load_source
from ..detect.session import pose_points, stored_settings
from ..errors import CalibrationError
from ..fit.ellipsoid import MODELS
from ..io.files import check_output, write_file
from ..io.logs import is_log
from ..io.sections import tilt_points
from ..io.tables import pick_columns, read_table
from ..report import QualityReport, plot_report, quality_report
from ..report.flight import flight_check, flight_text, plot_flight
from ..report.text import coefficient_table, printable, stored_text, summary_only, summary_text
from ._calfile import file_sha256
from ._fit_options import add_field_options, add_fit_options, fit_request
from ._help import renamed


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "report",
        help="quality report of a calibration: numbers, warnings and a figure",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("data", metavar="SESSION.csv|LOG|CAL.json",
                   help="a session CSV, table of numbers or log to fit and report, or a "
                        "calibration file to judge on its data")
    p.add_argument("--plot", metavar="FIG.png", default=None,
                   help="save the figure (needs matplotlib: pip install 'triaxcal[plot]'); with "
                        "several sensors, the sensor name is added before .png")
    p.add_argument("--data", dest="data_file", default=None, metavar="FILE",
                   help="with CAL.json: the readings to judge it on")
    p.add_argument("-o", "--output", dest="json_out", default=None, metavar="REPORT.json",
                   help="also write the numbers as JSON")
    renamed(p, "--json", "--output")
    add_fit_options(p)
    add_field_options(p)
    p.set_defaults(func=run)


def _is_calibration(path: Path) -> bool:
    if path.suffix.lower() == ".json":
        return True
    try:
        with open(path, "rb") as f:
            head = f.read(200).lstrip()
    except OSError:
        return False
    return head.startswith(b"{")


def _find_source(cal_path: Path, part: SensorCalibration) -> Path | None:
    if not part.source:
        return None
    src = Path(part.source)
    for cand in (src, cal_path.parent / src, cal_path.parent / src.name):
        if cand.is_file() or (cand.is_dir() and is_log(cand)):
            return cand
    return None


def _log_report(src: Path, part: SensorCalibration, sensor: str,
                args: argparse.Namespace) -> tuple[QualityReport, Any]:
    """Report ``part`` on the log it was fitted from, read with the options it was read with
    (``stats["log"]``) unless given again on the command line."""
    log = part.stats.get("log") or {}
    given = fit_request(args, sensor=sensor).source
    topics = given.topics or (tuple(log["topic"]) if log.get("topic") else None)
    options = replace(
        given,
        instance=given.instance if given.instance is not None else log.get("instance"),
        topics=topics,
        undo_autopilot_cal=given.undo_autopilot_cal or bool(log.get("undo_autopilot_cal")),
        poses=bool(part.stats.get("poses")) or given.poses,
        # the poses it was fitted on, found with its stored settings
        detection=(stored_settings(part.stats) if part.stats.get("poses")
                   else given.detection),
    )
    data = load_source(src, sensor, options)
    if args.data_file is None and part.input_sha256 not in (None, data.sha256):
        raise CalibrationError(
            f"{src} has changed since the calibration was made (SHA-256 differs): pass "
            "--data FILE explicitly to judge the calibration on it anyway"
        )
    rej = part.stats.get("rejected") if data.sha256 == part.input_sha256 else None
    if rej is None or (rej and max(rej) >= len(data.points)):
        rej = []
    return quality_report(data.points, part, sensor=sensor, rejected=rej), data.points


def _plot_path(base: str, sensor: str, many: bool) -> Path:
    p = Path(base)
    return p.with_name(f"{p.stem}_{sensor}{p.suffix or '.png'}") if many else p


def run(args: argparse.Namespace) -> int:
    path = Path(args.data)
    if not path.exists():
        raise CalibrationError(f"{path} not found")
    if path.is_dir() and not is_log(path):
        raise CalibrationError(
            f"{path} is a folder: give the calibration file or the session CSV inside it"
        )
    if args.plot:
        check_output(args.plot, "figure")
    if args.json_out:
        check_output(args.json_out, "report")
    skip = getattr(args, "skip_bad_lines", False)
    reports: dict[str, QualityReport] = {}
    numbers: dict[str, Any] = {}
    if _is_calibration(path):
        if getattr(args, "bootstrap", 0):
            raise CalibrationError(
                "--bootstrap applies when a session is fitted: triaxcal fit SESSION --bootstrap N "
                "stores the intervals in the calibration, and report shows them"
            )
        cal = Calibration.load(path)
        sensors = [args.sensor] if args.sensor else list(cal.sensors)
        for sensor in sensors:
            part = cal.part(sensor)
            if part.model == "attitude":  # a compass calibrated from a flight
                _attitude_report(path, part, sensor, args, len(sensors) > 1, numbers)
                continue
            src = Path(args.data_file) if args.data_file else _find_source(path, part)
            if src is not None and part.model not in MODELS:
                print(stored_text(sensor, part,
                                  f"model {part.model!r} is not a fit to a sphere: no figure"))
                continue
            if src is None:
                print(stored_text(sensor, part,
                                  "pass --data FILE for the full report and figure"))
                if args.plot:
                    print(f"  (no figure for {sensor}: its data file {part.source!r} was not "
                          "found; pass --data FILE)", file=sys.stderr)
                continue
            if summary_only(part):  # gyro gains, temperature terms, a bias: not a sphere
                print(summary_text(sensor, part))
                continue
            if is_log(src):
                rep, log_pts = _log_report(src, part, sensor, args)
                reports[sensor] = rep
                print(rep.text())
                if args.plot:
                    out = plot_report(log_pts, part,
                                      _plot_path(args.plot, sensor, len(sensors) > 1), report=rep)
                    print(f"  figure: {out}")
                continue
            if part.stats.get("method") == "tilt-rig":
                pts = tilt_points(src, part.stats.get("columns", [0, 1, 2]))
                sha = file_sha256(src)
            else:
                table = read_table(src, skip_bad_lines=skip)
                for n in table.notes:
                    print(f"  note: {n}", file=sys.stderr)
                sha = table.sha256
                cols_spec = args.columns or ",".join(
                    str(c) for c in part.stats.get("columns", []))
                cols = pick_columns(table, cols_spec or None, sensor)
                pts = table.data[:, cols]
                if part.stats.get("poses"):
                    # the poses the part was fitted on, found again with its stored settings
                    pts, _ = pose_points(table, cols, stored_settings(part.stats))
            if args.data_file is None and part.input_sha256 not in (None, sha):
                raise CalibrationError(
                    f"{src} has changed since the calibration was made (SHA-256 differs): pass "
                    "--data FILE explicitly to judge the calibration on it anyway"
                )
            rej = part.stats.get("rejected") if sha == part.input_sha256 else None
            if rej is not None and (not rej or max(rej) < len(pts)):
                rep = quality_report(pts, part, sensor=sensor, rejected=rej)
            else:
                rep = quality_report(pts, part, sensor=sensor, rejected=[])
            reports[sensor] = rep
            print(rep.text())
            if args.plot:
                out = plot_report(pts, part, _plot_path(args.plot, sensor, len(sensors) > 1),
                                  report=rep)
                print(f"  figure: {out}")
    else:
        res = fit_session(args.data, fit_request(args))
        for n in res.notes:
            print(f"  {n}", file=sys.stderr)
        if res.flight is not None:
            _print_flight(res.part, res.flight, res.sensor, args, False, numbers)
            return _write_json(args, reports, numbers)
        rep = quality_report(res.points, res.part, sensor=res.sensor,
                             rejected=res.rejected.tolist(), model_reason=res.reason)
        reports[res.sensor] = rep
        print(rep.text())
        if args.plot:
            out = plot_report(res.points, res.part, args.plot, report=rep)
            print(f"  figure: {out}")
    return _write_json(args, reports, numbers)


def _write_json(args: argparse.Namespace, reports: dict[str, QualityReport],
                numbers: dict[str, Any]) -> int:
    if args.json_out:
        out = {**{k: r.to_dict() for k, r in reports.items()}, **numbers}
        write_file(args.json_out, json.dumps(out, indent=2) + "\n", what="report")
        print(f"  numbers: {args.json_out}")
    return 0


def _attitude_report(cal_path: Path, part: SensorCalibration, sensor: str,
                     args: argparse.Namespace, many: bool, numbers: dict[str, Any]) -> None:
    """A compass calibrated from a flight (``--method attitude``): its held-out check,
    recomputed on the log it was fitted on (found by the part's source path and checked by its
    SHA-256, or given with ``--data``)."""
    src = Path(args.data_file) if args.data_file else _find_source(cal_path, part)
    if src is None:
        print(stored_text(sensor, part, "pass --data LOG for the held-out check and figure"))
        if args.plot:
            print(f"  (no figure for {sensor}: its flight log {printable(part.source)!r} was "
                  "not found; pass --data LOG)", file=sys.stderr)
        return
    if args.data_file is None and part.input_sha256 not in (None, file_sha256(src)):
        raise CalibrationError(
            f"{src} has changed since the calibration was made (SHA-256 differs): pass "
            "--data FILE explicitly to judge the calibration on it anyway")
    log = part.stats.get("log") or {}
    inst = log.get("instance")
    request = FitRequest(sensor="mag", method="attitude",
                         source=SourceOptions(instance=inst if isinstance(inst, int) else None))
    _print_flight(part, flight_source(src, request), sensor, args, many, numbers)


def _print_flight(part: SensorCalibration, src: Any, sensor: str, args: argparse.Namespace,
                  many: bool, numbers: dict[str, Any]) -> None:
    print("\n".join(coefficient_table(part, sensor)))
    inter = part.stats.get("interference")
    if isinstance(inter, dict):
        per = "A" if inter.get("per") == "A" else "unit of throttle"
        print("  interference  " + "  ".join(f"{float(v):.4g}" for v in inter["vector"])
              + f"  {part.unit} per {per}, ADDED after the matrix "
              f"({printable(inter.get('source'))})")
    verdict = check_part(part, sensor)
    print("  " + verdict.text("this flight calibration"))
    try:
        check = flight_check(part, src)
    except CalibrationError as exc:  # e.g. the fit on one half failed: nothing to draw
        print(f"  (no held-out check: {exc})")
        return
    print(flight_text(part, check, sensor))
    numbers[sensor] = check.to_dict()
    if args.plot:
        out = plot_flight(part, check, _plot_path(args.plot, sensor, many))
        print(f"  figure: {out}")
