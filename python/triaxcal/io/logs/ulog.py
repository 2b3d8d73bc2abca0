"""PX4 ULog (``.ulg``) reader: framing and decoding in the Rust core, pyulog for rare layouts.

Two ways to read a log:

* default: ``sensor_combined`` (gyro in rad/s, accelerometer in m/s^2, and in older firmware
  the magnetometer in gauss) and, when ``sensor_combined`` has no magnetometer,
  ``vehicle_magnetometer`` (gauss). These are CALIBRATED and ROTATED to the body frame by
  PX4 with its ``CAL_*`` parameters (:mod:`triaxcal.io.logs.autopilot` gives the equation);
  ``undo=True`` turns them back into raw sensor-frame readings. No temperature.
* ``instance=N``: the per-sensor topics ``sensor_accel``, ``sensor_gyro``, ``sensor_mag``
  instance N (``x, y, z`` in m/s^2, rad/s, gauss, and ``temperature`` in deg C). From PX4
  v1.12 these are the RAW driver readings (calibration is applied later, in the ``sensors``
  module); in v1.11 accelerometer and gyroscope are raw but the magnetometer driver already
  applied its calibration; earlier drivers applied all of it.

Times are ``timestamp_sample`` (or ``timestamp`` plus the ``*_timestamp_relative`` offset of
``sensor_combined``), in s from the first sample read. Readings repeated by
``sensor_combined`` while a slower sensor had no new sample are dropped.

The file is framed and decoded by the Rust core (``rust/logs/ulog.rs``), in one pass with
memory bounded by the window it reads through; it makes of a damaged file exactly what pyulog
makes of it. A log with data appended at offsets (a rare layout) is read with ``pyulog``, the
optional ``logs`` extra.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np

from ..._core import read_ulog as _core_read_ulog
from ...errors import CalibrationError
from ..recording import LogRecording, Stream
from . import require
from .autopilot import AutopilotCalibration, AutopilotPart, px4_calibration, px4_index, px4_part

__all__ = ["read_ulog"]

_RELATIVE_INVALID = 2147483647  # sensor_combined: "no sample" marker of *_timestamp_relative
_TOPICS = ("sensor_combined", "vehicle_magnetometer", "sensor_selection", "sensor_accel",
           "sensor_gyro", "sensor_mag")


def _version(info: dict[str, Any]) -> tuple[int, int, int] | None:
    v = info.get("ver_sw_release")
    if not isinstance(v, (int, np.integer)) or int(v) <= 0:
        return None
    v = int(v)
    return (v >> 24) & 0xFF, (v >> 16) & 0xFF, (v >> 8) & 0xFF


def _vec(data: dict[str, np.ndarray], names: list[str]) -> np.ndarray:
    return np.column_stack([np.asarray(data[n], dtype=np.float64) for n in names])


def _dedupe(t_us: np.ndarray, data: np.ndarray, temp: np.ndarray | None = None
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Keep the first row of each distinct sample time, in time order."""
    order = np.argsort(t_us, kind="stable")
    t_us, data = t_us[order], data[order]
    keep = np.ones(len(t_us), bool)
    keep[1:] = np.diff(t_us) != 0
    if temp is not None:
        temp = temp[order][keep]
    return t_us[keep], data[keep], temp


@dataclasses.dataclass(frozen=True)
class _Parsed:
    """What the reader takes from a ULog (as pyulog names it)."""

    msg_info_dict: dict[str, Any]
    initial_parameters: dict[str, Any]
    changed_parameters: list[tuple[int, str, Any]]
    topics: dict[tuple[str, int], dict[str, np.ndarray]]


def _parse_core(p: Path) -> _Parsed | None:
    """The topics of :data:`_TOPICS`, framed and decoded by the Rust core; None for a log with
    appended data."""
    try:
        d = _core_read_ulog(str(p), list(_TOPICS))
    except CalibrationError as exc:
        raise CalibrationError(f"{p} is not a readable PX4 ULog file ({exc})") from None
    if d["appended"]:
        return None
    return _Parsed(d["info"], d["initial_parameters"], d["changed_parameters"],
                   {(name, multi_id): cols for name, multi_id, cols in d["datasets"]})


