"""``triaxcal noise LOG_OR_SESSION [--sensor gyro|accel|both] [--rate HZ] [--cal CAL.json |
--unit U [--counts-per-unit X]] [--plot FIG.png] [--format text|json|kalibr] [-o OUT]``:
noise figures of a sensor logged at rest.

Reads a session CSV from ``triaxcal capture`` (header ``t,ax,ay,az,gx,gy,gz,...``) or any
numeric table (``--columns`` picks three columns), chunk by chunk, so a 24-hour log never sits
in memory, or an autopilot / ROS log (``.ulg``, ``.bin``, ``.bag``, ``.db3``, ``.mcap``: see
``triaxcal fit``'s ``--instance``, ``--topic``, ``--undo-autopilot-cal``); computes the
overlapping Allan deviation in the Rust core and fits angle / velocity random walk, bias
instability and rate / acceleration random walk (:func:`triaxcal.noise_figures`). The sample
rate comes from the ``t`` column (seconds) or ``--rate``. Readings are used in their own unit
(raw counts by default); ``--cal`` applies a calibration file's matrix (the offset does not
change an Allan deviation), ``--unit`` with ``--counts-per-unit`` divides counts by a nominal
sensitivity. ``--format kalibr`` writes Kalibr's noise keys in SI units (rad/s, m/s^2), which
needs readings in a unit that converts to them; with ``-o NOISE.json`` it writes them as the
JSON object ``triaxcal export --format kalibr --noise NOISE.json`` takes.
"""

from __future__ import annotations

import argparse
import io
import json
import math
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from ..calibration.file import Calibration
from ..conventions.units import UNITS
from ..errors import CalibrationError
from ..io.logs import is_log, read_log
from ..io.tables import SENSOR_COLUMNS
from ..methods.allan import AllanAccumulator
from ..methods.noise import NoiseFigures, kalibr_noise, kalibr_yaml, noise_figures, plot_allan
from ._fit_options import add_source_options

#: Rows parsed at a time.
CHUNK_ROWS = 200_000


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
    p.add_argument("--rate", type=float, default=None,
                   help="sample rate in Hz (default: from the t column, in seconds)")
    p.add_argument("--cal", default=None, metavar="CAL.json",
                   help="apply this calibration's matrix; the figures are then in its unit")
    p.add_argument("--unit", default=None,
                   help="unit of the readings (after --counts-per-unit), e.g. deg/s, rad/s, g, "
                        "m/s^2 (default counts); with --sensor both: gyro=deg/s,accel=g")
    p.add_argument("--counts-per-unit", default=None,
                   help="divide raw counts by this nominal sensitivity (e.g. 131 for deg/s); "
                        "with --sensor both: gyro=131,accel=16384")
    p.add_argument("--taus", choices=("log", "octave"), default="log",
                   help="averaging times: about 10 per decade (default) or octaves")
    p.add_argument("--plot", default=None, metavar="FIG.png",
                   help="save the Allan deviation with the fitted slopes (needs matplotlib: "
                        "pip install 'triaxcal[plot]'); with --sensor both, _gyro/_accel are "
                        "added before .png")
    p.add_argument("--format", choices=("text", "json", "kalibr"), default="text",
                   help="text (default), json, or Kalibr's imu.yaml noise keys")
    p.add_argument("-o", "--output", default=None, metavar="FILE",
                   help="write the output here instead of printing it; with --format kalibr "
                        "and a .json name, the JSON that triaxcal export --noise takes")
    p.add_argument("--rostopic", default="/imu0", help="rostopic for --format kalibr")
    add_source_options(p)
    p.set_defaults(func=run)


# --------------------------------------------------------------------------------------------
# reading a table in chunks


def _header(path: Path) -> tuple[tuple[str, ...] | None, str | None, int]:
    """(column names or None, delimiter, number of lines before the data)."""
    with open(path, encoding="utf-8", errors="replace") as f:
        skipped = 0
        for line in f:
            s = line.strip()
            if not s or s.startswith("#"):
                skipped += 1
                continue
            delim = next((d for d in (",", ";", "\t") if d in s), None)
            toks = [t.strip().strip('"') for t in (s.split(delim) if delim else s.split())]
            try:
                [float(t) for t in toks]
            except ValueError:
                return tuple(toks), delim, skipped + 1
            return None, delim, skipped
    raise CalibrationError(f"{path} holds no data rows")


