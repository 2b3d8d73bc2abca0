"""ArduPilot DataFlash (``.bin``) reader, with ``pymavlink`` (the optional ``logs`` extra).

Messages: ``IMU`` (older logs: ``IMU2``, ``IMU3`` for the other IMUs; newer logs: one ``IMU``
message with an instance field ``I``) with ``GyrX/Y/Z`` (rad/s), ``AccX/Y/Z`` (m/s^2) and the
temperature ``T`` (older: ``Temp``) in deg C; ``MAG`` (``MAG2``, ``MAG3`` or field ``I``) with
``MagX/Y/Z`` (milligauss) and the offsets ``OfsX/Y/Z`` and motor offsets ``MOfsX/Y/Z`` the
autopilot applied; ``PARM`` records (``Name``, ``Value``: the parameters, last value wins).
Every ``IMU`` and ``MAG`` reading is CALIBRATED by ArduPilot (equations in
:mod:`triaxcal.io.logs.autopilot`); ``undo=True`` gives the raw readings back, using the
per-sample offsets the ``MAG`` message logged. A temperature column that is exactly zero
throughout (boards that do not report it) is dropped.
"""

from __future__ import annotations

import contextlib
import io
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import CalibrationError
from ..recording import LogRecording, Stream
from . import require
from .autopilot import ardupilot_calibration

__all__ = ["read_dataflash"]


_FIELDS = {
    "IMU": ("TimeUS", "AccX", "AccY", "AccZ", "GyrX", "GyrY", "GyrZ", "T", "Temp"),
    "MAG": ("TimeUS", "MagX", "MagY", "MagZ", "OfsX", "OfsY", "OfsZ", "MOfsX", "MOfsY", "MOfsZ"),
}


def _message_names(kind: str, instance: int) -> tuple[str, ...]:
    return (kind,) if instance == 0 else (kind, f"{kind}{instance + 1}")


