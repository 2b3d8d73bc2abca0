"""A simulated flight with known compass errors, written as a real ArduPilot DataFlash log and
as a PX4 ULog.

The vehicle turns through several full circles while rolling and pitching, its battery current
and throttle rise and fall on their own rhythm, and its compass reads the Earth's field through
known hard iron, soft iron and current interference, in ArduPilot's convention
(``AP_Compass_Backend::correct_field``)::

    field = M @ (raw + COMPASS_OFS) + COMPASS_MOT * current       (mG, body frame)

so the raw reading is ``inv(M) @ (R.T @ B - COMPASS_MOT * current) - COMPASS_OFS`` plus noise.

**DataFlash** (``flight.BIN``): what ArduPilot logs with no calibration stored (``COMPASS_OFS``
= 0, ``DIA`` = 1, ``COMPASS_MOTCT`` = 0): ``MAG`` (the raw readings), ``ATT`` (the true
attitude, as from an independent yaw source: ``EK3_SRC1_YAW`` = 2, GPS), ``CURR`` (the older
firmware's name) and ``BAT`` (ArduPilot 4's, instance 0, which MAVProxy's MAGFit reads), both
with the same current, ``CTUN`` (throttle), ``GPS`` and ``PARM`` records (``AHRS_TRIM_*`` = 0
too, which MAGFit adds to the attitude), each type described by its ``FMT`` record, which
pymavlink and triaxcal read. The format (ArduPilot ``libraries/AP_Logger/LogStructure.h``):
every record is ``0xA3 0x95 <type>`` then the fields packed little-endian as the type's
``FMT`` record says (``Q`` uint64, ``I``/``H``/``B`` uint32/16/8, ``f`` float32, ``L`` int32
degrees * 1e7, ``N`` char[16], ``n`` char[4], ``Z`` char[64]); ``FMT`` itself is type 128.
``GPS`` carries the GPS week and time of week (``GWk``, ``GMS``) from which pymavlink builds
its clock.

**ULog** (``flight.ulg``, :mod:`triaxcal.sim.ulog`): the same samples as PX4 v1.14 logs them:
``vehicle_magnetometer`` (gauss, body frame, no calibration stored: ``CAL_MAG0_*OFF`` = 0,
``*SCALE`` = 1, ``CAL_MAG_COMP_TYP`` = 0), ``vehicle_attitude`` (quaternion, body to NED;
``EKF2_MAG_TYPE`` = 5: the compass was not fused), ``battery_status`` (``current_a``),
``actuator_controls_0`` (``control[3]``, throttle), ``vehicle_gps_position`` and
``sensor_combined`` (the specific force and body rates of the same motion).
"""

from __future__ import annotations

import json
import math
import struct
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from .._checks.options import seed as seed_of
from ..conventions.rotations import euler_to_dcm
from ..errors import CalibrationError
from ..io.files import write_file
from .ulog import ulog_bytes

__all__ = ["FlightTruth", "dataflash_bytes", "flight_ulog_bytes", "simulate_flight",
           "write_flight"]

_HEAD = b"\xa3\x95"
_TYPES = {  # name: (id, format, columns)
    "FMT": (128, "BBnNZ", "Type,Length,Name,Format,Columns"),
    "PARM": (129, "QNf", "TimeUS,Name,Value"),
    "ATT": (130, "Qfff", "TimeUS,Roll,Pitch,Yaw"),
    "MAG": (131, "Qfffffffff", "TimeUS,MagX,MagY,MagZ,OfsX,OfsY,OfsZ,MOfsX,MOfsY,MOfsZ"),
    "CURR": (132, "Qff", "TimeUS,Volt,Curr"),
    "BAT": (135, "QBff", "TimeUS,Instance,Volt,Curr"),
    "CTUN": (133, "Qf", "TimeUS,ThO"),
    "GPS": (134, "QBIHBLLf", "TimeUS,Status,GMS,GWk,NSats,Lat,Lng,Alt"),
}
_STRUCT = {"Q": "Q", "f": "f", "B": "B", "H": "H", "I": "I", "i": "i", "L": "i", "N": "16s",
           "n": "4s", "Z": "64s"}