def read_chunks(path: Path, cols: list[int], *, chunk_rows: int | None = None,
                time_col: int | None = None) -> Iterator[tuple[np.ndarray, np.ndarray | None]]:
    """Yield (readings (rows, len(cols)), times or None) chunk by chunk (``CHUNK_ROWS``)."""
    rows = int(chunk_rows or CHUNK_ROWS)
    _, delim, skip = _header(path)
    want = list(cols) + ([time_col] if time_col is not None else [])
    with open(path, encoding="utf-8", errors="replace") as f:
        for _ in range(skip):
            f.readline()
        lineno = skip
        while True:
            lines: list[str] = []
            first = lineno + 1
            for line in f:
                lineno += 1
                s = line.strip()
                if s and not s.startswith("#"):
                    lines.append(s)
                    if len(lines) >= rows:
                        break
            if not lines:
                return
            try:
                arr = np.loadtxt(io.StringIO("\n".join(lines)), delimiter=delim,
                                 usecols=want, ndmin=2, dtype=np.float64)
            except ValueError as exc:
                raise CalibrationError(
                    f"{path}, lines {first}..{lineno}: a row is not numbers or has too few "
                    f"columns ({exc}); fix or remove it"
                ) from None
            yield arr[:, :len(cols)], (arr[:, -1] if time_col is not None else None)


def _columns(names: tuple[str, ...] | None, spec: str | None, sensor: str, path: Path,
             ncol_hint: int) -> list[int]:
    if spec is not None:
        parts = [s.strip() for s in spec.split(",") if s.strip()]
        if len(parts) != 3:
            raise CalibrationError(f"--columns needs three columns (x,y,z), got {spec!r}")
        out = []
        for s in parts:
            if s.isdigit():
                out.append(int(s))
            elif names is not None and s in names:
                out.append(names.index(s))
            else:
                raise CalibrationError(f"--columns: no column {s!r} in {path}")
        return out
    if names is not None:
        want = SENSOR_COLUMNS[sensor]
        if all(w in names for w in want):
            return [names.index(w) for w in want]
        raise CalibrationError(
            f"{path} has columns {', '.join(names)} but not {', '.join(want)}: pass --columns"
        )
    if ncol_hint == 3:
        return [0, 1, 2]
    raise CalibrationError(f"{path} has unnamed columns: pass --columns (e.g. 0,1,2)")


def _per_sensor(text: str | None, sensor: str, what: str) -> str | None:
    """``"deg/s"`` or ``"gyro=deg/s,accel=g"`` -> the value for ``sensor``."""
    if text is None or "=" not in text:
        return text
    pairs = {}
    for item in text.split(","):
        key, sep, val = item.partition("=")
        if not sep or key.strip() not in ("gyro", "accel") or not val.strip():
            raise CalibrationError(f"{what} {text!r}: use one value or gyro=...,accel=...")
        pairs[key.strip()] = val.strip()
    return pairs.get(sensor)


def _scale(args: argparse.Namespace, sensor: str, default_unit: str = "counts"
           ) -> tuple[np.ndarray | None, float, str]:
    """(matrix to apply or None, divisor, unit of the result)."""
    unit = _per_sensor(args.unit, sensor, "--unit")
    cpu_text = _per_sensor(args.counts_per_unit, sensor, "--counts-per-unit")
    if args.cal:
        if unit or cpu_text:
            raise CalibrationError("give either --cal or --unit / --counts-per-unit, not both")
        part = Calibration.load(args.cal).part(sensor)
        if part.temperature is not None:
            print(f"triaxcal noise: note: {args.cal} has temperature terms for {sensor}; only "
                  "its matrix at the reference temperature is applied", file=sys.stderr)
        return np.asarray(part.matrix), 1.0, part.unit
    div = 1.0
    if cpu_text is not None:
        try:
            cpu = float(cpu_text)
        except ValueError:
            raise CalibrationError(f"--counts-per-unit {cpu_text!r} is not a number") from None
        if not (math.isfinite(cpu) and cpu > 0):
            raise CalibrationError(f"--counts-per-unit must be > 0, got {cpu_text}")
        if not unit:
            raise CalibrationError("--counts-per-unit needs --unit (what the counts become)")
        div = cpu
    unit = unit or default_unit
    if unit != "counts" and unit not in UNITS:
        raise CalibrationError(f"--unit {unit!r}: use counts or one of {sorted(UNITS)}")
    return None, div, unit


