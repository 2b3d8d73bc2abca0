"""The calibration an autopilot applied to the readings it logged, read from the log's parameters.

Autopilot logs hold readings that the autopilot has already corrected with its stored
calibration. This module reads that calibration from the parameters, states the autopilot's
own equation, applies it and undoes it, so that a fit can see the raw sensor again.

PX4 (``src/lib/sensor_calibration/Accelerometer.hpp``, ``Gyroscope.hpp``, ``Magnetometer.hpp``,
``Correct()``; ``src/modules/temperature_compensation/TemperatureCompensation.cpp``)::

    accel  body = R @ ((raw - thermal(T) - CAL_ACCn_OFF) * CAL_ACCn_SCALE)
    gyro   body = R @ (raw - thermal(T) - CAL_GYROn_OFF)          (older firmware: * SCALE)
    mag    body = R @ (S @ (raw + power * CAL_MAGn_COMP - CAL_MAGn_OFF))
           S = [[XSCALE, XODIAG, YODIAG], [XODIAG, YSCALE, ZODIAG], [YODIAG, ZODIAG, ZSCALE]]

``R`` rotates sensor to body: ``Dcm(Euler(SENS_BOARD_X/Y/Z_OFF)) @ rot(SENS_BOARD_ROT)`` for
internal sensors, ``... @ rot(CAL_MAGn_ROT)`` for an external magnetometer
(``Utilities.cpp`` ``GetSensorLevelAdjustment``; ``Magnetometer::set_rotation``). Offsets are
SUBTRACTED, scales MULTIPLY. Units: m/s^2, rad/s, gauss. Firmware before the 2020 move of
calibration into the ``sensors`` module applied the same equation inside the drivers.

ArduPilot (``libraries/AP_InertialSensor/AP_InertialSensor_Backend.cpp``
``_rotate_and_correct_accel`` / ``_rotate_and_correct_gyro``;
``AP_InertialSensor_tempcal.cpp`` ``TCal::correct_sensor``;
``libraries/AP_Compass/AP_Compass_Backend.cpp`` ``correct_field``)::

    accel  body = R_board @ ((raw - tcal(T) - INS_ACCOFFS) * INS_ACCSCAL)
    gyro   body = R_board @ (raw - tcal(T) - INS_GYROFFS)
    mag    body = M @ ((raw + COMPASS_OFS) * COMPASS_SCALE) + motor offset
           M = [[DIA_X, ODI_X, ODI_Y], [ODI_X, DIA_Y, ODI_Z], [ODI_Y, ODI_Z, DIA_Z]]
    tcal(T) = P(clamp(T) - 35) - P(clamp(T_cal) - 35),  P(x) = (c1 x + c2 x^2 + c3 x^3) * 1e-6

with ``R_board = rot(AHRS_ORIENTATION)``; the compass is rotated to the body frame *before*
its correction, so its calibration is in the body frame. The INS offsets are SUBTRACTED, the
COMPASS offsets are ADDED; scales multiply; ``COMPASS_SCALE`` is used only within
0.85..1.4 (``Compass::have_scale_factor``). Units: m/s^2, rad/s, milligauss.

Rotations (both autopilots): the enum value names (roll, pitch, yaw) in degrees and
``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)`` takes a sensor-frame vector to the body frame (PX4
``src/lib/conversion/rotation.h`` ``rot_lookup`` and ``get_rot_matrix``; ArduPilot
``AP_Math`` ``Vector3::rotate``, whose ``ROTATION_ROLL_180_YAW_45`` case is exactly
``Rz(45) @ Rx(180)``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ...conventions.autopilot import (
    PX4_COMP_TYPE,
    PX4_SENSOR,
    PX4_TC_ENABLE,
    ardupilot_names,
    px4_prefix,
)
from ...errors import CalibrationError

__all__ = [
    "ARDUPILOT_ROTATIONS",
    "PX4_ROTATIONS",
    "AutopilotCalibration",
    "AutopilotPart",
    "ThermalPoly",
    "ardupilot_calibration",
    "euler_matrix",
    "px4_calibration",
    "rotation_matrix",
]

#: PX4 ``enum Rotation`` -> (roll, pitch, yaw) in degrees (``rotation.h`` ``rot_lookup``).
PX4_ROTATIONS: dict[int, tuple[float, float, float]] = dict(enumerate([
    (0, 0, 0), (0, 0, 45), (0, 0, 90), (0, 0, 135), (0, 0, 180), (0, 0, 225), (0, 0, 270),
    (0, 0, 315), (180, 0, 0), (180, 0, 45), (180, 0, 90), (180, 0, 135), (0, 180, 0),
    (180, 0, 225), (180, 0, 270), (180, 0, 315), (90, 0, 0), (90, 0, 45), (90, 0, 90),
    (90, 0, 135), (270, 0, 0), (270, 0, 45), (270, 0, 90), (270, 0, 135), (0, 90, 0),
    (0, 270, 0), (0, 180, 90), (0, 180, 270), (90, 90, 0), (180, 90, 0), (270, 90, 0),
    (90, 180, 0), (270, 180, 0), (90, 270, 0), (180, 270, 0), (270, 270, 0), (90, 180, 90),
    (90, 0, 270), (90, 68, 293), (0, 315, 0), (90, 315, 0), (270, 0, 180), (270, 0, 270),
    (0, 90, 180), (0, 9, 180), (0, 45, 0), (270, 0, 225), (270, 0, 315),
]))

#: ArduPilot ``enum Rotation`` values whose angles are the same as PX4's / MAVLink's
#: ``MAV_SENSOR_ORIENTATION`` (0..37, 39, 40), plus Roll45 (42) and Roll315 (43). Others
#: (38, 41, custom 100+) are refused rather than guessed.
ARDUPILOT_ROTATIONS: dict[int, tuple[float, float, float]] = {
    **{k: v for k, v in PX4_ROTATIONS.items() if k <= 37 or k in (39, 40)},
    42: (45, 0, 0),
    43: (315, 0, 0),
}


def euler_matrix(roll_deg: float, pitch_deg: float, yaw_deg: float) -> np.ndarray:
    """``Rz(yaw) @ Ry(pitch) @ Rx(roll)`` (angles in degrees): sensor frame to body frame.

    >>> np.round(euler_matrix(180, 0, 45) @ [1.0, 0.0, 0.0], 6).tolist()
    [0.707107, 0.707107, 0.0]
    """
    r, p, y = (math.radians(float(a)) for a in (roll_deg, pitch_deg, yaw_deg))
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), \
        math.cos(y), math.sin(y)
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    m = rz @ ry @ rx
    m[np.abs(m) < 1e-15] = 0.0
    return m


def rotation_matrix(value: float, autopilot: str, param: str) -> np.ndarray:
    """The matrix of rotation enum ``value`` of ``autopilot`` (``"px4"``/``"ardupilot"``)."""
    table = PX4_ROTATIONS if autopilot == "px4" else ARDUPILOT_ROTATIONS
    if not float(value).is_integer() or int(value) not in table:
        raise CalibrationError(
            f"{param} = {value:g} is a rotation triaxcal does not know for {autopilot} (known: "
            f"{min(table)}..{max(table)} except custom ones); the calibration cannot be undone "
            "exactly -- read the raw per-sensor topics, or set a standard rotation"
        )
    return euler_matrix(*table[int(value)])


@dataclass(frozen=True, eq=False)
class ThermalPoly:
    """ArduPilot's temperature correction ``tcal(T)``, subtracted from the raw reading.

    ``tcal(T) = P(clamp(T) - 35) - P(clamp(T_cal) - 35)`` with
    ``P(x) = (c1 x + c2 x^2 + c3 x^3) * 1e-6`` and ``clamp`` to ``[tmin, tmax]`` deg C
    (``AP_InertialSensor_tempcal.cpp``: ``polynomial_eval``, ``correct_sensor``).
    """

    coeff: np.ndarray  # (3, 3): rows c1, c2, c3 (the INS_TCALn_ACC1..3 values), columns x, y, z
    tmin: float
    tmax: float
    cal_temp: float
    reference_c: float = 35.0

    def __call__(self, temp_c: Any) -> np.ndarray:
        t = np.clip(np.asarray(temp_c, float).ravel(), self.tmin, self.tmax)
        tc = min(max(self.cal_temp, self.tmin), self.tmax)
        return self._p(t - self.reference_c) - self._p(np.array([tc - self.reference_c]))

    def _p(self, x: np.ndarray) -> np.ndarray:
        c = self.coeff
        x = x[:, None]
        return (c[0] + (c[1] + c[2] * x) * x) * x * 1e-6


@dataclass(frozen=True, eq=False)
class AutopilotPart:
    """One sensor's calibration as an autopilot applies it (see the module docstring).

    ``corrected = rotation @ (matrix @ ((raw - thermal(T) + offset_sign * offset) *
    scale_factor))``: PX4 and the ArduPilot INS subtract the offset (``offset_sign = -1``),
    the ArduPilot compass adds it (``+1``); ``matrix`` multiplies.
    """

    sensor: str
    autopilot: str
    index: int
    unit: str
    offset: np.ndarray
    matrix: np.ndarray
    offset_sign: int = -1
    scale_factor: float = 1.0
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    thermal: ThermalPoly | None = None
    equation: str = ""
    citation: str = ""
    params: Mapping[str, float] = field(default_factory=dict)
    not_undoable: str | None = None

    def __post_init__(self) -> None:
        for name, shape in (("offset", (3,)), ("matrix", (3, 3)), ("rotation", (3, 3))):
            a = np.array(getattr(self, name), dtype=float)
            if a.shape != shape or not np.isfinite(a).all():
                raise CalibrationError(f"{self.autopilot} {self.sensor} {name}: bad values {a}")
            a.setflags(write=False)
            object.__setattr__(self, name, a)
        if abs(np.linalg.det(self.matrix)) < 1e-12 or self.scale_factor == 0:
            raise CalibrationError(
                f"{self.autopilot} {self.sensor} calibration in the log is singular "
                f"(scale/soft-iron determinant {np.linalg.det(self.matrix):.3g}): it cannot be "
                "undone"
            )

    def apply(self, raw: Any, temp_c: Any = None) -> np.ndarray:
        """What the autopilot makes of raw readings (N, 3) in :attr:`unit`."""
        d = np.array(raw, dtype=float, ndmin=2)
        if self.thermal is not None:
            d = d - self.thermal(self._temps(temp_c, len(d)))
        d = (d + self.offset_sign * self.offset) * self.scale_factor
        return d @ (self.rotation @ self.matrix).T

    def undo(self, corrected: Any, temp_c: Any = None) -> np.ndarray:
        """Raw readings back from what the autopilot logged (inverse of :meth:`apply`)."""
        if self.not_undoable:
            raise CalibrationError(self.not_undoable)
        c = np.array(corrected, dtype=float, ndmin=2)
        d = c @ np.linalg.inv(self.rotation @ self.matrix).T / self.scale_factor
        d = d - self.offset_sign * self.offset
        if self.thermal is not None:
            d = d + self.thermal(self._temps(temp_c, len(d)))
        return d

    def _temps(self, temp_c: Any, n: int) -> np.ndarray:
        if temp_c is None:
            raise CalibrationError(
                f"the {self.autopilot} {self.sensor} calibration has temperature terms: the "
                "sensor temperature is needed to apply or undo it"
            )
        t = np.broadcast_to(np.asarray(temp_c, float).ravel(), (n,))
        if not np.isfinite(t).all():
            raise CalibrationError("temperatures must be finite")
        return t

    @property
    def triaxcal_offset(self) -> np.ndarray:
        """The offset in triaxcal's convention (``calibrated = (raw - offset) @ matrix.T``)."""
        return -self.offset_sign * self.offset

    @property
    def triaxcal_matrix(self) -> np.ndarray:
        """The matrix in triaxcal's convention, in the sensor frame (rotation left out)."""
        return self.scale_factor * self.matrix

    def describe(self) -> str:
        """The parameters and the equation, in a few lines of text."""
        off = ", ".join(f"{v:.6g}" for v in self.offset)
        m = self.matrix
        lines = [f"{self.autopilot} {self.sensor} calibration (slot {self.index}, {self.unit}): "
                 f"{self.equation}",
                 f"  offset [{off}] {self.unit}; matrix diag [{m[0, 0]:.6g}, {m[1, 1]:.6g}, "
                 f"{m[2, 2]:.6g}] offdiag [{m[0, 1]:.6g}, {m[0, 2]:.6g}, {m[1, 2]:.6g}]"]
        if self.scale_factor != 1.0:
            lines.append(f"  scale factor {self.scale_factor:.6g}")
        if not np.allclose(self.rotation, np.eye(3)):
            lines.append("  rotation to body frame " + np.array2string(
                self.rotation, precision=4, suppress_small=True).replace("\n", ""))
        if self.thermal is not None:
            lines.append(f"  temperature terms over {self.thermal.tmin:g}..{self.thermal.tmax:g} "
                         f"degC, calibrated at {self.thermal.cal_temp:g} degC")
        lines.append(f"  source: {self.citation}")
        return "\n".join(lines)


