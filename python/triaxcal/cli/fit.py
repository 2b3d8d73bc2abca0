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

A fit that did not converge, or whose readings cover too little of the sphere to determine
its model, is not written: the command exits with status 2 and says what to record instead
(``--force`` writes it anyway, with the warning kept in the file's statistics).
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

import numpy as np

from ..calibration.file import Calibration, SensorCalibration
from ..calibration.session import (
    RECORD_INSTEAD,
    FitOutcome,
    _fields,
    add_fit_options,
    fit_file,
    undetermined,
)
from ..calibration.source import autopilot_lines
from ..calibration.surroundings import add_field_options, alignment_for
from ..errors import CalibrationError
from ..io.files import check_output


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
                   help="write the calibration even when the fit did not converge or its "
                        "readings cover too little of the sphere (the warning is kept in the "
                        "file)")
    add_field_options(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    path = check_output(args.output, "calibration file")
    out = fit_file(args)
    for n in out.notes:
        if n.startswith("note: "):  # warnings are printed with the fit's below
            print(f"  {n}", file=sys.stderr)
    # a yaw-only part is meant to cover a band round the vertical; it states its own limits
    why = [] if out.part.model == "yaw" else undetermined(out.part, out.points[_inliers(out)])
    if why and not args.force:
        print(
            f"triaxcal fit: not written: this {out.sensor} fit is not a calibration: "
            + "; ".join(why) + f". Record instead: {RECORD_INSTEAD[out.sensor]}. (--force "
            "writes it anyway, with this warning kept in the file.)",
            file=sys.stderr,
        )
        return 2
    if why:
        stats = dict(out.part.stats)
        stats["warnings"] = [*stats.get("warnings", []),
                             *(f"written with --force although {w}" for w in why)]
        stats["forced"] = True
        out.part = SensorCalibration(**{**_fields(out.part), "stats": stats})
    align_text = None
    if getattr(args, "align", False):
        al, align_text = alignment_for(args, out.source, out.part, out.expected)
        out.part = out.part.replace(alignment=al)
    cal = None
    if path.is_file() and path.stat().st_size > 0 and not args.new:
        try:
            cal = Calibration.load(path)
        except CalibrationError as exc:
            raise CalibrationError(
                f"{path} exists but is not a calibration file ({exc}); pass --new to replace it"
            ) from None
    # the calibration this one replaces is not lost: its summary goes into `previous`
    old = cal
    if old is None and path.exists():
        try:
            old = Calibration.load(path)
        except CalibrationError:
            old = None  # --new over a file that is not a calibration: nothing to keep
    if old is not None and getattr(old, out.sensor) is not None:
        out.part = out.part.with_previous(old.part(out.sensor), created_utc=old.created_utc)
    if cal is None:
        parts: dict[str, Any] = {out.sensor: out.part}
        cal = Calibration(**parts, sensor_id=args.sensor_id or "")
        verb = "wrote"
    else:
        changes: dict[str, Any] = {out.sensor: out.part}
        if args.sensor_id is not None:
            changes["sensor_id"] = args.sensor_id
        cal = cal.replace(**changes)
        verb = "updated"
    cal.save(path)
    s = out.part.stats
    som = s.get("norms", {}).get("std_over_mean")
    print(
        f"{verb} {path}: {out.sensor} ({out.part.raw_unit} -> {out.part.unit}), model "
        f"{out.part.model}, {s['n']} readings used, {len(out.rejected)} rejected; residual RMS "
        f"{s['rms']:.4g} {out.part.unit} ({s['rms_pct_of_radius']:.3g} % of radius); "
        f"std/mean of |v| {'n/a' if som is None else f'{100 * som:.3g} %'}; coverage "
        f"{s['coverage_pct']:.0f} %",
        file=sys.stdout,
    )
    if out.reason:
        print(f"  model: {out.reason}")
    if out.expected is not None:
        print(f"  expected field: {out.expected.text()}")
        if s.get("field_strength_ut") is not None:
            print(f"  the readings show {s['field_strength_ut']:.4g} uT")
    if "yaw" in s:
        from ..methods.yaw import yaw_text

        print("  " + yaw_text(s["yaw"], out.part.unit).replace("\n", "\n  "))
    if align_text:
        print("  " + align_text.replace("\n", "\n  "))
    for w in s.get("warnings", []):
        print(f"  warning: {w}")
    if out.source is not None and out.source.recording is not None:
        for line in autopilot_lines(out.source, out.sensor, out.part.offset, out.part.matrix,
                                    out.part.unit):
            print(line)
        for w in out.source.recording.meta.get("warnings", []):
            print(f"  warning: {w}")
    return 0


def _inliers(out: FitOutcome) -> np.ndarray:
    keep = np.ones(len(out.points), dtype=bool)
    keep[np.asarray(out.rejected, dtype=np.int64)] = False
    return keep