def _figures_from_log(args: argparse.Namespace, sensor: str) -> NoiseFigures:
    path = Path(args.data)
    if args.columns:
        raise CalibrationError(f"--columns applies to tables; {path} is a log")
    rec = read_log(path, instance=args.instance, topic=args.topic,
                   undo_autopilot_cal=args.undo_autopilot_cal)
    stream = rec.stream(sensor)
    matrix, div, unit = _scale(args, sensor, default_unit=stream.unit)
    rate = args.rate if args.rate is not None else stream.rate_hz
    if not (math.isfinite(rate) and rate > 0):
        raise CalibrationError(f"{path}: no sample rate for {sensor} (too few samples?): pass "
                               "--rate HZ")
    x = np.asarray(stream.data) / div
    if matrix is not None:
        x = x @ matrix.T
    acc = AllanAccumulator(rate, axes=3, taus=args.taus, unit=unit)
    acc.add(x)
    return noise_figures(acc.result(), sensor=sensor)


def figures_from_file(args: argparse.Namespace, sensor: str) -> NoiseFigures:
    """Stream the file once and fit the figures of one sensor."""
    path = Path(args.data)
    if is_log(path) and path.exists():
        return _figures_from_log(args, sensor)
    if args.instance is not None or args.topic or args.undo_autopilot_cal:
        raise CalibrationError("--instance, --topic and --undo-autopilot-cal apply to logs (.ulg, "
                               f".bin, .bag, .db3, .mcap); {path} is read as a table")
    if not path.is_file():
        raise CalibrationError(f"{path} not found")
    names, delim, _ = _header(path)
    with open(path, encoding="utf-8", errors="replace") as f:
        sample = next((ln for ln in f if ln.strip() and not ln.lstrip().startswith("#")), "")
    ncol = len(sample.strip().split(delim) if delim else sample.split())
    cols = _columns(names, args.columns, sensor, path, ncol)
    time_col = names.index("t") if names is not None and "t" in names else None
    matrix, div, unit = _scale(args, sensor)
    rate = args.rate
    if rate is not None and not (math.isfinite(rate) and rate > 0):
        raise CalibrationError(f"--rate must be > 0 Hz, got {rate}")
    acc: AllanAccumulator | None = None
    for chunk, t in read_chunks(path, cols, time_col=time_col if rate is None else None):
        if acc is None:
            if rate is None:
                rate = _rate_from_t(t, path)
            acc = AllanAccumulator(rate, axes=3, taus=args.taus, unit=unit)
        x = chunk / div
        if matrix is not None:
            x = x @ matrix.T
        acc.add(x)
    if acc is None:
        raise CalibrationError(f"{path} holds no data rows")
    return noise_figures(acc.result(), sensor=sensor)


def _rate_from_t(t: np.ndarray | None, path: Path) -> float:
    if t is None:
        raise CalibrationError(f"{path} has no t column (seconds): pass --rate HZ")
    dt = np.diff(t)
    if dt.size < 2 or not (np.median(dt) > 0):
        raise CalibrationError(f"{path}: the t column does not increase: pass --rate HZ")
    med = float(np.median(dt))
    if np.mean(np.abs(dt - med) > 0.5 * med) > 0.01:
        print(f"triaxcal noise: warning: {path} has gaps or jitter in t (more than 1 % of the "
              "intervals differ from the median by half); the Allan deviation assumes even "
              "sampling", file=sys.stderr)
    return 1.0 / med


def run(args: argparse.Namespace) -> int:
    sensors = ["gyro", "accel"] if args.sensor == "both" else [args.sensor]
    if args.columns and len(sensors) > 1:
        raise CalibrationError("--columns picks one sensor's columns: use --sensor gyro or accel")
    figs = {s: figures_from_file(args, s) for s in sensors}
    if args.format == "kalibr" and args.output and args.output.lower().endswith(".json"):
        out = json.dumps(kalibr_noise(figs.get("gyro"), figs.get("accel")), indent=2) + "\n"
    elif args.format == "kalibr":
        out = kalibr_yaml(figs.get("gyro"), figs.get("accel"), rostopic=args.rostopic)
    elif args.format == "json":
        out = json.dumps({s: f.to_dict() for s, f in figs.items()}, indent=2) + "\n"
    else:
        out = "\n".join(f.text() for f in figs.values()) + "\n"
    if args.output:
        Path(args.output).write_text(out, encoding="utf-8")
        print(f"wrote {args.output}")
    else:
        sys.stdout.write(out)
    if args.format != "text":
        for f in figs.values():
            for w in f.warnings:
                print(f"triaxcal noise: warning: {w}", file=sys.stderr)
    if args.plot:
        for s, f in figs.items():
            p = Path(args.plot)
            if len(figs) > 1:
                p = p.with_name(f"{p.stem}_{s}{p.suffix or '.png'}")
            print(f"figure: {plot_allan(f, p)}")
    return 0