@dataclass(frozen=True, eq=False)
class AutopilotCalibration:
    """The autopilot's calibration of each sensor stream of a log (parts may be missing)."""

    autopilot: str
    accel: AutopilotPart | None = None
    gyro: AutopilotPart | None = None
    mag: AutopilotPart | None = None

    @property
    def sensors(self) -> tuple[str, ...]:
        return tuple(s for s in ("accel", "gyro", "mag") if getattr(self, s) is not None)

    def part(self, sensor: str) -> AutopilotPart:
        p = getattr(self, sensor, None)
        if p is None:
            raise CalibrationError(f"the log's parameters hold no {self.autopilot} calibration "
                                   f"for the {sensor}")
        return p

    def describe(self) -> str:
        return "\n".join(self.part(s).describe() for s in self.sensors)


# --------------------------------------------------------------------------------------------
# PX4

_PX4_UNITS = {"accel": "m/s^2", "gyro": "rad/s", "mag": "gauss"}
_PX4_SOURCE = ("PX4-Autopilot src/lib/sensor_calibration/{cls}.hpp {cls}::Correct(); "
               "rotation: src/lib/conversion/rotation.h, Utilities.cpp GetSensorLevelAdjustment")
_PX4_EQ = {
    "accel": "body = R @ ((raw - thermal(T) - offset) * scale)",
    "gyro": "body = R @ ((raw - thermal(T) - offset) * scale)",
    "mag": "body = R @ (S @ (raw + power * comp - offset))",
}