def _parse_pyulog(p: Path) -> _Parsed:
    """The same with pyulog (logs with appended data, and the reference in the tests)."""
    pyulog = require("pyulog", "PX4 ULog files with appended data")
    try:
        with open(p, "rb") as fh:
            ulog = pyulog.ULog(fh, list(_TOPICS))
    except Exception as exc:  # pyulog raises plain Exceptions on damaged files
        raise CalibrationError(
            f"{p} is not a readable PX4 ULog file ({type(exc).__name__}: {exc})"
        ) from None
    return _Parsed(ulog.msg_info_dict, ulog.initial_parameters, ulog.changed_parameters,
                   {(d.name, d.multi_id): d.data for d in ulog.data_list})


def read_ulog(path: str | Path, *, instance: int | None = None, topic: Any = None,
              undo: bool = False, engine: str = "core") -> LogRecording:
    """Read a PX4 ULog; see the module docstring. Used through :func:`triaxcal.read_log`.

    ``engine="pyulog"`` reads with pyulog instead of the Rust core (same result).
    """
    if engine not in ("core", "pyulog"):
        raise CalibrationError(f"engine must be 'core' or 'pyulog', got {engine!r}")
    if topic:
        raise CalibrationError(
            "--topic selects ROS bag topics; for a PX4 ULog choose a sensor with --instance N "
            "(the per-sensor topics sensor_accel/sensor_gyro/sensor_mag instance N)"
        )
    p = Path(path)
    if not p.is_file():
        raise CalibrationError(f"log file {p} not found")
    ulog = (_parse_core(p) if engine == "core" else None) or _parse_pyulog(p)
    params = {str(k): v for k, v in ulog.initial_parameters.items()}
    changed = sorted({name for _, name, _ in ulog.changed_parameters
                      if name.startswith(("CAL_", "SENS_BOARD", "TC_"))})
    topics = ulog.topics
    version = _version(ulog.msg_info_dict)
    meta: dict[str, Any] = {
        "firmware": ".".join(map(str, version)) if version else None,
        "hardware": ulog.msg_info_dict.get("ver_hw"),
        "calibration_params_changed": changed,
    }
    streams: dict[str, dict[str, Any]] = {}
    device_ids: dict[str, int | None] = {}
    if instance is None:
        sc = topics.get(("sensor_combined", 0))
        if sc is None:
            avail = sorted({f"{n}[{i}]" for n, i in topics})
            raise CalibrationError(
                f"{p} has no sensor_combined topic (it has: {', '.join(avail) or 'none'}); "
                "pass --instance N to read the per-sensor topics"
            )
        ts = np.asarray(sc["timestamp"], dtype=np.int64)
        for sensor, field, rel in (("gyro", "gyro_rad", None),
                                   ("accel", "accelerometer_m_s2",
                                    "accelerometer_timestamp_relative"),
                                   ("mag", "magnetometer_ga", "magnetometer_timestamp_relative")):
            names = [f"{field}[{i}]" for i in range(3)]
            if not all(n in sc for n in names):
                continue
            t_us = ts.copy()
            valid = np.ones(len(ts), bool)
            if rel is not None and rel in sc:
                r = np.asarray(sc[rel], dtype=np.int64)
                valid = r != _RELATIVE_INVALID
                t_us = ts + np.where(valid, r, 0)
            t_us, data, _ = _dedupe(t_us[valid], _vec(sc, names)[valid])
            streams[sensor] = {"t_us": t_us, "data": data, "temp": None,
                               "name": "sensor_combined", "calibrated": True}
        vm = topics.get(("vehicle_magnetometer", 0))
        if "mag" not in streams and vm is not None:
            names = [f"magnetometer_ga[{i}]" for i in range(3)]
            key = "timestamp_sample" if "timestamp_sample" in vm else "timestamp"
            t_us, data, _ = _dedupe(np.asarray(vm[key], dtype=np.int64), _vec(vm, names))
            streams["mag"] = {"t_us": t_us, "data": data, "temp": None,
                              "name": "vehicle_magnetometer", "calibrated": True}
        sel = topics.get(("sensor_selection", 0))
        if sel is not None:
            for sensor in ("accel", "gyro", "mag"):
                key = f"{sensor}_device_id"
                if key in sel and len(sel[key]):
                    device_ids[sensor] = int(sel[key][-1])
    else:
        if not isinstance(instance, (int, np.integer)) or instance < 0:
            raise CalibrationError(f"--instance must be a whole number >= 0, got {instance!r}")
        for sensor, name in (("accel", "sensor_accel"), ("gyro", "sensor_gyro"),
                             ("mag", "sensor_mag")):
            d = topics.get((name, int(instance)))
            if d is None:
                continue
            key = "timestamp_sample" if "timestamp_sample" in d else "timestamp"
            temp = np.asarray(d["temperature"], dtype=np.float64) if "temperature" in d else None
            if temp is not None and not np.isfinite(temp).any():
                temp = None
            t_us, data, temp = _dedupe(np.asarray(d[key], dtype=np.int64),
                                       _vec(d, ["x", "y", "z"]), temp)
            streams[sensor] = {"t_us": t_us, "data": data, "temp": temp,
                               "name": f"{name}[{int(instance)}]",
                               "calibrated": _per_sensor_calibrated(sensor, version)}
            if "device_id" in d and len(d["device_id"]):
                device_ids[sensor] = int(d["device_id"][0])
        if not streams:
            have = sorted({f"{n}[{i}]" for n, i in topics if n.startswith("sensor_")
                           and n != "sensor_combined" and n != "sensor_selection"})
            raise CalibrationError(
                f"{p} has no sensor_accel/sensor_gyro/sensor_mag instance {instance} "
                f"(per-sensor topics present: {', '.join(have) or 'none'})"
            )
    if not streams:
        raise CalibrationError(f"{p} holds no accelerometer, gyroscope or magnetometer samples")
    t0 = min(int(s["t_us"][0]) for s in streams.values() if len(s["t_us"]))
    out = {
        sensor: Stream(t=(s["t_us"] - t0) * 1e-6, data=s["data"],
                       unit={"accel": "m/s^2", "gyro": "rad/s", "mag": "gauss"}[sensor],
                       temp_c=s["temp"], name=s["name"], calibrated=s["calibrated"])
        for sensor, s in streams.items()
    }
    cal = _autopilot(params, device_ids, out, version, instance)
    meta.update({"instance": instance, "device_ids": device_ids,
                 "topics": {k: v.name for k, v in out.items()},
                 "time_origin_us": t0})  # the log time (us) that is 0 s in every stream
    return LogRecording(**out, source=str(p), format="px4-ulog", params=params, autopilot=cal,
                        meta=meta)


