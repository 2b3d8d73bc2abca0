"""``triaxcal fit SESSION.csv|LOG --sensor {accel,gyro,mag} [--columns ...] [--model ...]
[--radius ...] -o CAL.json``: fit one sensor's readings and write (or update) a calibration file.

Input: a session CSV from ``triaxcal capture`` (header ``t,ax,ay,az,...``) or any table of
numbers -- comma, semicolon, tab or space separated, with or without a header row (detected);
or a log: PX4 ``.ulg``, ArduPilot ``.bin``, ROS ``.bag`` / ``.db3`` / ``.mcap`` (``--instance``,
``--topic``, ``--undo-autopilot-cal``; the raw unit is the log's).
``--columns`` picks three columns by name or zero-based index (``ax,ay,az`` or ``0,1,2``);
by default the sensor's named columns, or the first three of a headerless file. ``--poses``
first reduces a raw time series to still-pose means (:func:`triaxcal.detect.detect_poses`).
Outliers are rejected by the iterated 2-sigma rule on vector lengths (``--sigma 0`` disables).
"""

from __future__ import annotations

import argparse
import hashlib
import re
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..calibration import SENSORS, Calibration, SensorCalibration
from ..errors import CalibrationError
from ..fit import MODELS
from ._source import Source, add_source_options, autopilot_lines, autopilot_stats, load_source

#: Default column names per sensor (the device channel order,
#: :data:`triaxcal.io.protocol.CHANNELS_10`).
SENSOR_COLUMNS = {"accel": ("ax", "ay", "az"), "gyro": ("gx", "gy", "gz"),
                  "mag": ("mx", "my", "mz")}
#: Default radius per sensor when --radius is not given (None: keep the data's own scale).
DEFAULT_RADIUS = {"accel": (1.0, "g"), "gyro": None, "mag": None}

_UNITS_EXACT = ("g", "mg", "m/s^2", "uT", "nT", "mT", "gauss", "mG", "deg/s", "rad/s", "counts")
_UNIT_ALIASES = {"m/s2": "m/s^2", "mps2": "m/s^2", "ut": "uT", "µt": "uT", "dps": "deg/s",
                 "lsb": "counts", "G": "gauss"}


def parse_radius(text: str, sensor: str) -> tuple[float, str]:
    """``"1g"`` -> (1.0, "g"); ``"48uT"`` -> (48.0, "uT"); a bare number gets a unit by size.

    Bare numbers: accelerometer 0.5..2 -> g, 5..15 -> m/s^2, else counts; magnetometer
    10..100 -> uT, else counts; gyroscope -> deg/s.

    >>> (parse_radius("1g", "accel"), parse_radius("9.80665", "accel"),
    ...  parse_radius("16384", "accel"))
    ((1.0, 'g'), (9.80665, 'm/s^2'), (16384.0, 'counts'))
    >>> parse_radius("48uT", "mag")
    (48.0, 'uT')
    """
    m = re.fullmatch(r"\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([^\s\d].*)?\s*", text)
    if not m:
        raise CalibrationError(
            f"--radius {text!r}: give a number with an optional unit, e.g. 1g, 9.80665, 48uT, "
            "16384"
        )
    value = float(m.group(1))
    if not value > 0:
        raise CalibrationError(f"--radius must be greater than zero, got {text!r}")
    suffix = (m.group(2) or "").strip()
    if suffix:
        unit = (suffix if suffix in _UNITS_EXACT
                else _UNIT_ALIASES.get(suffix) or _UNIT_ALIASES.get(suffix.lower()))
        if unit is None:
            raise CalibrationError(
                f"--radius {text!r}: unknown unit {suffix!r}; use one of {_UNITS_EXACT}"
            )
        return value, unit
    if sensor == "accel":
        return value, "g" if 0.5 <= value <= 2 else "m/s^2" if 5 <= value <= 15 else "counts"
    if sensor == "mag":
        return value, "uT" if 10 <= value <= 100 else "counts"
    return value, "deg/s"


