"""Autopilot logs and ROS bags in: one reader module per format, one entry point.

:func:`read_log` dispatches on the file: ``.ulg`` (PX4 ULog, :mod:`.ulog`), ``.bin``
(ArduPilot DataFlash, :mod:`.dataflash`), ``.bag`` (ROS 1) and ``.db3`` / ``.mcap`` / a bag
folder with ``metadata.yaml`` (ROS 2, :mod:`.rosbag`). It returns a
:class:`~triaxcal.io.recording.LogRecording`: one :class:`~triaxcal.io.recording.Stream` per
sensor (time in s, readings with their unit, temperature in deg C when logged), the log's
parameters, and the calibration the autopilot had already applied
(:mod:`.autopilot`, with its equation), which ``undo_autopilot_cal=True`` removes.

ULog and DataFlash files are framed and decoded by the Rust core (``rust/logs/``), in one
streaming pass, with the same result as ``pyulog`` and ``pymavlink`` give; those two read the
rare layouts the core leaves to them (ULog data appended at offsets, DataFlash format
definitions damaged in ways only pymavlink's own reading reproduces), and ``rosbags`` reads
ROS bags. They are the optional ``logs`` extra (``pip install 'triaxcal[logs]'``); where one is
needed and missing a :class:`~triaxcal.CalibrationError` names the extra.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from ...errors import CalibrationError
from ..files import check_regular
from ..recording import LogRecording

__all__ = ["LOG_FORMATS", "LOG_SUFFIXES", "is_log", "log_format", "read_log", "require",
           "undo_autopilot_calibration"]

#: File suffix (lower case) -> log format.
LOG_SUFFIXES = {
    ".ulg": "px4-ulog",
    ".bin": "ardupilot-dataflash",
    ".bag": "ros1-bag",
    ".db3": "ros2-bag",
    ".mcap": "ros2-bag",
}
LOG_FORMATS = ("px4-ulog", "ardupilot-dataflash", "ros1-bag", "ros2-bag")


def require(module: str, what: str, *, package: str | None = None) -> ModuleType:
    """Import ``module`` or raise a CalibrationError naming the ``logs`` extra."""
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as exc:
        top = module.split(".")[0]
        missing = "" if exc.name in (None, top) else f" (its dependency {exc.name} is missing)"
        raise CalibrationError(
            f"reading {what} needs the optional package {package or top}{missing}: "
            "pip install 'triaxcal[logs]'"
        ) from None


def log_format(path: str | Path) -> str | None:
    """The log format of ``path`` by its suffix (or a ROS 2 bag folder), else None."""
    p = Path(path)
    if p.is_dir() and (p / "metadata.yaml").is_file():
        return "ros2-bag"
    return LOG_SUFFIXES.get(p.suffix.lower())


def is_log(path: str | Path) -> bool:
    """Whether :func:`read_log` (rather than the table reader) handles ``path``."""
    return log_format(path) is not None


def read_log(
    path: str | Path,
    *,
    instance: int | None = None,
    topic: Any = None,
    undo_autopilot_cal: bool = False,
    format: str | None = None,
) -> LogRecording:
    """Read the accelerometer, gyroscope and magnetometer streams of a log file.

    Parameters
    ----------
    path : str or Path
        ``.ulg``, ``.bin``, ``.bag``, ``.db3``, ``.mcap`` or a ROS 2 bag folder.
    instance : int, optional
        Which sensor of an autopilot log: PX4 reads the per-sensor topics ``sensor_accel`` /
        ``sensor_gyro`` / ``sensor_mag`` of that instance (default: ``sensor_combined`` and
        ``vehicle_magnetometer``); ArduPilot reads ``IMU``/``MAG`` (0), ``IMU2``/``MAG2`` (1)...
    topic : str or list of str, optional
        ROS bags: the ``sensor_msgs/Imu`` and/or ``sensor_msgs/MagneticField`` topic(s) to read
        when the bag has several.
    undo_autopilot_cal : bool
        Remove the calibration the autopilot applied (its equation and parameters are in
        ``rec.autopilot``), so that a fit sees the raw sensor. Streams that were logged raw
        are left as they are.
    format : str, optional
        Force a format (one of :data:`LOG_FORMATS`) instead of guessing from the suffix.

    Returns
    -------
    LogRecording
        ``rec.accel``, ``rec.gyro``, ``rec.mag`` (:class:`~triaxcal.io.recording.Stream`:
        ``t`` in s, ``data`` (N, 3) in ``unit``, ``temp_c``), ``rec.params``,
        ``rec.autopilot``.

    Examples
    --------
    >>> import triaxcal as tc
    >>> rec = tc.read_log("flight.ulg")                     # doctest: +SKIP
    >>> rec.mag.data.shape, rec.mag.unit, rec.mag.rate_hz   # doctest: +SKIP
    ((6759, 3), 'gauss', 99.6)
    >>> print(rec.autopilot.describe())                     # doctest: +SKIP
    """
    fmt = format or log_format(path)
    if fmt is None:
        raise CalibrationError(
            f"{path}: not a log triaxcal reads (by its name): use .ulg (PX4), .bin (ArduPilot), "
            ".bag (ROS 1), .db3/.mcap or a bag folder (ROS 2)"
        )
    if fmt not in LOG_FORMATS:
        raise CalibrationError(f"unknown log format {fmt!r}: use one of {LOG_FORMATS}")
    if not (fmt == "ros2-bag" and Path(path).is_dir()):
        check_regular(path, what="log file")  # a pipe, device or socket is refused unread
    reader: Callable[..., LogRecording]
    if fmt == "px4-ulog":
        from .ulog import read_ulog as reader
    elif fmt == "ardupilot-dataflash":
        from .dataflash import read_dataflash as reader
    else:
        from .rosbag import read_rosbag as reader
    rec = _clean(reader(path, instance=instance, topic=topic, undo=undo_autopilot_cal))
    if undo_autopilot_cal:
        rec = undo_autopilot_calibration(rec)
    return rec


def _clean(rec: LogRecording) -> LogRecording:
    """Drop rows with NaN/inf (some drivers publish NaN between samples) and note oddities.

    ``rec.meta["dropped_nonfinite"]`` counts dropped rows per sensor; ``rec.meta["warnings"]``
    says when a stream is empty after that, or when every vector has the same length (a
    driver that publishes only the direction: no calibration can be fitted to it).
    """
    changes: dict[str, Any] = {}
    dropped: dict[str, int] = {}
    warnings: list[str] = list(rec.meta.get("warnings", []))
    for sensor in rec.sensors:
        s = rec.stream(sensor)
        ok = np.isfinite(s.data).all(axis=1) & np.isfinite(s.t)
        if not ok.all():
            dropped[sensor] = int((~ok).sum())
            s = s.replace(t=s.t[ok], data=s.data[ok],
                          temp_c=None if s.temp_c is None else s.temp_c[ok])
            changes[sensor] = s
        if len(s) == 0:
            warnings.append(f"{s.name}: no finite {sensor} readings")
            changes[sensor] = None
            continue
        norms = np.linalg.norm(s.data, axis=1)
        mean = float(norms.mean())
        if len(s) >= 10 and mean > 0 and float(norms.std()) <= 1e-6 * mean:
            warnings.append(
                f"{s.name}: every {sensor} vector has the same length ({mean:.6g} {s.unit}): "
                "the driver published only the direction, so a calibration fit cannot recover "
                "offsets or gains from it"
            )
    if not changes and not warnings:
        return rec
    meta = dict(rec.meta)
    meta["dropped_nonfinite"] = dropped
    meta["warnings"] = warnings
    return rec.replace(**changes, meta=meta)


def undo_autopilot_calibration(rec: LogRecording) -> LogRecording:
    """``rec`` with the autopilot's calibration removed from every stream it had applied.

    Each undone stream is marked ``calibrated=False``; ``rec.meta["undone"]`` lists them. A
    stream whose calibration state is unknown, or whose calibration cannot be inverted exactly
    (see :attr:`AutopilotPart.not_undoable`), raises :class:`CalibrationError` saying why.
    """
    changes: dict[str, Any] = {}
    undone: list[str] = []
    for sensor in rec.sensors:
        s = rec.stream(sensor)
        if s.calibrated is False:
            continue
        if s.calibrated is None:
            raise CalibrationError(
                f"{rec.source}: whether {s.name} was calibrated is not recorded, so there is "
                "nothing triaxcal can undo for it; drop --undo-autopilot-cal"
            )
        if rec.autopilot is None or getattr(rec.autopilot, sensor) is None:
            raise CalibrationError(
                f"{rec.source}: {s.name} holds calibrated {sensor} readings but the log's "
                f"parameters do not say which calibration was applied; it cannot be undone"
            )
        part = rec.autopilot.part(sensor)
        if part.not_undoable:
            raise CalibrationError(f"{rec.source}: cannot undo the {sensor} calibration: "
                                   f"{part.not_undoable}")
        if rec.format == "ardupilot-dataflash" and sensor == "mag":
            from .dataflash import undo_mag

            raw = undo_mag(rec)
        else:
            raw = part.undo(s.data, temp_c=s.temp_c if part.thermal is not None else None)
        changes[sensor] = s.replace(data=raw, calibrated=False)
        undone.append(sensor)
    meta = dict(rec.meta)
    meta["undone"] = undone
    return rec.replace(**changes, meta=meta)