def _num(params: Mapping[str, Any], name: str, default: float) -> float:
    v = params.get(name, default)
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise CalibrationError(f"parameter {name} is not a number: {v!r}") from None
    if not math.isfinite(f):
        raise CalibrationError(f"parameter {name} is not finite: {f}")
    return f


def _rotation_or_reason(make: Any) -> tuple[np.ndarray, str | None]:
    """The rotation ``make()`` builds, or the identity and why the data cannot be undone."""
    try:
        return make(), None
    except CalibrationError as exc:
        return np.eye(3), str(exc)


def px4_board_rotation(params: Mapping[str, Any]) -> np.ndarray:
    """``Dcm(Euler(SENS_BOARD_X/Y/Z_OFF)) @ rot(SENS_BOARD_ROT)``: board to body frame."""
    level = euler_matrix(*(_num(params, f"SENS_BOARD_{a}_OFF", 0.0) for a in "XYZ"))
    return level @ rotation_matrix(_num(params, "SENS_BOARD_ROT", 0), "px4", "SENS_BOARD_ROT")


def px4_index(params: Mapping[str, Any], sensor: str, device_id: int | None) -> int | None:
    """The ``CAL_<S>n`` slot of ``device_id`` (``CAL_<S>_PRIME`` when None); None if absent."""
    s = PX4_SENSOR[sensor]
    if device_id is None:
        prime = params.get(f"CAL_{s}_PRIME")
        device_id = int(prime) if prime not in (None, 0) else None
    for n in range(4):
        dev = params.get(f"{px4_prefix(sensor, n)}ID")
        if dev is None:
            continue
        if device_id is None:
            if int(dev) != 0:
                return n
        elif int(dev) == int(device_id):
            return n
    if device_id is None and f"{px4_prefix(sensor, 0)}XOFF" in params:
        return 0
    return None


