"""ArduPilot DataFlash (``.bin``) reader: FMT-driven decoding in the Rust core, pymavlink for rare
damage.

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
import dataclasses
import gc
import io
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from ..._core import read_dataflash as _core_read_dataflash
from ...errors import CalibrationError
from ..recording import LogRecording, Stream
from . import require
from .autopilot import ardupilot_calibration

__all__ = ["read_dataflash"]


_FIELDS = {
    "IMU": ("TimeUS", "AccX", "AccY", "AccZ", "GyrX", "GyrY", "GyrZ", "T", "Temp"),
    "MAG": ("TimeUS", "MagX", "MagY", "MagZ", "OfsX", "OfsY", "OfsZ", "MOfsX", "MOfsY", "MOfsZ"),
}

# the fields a reading cannot do without
_NEEDED = {"IMU": _FIELDS["IMU"][:7], "MAG": _FIELDS["MAG"][:4]}


def _message_names(kind: str, instance: int) -> tuple[str, ...]:
    return (kind,) if instance == 0 else (kind, f"{kind}{instance + 1}")


@dataclasses.dataclass
class _Parsed:
    """What the reader takes from a DataFlash log: per sensor family (``IMU``, ``MAG``) the
    fields of ``_FIELDS`` the messages have, in file order, as arrays (``TimeUS`` as int64,
    the rest float64), or None; the parameters; the parameter names whose value changed; the
    firmware text; the bytes skipped at damaged headers."""

    rows: dict[str, dict[str, np.ndarray] | None]
    params: dict[str, float]
    changed: set[str]
    firmware: str | None
    skipped: int


def _time_us(values: Any, p: Path) -> np.ndarray:
    t = np.asarray(values)
    if t.dtype == np.uint64 and t.size and int(t.max()) > np.iinfo(np.int64).max:
        raise CalibrationError(
            f"{p} has a TimeUS beyond 2^63 us (a damaged message): cut the log before the "
            "damage or read another one"
        )
    return t.astype(np.int64)


def _params_of(names: list[str], values: np.ndarray) -> tuple[dict[str, float], set[str]]:
    params: dict[str, float] = {}
    changed: set[str] = set()
    for name, value in zip(names, values.tolist()):
        if name in params and params[name] != value and name.startswith(
                ("INS_", "COMPASS_", "AHRS_ORIENT")):
            changed.add(name)
        params[name] = value
    return params, changed


def _firmware(texts: list[str]) -> str | None:
    for text in texts:
        if ("Copter" in text or "Plane" in text or "Rover" in text or "Sub" in text
                or "ArduPilot" in text):
            return text
    return None


def _parse_core(p: Path, wanted: list[str], inst: int) -> _Parsed | None:
    """The messages decoded by the Rust core; None when its format definitions are damaged
    in a way only pymavlink's own reading reproduces."""
    try:
        d = _core_read_dataflash(str(p), wanted)
    except CalibrationError as exc:
        raise CalibrationError(f"{p} is not a readable ArduPilot DataFlash log ({exc})") from None
    if d["fallback"] is not None:
        return None
    msgs = d["messages"]
    params: dict[str, float] = {}
    changed: set[str] = set()
    if "PARM" in msgs:
        c = msgs["PARM"]["columns"]
        if not isinstance(c.get("Name"), list) or not isinstance(c.get("Value"), np.ndarray):
            return None
        params, changed = _params_of(c["Name"], c["Value"].astype(np.float64))
    firmware = None
    if "MSG" in msgs:
        text = msgs["MSG"]["columns"].get("Message")
        if not isinstance(text, list):
            return None
        firmware = _firmware(text)
    rows: dict[str, dict[str, np.ndarray] | None] = {}
    for base in ("IMU", "MAG"):
        parts = []
        for kind in _message_names(base, inst):
            if kind not in msgs:
                continue
            cols, seq = msgs[kind]["columns"], msgs[kind]["seq"]
            if "I" in cols:  # newer logs: one message type, instance in field I
                if cols["I"].dtype.kind not in "iu":
                    return None
                keep = cols["I"] == inst
            elif kind == (base if inst == 0 else f"{base}{inst + 1}"):
                keep = np.ones(len(seq), bool)
            else:
                continue
            if keep.any():
                present = {f: cols[f] for f in _FIELDS[base] if f in cols}
                if any(isinstance(v, list) for v in present.values()):
                    return None
                parts.append((seq[keep], {f: v[keep] for f, v in present.items()}))
        if not parts:
            rows[base] = None
            continue
        if len({tuple(f) for _, f in parts}) > 1:
            return None  # two message types with different fields: pymavlink's order decides
        seq = np.concatenate([q for q, _ in parts])
        order = np.argsort(seq, kind="stable")
        merged = {f: np.concatenate([c[f] for _, c in parts])[order] for f in parts[0][1]}
        rows[base] = {f: _time_us(v, p) if f == "TimeUS" else v.astype(np.float64)
                      for f, v in merged.items()}
    return _Parsed(rows, params, changed, firmware, int(d["bad_headers"]))