def read_dataflash(path: str | Path, *, instance: int | None = None, topic: Any = None,
                   undo: bool = False) -> LogRecording:
    """Read an ArduPilot DataFlash log; see the module docstring."""
    dfreader = require("pymavlink.DFReader", "ArduPilot DataFlash logs", package="pymavlink")
    if topic:
        raise CalibrationError(
            "--topic selects ROS bag topics; for an ArduPilot log choose the IMU / compass "
            "with --instance N (0 = IMU and MAG, 1 = IMU2 and MAG2, ...)"
        )
    inst = 0 if instance is None else instance
    if not isinstance(inst, (int, np.integer)) or not 0 <= inst <= 2:
        raise CalibrationError(f"--instance must be 0, 1 or 2 for ArduPilot, got {instance!r}")
    p = Path(path)
    if not p.is_file():
        raise CalibrationError(f"log file {p} not found")
    with open(p, "rb") as fh:
        head = fh.read(2)
    if head != b"\xa3\x95":
        raise CalibrationError(
            f"{p} is not an ArduPilot DataFlash log: it does not start with the 0xA3 0x95 "
            "message header (an empty, text or damaged file?)"
        )
    wanted = sorted({*_message_names("IMU", inst), *_message_names("MAG", inst), "PARM", "MSG"})
    rows: dict[str, list[Any]] = {"IMU": [], "MAG": []}
    params: dict[str, float] = {}
    changed: set[str] = set()
    firmware = None
    log = None
    quiet = io.StringIO()  # pymavlink prints every damaged header it skips
    try:
        with contextlib.redirect_stdout(quiet):
            log = dfreader.DFReader_binary(str(p), zero_time_base=False)
        while True:
            with contextlib.redirect_stdout(quiet):
                msg = log.recv_match(type=wanted)
            if msg is None:
                break
            kind = msg.get_type()
            if kind == "PARM":
                name, value = str(msg.Name), float(msg.Value)
                if name in params and params[name] != value and name.startswith(
                        ("INS_", "COMPASS_", "AHRS_ORIENT")):
                    changed.add(name)
                params[name] = value
                continue
            if kind == "MSG":
                text = str(getattr(msg, "Message", ""))
                if firmware is None and ("Copter" in text or "Plane" in text or "Rover" in text
                                         or "Sub" in text or "ArduPilot" in text):
                    firmware = text
                continue
            base = kind[:3]
            names = msg.get_fieldnames()
            if "I" in names:  # newer logs: one message type, instance in field I
                if int(msg.I) != inst:
                    continue
            elif kind != (base if inst == 0 else f"{base}{inst + 1}"):
                continue
            rows[base].append({f: getattr(msg, f) for f in _FIELDS[base] if f in names})
    except CalibrationError:
        raise
    except Exception as exc:  # pymavlink raises assorted errors on damaged files
        raise CalibrationError(
            f"{p} is not a readable ArduPilot DataFlash log ({type(exc).__name__}: {exc})"
        ) from None
    finally:
        if log is not None:
            log.close()
    skipped = quiet.getvalue().count("bad header")
    if not rows["IMU"] and not rows["MAG"]:
        raise CalibrationError(
            f"{p} has no IMU or MAG messages for instance {inst} (is it a DataFlash .bin log "
            "with INS and compass logging enabled?)"
        )
    streams: dict[str, Stream] = {}
    t_all = [np.array([r["TimeUS"] for r in rows[k]], dtype=np.int64) for k in ("IMU", "MAG")
             if rows[k]]
    t0 = min(int(t.min()) for t in t_all)
    imu_name = "IMU" if inst == 0 else f"IMU{inst + 1}"
    if rows["IMU"]:
        r = rows["IMU"]
        t = (np.array([x["TimeUS"] for x in r], dtype=np.int64) - t0) * 1e-6
        tkey = "T" if "T" in r[0] else "Temp" if "Temp" in r[0] else None
        temp = np.array([x[tkey] for x in r], dtype=np.float64) if tkey else None
        if temp is not None and not np.any(temp != 0):
            temp = None
        order = np.argsort(t, kind="stable")
        for sensor, keys in (("accel", ("AccX", "AccY", "AccZ")),
                             ("gyro", ("GyrX", "GyrY", "GyrZ"))):
            data = np.array([[x[k] for k in keys] for x in r], dtype=np.float64)
            streams[sensor] = Stream(t=t[order], data=data[order],
                                     unit="m/s^2" if sensor == "accel" else "rad/s",
                                     temp_c=None if temp is None else temp[order],
                                     name=imu_name, calibrated=True)
    mag_offsets = None
    mag_motor = None
    if rows["MAG"]:
        r = rows["MAG"]
        t = (np.array([x["TimeUS"] for x in r], dtype=np.int64) - t0) * 1e-6
        order = np.argsort(t, kind="stable")
        data = np.array([[x["MagX"], x["MagY"], x["MagZ"]] for x in r], dtype=np.float64)
        streams["mag"] = Stream(t=t[order], data=data[order], unit="mG",
                                name="MAG" if inst == 0 else f"MAG{inst + 1}", calibrated=True)
        if "OfsX" in r[0]:
            mag_offsets = np.array([[x["OfsX"], x["OfsY"], x["OfsZ"]] for x in r],
                                   dtype=np.float64)[order]
        if "MOfsX" in r[0]:
            mag_motor = np.array([[x["MOfsX"], x["MOfsY"], x["MOfsZ"]] for x in r],
                                 dtype=np.float64)[order]
    cal = ardupilot_calibration(params, imu=inst, compass=inst) if params else None
    meta: dict[str, Any] = {
        "instance": inst,
        "firmware": firmware,
        "calibration_params_changed": sorted(changed),
        "messages": {k: v.name for k, v in streams.items()},
        "mag_offsets_logged": mag_offsets,
        "mag_motor_offsets_logged": mag_motor,
        "damaged_headers_skipped": skipped,
        "time_origin_us": t0,  # the log time (TimeUS) that is 0 s in every stream
    }
    return LogRecording(**streams, source=str(p), format="ardupilot-dataflash", params=params,
                        autopilot=cal if cal is not None and cal.sensors else None, meta=meta)


def undo_mag(rec: LogRecording) -> np.ndarray:
    """Raw compass readings (mG, body frame) from the logged ``MAG`` readings.

    ``raw = inv(M) @ (mag / COMPASS_SCALE) - Ofs`` with the offsets logged in each ``MAG``
    message (they follow in-flight offset learning); refuses when motor compensation was
    active, because its place in the equation changed between firmware versions.
    """
    assert rec.autopilot is not None and rec.mag is not None
    part = rec.autopilot.part("mag")
    motor = rec.meta.get("mag_motor_offsets_logged")
    if motor is not None and np.any(motor != 0):
        raise CalibrationError(
            "this log's compass readings include motor-interference compensation (MAG.MOfs is "
            "not zero), which ArduPilot applied before the soft-iron matrix in older firmware "
            "and after it in newer: triaxcal will not guess; record with COMPASS_MOTCT = 0"
        )
    ofs = rec.meta.get("mag_offsets_logged")
    d = rec.mag.data @ np.linalg.inv(part.matrix).T / part.scale_factor
    return d - (part.offset if ofs is None else ofs)