# --------------------------------------------------------------------------------------------
# Reading tables


@dataclass(frozen=True)
class Table:
    """A numeric table read from a file: ``names`` (None without a header) and ``data``."""

    names: tuple[str, ...] | None
    data: np.ndarray
    path: Path
    sha256: str


def _split(line: str, delim: str | None) -> list[str]:
    if delim is None:
        return line.split()
    return [t.strip() for t in line.split(delim)]


def _is_number(tok: str) -> bool:
    try:
        float(tok)
    except ValueError:
        return False
    return True


def read_table(path: str | Path) -> Table:
    """Read a CSV / whitespace table; the header row and the delimiter are detected.

    Lines starting with ``#`` and blank lines are skipped. Raises :class:`CalibrationError`
    with the line number when a row is not numbers.
    """
    p = Path(path)
    try:
        raw = p.read_bytes()
    except FileNotFoundError:
        raise CalibrationError(f"data file {p} not found") from None
    text = raw.decode("utf-8", errors="replace")
    lines = [(i + 1, ln.strip()) for i, ln in enumerate(text.splitlines())]
    lines = [(i, ln) for i, ln in lines if ln and not ln.startswith("#")]
    if not lines:
        raise CalibrationError(f"{p} holds no data rows")
    first = lines[0][1]
    delim: str | None = None
    for d in (",", ";", "\t"):
        if d in first:
            delim = d
            break
    names: tuple[str, ...] | None = None
    toks = _split(first, delim)
    if not all(_is_number(t) for t in toks):
        names = tuple(t.strip().strip('"') for t in toks)
        lines = lines[1:]
    rows = []
    width = len(names) if names else None
    for lineno, ln in lines:
        toks = _split(ln, delim)
        if width is None:
            width = len(toks)
        if len(toks) != width:
            raise CalibrationError(
                f"{p}, line {lineno}: {len(toks)} values, expected {width}; fix or remove it"
            )
        try:
            rows.append([float(t) for t in toks])
        except ValueError:
            raise CalibrationError(
                f"{p}, line {lineno}: not all numbers ({ln[:60]!r})"
            ) from None
    if not rows:
        raise CalibrationError(f"{p} has a header but no data rows")
    data = np.array(rows, dtype=np.float64)
    return Table(names=names, data=data, path=p, sha256=hashlib.sha256(raw).hexdigest())


def pick_columns(table: Table, spec: str | None, sensor: str) -> list[int]:
    """Indices of the three columns named by ``spec`` (names or zero-based indices)."""
    ncol = table.data.shape[1]
    if spec is None:
        if table.names is not None:
            want = SENSOR_COLUMNS[sensor]
            if all(w in table.names for w in want):
                return [table.names.index(w) for w in want]
            numeric = [i for i, n in enumerate(table.names) if n != "t"]
            if len(numeric) == 3:
                return numeric
            raise CalibrationError(
                f"{table.path} has columns {', '.join(table.names)} but not "
                f"{', '.join(want)}: pass --columns (names or zero-based indices, e.g. 0,1,2)"
            )
        if ncol == 3:
            return [0, 1, 2]
        raise CalibrationError(
            f"{table.path} has {ncol} unnamed columns: pass --columns with three zero-based "
            "indices, e.g. --columns 0,1,2"
        )
    parts = [s.strip() for s in spec.split(",") if s.strip()]
    if len(parts) != 3:
        raise CalibrationError(f"--columns needs three columns (x,y,z), got {spec!r}")
    out = []
    for s in parts:
        if s.lstrip("-").isdigit():
            i = int(s)
            if not 0 <= i < ncol:
                raise CalibrationError(
                    f"--columns: index {i} is out of range; {table.path} has {ncol} columns "
                    f"(0..{ncol - 1})"
                )
            out.append(i)
        elif table.names is not None and s in table.names:
            out.append(table.names.index(s))
        else:
            have = ", ".join(table.names) if table.names else "none (headerless: use indices)"
            raise CalibrationError(f"--columns: no column {s!r}; names are: {have}")
    return out