def px4_part(params: Mapping[str, Any], sensor: str, index: int) -> AutopilotPart:
    """The PX4 calibration ``CAL_<S><index>_*`` of ``sensor`` as an :class:`AutopilotPart`."""
    p = px4_prefix(sensor, index)
    if f"{p}XOFF" not in params:
        raise CalibrationError(f"the log's parameters have no {p}XOFF: no PX4 {sensor} "
                               f"calibration in slot {index}")
    used: dict[str, float] = {}

    def get(name: str, default: float) -> float:
        v = _num(params, name, default)
        if name in params:
            used[name] = v
        return v

    offset = np.array([get(f"{p}{a}OFF", 0.0) for a in "XYZ"])
    scale = np.array([get(f"{p}{a}SCALE", 1.0) for a in "XYZ"])
    m = np.diag(scale)
    not_undoable = None
    if sensor == "mag":
        od = [get(f"{p}{a}ODIAG", 0.0) for a in "XYZ"]
        for k, (i, j) in enumerate(((0, 1), (0, 2), (1, 2))):
            m[i, j] = m[j, i] = od[k]
        comp = [get(f"{p}{a}COMP", 0.0) for a in "XYZ"]
        if _num(params, PX4_COMP_TYPE, 0) != 0 and any(comp):
            not_undoable = (f"PX4 magnetometer power compensation ({PX4_COMP_TYPE}, "
                            f"{p}COMP) depends on throttle/current, which the log's sensor topics "
                            "do not carry: use the raw sensor_mag topic instead")
        rot = _num(params, f"{p}ROT", -1)
        used[f"{p}ROT"] = rot
        r, why = _rotation_or_reason(lambda: px4_board_rotation(params) if rot < 0 else (
            euler_matrix(*(_num(params, f"SENS_BOARD_{a}_OFF", 0.0) for a in "XYZ"))
            @ rotation_matrix(rot, "px4", f"{p}ROT")))
    else:
        r, why = _rotation_or_reason(lambda: px4_board_rotation(params))
    not_undoable = not_undoable or why
    for name in ("SENS_BOARD_ROT", "SENS_BOARD_X_OFF", "SENS_BOARD_Y_OFF", "SENS_BOARD_Z_OFF"):
        if name in params:
            used[name] = _num(params, name, 0.0)
    if _num(params, PX4_TC_ENABLE[sensor], 0) == 1 and not_undoable is None:
        not_undoable = (f"{PX4_TC_ENABLE[sensor]} = 1: PX4 also subtracted temperature-dependent "
                        "offsets (TC_* parameters) and the combined topics carry no "
                        "temperature; use the raw per-sensor topic (--instance N) instead")
    cls = {"accel": "Accelerometer", "gyro": "Gyroscope", "mag": "Magnetometer"}[sensor]
    return AutopilotPart(
        sensor=sensor, autopilot="px4", index=index, unit=_PX4_UNITS[sensor], offset=offset,
        matrix=m, offset_sign=-1, rotation=r, equation=_PX4_EQ[sensor],
        citation=_PX4_SOURCE.format(cls=cls), params=used, not_undoable=not_undoable,
    )


