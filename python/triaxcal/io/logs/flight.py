"""What an autopilot log says about the flight besides the sensors: attitude, battery current,
throttle and position (for the compass calibration of :mod:`triaxcal.methods.attitude`).

Read in a pass of its own, beside the sensor readers (:mod:`.dataflash`, :mod:`.ulog`):

==========================  ========================================  =========================
                            ArduPilot DataFlash                       PX4 ULog
==========================  ========================================  =========================
attitude (body to NED)      ``ATT`` Roll, Pitch, Yaw (deg)            ``vehicle_attitude`` q
battery current (A)         ``BAT`` Curr (A; instance 0), older       ``battery_status`` current_a
                            ``CURR`` Curr (A; centiamps when logged   (instance 0)
                            as an integer)
throttle (0..1)             ``CTUN`` ThO (older ThrOut, 0..1000)      ``actuator_controls_0``
                                                                      control[3]
position (deg, deg, m)      ``GPS`` (fix 3D or better), else the      ``vehicle_gps_position``
                            EKF origin ``ORGN``                       (fix >= 3), else the EKF
                                                                      origin (vehicle_local_
                                                                      position ref_lat/ref_lon)
==========================  ========================================  =========================

Times are in seconds on the same clock as the sensor streams of :func:`triaxcal.read_log`
(``time_origin_us``: the first sample that reader took, in the log's microseconds).
"""

from __future__ import annotations

import contextlib
import io
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import CalibrationError
from . import log_format, require

__all__ = ["FlightData", "Series", "read_flight"]


@dataclass(frozen=True, eq=False)
class Series:
    """One logged quantity: ``t`` (s), ``values`` ((N,) or (N, k)), where it came from."""

    t: np.ndarray
    values: np.ndarray
    name: str
    unit: str

    def at(self, t: Any) -> np.ndarray:
        """The values linearly interpolated at times ``t`` (held at the ends)."""
        tt = np.asarray(t, float)
        v = self.values
        if v.ndim == 1:
            return np.interp(tt, self.t, v)
        return np.column_stack([np.interp(tt, self.t, v[:, k]) for k in range(v.shape[1])])


@dataclass(frozen=True, eq=False)
class FlightData:
    """Attitude, current, throttle and position of a flight log (any may be missing).

    ``attitude.values`` are Euler angles (roll, pitch, yaw in deg, ArduPilot) or quaternions
    (w, x, y, z, PX4), as ``attitude.unit`` says (``"deg"`` / ``"quaternion"``).
    """

    attitude: Series | None = None
    current: Series | None = None
    throttle: Series | None = None
    position: tuple[float, float, float] | None = None
    position_source: str | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    def dcm(self, t: Any) -> np.ndarray:
        """Body-to-NED rotation matrices (N, 3, 3) at times ``t`` (nearest attitude sample:
        angles do not interpolate linearly across the +-180 deg wrap)."""
        from ...conventions.rotations import euler_to_dcm, quat_to_dcm

        if self.attitude is None:
            raise CalibrationError("this log has no attitude")
        a = self.attitude
        j = np.clip(np.searchsorted(a.t, t), 1, len(a.t) - 1)
        tt = np.asarray(t, float)
        j = np.where(np.abs(a.t[j - 1] - tt) <= np.abs(a.t[j] - tt), j - 1, j)
        v = a.values[j]
        if a.unit == "quaternion":
            return quat_to_dcm(v)
        return euler_to_dcm(v[:, 0], v[:, 1], v[:, 2])


def read_flight(path: str | Path, *, time_origin_us: int | None = None) -> FlightData:
    """The attitude, current, throttle and position in an autopilot log (see the module
    docstring); ``time_origin_us`` is the log time that is 0 s (the sensor reader's
    ``rec.meta["time_origin_us"]``; without it the first sensor sample is found, which costs a
    pass over the sensor messages)."""
    fmt = log_format(path)
    if fmt == "ardupilot-dataflash":
        return _dataflash(Path(path), time_origin_us)
    if fmt == "px4-ulog":
        return _ulog(Path(path), time_origin_us)
    raise CalibrationError(
        f"{path}: only autopilot logs (ArduPilot .bin, PX4 .ulg) carry the vehicle's attitude; "
        "a compass calibration from the attitude needs one")


def _series(rows: list[tuple[int, Any]], t0: int, name: str, unit: str) -> Series | None:
    if not rows:
        return None
    t = np.array([r[0] for r in rows], dtype=np.int64)
    v = np.array([r[1] for r in rows], dtype=np.float64)
    order = np.argsort(t, kind="stable")
    return Series(t=(t[order] - t0) * 1e-6, values=v[order], name=name, unit=unit)


def _deg(v: Any) -> float:
    """Degrees from a DataFlash latitude/longitude: pymavlink scales ``L`` fields to degrees;
    plain int32 fields hold degrees * 1e7."""
    return float(v) * 1e-7 if isinstance(v, int) and abs(v) > 360 else float(v)