#: GPS week and time of week (ms) at the log's start: any date will do.
_GPS_WEEK, _GPS_START_MS, _WEEK_MS = 2420, 3 * 86_400_000, 604_800_000


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
    trim_deg: tuple[float, float] = (0.0, 0.0)   # AHRS_TRIM_X/Y (deg)
    field_date: str | None = None                # the date the field is the WMM's for

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
            "AHRS_TRIM_deg": list(self.trim_deg),
            "field_date": self.field_date,
        }


def simulate_flight(field_ned_mg: Any, *, duration_s: float = 600.0, rate_hz: float = 10.0,
                    seed: int = 7, location: tuple[float, float, float] = (47.37, 8.54, 400.0),
                    noise_mg: float = 2.0, attitude_noise_deg: float = 0.3,
                    trim_deg: tuple[float, float] = (0.0, 0.0), field_date: str | None = None
                    ) -> tuple[dict[str, np.ndarray], FlightTruth]:
    """The samples of a simulated flight (time in s, attitude in deg, current in A, throttle
    0..1, raw compass in mG) and the truth.

    ``samples["attitude"]`` is the autopilot body's attitude (roll, pitch, yaw), the one the
    compass reads in; ``samples["attitude_vehicle"]`` the vehicle body's, which ArduPilot logs
    in ``ATT`` when ``AHRS_TRIM_X/Y`` (``trim_deg``, written to the log in radians) are not
    zero: ``R_vehicle = R_autopilot @ R_trim.T`` (``AP_AHRS::update_trim_rotation_matrices``).
    """
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
    dcm = euler_to_dcm(roll, pitch, yaw)
    body = np.einsum("nji,j->ni", dcm, b) - current[:, None] * truth.compass_mot
    raw = body @ np.linalg.inv(truth.matrix).T - truth.compass_ofs
    raw = raw + rng.normal(0.0, noise_mg, raw.shape)
    logged_att = np.column_stack([roll, pitch, yaw]) + rng.normal(0.0, attitude_noise_deg,
                                                                  (len(t), 3))
    logged_att[:, 2] %= 360.0
    tx, ty = (float(a) for a in trim_deg)
    if not (abs(tx) <= 10 and abs(ty) <= 10):
        raise CalibrationError("trim_deg: AHRS_TRIM_X/Y within +-10 deg")
    vehicle = logged_att
    if tx or ty:
        r = euler_to_dcm(logged_att[:, 0], logged_att[:, 1], logged_att[:, 2]) @ \
            euler_to_dcm([tx], [ty], [0.0])[0].T
        vehicle = np.degrees(np.column_stack([
            np.arctan2(r[:, 2, 1], r[:, 2, 2]), np.arcsin(np.clip(-r[:, 2, 0], -1, 1)),
            np.arctan2(r[:, 1, 0], r[:, 0, 0]) % (2 * np.pi)]))
    truth = replace(truth, trim_deg=(tx, ty), field_date=field_date)
    return {"t": t, "attitude": logged_att, "attitude_vehicle": vehicle, "current": current,
            "throttle": throttle, "mag": raw}, truth


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
              "AHRS_ORIENTATION": 0.0, "AHRS_TRIM_X": math.radians(truth.trim_deg[0]),
              "AHRS_TRIM_Y": math.radians(truth.trim_deg[1]), "AHRS_TRIM_Z": 0.0,
              "AHRS_EKF_TYPE": 3.0, "EK3_SRC1_YAW": 2.0}
    for k, v in params.items():
        out += _record("PARM", 0, k.encode(), v)
    lat, lon, alt = truth.location
    t_us = (1_000_000 + samples["t"] * 1e6).astype(np.int64)
    for i, tu in enumerate(t_us):
        tu = int(tu)
        if i % 10 == 0:
            ms = _GPS_START_MS + tu // 1000  # GPS time of week (pymavlink's clock uses it)
            out += _record("GPS", tu, 3, ms % _WEEK_MS, _GPS_WEEK + ms // _WEEK_MS, 12,
                           int(round(lat * 1e7)), int(round(lon * 1e7)), alt)
        r, p, y = samples["attitude_vehicle"][i]
        out += _record("ATT", tu - 500, float(r), float(p), float(y))
        volt = 16.0 - 0.05 * samples["current"][i]
        out += _record("CURR", tu + 200, volt, float(samples["current"][i]))
        out += _record("BAT", tu + 200, 0, volt, float(samples["current"][i]))
        out += _record("CTUN", tu + 300, float(samples["throttle"][i]))
        m = samples["mag"][i]
        out += _record("MAG", tu, float(m[0]), float(m[1]), float(m[2]), 0.0, 0.0, 0.0,
                       0.0, 0.0, 0.0)
    return bytes(out)