def _parse_pymavlink(p: Path, wanted: list[str], inst: int) -> _Parsed:
    """The same with pymavlink (logs with damaged format definitions, and the reference in
    the tests)."""
    dfreader = require("pymavlink.DFReader", "ArduPilot DataFlash logs with damaged formats",
                       package="pymavlink")
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
                if firmware is None:
                    firmware = _firmware([str(getattr(msg, "Message", ""))])
                continue
            base = kind[:3]
            names = msg.get_fieldnames()
            if "I" in names:  # newer logs: one message type, instance in field I
                if int(msg.I) != inst:
                    continue
            elif kind != (base if inst == 0 else f"{base}{inst + 1}"):
                continue
            rows[base].append({f: getattr(msg, f) for f in _FIELDS[base] if f in names})
        arrays: dict[str, dict[str, np.ndarray] | None] = {}
        for base, r in rows.items():
            arrays[base] = None if not r else {
                f: np.array([x[f] for x in r], dtype=np.int64 if f == "TimeUS" else np.float64)
                for f in r[0]
            }
    except CalibrationError:
        raise
    except Exception as exc:  # pymavlink raises assorted errors on damaged files
        why = f"{p} is not a readable ArduPilot DataFlash log ({type(exc).__name__}: {exc})"
        failed = True
    else:
        failed = False
    finally:
        if log is not None:
            with contextlib.suppress(Exception):
                log.close()
    if failed:
        # a reader that failed while opening holds its file and memory map in the frames of
        # the traceback, which are gone now: close them without a warning
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ResourceWarning)
            gc.collect()
        raise CalibrationError(why)
    return _Parsed(arrays, params, changed, firmware, quiet.getvalue().count("bad header"))


def read_dataflash(path: str | Path, *, instance: int | None = None, topic: Any = None,
                   undo: bool = False, engine: str = "core") -> LogRecording:
    """Read an ArduPilot DataFlash log; see the module docstring.

    ``engine="pymavlink"`` reads with pymavlink instead of the Rust core (the same result,
    but for ``meta["damaged_headers_skipped"]``, which pymavlink reports only on the
    terminal).
    """
    if engine not in ("core", "pymavlink"):
        raise CalibrationError(f"engine must be 'core' or 'pymavlink', got {engine!r}")
    if topic:
        raise CalibrationError(
            "--topic selects ROS bag topics; for an ArduPilot log choose the IMU / compass "
            "with --instance N (0 = IMU and MAG, 1 = IMU2 and MAG2, ...)"
        )
    inst = 0 if instance is None else instance
    if not isinstance(inst, (int, np.integer)) or not 0 <= inst <= 2:
        raise CalibrationError(f"--instance must be 0, 1 or 2 for ArduPilot, got {instance!r}")
    inst = int(inst)
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
    parsed = (_parse_core(p, wanted, inst) if engine == "core" else None) or _parse_pymavlink(
        p, wanted, inst)
    imu, mag = parsed.rows["IMU"], parsed.rows["MAG"]
    for base, got in (("IMU", imu), ("MAG", mag)):
        missing = [f for f in _NEEDED[base] if got is not None and f not in got]
        if missing:
            raise CalibrationError(
                f"{p}: the {base} messages have no field {', '.join(missing)} (their format "
                "definition (FMT) is damaged or of a layout this reader does not know): read "
                "another log, or choose another sensor with --instance N"
            )
    if imu is None and mag is None:
        raise CalibrationError(
            f"{p} has no IMU or MAG messages for instance {inst} (is it a DataFlash .bin log "
            "with INS and compass logging enabled?)"
        )
    streams: dict[str, Stream] = {}
    t0 = min(int(r["TimeUS"].min()) for r in (imu, mag) if r is not None)
    imu_name = "IMU" if inst == 0 else f"IMU{inst + 1}"
    if imu is not None:
        t = (imu["TimeUS"] - t0) * 1e-6
        tkey = "T" if "T" in imu else "Temp" if "Temp" in imu else None
        temp = imu[tkey] if tkey else None
        if temp is not None and not np.any(temp != 0):
            temp = None
        order = np.argsort(t, kind="stable")
        for sensor, keys in (("accel", ("AccX", "AccY", "AccZ")),
                             ("gyro", ("GyrX", "GyrY", "GyrZ"))):
            data = np.column_stack([imu[k] for k in keys])
            streams[sensor] = Stream(t=t[order], data=data[order],
                                     unit="m/s^2" if sensor == "accel" else "rad/s",
                                     temp_c=None if temp is None else temp[order],
                                     name=imu_name, calibrated=True)
    mag_offsets = None
    mag_motor = None
    if mag is not None:
        t = (mag["TimeUS"] - t0) * 1e-6
        order = np.argsort(t, kind="stable")
        data = np.column_stack([mag["MagX"], mag["MagY"], mag["MagZ"]])
        streams["mag"] = Stream(t=t[order], data=data[order], unit="mG",
                                name="MAG" if inst == 0 else f"MAG{inst + 1}", calibrated=True)
        if "OfsX" in mag:
            mag_offsets = np.column_stack([mag["OfsX"], mag["OfsY"], mag["OfsZ"]])[order]
        if "MOfsX" in mag:
            mag_motor = np.column_stack([mag["MOfsX"], mag["MOfsY"], mag["MOfsZ"]])[order]
    params = parsed.params
    cal = ardupilot_calibration(params, imu=inst, compass=inst) if params else None
    meta: dict[str, Any] = {
        "instance": inst,
        "firmware": parsed.firmware,
        "calibration_params_changed": sorted(parsed.changed),
        "messages": {k: v.name for k, v in streams.items()},
        "mag_offsets_logged": mag_offsets,
        "mag_motor_offsets_logged": mag_motor,
        "damaged_headers_skipped": parsed.skipped,
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