def _per_sensor_calibrated(sensor: str, version: tuple[int, int, int] | None) -> bool | None:
    if version is None:
        return None
    if version >= (1, 12, 0):
        return False
    if version >= (1, 11, 0):
        return sensor == "mag"
    return True


def _autopilot(params: dict[str, Any], device_ids: dict[str, int | None],
               streams: dict[str, Stream], version: tuple[int, int, int] | None,
               instance: int | None) -> AutopilotCalibration | None:
    parts: dict[str, AutopilotPart] = {}
    base = px4_calibration(params, device_ids)
    for sensor in streams:
        idx = px4_index(params, sensor, device_ids.get(sensor))
        part = base.part(sensor) if getattr(base, sensor) is not None else (
            px4_part(params, sensor, idx) if idx is not None else None)
        if part is None:
            continue
        s = streams[sensor]
        why = None
        if s.calibrated is None:
            why = ("this PX4 log does not say its firmware version, so whether the driver had "
                   f"already calibrated {s.name} is unknown")
        elif s.calibrated and instance is not None:
            why = (f"{s.name} was calibrated inside the driver by this PX4 version "
                   f"({'.'.join(map(str, version)) if version else 'unknown'}), whose order of "
                   "rotation and correction triaxcal does not reproduce; read a PX4 v1.12+ log")
        elif sensor == "mag" and version is not None and (1, 11, 0) <= version < (1, 12, 0):
            why = ("PX4 v1.11 calibrated the magnetometer inside its driver; triaxcal does not "
                   "reproduce that version's rotation order, so it cannot undo it exactly")
        if why and not part.not_undoable:
            part = dataclasses.replace(part, not_undoable=why)
        parts[sensor] = part
    if not parts:
        return None
    return AutopilotCalibration(autopilot="px4", **parts)