# --------------------------------------------------------------------------------------------
# The fit pipeline, shared with `triaxcal report`


def add_fit_options(p: argparse.ArgumentParser) -> None:
    """The options of ``fit`` that ``report`` also takes for a session file."""
    p.add_argument("--sensor", choices=SENSORS, default=None,
                   help="which sensor the columns hold (default: accel)")
    p.add_argument("--columns", default=None,
                   help="three columns by name or zero-based index: ax,ay,az or 0,1,2 "
                        "(default: the sensor's named columns, or the first three)")
    p.add_argument("--model", choices=(*MODELS, "auto"), default="auto",
                   help="sphere (offset + 1 scale), axis (+ 3 gains), full (+ cross-axis / soft "
                        "iron), auto: chosen by BIC (default)")
    p.add_argument("--radius", default=None,
                   help="magnitude of calibrated readings with unit: 1g (accel default), "
                        "9.80665, 48uT, 16384 (counts). Default for gyro/mag: the data's own")
    p.add_argument("--unit", default=None,
                   help="calibrated unit to record (default: from --radius)")
    p.add_argument("--raw-unit", default=None,
                   help="unit of the raw readings (default: counts; a log's own unit)")
    p.add_argument("--sigma", type=float, default=2.0,
                   help="reject readings whose length is more than SIGMA standard deviations "
                        "from the mean (Magneto's rule), iterated; 0 disables (default 2)")
    p.add_argument("--rounds", type=int, default=10,
                   help="most reject-and-refit rounds (1 = a single pass like Magneto)")
    p.add_argument("--reject-on", choices=("calibrated", "raw"), default="calibrated",
                   help="judge the first round on calibrated lengths (default) or raw lengths "
                        "(exactly Magneto's rule)")
    p.add_argument("--poses", action="store_true",
                   help="reduce a raw time series (a capture session) to still-pose means first")
    p.add_argument("--window", type=int, default=25, help="pose detection window (samples)")
    p.add_argument("--units-per-g", type=float, default=16384.0,
                   help="accelerometer counts per g, for --poses (16384 at +-2 g)")
    p.add_argument("--threshold-g", type=float, default=0.07, metavar="G",
                   help="--poses: steady when no axis of the window mean moved by more than G "
                        "g since the previous window (default 0.07, the seed's; a steadier "
                        "board allows less, which keeps the start and end of moves out of the "
                        "poses)")
    add_source_options(p)


@dataclass
class FitOutcome:
    """Everything ``fit`` and ``report`` need after fitting a file."""

    part: SensorCalibration
    points: np.ndarray
    sensor: str
    rejected: np.ndarray
    reason: str | None
    table: Table | None
    source: Source | None = None


def _pose_points(table: Table, cols: list[int], args: argparse.Namespace) -> np.ndarray:
    from ..detect import detect_poses

    names = table.names or ()
    acc = [names.index(c) for c in SENSOR_COLUMNS["accel"]] if all(
        c in names for c in SENSOR_COLUMNS["accel"]) else cols
    thr = getattr(args, "threshold_g", 0.07)
    if not (isinstance(thr, float) and 0 < thr < 2):
        raise CalibrationError(f"--threshold-g must lie between 0 and 2 g, got {thr}")
    det = detect_poses(table.data, window=args.window, units_per_g=args.units_per_g,
                       threshold=thr * args.units_per_g, columns=acc)
    if len(det.poses) == 0:
        raise CalibrationError(
            f"no still poses found in {table.path} (window {args.window} samples): hold the "
            "board still for a second in each pose, or drop --poses for point-per-row data"
        )
    return np.array([np.asarray(p.mean)[cols] for p in det.poses], dtype=np.float64)


