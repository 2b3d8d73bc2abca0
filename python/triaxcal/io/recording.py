"""Recordings read from files: one :class:`Stream` per sensor, gathered in a :class:`LogRecording`.

A log rarely samples its sensors together: an ArduPilot ``.bin`` logs ``IMU`` at ~20 Hz and
``MAG`` at ~10 Hz, a ROS bag stamps ``Imu`` and ``MagneticField`` messages separately, a PX4
ULog has one topic per sensor instance. So each sensor keeps its own time base:

* :class:`Stream` -- ``t`` (s, from the first sample of the whole recording), ``data`` (N, 3)
  in ``unit``, the sensor's temperature ``temp_c`` (deg C) when the log has it, where it came
  from (``name``: topic or message) and whether the autopilot had already applied its own
  calibration to it (``calibrated``);
* :class:`LogRecording` -- the ``accel``, ``gyro`` and ``mag`` streams present, the log's
  parameters and the calibration the autopilot applied (:mod:`triaxcal.io.logs.autopilot`).

The simulator's :class:`triaxcal.sim.Recording` samples every sensor at once on one time base;
:meth:`LogRecording.from_sim` turns it into the same form, so code written for logs takes
simulated data too.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import CalibrationError

if TYPE_CHECKING:  # pragma: no cover
    from .logs.autopilot import AutopilotCalibration

__all__ = ["SENSOR_NAMES", "LogRecording", "Stream"]

SENSOR_NAMES = ("accel", "gyro", "mag")


def _frozen(a: Any, shape_tail: tuple[int, ...], what: str) -> np.ndarray:
    try:
        arr = np.asarray(a) if not isinstance(a, (str, bytes, dict)) else None
    except (TypeError, ValueError):  # ragged lists
        arr = None
    if arr is None or arr.dtype.kind not in "iuf":
        raise CalibrationError(f"{what} must hold real numbers, got {str(a)[:60]!r}")
    arr = np.ascontiguousarray(arr, dtype=np.float64)
    if arr.ndim != 1 + len(shape_tail) or arr.shape[1:] != shape_tail:
        want = "(N)" if not shape_tail else f"(N, {', '.join(map(str, shape_tail))})"
        raise CalibrationError(f"{what} must have shape {want}, got {arr.shape}")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class Stream:
    """Readings of one three-axis sensor.

    Attributes
    ----------
    t : ndarray (N,)
        Sample time in seconds from the start of the recording (increasing).
    data : ndarray (N, 3)
        Readings in ``unit``.
    unit : str
        ``"m/s^2"``, ``"rad/s"``, ``"gauss"``, ``"mG"``, ``"uT"``, ``"counts"``...
    temp_c : ndarray (N,), optional
        Sensor temperature in deg C at each sample, when the log has it.
    name : str
        Where the readings came from (``"sensor_combined"``, ``"IMU"``, ``"/imu/mag"``...).
    calibrated : bool or None
        True when the autopilot had already applied its own calibration (see
        :attr:`LogRecording.autopilot`), False for raw sensor readings, None when unknown
        (ROS bags, tables).
    """

    t: np.ndarray
    data: np.ndarray
    unit: str
    temp_c: np.ndarray | None = None
    name: str = ""
    calibrated: bool | None = None

    def __post_init__(self) -> None:
        t = _frozen(self.t, (), "t")
        d = _frozen(self.data, (3,), "data")
        if len(t) != len(d):
            raise CalibrationError(f"t has {len(t)} samples but data has {len(d)}")
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "data", d)
        if self.temp_c is not None:
            tc = _frozen(self.temp_c, (), "temp_c")
            if len(tc) != len(t):
                raise CalibrationError(f"temp_c has {len(tc)} samples, t has {len(t)}")
            object.__setattr__(self, "temp_c", tc)
        if not isinstance(self.unit, str) or not self.unit:
            raise CalibrationError("unit must name the unit of the readings, e.g. 'm/s^2'")

    def __len__(self) -> int:
        return len(self.t)

    @property
    def rate_hz(self) -> float:
        """Median sample rate in Hz (NaN with fewer than two samples)."""
        if len(self.t) < 2:
            return float("nan")
        dt = np.diff(self.t)
        dt = dt[dt > 0]
        return float(1.0 / np.median(dt)) if dt.size else float("nan")

    @property
    def mean_rate_hz(self) -> float:
        """Samples per second over the whole stream, ``(N - 1) / duration`` (NaN if < 2)."""
        d = self.duration_s
        return float((len(self.t) - 1) / d) if len(self.t) > 1 and d > 0 else float("nan")

    @property
    def duration_s(self) -> float:
        """Time from the first to the last sample, s."""
        return float(self.t[-1] - self.t[0]) if len(self.t) else 0.0

    def replace(self, **changes: Any) -> Stream:
        """A copy with some fields changed."""
        d = {k: getattr(self, k) for k in ("t", "data", "unit", "temp_c", "name", "calibrated")}
        d.update(changes)
        return Stream(**d)

    def __repr__(self) -> str:
        temp = ", temp_c" if self.temp_c is not None else ""
        cal = {True: ", calibrated by the autopilot", False: ", raw", None: ""}[self.calibrated]
        return (f"Stream({self.name!r}: {len(self)} samples of {self.unit}, "
                f"{self.rate_hz:.4g} Hz, {self.duration_s:.4g} s{temp}{cal})")


@dataclass(frozen=True, eq=False)
class LogRecording:
    """The sensor streams of one log file, with its parameters.

    Attributes
    ----------
    accel, gyro, mag : Stream, optional
        The streams present (accelerometer, gyroscope, magnetometer).
    source : str
        The file read.
    format : str
        ``"px4-ulog"``, ``"ardupilot-dataflash"``, ``"ros1-bag"``, ``"ros2-bag"`` or ``"sim"``.
    params : dict
        The log's parameters by name (autopilot logs; empty otherwise).
    autopilot : AutopilotCalibration, optional
        The calibration the autopilot applied to the streams marked ``calibrated``, read from
        ``params``, with its equation (:mod:`triaxcal.io.logs.autopilot`).
    meta : dict
        What was read: topics / messages, instance, device ids, firmware, undo applied...
    """

    accel: Stream | None = None
    gyro: Stream | None = None
    mag: Stream | None = None
    source: str = ""
    format: str = ""
    params: Mapping[str, float] = field(default_factory=dict)
    autopilot: AutopilotCalibration | None = None
    meta: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name in SENSOR_NAMES:
            s = getattr(self, name)
            if s is not None and not isinstance(s, Stream):
                raise CalibrationError(f"{name} must be a Stream or None")

    @property
    def sensors(self) -> tuple[str, ...]:
        """Names of the streams present, in the order accel, gyro, mag."""
        return tuple(s for s in SENSOR_NAMES if getattr(self, s) is not None)

    def stream(self, sensor: str) -> Stream:
        """The stream of ``sensor``; a clear error if the log has none."""
        if sensor not in SENSOR_NAMES:
            raise CalibrationError(f"unknown sensor {sensor!r}: use one of {SENSOR_NAMES}")
        s = getattr(self, sensor)
        if s is None:
            have = ", ".join(self.sensors) or "none"
            raise CalibrationError(
                f"{self.source or 'this recording'} has no {sensor} readings (it has: {have})"
            )
        return s

    def replace(self, **changes: Any) -> LogRecording:
        """A copy with some fields changed (``rec.replace(mag=None)``)."""
        d = {k: getattr(self, k) for k in (*SENSOR_NAMES, "source", "format", "params",
                                            "autopilot", "meta")}
        d.update(changes)
        return LogRecording(**d)

    def synchronized(self, sensors: tuple[str, ...] = ("accel", "mag"), *,
                     max_gap_s: float | None = None) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Readings of several sensors on one time base, by linear interpolation.

        The time base is that of the slowest stream (fewest samples) within the span all
        streams cover; other streams are interpolated onto it. Samples farther than
        ``max_gap_s`` (default: two sample periods of the fastest interpolated stream) from
        both neighbouring samples of a stream are dropped rather than invented.

        Returns
        -------
        t : ndarray (M,)
        data : dict of ndarray (M, 3), by sensor
        """
        streams = [self.stream(s) for s in sensors]
        base = min(streams, key=len)
        lo = max(s.t[0] for s in streams)
        hi = min(s.t[-1] for s in streams)
        t = base.t[(base.t >= lo) & (base.t <= hi)]
        keep = np.ones(len(t), bool)
        out: dict[str, np.ndarray] = {}
        for name, s in zip(sensors, streams):
            if s is base:
                out[name] = base.data[(base.t >= lo) & (base.t <= hi)]
                continue
            gap = max_gap_s if max_gap_s is not None else 2.0 / s.rate_hz
            j = np.clip(np.searchsorted(s.t, t), 1, len(s.t) - 1)
            near = np.minimum(np.abs(t - s.t[j - 1]), np.abs(s.t[j] - t))
            keep &= near <= gap
            out[name] = np.column_stack([np.interp(t, s.t, s.data[:, k]) for k in range(3)])
        return t[keep], {k: v[keep] for k, v in out.items()}

    @classmethod
    def from_sim(cls, rec: Any) -> LogRecording:
        """The simulator's :class:`triaxcal.sim.Recording` as a LogRecording (raw counts).

        Examples
        --------
        >>> from triaxcal.sim import SimIMU, six_face_script
        >>> from triaxcal.io.recording import LogRecording
        >>> sim = SimIMU(seed=1).record(six_face_script(hold_s=1.0), rate_hz=50)
        >>> log = LogRecording.from_sim(sim)
        >>> log.sensors, log.mag.unit, round(log.accel.rate_hz)
        (('accel', 'gyro', 'mag'), 'counts', 50)
        """
        kw: dict[str, Any] = {name: Stream(t=rec.t, data=getattr(rec, name), unit="counts",
                           temp_c=rec.temp_c, name=f"sim.{name}", calibrated=False)
              for name in SENSOR_NAMES}
        return cls(**kw, source="sim", format="sim",
                   meta={"rate_hz": float(rec.rate_hz)})

    def summary(self) -> str:
        """One line per stream: name, samples, rate, duration, unit, temperature."""
        lines = [f"{self.source} ({self.format})"]
        for name in self.sensors:
            s = self.stream(name)
            temp = ""
            if s.temp_c is not None and len(s):
                temp = f", {np.min(s.temp_c):.1f}..{np.max(s.temp_c):.1f} degC"
            state = {True: "calibrated by the autopilot", False: "raw", None: "as logged"}[
                s.calibrated]
            lines.append(f"  {name:5s} {s.name}: {len(s)} samples, {s.rate_hz:.4g} Hz (median; "
                         f"mean {s.mean_rate_hz:.4g} Hz), {s.duration_s:.4g} s, {s.unit}{temp} "
                         f"({state})")
        for w in self.meta.get("warnings", []):
            lines.append(f"  warning: {w}")
        return "\n".join(lines)
