"""A simulated flight with known compass errors, written as a real ArduPilot DataFlash log.

The vehicle turns through several full circles while rolling and pitching, its battery current
and throttle rise and fall on their own rhythm, and its compass reads the Earth's field through
known hard iron, soft iron and current interference, in ArduPilot's convention
(``AP_Compass_Backend::correct_field``)::

    field = M @ (raw + COMPASS_OFS) + COMPASS_MOT * current       (mG, body frame)

so the raw reading is ``inv(M) @ (R.T @ B - COMPASS_MOT * current) - COMPASS_OFS`` plus noise.
The log holds what ArduPilot logs with no calibration stored (``COMPASS_OFS`` = 0, ``DIA`` = 1,
``COMPASS_MOTCT`` = 0): ``MAG`` (the raw readings), ``ATT`` (the true attitude, as from an
independent yaw source), ``CURR``, ``CTUN`` (throttle), ``GPS`` and ``PARM`` records, each type
described by its ``FMT`` record, which pymavlink and triaxcal read.

The DataFlash format (ArduPilot ``libraries/AP_Logger/LogStructure.h``): every record is
``0xA3 0x95 <type>`` then the fields packed little-endian as the type's ``FMT`` record says
(``Q`` uint64, ``f`` float32, ``B`` uint8, ``i`` int32 (GPS degrees * 1e7), ``N`` char[16],
``n`` char[4], ``Z`` char[64]); ``FMT`` itself is type 128.
"""

from __future__ import annotations

import json
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .._checks.options import seed as seed_of
from ..errors import CalibrationError
from ..io.files import write_file

__all__ = ["FlightTruth", "simulate_flight", "write_flight"]

_HEAD = b"\xa3\x95"
_TYPES = {  # name: (id, format, columns)
    "FMT": (128, "BBnNZ", "Type,Length,Name,Format,Columns"),
    "PARM": (129, "QNf", "TimeUS,Name,Value"),
    "ATT": (130, "Qfff", "TimeUS,Roll,Pitch,Yaw"),
    "MAG": (131, "Qfffffffff", "TimeUS,MagX,MagY,MagZ,OfsX,OfsY,OfsZ,MOfsX,MOfsY,MOfsZ"),
    "CURR": (132, "Qff", "TimeUS,Volt,Curr"),
    "CTUN": (133, "Qf", "TimeUS,ThO"),
    "GPS": (134, "QBiif", "TimeUS,Status,Lat,Lng,Alt"),
}
_STRUCT = {"Q": "Q", "f": "f", "B": "B", "i": "i", "N": "16s", "n": "4s", "Z": "64s"}


def _packer(fmt: str) -> struct.Struct:
    return struct.Struct("<" + "".join(_STRUCT[c] for c in fmt))


@dataclass(frozen=True)
class FlightTruth:
    """What the simulated compass really has, in ArduPilot's convention (mG, body frame)."""

    compass_ofs: np.ndarray      # COMPASS_OFS (ADDED to raw)
    matrix: np.ndarray           # DIA / ODI (symmetric)
    compass_mot: np.ndarray      # COMPASS_MOT, mG per A (ADDED after the matrix)
    field_ned: np.ndarray        # mG
    location: tuple[float, float, float]

    def to_dict(self) -> dict[str, Any]:
        m = self.matrix
        return {
            "convention": "ArduPilot AP_Compass_Backend::correct_field: field = M @ (raw + "
                          "COMPASS_OFS) + COMPASS_MOT * current (mG, body frame)",
            "COMPASS_OFS": [float(v) for v in self.compass_ofs],
            "COMPASS_DIA": [float(m[i, i]) for i in range(3)],
            "COMPASS_ODI": [float(m[0, 1]), float(m[0, 2]), float(m[1, 2])],
            "COMPASS_MOT": [float(v) for v in self.compass_mot],
            "COMPASS_MOT_unit": "mG per A",
            "field_mG": [float(v) for v in self.field_ned],
            "field_frame": "north, east, down",
            "location": list(self.location),
        }