def fit_file(args: argparse.Namespace) -> FitOutcome:
    """Read ``args.data``, pick columns, optionally reduce to poses, fit robustly."""
    from ..select import fit_robust

    sensor = args.sensor or "accel"
    src = load_source(args.data, sensor, args)
    table, pts = src.table, src.points
    raw_unit = args.raw_unit or src.raw_unit or "counts"
    if args.radius is not None:
        radius, unit = parse_radius(args.radius, sensor)
    elif DEFAULT_RADIUS[sensor] is not None:
        radius, unit = DEFAULT_RADIUS[sensor]  # type: ignore[misc]
    else:
        radius, unit = None, raw_unit
    if args.unit:
        unit = args.unit
    if args.rounds < 0:
        raise CalibrationError("--rounds must be >= 0")
    rob = fit_robust(pts, model=args.model, radius=radius, sigma=args.sigma,
                     max_rounds=args.rounds, lengths=args.reject_on)
    extra: dict[str, Any] = {
        "columns": src.columns,
        "poses": bool(args.poses),
        "n_input": len(pts),
        "sigma": float(args.sigma),
        "rejection_rounds": int(rob.rounds),
    }
    if args.poses:
        extra["pose_window"] = int(args.window)
        extra["units_per_g"] = float(args.units_per_g)
        extra["threshold_g"] = float(getattr(args, "threshold_g", 0.07))
    if rob.model_reason:
        extra["model_reason"] = rob.model_reason
    extra.update(src.extra)
    extra.update(autopilot_stats(src, sensor))
    from ..report import coverage

    part = SensorCalibration.from_fit(
        rob.fit, raw_unit=raw_unit, unit=unit, points=pts[rob.inliers],
        rejected=rob.rejected, input_sha256=src.sha256, source=str(src.path),
        extra_stats=extra,
    )
    stats = dict(part.stats)
    stats["coverage_pct"] = coverage(part.apply(pts[rob.inliers]))[1]
    part = SensorCalibration(**{**_fields(part), "stats": stats})
    return FitOutcome(part=part, points=pts, sensor=sensor, rejected=rob.rejected,
                      reason=rob.model_reason, table=table, source=src)


def _fields(part: SensorCalibration) -> dict[str, Any]:
    return {k: getattr(part, k) for k in ("offset", "matrix", "raw_unit", "unit", "radius",
                                          "model", "temperature", "stats", "input_sha256",
                                          "source")}


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
                   help="overwrite CAL.json instead of adding this sensor to it")
    p.add_argument("--sensor-id", default=None, help="board / sensor id to record")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    out = fit_file(args)
    path = Path(args.output)
    cal = None
    if path.exists() and not args.new:
        try:
            cal = Calibration.load(path)
        except CalibrationError as exc:
            raise CalibrationError(
                f"{path} exists but is not a calibration file ({exc}); pass --new to replace it"
            ) from None
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
    norms = s.get("norms", {})
    print(
        f"{verb} {path}: {out.sensor} ({out.part.raw_unit} -> {out.part.unit}), model "
        f"{out.part.model}, {s['n']} readings used, {len(out.rejected)} rejected; residual RMS "
        f"{s['rms']:.4g} {out.part.unit} ({s['rms_pct_of_radius']:.3g} % of radius); "
        f"std/mean of |v| {100 * norms.get('std_over_mean', float('nan')):.3g} %; coverage "
        f"{s['coverage_pct']:.0f} %",
        file=sys.stdout,
    )
    if out.reason:
        print(f"  model: {out.reason}")
    for w in s.get("warnings", []):
        print(f"  warning: {w}")
    if out.source is not None and out.source.recording is not None:
        for line in autopilot_lines(out.source, out.sensor, out.part.offset, out.part.matrix,
                                    out.part.unit):
            print(line)
        for w in out.source.recording.meta.get("warnings", []):
            print(f"  warning: {w}")
    return 0
