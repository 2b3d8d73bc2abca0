"""Noise figures of a recording: what ``triaxcal noise`` does, as a library call.

:class:`NoiseRequest` says what to read and how (validated once, when it is made);
:func:`noise_from_file` reads the file once, chunk by chunk -- a capture session or any table
through :func:`triaxcal.io.tables.iter_table` (memory bounded by a block, however long the
log), a PX4 / ArduPilot / ROS log through :func:`triaxcal.io.logs.read_log` -- and streams each
sensor's readings into the Allan deviation (:class:`~triaxcal.methods.allan.AllanAccumulator`)
and the at-rest test (:class:`~triaxcal.methods.rest.RestMonitor`). Moving readings are refused
(:class:`~triaxcal.methods.rest.NotAtRestError`, naming the motion found) unless ``force``,
which computes the figures marked. The result, :class:`NoiseResult`, writes itself as text,
JSON (always valid JSON: a value that is not a finite number is ``null``, with why) or
Kalibr's noise keys.

Units, per sensor: a calibration's matrix (``cal``: the figures are in its unit; the offset
does not change an Allan deviation), a nominal sensitivity (``counts_per_unit``: counts divided
by it), the unit the readings are already in (``unit``), or the unit a log records.

The sample rate: ``rate_hz``; a log's time stamps (median interval); or a table's ``t`` column
(seconds). ``triaxcal capture`` stamps each batch of rows the host reads with one host time,
so consecutive stamps repeat and then jump: the rate is the rows over the time span of the
whole session (:class:`TimeBase`), not a median interval, and the notes say so.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .._checks import options
from .._checks.spelling import opt
from ..conventions.units import UNITS
from ..errors import CalibrationError
from ..io.logs import is_log, read_log
from ..io.tables import iter_table, pick_columns
from ..quality.bounds import MAX_CLOCK_STEP_BACK_S, MAX_TIME_GAP_SHARE, sample_rate
from .allan import AllanAccumulator
from .noise import NoiseFigures, kalibr_noise, kalibr_yaml, noise_figures
from .rest import NotAtRestError, RestCheck, RestMonitor, not_at_rest

__all__ = ["NoiseRequest", "NoiseResult", "TimeBase", "check_rate", "noise_from_file"]

SENSOR_CHOICES = ("gyro", "accel", "both")
_NAMES = {"gyro": "gyroscope", "accel": "accelerometer"}


#: ``rate_hz`` as a float within :data:`~triaxcal.quality.bounds.SAMPLE_RATE_HZ`.
check_rate = sample_rate


# --------------------------------------------------------------------------------------------
# the request


def _part(cal: Any, sensor: str) -> Any:
    if isinstance(cal, Mapping):
        if sensor not in cal:
            raise CalibrationError(f"{opt('cal')} has no {sensor} part (it has: "
                                   f"{', '.join(map(str, cal)) or 'none'})")
        return cal[sensor]
    if hasattr(cal, "part"):
        return cal.part(sensor)
    raise CalibrationError(f"{opt('cal')} must be a calibration (or a mapping of sensor to "
                           f"calibration part), got {type(cal).__name__}")


def _sensor_unit(u: Any, sensor: str, what: str) -> str:
    if not isinstance(u, str) or not (u == "counts" or (u in UNITS and UNITS[u][0] == sensor)):
        fit = sorted(k for k, (q, _) in UNITS.items() if q == sensor)
        raise CalibrationError(f"{what}: {u!r} is not a unit of the {_NAMES[sensor]}: use "
                               f"counts or one of {', '.join(fit)}")
    return u


def _per_sensor(value: Any, sensors: tuple[str, ...], name: str) -> dict[str, Any]:
    """``value`` as {sensor: value}: a mapping (keys among ``sensors``), or one value for the
    only sensor."""
    if value is None:
        return {}
    if isinstance(value, Mapping):
        out = dict(value)
        for k in out:
            if k not in sensors:
                raise CalibrationError(
                    f"{opt(name)} names {k!r}, but the sensors read are {', '.join(sensors)}"
                )
        return out
    if len(sensors) > 1:
        raise CalibrationError(f"{opt(name)} needs one value per sensor with "
                               f"{opt('sensor', 'both')}: e.g. gyro=... and accel=...")
    return {sensors[0]: value}


@dataclass(frozen=True)
class NoiseRequest:
    """What :func:`noise_from_file` reads and how, validated when it is made.

    Parameters
    ----------
    path : str or Path
        A capture session or table of numbers, or a log (``.ulg``, ``.bin``, ``.bag``,
        ``.db3``, ``.mcap``).
    sensor : {"gyro", "accel", "both"}
        Which sensor's figures (tables: columns ``gx,gy,gz`` / ``ax,ay,az``).
    columns : str or sequence of three, optional
        A table's three columns (names or zero-based indices); one sensor only.
    rate_hz : float, optional
        Sample rate in Hz; default from the log's time stamps or the table's ``t`` column.
    unit : str or mapping, optional
        Unit of the readings per sensor (``{"gyro": "rad/s", "accel": "m/s^2"}``), after
        ``counts_per_unit``; one unit applies to the sensor it measures. Default: ``counts``
        for tables, the unit a log records.
    counts_per_unit : mapping, optional
        Nominal sensitivity per sensor, ``{"gyro": (131.0, "deg/s")}`` or ``{"gyro": 131.0}``
        with ``unit``: counts are divided by it.
    cal : Calibration or mapping, optional
        A calibration (its parts' matrices are applied; the figures are in its units).
    taus : {"log", "octave"}
        Averaging times: about 10 per decade or octaves.
    force : bool
        Compute the figures although the readings are not at rest (they are marked).
    skip_bad_lines : bool
        Tables: skip lines that are not a row of numbers (counted in the notes).
    instance, topics, undo_autopilot_cal
        Logs: which sensor, which ROS topics, undo the autopilot's calibration (see
        :func:`triaxcal.io.logs.read_log`).
    chunk_rows : int
        Rows of a table read at a time.
    """

    path: str | os.PathLike[str]
    sensor: str = "gyro"
    columns: Any = None
    rate_hz: float | None = None
    unit: Any = None
    counts_per_unit: Any = None
    cal: Any = None
    taus: str = "log"
    force: bool = False
    skip_bad_lines: bool = False
    instance: int | None = None
    topics: Any = None
    undo_autopilot_cal: bool = False
    chunk_rows: int = 65536
    cal_name: str = field(default="the calibration", repr=False)

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        if not isinstance(self.path, (str, os.PathLike)):
            raise CalibrationError(f"path must name a file, got {self.path!r}")
        set_(self, "path", Path(self.path))
        options.choice(self.sensor, opt("sensor"), SENSOR_CHOICES)
        sensors = self.sensors
        if self.columns is not None:
            if len(sensors) > 1:
                raise CalibrationError(f"{opt('columns')} picks one sensor's columns: use "
                                       f"{opt('sensor', 'gyro')} or {opt('sensor', 'accel')}")
            cols = self.columns
            if not isinstance(cols, str):
                if isinstance(cols, bytes) or not isinstance(cols, Sequence) or len(cols) != 3:
                    raise CalibrationError(f"{opt('columns')} needs three columns (x,y,z), got "
                                           f"{cols!r}")
                cols = ",".join(str(c) for c in cols)
            set_(self, "columns", cols)
        if self.rate_hz is not None:
            set_(self, "rate_hz", check_rate(self.rate_hz, opt("rate_hz")))
        options.choice(self.taus, opt("taus"), ("log", "octave"))
        options.flag(self.force, opt("force"))
        options.flag(self.skip_bad_lines, opt("skip_bad_lines"))
        options.flag(self.undo_autopilot_cal, opt("undo_autopilot_cal"))
        set_(self, "chunk_rows", options.integer(self.chunk_rows, "chunk_rows", ge=1,
                                                 le=1 << 24))
        if self.instance is not None:
            options.integer(self.instance, opt("instance"), ge=0, le=15)
        # units: one place decides them, per sensor
        units: dict[str, str] = {}
        if isinstance(self.unit, str):
            u = self.unit
            if u == "counts":
                units = dict.fromkeys(sensors, u)
            elif u in UNITS and UNITS[u][0] in sensors:
                units = {UNITS[u][0]: u}
            elif u in UNITS and len(sensors) == 1:
                _sensor_unit(u, sensors[0], opt("unit"))
            else:
                raise CalibrationError(f"{opt('unit')}: unknown unit {u!r}: use counts or one of "
                                       f"{', '.join(UNITS)}")
        else:
            units = _per_sensor(self.unit, sensors, "unit")
        for s, u in units.items():
            _sensor_unit(u, s, opt("unit"))
        cpu: dict[str, tuple[float, str | None]] = {}
        for s, v in _per_sensor(self.counts_per_unit, sensors, "counts_per_unit").items():
            raw, said = (v if isinstance(v, tuple) and len(v) == 2 else (v, None))
            value = options.number(raw, opt("counts_per_unit"), gt=0,
                                   hint=f"counts per unit of the {_NAMES[s]}, e.g. 131 for "
                                        "deg/s")
            if said is not None:
                _sensor_unit(said, s, opt("counts_per_unit"))
                if s in units and units[s] != said:
                    raise CalibrationError(f"{opt('counts_per_unit')} says the {_NAMES[s]}'s "
                                           f"counts become {said}, {opt('unit')} says "
                                           f"{units[s]}")
            become = said or units.get(s)
            if become is None or become == "counts":
                raise CalibrationError(
                    f"{opt('counts_per_unit')} {s}={value:g} needs {opt('unit')} (what the "
                    f"counts become), or say it there: {s}={value:g}:UNIT"
                )
            cpu[s] = (value, become)
        if self.cal is not None:
            if units or cpu:
                raise CalibrationError(f"give either {opt('cal')} or {opt('unit')} / "
                                       f"{opt('counts_per_unit')}, not both")
            parts = {s: _part(self.cal, s) for s in sensors}
            for s, p in parts.items():
                try:
                    m = np.asarray(getattr(p, "matrix", None), dtype=np.float64)
                except (TypeError, ValueError):
                    m = np.zeros(0)
                if m.shape != (3, 3) or not np.isfinite(m).all():
                    raise CalibrationError(f"{self.cal_name}: the {s} part has no finite 3x3 "
                                           "matrix")
            set_(self, "cal", parts)
        set_(self, "unit", units)
        set_(self, "counts_per_unit", cpu)

    @property
    def sensors(self) -> tuple[str, ...]:
        """The sensors read: ``("gyro",)``, ``("accel",)`` or ``("gyro", "accel")``."""
        return ("gyro", "accel") if self.sensor == "both" else (self.sensor,)


@dataclass(frozen=True)
class _Scale:
    """How readings of one sensor become figures: divided by ``divide_by``, then multiplied by
    ``matrix``; the result is in ``unit``. ``note``: how the unit was decided, if worth saying."""

    unit: str
    divide_by: float = 1.0
    matrix: np.ndarray | None = None
    note: str = ""

    def apply(self, x: np.ndarray) -> np.ndarray:
        if self.divide_by != 1.0:
            x = x / self.divide_by
        if self.matrix is not None:
            x = x @ self.matrix.T
        return x


def _scale(req: NoiseRequest, sensor: str, recorded: str | None) -> _Scale:
    """The scale of ``sensor``; ``recorded``: the unit a log records (None for a table)."""
    name = _NAMES[sensor]
    if req.cal is not None:
        part = req.cal[sensor]
        raw = getattr(part, "raw_unit", None)
        if recorded is not None and raw is not None and raw != recorded:
            raise CalibrationError(
                f"{req.cal_name}'s {sensor} part was fitted on readings in {raw}, but the log "
                f"records the {name} in {recorded}: use a calibration of this log's readings"
            )
        note = ""
        if getattr(part, "temperature", None) is not None:
            note = (f"{req.cal_name} has temperature terms for the {name}; only its matrix at "
                    "the reference temperature is applied")
        return _Scale(str(part.unit), 1.0, np.asarray(part.matrix, dtype=np.float64), note)
    unit = req.unit.get(sensor)
    if sensor in req.counts_per_unit:
        value, u = req.counts_per_unit[sensor]
        if recorded is not None and recorded != "counts":
            raise CalibrationError(
                f"{opt('counts_per_unit')} divides counts, but the log records the {name} in "
                f"{recorded}"
            )
        return _Scale(u, value)
    if unit is not None:
        if recorded is not None and unit != recorded:
            raise CalibrationError(
                f"the log records the {name} in {recorded}; {opt('unit')} applies to tables"
            )
        return _Scale(unit)
    return _Scale(recorded or "counts")


# --------------------------------------------------------------------------------------------
# time stamps


def _lead(t: np.ndarray, value: float) -> int:
    """How many of the first values of ``t`` equal ``value``."""
    other = np.flatnonzero(t != value)
    return int(other[0]) if len(other) else len(t)


class TimeBase:
    """The sample rate of a table from its ``t`` column (seconds), streamed block by block.

    The rate is the rows after the first time stamp over the time span,
    ``(n - n_first) / (t_last - t_first)``, where ``n_first`` rows share the first stamp: each
    stamp of a capture session is the host time at which its batch of rows arrived, so the
    rows after the first stamp arrived within the span. For evenly stamped rows it is
    ``(n - 1) / span``, the mean rate.

    >>> import numpy as np
    >>> tb = TimeBase("s.csv")
    >>> tb.add(np.repeat(np.arange(0.0, 10.0, 0.1), 10)[9:])   # batches of 10 rows, 100 Hz
    >>> round(tb.rate_hz(), 6), tb.batched
    (100.0, True)
    """

    def __init__(self, path: Any) -> None:
        self.path = path
        self.n = 0
        self.n_first = 0
        self.distinct = 0
        self.t_first = math.nan
        self.t_last = math.nan
        self.back = 0.0  # largest step back
        self.backs = 0
        self.gap = 0.0  # largest step forward ...
        self.gap_at = 0.0  # ... its end, and the rows stamped there
        self.gap_rows = 0
        self._open_gap = False

    def add(self, t: Any) -> None:
        """The next rows' time stamps (s)."""
        t = np.asarray(t, dtype=np.float64)
        if not len(t):
            return
        if not np.isfinite(t).all():
            i = int(np.flatnonzero(~np.isfinite(t))[0])
            raise CalibrationError(f"{self.path}: the t column is not a number at data row "
                                   f"{self.n + i + 1}: repair it or pass {opt('rate_hz')}")
        if self.n == 0:
            self.t_first = float(t[0])
        if self.n_first == self.n:  # still in the rows of the first stamp
            self.n_first += _lead(t, self.t_first)
        if self._open_gap:  # more rows stamped at the end of the largest gap so far
            k = _lead(t, self.gap_at)
            self.gap_rows += k
            self._open_gap = k == len(t)
        full = t if self.n == 0 else np.concatenate([[self.t_last], t])
        with np.errstate(over="ignore"):  # stamps near the double's end: an inf step
            d = np.diff(full)
        if len(d):
            k = int(np.argmax(d))
            if d[k] > self.gap:
                self.gap = float(d[k])
                self.gap_at = float(full[k + 1])
                rest = full[k + 1:]
                self.gap_rows = _lead(rest, self.gap_at)
                self._open_gap = self.gap_rows == len(rest)
            if d[int(np.argmin(d))] < 0:
                self.backs += int(np.count_nonzero(d < 0))
                self.back = max(self.back, float(-d.min()))
            self.distinct += int(np.count_nonzero(d))
        self.n += len(t)
        self.t_last = float(t[-1])

    @property
    def batched(self) -> bool:
        """Whether rows share time stamps (as a capture session's batches do)."""
        return self.distinct + 1 < self.n

    @property
    def span_s(self) -> float:
        return self.t_last - self.t_first if self.n else 0.0

    def rate_hz(self) -> float:
        """Rows over the time span (see the class docstring); refuses a t column that does not
        advance or goes back."""
        if self.back > MAX_CLOCK_STEP_BACK_S:
            raise CalibrationError(
                f"{self.path}: the t column goes back by {self.back:.3g} s: it is not the time "
                f"of the rows in seconds: pass {opt('rate_hz')}"
            )
        rows = self.n - self.n_first
        if not (self.span_s > 0 and rows > 0):
            raise CalibrationError(
                f"{self.path}: the t column does not advance ({self.n} rows stamped "
                f"{self.t_first:g} s): pass {opt('rate_hz')}"
            )
        return rows / self.span_s

    def notes(self, rate: float) -> list[str]:
        """How the rate was found, and gaps in the stamps, in words."""
        how = (f"sample rate {rate:.6g} Hz from the t column: {self.n - self.n_first:,} rows "
               f"after the first stamp over {self.span_s:.6g} s")
        if self.batched:
            how += (" (rows share host time stamps, one per batch read, as triaxcal capture "
                    "writes them: the rate is rows over the span, not the median interval)")
        out = [how]
        lost = self.gap - self.gap_rows / rate
        if lost > MAX_TIME_GAP_SHARE * self.span_s and lost > 10.0 / rate:
            out.append(
                f"warning: the t column jumps by {self.gap:.3g} s at "
                f"{self.gap_at - self.t_first:.6g} s, about {lost * rate:,.0f} rows missing "
                "there; the Allan deviation assumes even sampling: record without gaps or cut "
                "the log there"
            )
        if self.backs:
            out.append(f"the t column steps back {self.backs} times (by up to {self.back:.3g} s: "
                       "the host's clock was corrected?)")
        return out