def simulate_flight(field_ned_mg: Any, *, duration_s: float = 600.0, rate_hz: float = 10.0,
                    seed: int = 7, location: tuple[float, float, float] = (47.37, 8.54, 400.0),
                    noise_mg: float = 2.0, attitude_noise_deg: float = 0.3
                    ) -> tuple[dict[str, np.ndarray], FlightTruth]:
    """The samples of a simulated flight (time in s, attitude in deg, current in A, throttle
    0..1, raw compass in mG) and the truth."""
    b = np.asarray(field_ned_mg, dtype=float).ravel()
    if b.shape != (3,) or not np.isfinite(b).all() or not 100 <= np.linalg.norm(b) <= 1000:
        raise CalibrationError("the simulated field must be (north, east, down) in mG, "
                               "100..1000 mG strong")
    if not (10 <= duration_s <= 36000 and 1 <= rate_hz <= 100):
        raise CalibrationError("duration 10..36000 s and rate 1..100 Hz")
    rng = np.random.default_rng(seed_of(seed))
    t = np.arange(0.0, duration_s, 1.0 / rate_hz)
    yaw = (360.0 * t / 45.0 + 40.0 * np.sin(2 * np.pi * t / 97.0)) % 360.0
    roll = 25.0 * np.sin(2 * np.pi * t / 13.0) + 8.0 * np.sin(2 * np.pi * t / 5.3)
    pitch = 20.0 * np.sin(2 * np.pi * t / 17.0 + 1.0) + 6.0 * np.sin(2 * np.pi * t / 7.1)
    throttle = np.clip(0.45 + 0.3 * np.sin(2 * np.pi * t / 23.0) + 0.1 * np.sin(
        2 * np.pi * t / 3.7), 0.05, 1.0)
    current = 2.0 + 40.0 * throttle ** 1.5
    truth = FlightTruth(compass_ofs=np.array([-120.0, 85.0, -60.0]),
                        matrix=np.array([[1.04, 0.02, -0.015], [0.02, 0.97, 0.01],
                                         [-0.015, 0.01, 1.01]]),
                        compass_mot=np.array([3.5, -2.0, 5.0]), field_ned=b, location=location)
    dcm = _dcm(roll, pitch, yaw)
    body = np.einsum("nji,j->ni", dcm, b) - current[:, None] * truth.compass_mot
    raw = body @ np.linalg.inv(truth.matrix).T - truth.compass_ofs
    raw = raw + rng.normal(0.0, noise_mg, raw.shape)
    logged_att = np.column_stack([roll, pitch, yaw]) + rng.normal(0.0, attitude_noise_deg,
                                                                  (len(t), 3))
    logged_att[:, 2] %= 360.0
    return {"t": t, "attitude": logged_att, "current": current, "throttle": throttle,
            "mag": raw}, truth


def _dcm(roll: np.ndarray, pitch: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """Body-to-NED ``Rz(yaw) Ry(pitch) Rx(roll)`` (angles in deg), one per sample."""
    r, p, y = np.radians(roll), np.radians(pitch), np.radians(yaw)
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.stack([
        np.stack([cp * cy, sr * sp * cy - cr * sy, cr * sp * cy + sr * sy], -1),
        np.stack([cp * sy, sr * sp * sy + cr * cy, cr * sp * sy - sr * cy], -1),
        np.stack([-sp, sr * cp, cr * cp], -1)], 1)


def _record(name: str, *values: Any) -> bytes:
    tid, fmt, _ = _TYPES[name]
    return _HEAD + bytes([tid]) + _packer(fmt).pack(*values)


def dataflash_bytes(samples: dict[str, np.ndarray], truth: FlightTruth) -> bytes:
    """The flight as an ArduPilot DataFlash log (see the module docstring)."""
    out = bytearray()
    for name, (tid, fmt, cols) in _TYPES.items():
        length = 3 + _packer(fmt).size
        out += _record("FMT", tid, length, name.encode(), fmt.encode(), cols.encode())
    params = {"COMPASS_OFS_X": 0.0, "COMPASS_OFS_Y": 0.0, "COMPASS_OFS_Z": 0.0,
              "COMPASS_DIA_X": 1.0, "COMPASS_DIA_Y": 1.0, "COMPASS_DIA_Z": 1.0,
              "COMPASS_ODI_X": 0.0, "COMPASS_ODI_Y": 0.0, "COMPASS_ODI_Z": 0.0,
              "COMPASS_MOTCT": 0.0, "COMPASS_MOT_X": 0.0, "COMPASS_MOT_Y": 0.0,
              "COMPASS_MOT_Z": 0.0, "COMPASS_ORIENT": 0.0, "COMPASS_USE": 1.0,
              "AHRS_ORIENTATION": 0.0, "AHRS_EKF_TYPE": 3.0, "EK3_SRC1_YAW": 2.0}
    for k, v in params.items():
        out += _record("PARM", 0, k.encode(), v)
    lat, lon, alt = truth.location
    t_us = (1_000_000 + samples["t"] * 1e6).astype(np.int64)
    for i, tu in enumerate(t_us):
        tu = int(tu)
        if i % 10 == 0:
            out += _record("GPS", tu, 3, int(round(lat * 1e7)), int(round(lon * 1e7)), alt)
        r, p, y = samples["attitude"][i]
        out += _record("ATT", tu - 500, float(r), float(p), float(y))
        out += _record("CURR", tu + 200, 16.0 - 0.05 * samples["current"][i],
                       float(samples["current"][i]))
        out += _record("CTUN", tu + 300, float(samples["throttle"][i]))
        m = samples["mag"][i]
        out += _record("MAG", tu, float(m[0]), float(m[1]), float(m[2]), 0.0, 0.0, 0.0,
                       0.0, 0.0, 0.0)
    return bytes(out)


def write_flight(out_dir: str | Path, field_ned_mg: Any, **kwargs: Any) -> dict[str, Path]:
    """Write ``flight.BIN`` and ``flight_truth.json`` into ``out_dir``; returns their paths."""
    d = Path(out_dir)
    d.mkdir(parents=True, exist_ok=True)
    samples, truth = simulate_flight(field_ned_mg, **kwargs)
    log = d / "flight.BIN"
    write_file(log, dataflash_bytes(samples, truth), what="simulated flight log")
    tj = d / "flight_truth.json"
    write_file(tj, json.dumps(truth.to_dict(), indent=2) + "\n", what="flight truth")
    return {"log": log, "truth": tj}