def px4_calibration(params: Mapping[str, Any],
                    device_ids: Mapping[str, int | None] | None = None) -> AutopilotCalibration:
    """PX4's stored calibration of each sensor, found by device id (or ``CAL_<S>_PRIME``)."""
    parts: dict[str, AutopilotPart] = {}
    for sensor in ("accel", "gyro", "mag"):
        idx = px4_index(params, sensor, (device_ids or {}).get(sensor))
        if idx is not None and f"{px4_prefix(sensor, idx)}XOFF" in params:
            parts[sensor] = px4_part(params, sensor, idx)
    return AutopilotCalibration(autopilot="px4", **parts)


# --------------------------------------------------------------------------------------------
# ArduPilot

_AP_UNITS = {"accel": "m/s^2", "gyro": "rad/s", "mag": "mG"}


def ardupilot_part(params: Mapping[str, Any], sensor: str, index: int = 0) -> AutopilotPart:
    """ArduPilot's stored calibration of ``sensor`` number ``index`` (0-based)."""
    names = ardupilot_names(sensor, index)
    if f"{names['offset']}X" not in params:
        raise CalibrationError(f"the log's parameters have no {names['offset']}X: no ArduPilot "
                               f"{sensor} calibration for instance {index + 1}")
    used: dict[str, float] = {}

    def get(name: str, default: float) -> float:
        v = _num(params, name, default)
        if name in params:
            used[name] = v
        return v

    offset = np.array([get(f"{names['offset']}{a}", 0.0) for a in "XYZ"])
    if sensor == "mag":
        dia = np.array([get(f"{names['dia']}{a}", 1.0) for a in "XYZ"])
        if not dia.any():
            dia = np.ones(3)  # correct_field: all-zero diagonals are taken as 1
        odi = [get(f"{names['odi']}{a}", 0.0) for a in "XYZ"]
        m = np.diag(dia)
        for k, (i, j) in enumerate(((0, 1), (0, 2), (1, 2))):
            m[i, j] = m[j, i] = odi[k]
        s = get(names["scale"], 0.0)
        scale = s if 0.85 <= s <= 1.4 else 1.0  # Compass::have_scale_factor
        return AutopilotPart(
            sensor="mag", autopilot="ardupilot", index=index, unit="mG", offset=offset,
            matrix=m, offset_sign=+1, scale_factor=scale,
            equation="body = M @ ((raw + offset) * COMPASS_SCALE) + motor offset (body frame)",
            citation=("ArduPilot libraries/AP_Compass/AP_Compass_Backend.cpp correct_field; "
                      "AP_Compass.cpp Compass::have_scale_factor"),
            params=used,
        )
    if sensor == "accel":
        sc = np.array([get(f"{names['scale']}{a}", 1.0) for a in "XYZ"])
        if not sc.any():
            sc = np.ones(3)
        m = np.diag(sc)
        eq = "body = R_board @ ((raw - tcal(T) - offset) * scale)"
    else:
        m = np.eye(3)
        eq = "body = R_board @ (raw - tcal(T) - offset)"
    orient = _num(params, "AHRS_ORIENTATION", 0)
    used["AHRS_ORIENTATION"] = orient
    rotation, not_undoable = _rotation_or_reason(
        lambda: rotation_matrix(orient, "ardupilot", "AHRS_ORIENTATION"))
    thermal = None
    tp = names["tcal"]
    if _num(params, f"{tp}ENABLE", 0) == 1:
        coeff = np.array([[get(f"{tp}{names['coeff']}{k}_{a}", 0.0) for a in "XYZ"]
                          for k in (1, 2, 3)])
        thermal = ThermalPoly(coeff=coeff, tmin=get(f"{tp}TMIN", 0.0),
                              tmax=get(f"{tp}TMAX", 70.0),
                              cal_temp=get(names["caltemp"], -300.0))
    return AutopilotPart(
        sensor=sensor, autopilot="ardupilot", index=index, unit=_AP_UNITS[sensor],
        offset=offset, matrix=m, offset_sign=-1,
        rotation=rotation, thermal=thermal, equation=eq, not_undoable=not_undoable,
        citation=("ArduPilot libraries/AP_InertialSensor/AP_InertialSensor_Backend.cpp "
                  f"_rotate_and_correct_{sensor}; AP_InertialSensor_tempcal.cpp "
                  "TCal::correct_sensor"),
        params=used,
    )


def ardupilot_calibration(params: Mapping[str, Any], *, imu: int = 0,
                          compass: int = 0) -> AutopilotCalibration:
    """ArduPilot's stored calibration of IMU ``imu`` and compass ``compass`` (0-based)."""
    parts: dict[str, AutopilotPart] = {}
    for sensor, idx in (("accel", imu), ("gyro", imu), ("mag", compass)):
        if f"{ardupilot_names(sensor, idx)['offset']}X" in params:
            parts[sensor] = ardupilot_part(params, sensor, idx)
    return AutopilotCalibration(autopilot="ardupilot", **parts)