#: Device id of the simulated PX4 compass (``CAL_MAG0_ID``; any non-zero id).
PX4_MAG_DEVICE_ID = 396825
#: PX4 v1.14.0 release as ``ver_sw_release`` encodes it (major, minor, patch, 0xFF = release).
PX4_VERSION = (1 << 24) | (14 << 16) | (0 << 8) | 0xFF
_G = 9.80665


def _quaternion(roll: np.ndarray, pitch: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """``(w, x, y, z)`` of ``Rz(yaw) Ry(pitch) Rx(roll)`` (deg), body to NED (Hamilton)."""
    r, p, y = (np.radians(a) / 2 for a in (roll, pitch, yaw))
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.column_stack([cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy,
                            cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy])


def flight_ulog_bytes(samples: dict[str, np.ndarray], truth: FlightTruth) -> bytes:
    """The flight as a PX4 ULog (see the module docstring)."""
    t_us = (1_000_000 + samples["t"] * 1e6).astype(np.uint64)
    n = len(t_us)
    att = samples["attitude"]
    dcm = euler_to_dcm(att[:, 0], att[:, 1], att[:, 2])
    # body rates from consecutive attitudes (R_i^T R_i+1 = I + [w dt]x), specific force -g up
    dt = np.diff(samples["t"]).mean() if n > 1 else 1.0
    rel = np.einsum("nji,njk->nik", dcm[:-1], dcm[1:])
    w = np.column_stack([rel[:, 2, 1] - rel[:, 1, 2], rel[:, 0, 2] - rel[:, 2, 0],
                         rel[:, 1, 0] - rel[:, 0, 1]]) / (2 * dt)
    gyro = np.vstack([w, w[-1:]]) if n > 1 else np.zeros((n, 3))
    accel = np.einsum("nji,j->ni", dcm, [0.0, 0.0, -_G])
    lat, lon, alt = truth.location
    ctl = np.zeros((n, 8))
    ctl[:, 3] = samples["throttle"]
    ts = ("uint64_t", "timestamp")
    topics = {
        "sensor_combined": ([ts, ("float[3]", "gyro_rad"), ("uint32_t", "gyro_integral_dt"),
                             ("int32_t", "accelerometer_timestamp_relative"),
                             ("float[3]", "accelerometer_m_s2"),
                             ("uint32_t", "accelerometer_integral_dt")],
                            {"timestamp": t_us - 2000, "gyro_rad": gyro,
                             "gyro_integral_dt": np.full(n, int(dt * 1e6)),
                             "accelerometer_timestamp_relative": np.zeros(n, np.int32),
                             "accelerometer_m_s2": accel,
                             "accelerometer_integral_dt": np.full(n, int(dt * 1e6))}),
        "vehicle_magnetometer": ([ts, ("uint64_t", "timestamp_sample"), ("uint32_t", "device_id"),
                                  ("float[3]", "magnetometer_ga"),
                                  ("uint8_t", "calibration_count")],
                                 {"timestamp": t_us + 100, "timestamp_sample": t_us,
                                  "device_id": np.full(n, PX4_MAG_DEVICE_ID),
                                  "magnetometer_ga": samples["mag"] / 1000.0,
                                  "calibration_count": np.zeros(n, np.uint8)}),
        "vehicle_attitude": ([ts, ("uint64_t", "timestamp_sample"), ("float[4]", "q")],
                             {"timestamp": t_us - 400, "timestamp_sample": t_us - 500,
                              "q": _quaternion(att[:, 0], att[:, 1], att[:, 2])}),
        "battery_status": ([ts, ("float", "voltage_v"), ("float", "current_a")],
                           {"timestamp": t_us + 200,
                            "voltage_v": 16.0 - 0.05 * samples["current"],
                            "current_a": samples["current"]}),
        "actuator_controls_0": ([ts, ("uint64_t", "timestamp_sample"), ("float[8]", "control")],
                                {"timestamp": t_us + 300, "timestamp_sample": t_us + 300,
                                 "control": ctl}),
        "vehicle_gps_position": ([ts, ("int32_t", "lat"), ("int32_t", "lon"),
                                  ("int32_t", "alt"), ("uint8_t", "fix_type")],
                                 {"timestamp": t_us[::10] + 50,
                                  "lat": np.full(len(t_us[::10]), int(round(lat * 1e7))),
                                  "lon": np.full(len(t_us[::10]), int(round(lon * 1e7))),
                                  "alt": np.full(len(t_us[::10]), int(round(alt * 1e3))),
                                  "fix_type": np.full(len(t_us[::10]), 3, np.uint8)}),
    }
    params: dict[str, float | int] = {
        "CAL_MAG0_ID": PX4_MAG_DEVICE_ID, "CAL_MAG0_ROT": -1, "CAL_MAG0_PRIO": 50,
        "CAL_MAG_COMP_TYP": 0, "CAL_ACC0_ID": 1310988, "CAL_GYRO0_ID": 1310988,
        "SENS_BOARD_ROT": 0, "SYS_HAS_MAG": 1, "EKF2_MAG_TYPE": 5,
        "TC_A_ENABLE": 0, "TC_G_ENABLE": 0, "TC_M_ENABLE": 0,
    }
    for a in "XYZ":
        params.update({f"CAL_MAG0_{a}OFF": 0.0, f"CAL_MAG0_{a}SCALE": 1.0,
                       f"CAL_MAG0_{a}ODIAG": 0.0, f"CAL_MAG0_{a}COMP": 0.0,
                       f"CAL_ACC0_{a}OFF": 0.0, f"CAL_ACC0_{a}SCALE": 1.0,
                       f"CAL_GYRO0_{a}OFF": 0.0})
    return ulog_bytes(topics, start_us=int(t_us[0]) - 500_000,
                      info={"sys_name": "PX4", "ver_hw": "SITL", "ver_sw_release": PX4_VERSION},
                      params=params)


def write_flight(out_dir: str | Path, field_ned_mg: Any, **kwargs: Any) -> dict[str, Path]:
    """Write ``flight.BIN``, ``flight.ulg`` (the same flight) and ``flight_truth.json`` into
    ``out_dir`` (``kwargs``: :func:`simulate_flight`'s); returns their paths (``"log"``,
    ``"ulog"``, ``"truth"``)."""
    d = Path(out_dir)
    d.mkdir(parents=True, exist_ok=True)
    samples, truth = simulate_flight(field_ned_mg, **kwargs)
    log = d / "flight.BIN"
    write_file(log, dataflash_bytes(samples, truth), what="simulated flight log")
    ulg = d / "flight.ulg"
    write_file(ulg, flight_ulog_bytes(samples, truth), what="simulated flight log (ULog)")
    tj = d / "flight_truth.json"
    write_file(tj, json.dumps(truth.to_dict(), indent=2) + "\n", what="flight truth")
    return {"log": log, "ulog": ulg, "truth": tj}
