"""``triaxcal noise LOG_OR_SESSION [--sensor gyro|accel|both] [--rate-hz HZ] [--cal CAL.json |
--unit [SENSOR=]UNIT ... | --counts-per-unit SENSOR=COUNTS[:UNIT] ...] [--force]
[--plot FIG.png] [--format text|json|kalibr] [-o OUT]``: noise figures of a sensor at rest.

Reads a session CSV from ``triaxcal capture`` (header ``t,ax,ay,az,gx,gy,gz,...``) or any
numeric table (``--columns`` picks three columns) in blocks, so a 24-hour log never sits in
memory, or an autopilot / ROS log (``.ulg``, ``.bin``, ``.bag``, ``.db3``, ``.mcap``: see
``triaxcal fit``'s ``--instance``, ``--topic``, ``--undo-autopilot-cal``). First it checks that
the sensor was at rest -- a hand moving or turning the board changes its one-second mean far
more than its noise allows -- and refuses readings that moved, naming the motion
(``--force`` computes the figures anyway, marked). Then it fits angle / velocity random walk,
bias instability and rate / acceleration random walk to the overlapping Allan deviation
(:func:`triaxcal.methods.noise_file.noise_from_file`).

The sample rate comes from ``--rate-hz``, a log's time stamps, or the ``t`` column (seconds):
rows over the session's time span, since a capture session stamps each batch of rows with one
host time. Units per sensor: ``--cal`` applies a calibration file's matrix (the offset does not
change an Allan deviation); ``--counts-per-unit gyro=131:deg/s`` divides counts by a nominal
sensitivity; ``--unit accel=m/s^2 --unit gyro=rad/s`` names the units a table is already in; a
log records its own. ``--format kalibr`` writes Kalibr's noise keys in SI units (rad/s, m/s^2);
with ``-o NOISE.json`` it writes them as the JSON object ``triaxcal export --format kalibr
--noise NOISE.json`` takes. ``--format json`` is always valid JSON (null where a value is not a
finite number). Files are written whole or not at all.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

from ..calibration.file import Calibration
from ..calibration.gate import require_valid
from ..errors import CalibrationError
from ..io.files import check_output, write_file
from ..methods.noise import plot_allan
from ..methods.noise_file import NoiseRequest, noise_from_file
from ._fit_options import add_source_options
from ._help import renamed

SENSORS = ("gyro", "accel")


def _counts(text: str) -> tuple[str | None, float, str | None]:
    """``SENSOR=COUNTS[:UNIT]`` (comma-separated for several) or a bare number (the old
    spelling) -> [(sensor or None, counts, unit or None), ...]."""
    out = []
    for item in text.split(","):
        sensor, sep, rest = item.partition("=")
        if not sep:
            sensor, rest = "", item
        value, _, unit = rest.partition(":")
        sensor = sensor.strip()
        try:
            if sensor and sensor not in SENSORS:
                raise ValueError
            out.append((sensor or None, float(value), unit.strip() or None))
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"{text!r}: use SENSOR=COUNTS[:UNIT], e.g. gyro=131:deg/s, accel=16384:g"
            ) from None
    return out  # type: ignore[return-value]


def _units(text: str) -> list[tuple[str | None, str]]:
    """``[SENSOR=]UNIT`` (comma-separated for several)."""
    out: list[tuple[str | None, str]] = []
    for item in text.split(","):
        sensor, sep, unit = item.partition("=")
        if not sep:
            sensor, unit = "", sensor
        if (sensor.strip() and sensor.strip() not in SENSORS) or not unit.strip():
            raise argparse.ArgumentTypeError(
                f"{text!r}: use [SENSOR=]UNIT, e.g. gyro=deg/s or accel=m/s^2"
            )
        out.append((sensor.strip() or None, unit.strip()))
    return out


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "noise",
        help="noise figures (random walks, bias instability) from a log at rest; Kalibr keys",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("data", metavar="LOG_OR_SESSION", help="session CSV or numeric table at rest")
    p.add_argument("--sensor", choices=("gyro", "accel", "both"), default="gyro",
                   help="which sensor's columns (default gyro: gx,gy,gz); both: gyro and accel")
    p.add_argument("--columns", default=None,
                   help="three columns by name or zero-based index (one sensor only)")
    p.add_argument("--rate-hz", type=float, default=None, metavar="HZ",
                   help="sample rate in Hz (default: a log's time stamps, or a table's t "
                        "column: rows over its time span)")
    renamed(p, "--rate", "--rate-hz")
    p.add_argument("--cal", default=None, metavar="CAL.json",
                   help="apply this calibration's matrices; the figures are then in its units")
    p.add_argument("--unit", type=_units, action="append", default=[],
                   metavar="[SENSOR=]UNIT",
                   help="unit a table's readings are in (after --counts-per-unit), per sensor: "
                        "--unit accel=m/s^2 --unit gyro=rad/s; a bare unit applies to the "
                        "sensor it measures (default counts)")
    p.add_argument("--counts-per-unit", type=_counts, action="append", default=[],
                   metavar="SENSOR=COUNTS[:UNIT]",
                   help="divide raw counts by this nominal sensitivity, per sensor: "
                        "gyro=131:deg/s, accel=16384:g (repeat for both)")
    p.add_argument("--force", action="store_true",
                   help="compute the figures although the readings are not at rest (or the "
                        "--cal part is not a valid calibration); the output is marked")
    p.add_argument("--skip-bad-lines", action="store_true",
                   help="tables: skip lines that are not a row of numbers (counted)")
    p.add_argument("--taus", choices=("log", "octave"), default="log",
                   help="averaging times: about 10 per decade (default) or octaves")
    p.add_argument("--plot", default=None, metavar="FIG.png",
                   help="save the Allan deviation with the fitted slopes (needs matplotlib: "
                        "pip install 'triaxcal[plot]'); with --sensor both, _gyro/_accel are "
                        "added before .png")
    p.add_argument("--format", choices=("text", "json", "kalibr"), default="text",
                   help="text (default), json, or Kalibr's imu.yaml noise keys")
    p.add_argument("-o", "--output", default=None, metavar="FILE",
                   help="write the output here instead of printing it (whole or not at all); "
                        "with --format kalibr and a .json name, the JSON that triaxcal export "
                        "--noise takes")
    p.add_argument("--ros-topic", default="/imu0", metavar="TOPIC",
                   help="rostopic written with --format kalibr")
    renamed(p, "--rostopic", "--ros-topic")
    add_source_options(p)
    p.set_defaults(func=run)


def _warn(text: str) -> None:
    print(f"triaxcal noise: {text}", file=sys.stderr)


def request_from_args(args: argparse.Namespace) -> NoiseRequest:
    """The typed request of a parsed command line (the old spellings turned into the new)."""
    sensors = ("gyro", "accel") if args.sensor == "both" else (args.sensor,)
    units: dict[str, str] = {}
    bare_units: list[str] = []
    for items in args.unit:
        for sensor, unit in items:
            if sensor is None:
                bare_units.append(unit)
            elif units.setdefault(sensor, unit) != unit:
                raise CalibrationError(f"--unit gives the {sensor} two units: {units[sensor]} "
                                       f"and {unit}")
    cpu: dict[str, Any] = {}
    for items in args.counts_per_unit:
        for sensor, value, unit in items:
            if sensor is None:
                if len(sensors) > 1:
                    raise CalibrationError(
                        f"--counts-per-unit {value:g}: with --sensor both say whose counts: "
                        "gyro=131:deg/s and accel=16384:g"
                    )
                sensor = sensors[0]
                _warn(f"--counts-per-unit {value:g} is now --counts-per-unit "
                      f"{sensor}={value:g}:UNIT; the old spelling goes in the next release")
            cpu[sensor] = (value, unit) if unit is not None else value
    unit_arg: Any = units
    if bare_units:
        if units or len(bare_units) > 1:  # several: each to the sensor it measures
            from ..conventions.units import UNITS

            for u in bare_units:
                q = UNITS.get(u, ("counts",))[0]
                target = q if q in sensors else (sensors[0] if len(sensors) == 1 else None)
                if target is None:
                    raise CalibrationError(f"--unit {u}: say which sensor, e.g. gyro={u}")
                units.setdefault(target, u)
        else:
            unit_arg = bare_units[0]
    cal = None
    cal_name = "the calibration"
    if args.cal:
        calibration = Calibration.load(args.cal)
        cal_name = args.cal
        cal = {}
        for s in sensors:
            part = calibration.part(s)
            verdict = require_valid(part, s, force=args.force, action="apply")
            if not verdict.valid:
                _warn(f"warning: the {s} part of {args.cal} is not a valid calibration "
                      f"({'; '.join(verdict.reasons)}); applied anyway (--force)")
            cal[s] = part
    return NoiseRequest(
        args.data, sensor=args.sensor, columns=args.columns, rate_hz=args.rate_hz,
        unit=unit_arg or None, counts_per_unit=cpu or None, cal=cal, cal_name=cal_name,
        taus=args.taus, force=args.force, skip_bad_lines=args.skip_bad_lines,
        instance=args.instance, topics=args.topic, undo_autopilot_cal=args.undo_autopilot_cal,
    )


def run(args: argparse.Namespace) -> int:
    out = check_output(args.output, "output") if args.output else None
    if args.plot:
        check_output(args.plot, "figure")
    request = request_from_args(args)
    result = noise_from_file(request)
    if args.format == "kalibr" and out is not None and out.suffix.lower() == ".json":
        text = result.kalibr_json()
    elif args.format == "kalibr":
        text = result.kalibr_yaml(ros_topic=args.ros_topic)
    elif args.format == "json":
        text = result.to_json()
    else:
        text = result.text() + "\n"
    if out is not None:
        write_file(out, text, what="output")
        print(f"wrote {out}")
    else:
        sys.stdout.write(text)
    if args.format != "text":
        for n in result.notes:
            _warn(n if n.startswith("warning: ") else f"note: {n}")
        for f in result.figures.values():
            for w in f.warnings:
                _warn(f"warning: {w}")
    if args.plot:
        from pathlib import Path

        for s, f in result.figures.items():
            p = Path(args.plot)
            if len(result.figures) > 1:
                p = p.with_name(f"{p.stem}_{s}{p.suffix or '.png'}")
            print(f"figure: {plot_allan(f, p)}")
    return 0