def _dataflash(p: Path, t0: int | None) -> FlightData:
    dfreader = require("pymavlink.DFReader", "ArduPilot DataFlash logs", package="pymavlink")
    if not p.is_file():
        raise CalibrationError(f"log file {p} not found")
    att: list[tuple[int, Any]] = []
    cur: list[tuple[int, Any]] = []
    bat: list[tuple[int, Any]] = []
    thr: list[tuple[int, Any]] = []
    gps = None
    origin = None
    first = None
    quiet = io.StringIO()
    log = None
    # the sensor messages only to find the first sample's time, when the caller does not know it
    types = ["ATT", "CURR", "BAT", "CTUN", "GPS", "ORGN", *(("IMU", "MAG") if t0 is None else ())]
    try:
        with contextlib.redirect_stdout(quiet):
            log = dfreader.DFReader_binary(str(p), zero_time_base=False)
        while True:
            with contextlib.redirect_stdout(quiet):
                m = log.recv_match(type=types)
            if m is None:
                break
            kind = m.get_type()
            tus = int(getattr(m, "TimeUS", 0))
            if kind in ("IMU", "MAG"):
                first = tus if first is None else min(first, tus)
                continue
            if kind == "ATT":
                att.append((tus, (float(m.Roll), float(m.Pitch), float(m.Yaw))))
            elif kind == "CURR":
                v = m.Curr
                # APM 3.x logged centiamps as an int16 ('h'); later firmware amps as a float
                cur.append((tus, float(v) / 100.0 if isinstance(v, int) else float(v)))
            elif kind == "BAT":
                if int(getattr(m, "Instance", getattr(m, "Inst", 0)) or 0) == 0:
                    bat.append((tus, float(m.Curr)))
            elif kind == "CTUN":
                if hasattr(m, "ThO"):
                    thr.append((tus, float(m.ThO)))
                elif hasattr(m, "ThrOut"):
                    thr.append((tus, float(m.ThrOut) / 1000.0))
            elif kind == "GPS" and gps is None:
                if int(getattr(m, "Status", 0)) >= 3 and (m.Lat != 0 or m.Lng != 0):
                    gps = (_deg(m.Lat), _deg(m.Lng), float(getattr(m, "Alt", 0.0)))
            elif kind == "ORGN" and origin is None and (m.Lat != 0 or m.Lng != 0):
                origin = (_deg(m.Lat), _deg(m.Lng), float(getattr(m, "Alt", 0.0)))
    except CalibrationError:
        raise
    except Exception as exc:  # pymavlink raises assorted errors on damaged files
        raise CalibrationError(f"{p} is not a readable ArduPilot DataFlash log "
                               f"({type(exc).__name__}: {exc})") from None
    finally:
        if log is not None:
            log.close()
    if t0 is None:
        t0 = first if first is not None else min((r[0] for r in att), default=0)
    current = _series(bat, t0, "BAT.Curr", "A") or _series(cur, t0, "CURR.Curr", "A")
    pos, src = (gps, "GPS") if gps is not None else (origin, "ORGN") if origin else (None, None)
    return FlightData(attitude=_series(att, t0, "ATT", "deg"), current=current,
                      throttle=_series(thr, t0, "CTUN.ThO", "throttle"), position=pos,
                      position_source=src)


def _ulog(p: Path, t0: int | None) -> FlightData:
    pyulog = require("pyulog", "PX4 ULog files")
    topics = ["vehicle_attitude", "battery_status", "actuator_controls_0",
              "vehicle_gps_position", "vehicle_local_position",
              *(("sensor_combined", "vehicle_magnetometer") if t0 is None else ())]
    try:
        with open(p, "rb") as fh:
            ulog = pyulog.ULog(fh, topics)
    except Exception as exc:
        raise CalibrationError(f"{p} is not a readable PX4 ULog file "
                               f"({type(exc).__name__}: {exc})") from None
    data = {(d.name, d.multi_id): d.data for d in ulog.data_list}
    if t0 is None:
        starts = [int(d["timestamp"][0]) for (n, _), d in data.items()
                  if n in ("sensor_combined", "vehicle_magnetometer") and len(d["timestamp"])]
        t0 = min(starts) if starts else int(ulog.start_timestamp)

    def series(topic: str, cols: list[str], name: str, unit: str, scale: float = 1.0
               ) -> Series | None:
        d = data.get((topic, 0))
        if d is None or not all(c in d for c in cols) or not len(d["timestamp"]):
            return None
        v = np.column_stack([np.asarray(d[c], float) for c in cols]) * scale
        t = np.asarray(d["timestamp"], np.int64)
        return Series(t=(t - t0) * 1e-6, values=v[:, 0] if len(cols) == 1 else v, name=name,
                      unit=unit)

    att = series("vehicle_attitude", [f"q[{i}]" for i in range(4)], "vehicle_attitude.q",
                 "quaternion")
    cur = series("battery_status", ["current_a"], "battery_status.current_a", "A")
    thr = series("actuator_controls_0", ["control[3]"], "actuator_controls_0.control[3]",
                 "throttle")
    pos, src = None, None
    g = data.get(("vehicle_gps_position", 0))
    if g is not None and "fix_type" in g:
        ok = np.asarray(g["fix_type"]) >= 3
        if ok.any():
            i = int(np.argmax(ok))
            pos = (float(g["lat"][i]) * 1e-7, float(g["lon"][i]) * 1e-7,
                   float(g["alt"][i]) * 1e-3)
            src = "vehicle_gps_position"
    lp = data.get(("vehicle_local_position", 0))
    if pos is None and lp is not None and "ref_lat" in lp:
        lat, lon = np.asarray(lp["ref_lat"], float), np.asarray(lp["ref_lon"], float)
        ok = (lat != 0) | (lon != 0)
        if "xy_global" in lp:
            ok &= np.asarray(lp["xy_global"]).astype(bool)
        if ok.any():
            i = int(np.argmax(ok))
            alt = float(lp["ref_alt"][i]) if "ref_alt" in lp else 0.0
            pos, src = (float(lat[i]), float(lon[i]), alt), "vehicle_local_position.ref_lat/lon"
    if cur is not None and not np.isfinite(cur.values).any():
        cur = None
    return FlightData(attitude=att, current=cur, throttle=thr, position=pos,
                      position_source=src)