# --------------------------------------------------------------------------------------------
# the result


def _json_safe(v: Any) -> Any:
    if isinstance(v, float):
        return v if math.isfinite(v) else None
    if isinstance(v, dict):
        return {k: _json_safe(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_json_safe(x) for x in v]
    return v


@dataclass(frozen=True)
class NoiseResult:
    """Noise figures of one recording.

    Attributes
    ----------
    figures : dict of str to NoiseFigures
        Per sensor (``gyro``, ``accel``).
    rest : dict of str to RestCheck
        The at-rest test per sensor.
    notes : tuple of str
        How the rate and units were decided, lines skipped, gaps.
    source : str
        The file read.
    """

    figures: Mapping[str, NoiseFigures]
    rest: Mapping[str, RestCheck]
    notes: tuple[str, ...] = ()
    source: str = ""

    @property
    def forced(self) -> bool:
        """Whether a sensor's figures were computed although it was not at rest."""
        return any(f.motion for f in self.figures.values())

    def text(self) -> str:
        """Console text: notes, the at-rest verdict and the figures of each sensor."""
        lines = [f"note: {n}" for n in self.notes]
        for s, f in self.figures.items():
            r = self.rest.get(s)
            if r is not None and not f.motion:
                lines.append(f"{r.message}")
            lines.append(f.text())
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON values per sensor: the figures (:meth:`NoiseFigures.to_dict`), the
        at-rest test and the notes. A value that is not a finite number is ``None`` (null)."""
        out = {}
        for s, f in self.figures.items():
            d = f.to_dict()
            if s in self.rest:
                d["rest"] = self.rest[s].to_dict()
            d["notes"] = list(self.notes)
            out[s] = d
        return _json_safe(out)

    def to_json(self) -> str:
        """:meth:`to_dict` as JSON text (strict: no NaN or Infinity)."""
        return json.dumps(self.to_dict(), indent=2, allow_nan=False) + "\n"

    def kalibr(self) -> dict[str, float]:
        """Kalibr's four noise keys (:func:`~triaxcal.methods.noise.kalibr_noise`)."""
        return kalibr_noise(self.figures.get("gyro"), self.figures.get("accel"))

    def kalibr_json(self) -> str:
        """The JSON object ``triaxcal export --format kalibr --noise`` takes. Refused for
        figures of readings that were not at rest: that object has no place to say so."""
        if self.forced:
            raise CalibrationError(
                "the figures were computed from readings that are not at rest "
                f"({opt('force', True)}), and Kalibr's noise JSON has no place to say so: write "
                "the Kalibr YAML (marked) or JSON figures instead, or record at rest"
            )
        return json.dumps(self.kalibr(), indent=2, allow_nan=False) + "\n"

    def kalibr_yaml(self, ros_topic: str = "/imu0") -> str:
        """The noise block of Kalibr's ``imu.yaml``
        (:func:`~triaxcal.methods.noise.kalibr_yaml`)."""
        return kalibr_yaml(self.figures.get("gyro"), self.figures.get("accel"),
                           ros_topic=ros_topic)


# --------------------------------------------------------------------------------------------
# reading


class _Sensor:
    """One sensor's accumulators."""

    def __init__(self, sensor: str, scale: _Scale, rate: float, window_rate: float,
                 taus: str) -> None:
        self.sensor = sensor
        self.scale = scale
        self.allan = AllanAccumulator(rate, axes=3, taus=taus, unit=scale.unit)
        self.rest = RestMonitor(window_rate, sensor=sensor, unit=scale.unit)

    def add(self, raw: np.ndarray) -> None:
        x = self.scale.apply(raw)
        self.allan.add(x)  # refuses NaN / inf, naming the row
        self.rest.add(x)


def _finish(req: NoiseRequest, acc: dict[str, _Sensor], rate: float | None,
            notes: list[str], source: str) -> NoiseResult:
    """Figures and verdicts from the accumulators; the refusal of moving readings. ``rate``:
    the sample rate found at the end (the accumulators ran at a provisional one), or None."""
    rests = {s: a.rest.result(rate_hz=rate) for s, a in acc.items()}
    moving = [r for r in rests.values() if r.at_rest is False]
    if moving and not req.force:
        raise NotAtRestError(not_at_rest(moving[0]) + "".join(
            f" (also: {r.message.split(' (')[0]})" for r in moving[1:]))
    for r in rests.values():
        if r.at_rest is None:
            notes.append(f"warning: {r.message}")
    figs: dict[str, NoiseFigures] = {}
    for s, a in acc.items():
        ad = a.allan.result()
        if rate is not None:  # the taus follow the rate found at the end
            taus = np.asarray(ad.m, dtype=np.float64) / rate
            taus.setflags(write=False)
            ad = dataclasses.replace(ad, taus=taus, rate_hz=rate)
        f = noise_figures(ad, sensor=s)
        r = rests[s]
        if r.at_rest is False:
            mark = (f"computed although the readings are not at rest ({opt('force', True)}): "
                    f"{r.message}")
            f = dataclasses.replace(f, motion=r.message, warnings=(mark, *f.warnings))
        figs[s] = f
        if a.scale.note:
            notes.append(a.scale.note)
    return NoiseResult(figs, rests, tuple(dict.fromkeys(notes)), source)


def _from_log(req: NoiseRequest, path: Path) -> NoiseResult:
    if req.columns is not None:
        raise CalibrationError(f"{opt('columns')} applies to tables; {path} is a log")
    rec = read_log(path, instance=req.instance, topic=req.topics,
                   undo_autopilot_cal=req.undo_autopilot_cal)
    acc: dict[str, _Sensor] = {}
    notes: list[str] = []
    rate = req.rate_hz
    for s in req.sensors:
        stream = rec.stream(s)
        r = rate if rate is not None else stream.rate_hz
        if not (math.isfinite(r) and r > 0):
            raise CalibrationError(f"{path}: no sample rate for the {_NAMES[s]} (too few "
                                   f"samples?): pass {opt('rate_hz')}")
        r = check_rate(r, f"the {_NAMES[s]}'s sample rate from the log's time stamps")
        if rate is None:
            notes.append(f"{_NAMES[s]}: {len(stream)} samples at {r:.6g} Hz (the median interval "
                         f"of the log's time stamps), in {stream.unit}")
        a = _Sensor(s, _scale(req, s, stream.unit), r, r, req.taus)
        a.add(np.asarray(stream.data))
        acc[s] = a
    return _finish(req, acc, None, notes, str(path))


def _from_table(req: NoiseRequest, path: Path) -> NoiseResult:
    if req.instance is not None or req.topics or req.undo_autopilot_cal:
        raise CalibrationError(
            f"{opt('instance')}, {opt('topics')} and {opt('undo_autopilot_cal')} apply to logs "
            f"(.ulg, .bin, .bag, .db3, .mcap); {path} is read as a table"
        )
    acc: dict[str, _Sensor] = {}
    cols: dict[str, list[int]] = {}
    tcol: int | None = None
    tb: TimeBase | None = None
    notes: list[str] = []
    last_notes: tuple[str, ...] = ()
    for block in iter_table(path, rows=req.chunk_rows, skip_bad_lines=req.skip_bad_lines):
        data = block.data
        if not cols:
            cols = {s: pick_columns(block, req.columns, s) for s in req.sensors}
            if len(cols) > 1 and cols["gyro"] == cols["accel"]:
                raise CalibrationError(
                    f"{path} has the columns of one sensor only: read it with "
                    f"{opt('sensor', 'gyro')} or {opt('sensor', 'accel')}"
                )
            if block.names is not None and "t" in block.names:
                tcol = block.names.index("t")
            if req.rate_hz is None:
                if tcol is None:
                    raise CalibrationError(
                        f"{path} has no t column (seconds): pass {opt('rate_hz')}"
                    )
                tb = TimeBase(path)
        if tb is not None:
            assert tcol is not None
            tb.add(data[:, tcol])
        if not acc:
            if tb is None:
                assert req.rate_hz is not None
                rate, window_rate = req.rate_hz, req.rate_hz
            else:  # the rate is known at the end; the first block sets the windows
                rate, window_rate = 1.0, check_rate(tb.rate_hz(), "the sample rate of the "
                                                    f"first {tb.n} rows' t column")
            acc = {s: _Sensor(s, _scale(req, s, None), rate, window_rate, req.taus)
                   for s in req.sensors}
        for s, a in acc.items():
            a.add(data[:, cols[s]])
        last_notes = block.notes
    found: float | None = None
    if tb is not None:
        found = check_rate(tb.rate_hz(), "the sample rate from the t column")
        notes += tb.notes(found)
    notes += list(last_notes)
    return _finish(req, acc, found, notes, str(path))


def noise_from_file(request: NoiseRequest) -> NoiseResult:
    """Noise figures of the recording ``request`` names (see the module docstring).

    Raises
    ------
    NotAtRestError
        When a sensor was not at rest (and ``request.force`` is False), naming the motion.
    CalibrationError
        For anything else that is wrong with the file or the request, saying what to do.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> import numpy as np
    >>> from triaxcal.sim import NoiseTruth, simulate_noise
    >>> gyro = simulate_noise(NoiseTruth(white=0.005), 30_000, 50.0, seed=1)   # deg/s
    >>> t = np.arange(len(gyro)) / 50.0
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "still.csv"
    >>> np.savetxt(p, np.column_stack([t, gyro]), delimiter=",", header="t,gx,gy,gz",
    ...            comments="")
    >>> res = noise_from_file(NoiseRequest(p, unit={"gyro": "deg/s"}))
    >>> res.rest["gyro"].at_rest, round(res.figures["gyro"].axes[0].white, 3)
    (True, 0.005)
    """
    if not isinstance(request, NoiseRequest):
        raise CalibrationError(f"request must be a NoiseRequest, got {type(request).__name__}")
    path = Path(request.path)
    if is_log(path) and path.exists():
        return _from_log(request, path)
    return _from_table(request, path)

