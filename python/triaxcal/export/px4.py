"""PX4 parameters: ``CAL_ACCn_*``, ``CAL_GYROn_*``, ``CAL_MAGn_*`` and ``TC_*`` thermal terms,
as a QGroundControl parameter file (``.params``).

The equations PX4 applies (``src/lib/sensor_calibration/Accelerometer.hpp``,
``Gyroscope.hpp``, ``Magnetometer.hpp``, ``Correct()``; the same are in
:mod:`triaxcal.io.logs.autopilot`), in the sensor frame before the rotation to the body::

    accel = (raw - thermal(T) - CAL_ACCn_OFF) * CAL_ACCn_SCALE        (m/s^2)
    gyro  =  raw - thermal(T) - CAL_GYROn_OFF                          (rad/s, no scale)
    mag   = S @ (raw - CAL_MAGn_OFF)                                   (gauss)
    S = [[XSCALE, XODIAG, YODIAG], [XODIAG, YSCALE, ZODIAG], [YODIAG, ZODIAG, ZSCALE]]

Offsets are SUBTRACTED; scales MULTIPLY. ``Magnetometer::set_offdiagonal`` puts ``XODIAG``
at (0,1)/(1,0), ``YODIAG`` at (0,2)/(2,0), ``ZODIAG`` at (1,2)/(2,1); ``set_scale`` accepts only
positive scales. Thermal terms (``src/modules/temperature_compensation/
TemperatureCompensation.cpp`` ``calc_thermal_offsets_3D``)::

    thermal(T) = X0 + X1 dT + X2 dT^2 + X3 dT^3,  dT = clamp(T, TMIN, TMAX) - TREF

per axis (``TC_A0_X1_2`` is the first-order term of axis z), applied to the sensor whose
device id is ``TC_A0_ID`` when ``TC_A_ENABLE = 1``. triaxcal writes ``TREF`` = its reference
temperature, ``X0 = 0`` (the constant is in ``CAL_*_OFF``) and ``TMIN``/``TMAX`` = the fitted
range; PX4 holds the correction constant outside it, triaxcal extrapolates.

A magnetometer alignment (``cal.mag.alignment``) goes to ``CAL_MAGn_ROT`` (PX4 applies
``rotation * (S (raw - OFF))``, the rotation after the correction, so offsets and ``S`` stay in
the sensor frame); PX4 uses it for external magnetometers only and resets it to -1 for
internal ones (``Magnetometer::ParametersUpdate``). Only the right-angle part is held: more
than 1 deg left over warns (``AlignmentWarning``), none within 20 deg is refused.

The file is QGroundControl's parameter file: ``#`` comments and tab-separated lines
``vehicle-id  component-id  name  value  type`` (``type`` a MAV_PARAM_TYPE: 9 float, 6 int32),
which QGroundControl's parameter editor loads (``src/FactSystem/ParameterManager.cc``
``readParametersFromStream``; newer versions ``ParameterEditorController::buildDiffFromFile``)
and Mission Planner reads too.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from .._checks.spelling import in_command_line
from .._core import __version__
from ..calibration.file import Calibration
from ..conventions.autopilot import (
    PX4_COMP_CURRENT,
    PX4_COMP_THROTTLE,
    PX4_COMP_TYPE,
    PX4_SENSOR,
    PX4_TC,
    PX4_TC_ENABLE,
    px4_prefix,
    px4_tc_prefix,
)
from ..conventions.units import unit_factor
from ..errors import CalibrationError
from ._params import (
    Physical,
    f32,
    interference,
    mag_mounting,
    physical,
    pick_sensors,
    require_degree,
    require_diagonal,
    require_identity,
    require_no_gain_poly,
    require_symmetric,
)
from ._trust import Prepared, Scales, comment_lines, mark_lines, prepare
from .ardupilot import _comment

__all__ = ["MAV_PARAM_TYPE_INT32", "MAV_PARAM_TYPE_REAL32", "px4_omitted", "px4_params",
           "px4_params_file"]

FMT = "PX4"
MAV_PARAM_TYPE_INT32 = 6
MAV_PARAM_TYPE_REAL32 = 9
_CAL = PX4_SENSOR
_TC = PX4_TC
_UNITS = {"accel": "m/s^2", "gyro": "rad/s", "mag": "gauss"}


def _device_id(device_ids: Mapping[str, Any] | None, sensor: str,
               part: Any = None) -> tuple[int | None, str]:
    """The device id of ``sensor`` and where it came from: ``device_ids`` (the user's), else the
    log the part was fitted on (``stats["log"]["device_id"]``, or the stored calibration's
    ``CAL_<S>n_ID``), else None."""
    if device_ids and device_ids.get(sensor) is not None:
        return _check_id(device_ids[sensor], sensor), "given"
    stats = getattr(part, "stats", None) or {}
    log: Mapping[str, Any] = stats["log"] if isinstance(stats.get("log"), Mapping) else {}
    v = log.get("device_id") if log.get("format") == "px4-ulog" else None
    if v is None and isinstance(stats.get("autopilot"), Mapping):
        ap = stats["autopilot"]
        if ap.get("autopilot") == "px4" and isinstance(ap.get("params"), Mapping):
            slot = ap.get("slot")
            v = ap["params"].get(f"{px4_prefix(sensor, slot)}ID") if isinstance(slot, int) \
                and 0 <= slot <= 3 else None
            if isinstance(v, float) and v.is_integer():
                v = int(v)
    if v is None or v == 0:
        return None, ""
    return _check_id(v, sensor), "from the log"


def _check_id(v: Any, sensor: str) -> int:
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not 0 < int(v) < 2**32:
        raise CalibrationError(f"device id of the {sensor} must be a positive 32-bit whole "
                               f"number (the CAL_*_ID value), got {v!r}")
    return int(v)


def _positive(values: np.ndarray, name: str) -> np.ndarray:
    for i, a in enumerate("XYZ"):
        if not values[i] > 0:
            raise CalibrationError(
                f"{name.format(a=a)} = {values[i]:.6g}: PX4 accepts only positive scales "
                "(set_scale); a reflected axis means a sign or orientation error in the data"
            )
    return values


def _power_compensation(part: Any, p: Physical, n: int) -> list[tuple[str, float, int]]:
    """``CAL_MAGn_<X|Y|Z>COMP`` and ``CAL_MAG_COMP_TYP`` of a part with an interference term.

    PX4 adds ``power * COMP`` to the raw reading before the offset, in the sensor frame
    (``Magnetometer::Correct``), with ``power`` the battery current in kA or the throttle
    (``VehicleMagnetometer::UpdatePowerCompensation``); the part adds ``v * x`` after the matrix,
    so ``COMP = S^-1 v`` (gauss per kA: ``v`` in gauss per A times 1000)."""
    inter = interference(part)
    if inter is None:
        return []
    per, vec = inter
    g = vec * unit_factor(part.unit, "gauss") * (1000.0 if per == "A" else 1.0)
    comp = np.linalg.solve(p.matrix, g)
    prefix = px4_prefix("mag", n)
    out = [(f"{prefix}{a}COMP", float(comp[i]), MAV_PARAM_TYPE_REAL32)
           for i, a in enumerate("XYZ")]
    out.append((PX4_COMP_TYPE, float(PX4_COMP_CURRENT if per == "A" else PX4_COMP_THROTTLE),
                MAV_PARAM_TYPE_INT32))
    return out


def px4_params(
    cal: Calibration,
    *,
    instance: int = 0,
    sensors: Iterable[str] | None = None,
    counts_per_unit: Mapping[str, Any] | None = None,
    device_ids: Mapping[str, int] | None = None,
    sensor_model: str | Sequence[str] | None = None,
    force: bool = False,
) -> list[tuple[str, float, int]]:
    """PX4 parameters ``(name, value, MAV_PARAM_TYPE)`` for the parts of ``cal``.

    Parameters
    ----------
    cal : Calibration
        Readings in (or convertible to) PX4's units: m/s^2, rad/s, gauss, in the sensor frame
        (PX4 rotates after the correction; ``read_log(..., instance=N)`` on a PX4 v1.12+ log
        gives such readings).
    instance : int
        The calibration slot ``n`` of ``CAL_ACCn_*`` etc. (0..3).
    sensors : iterable of str, optional
        Which parts to write (default: every part present).
    counts_per_unit : dict, optional
        The driver's scale for parts in raw counts.
    device_ids : dict, optional
        Device ids by sensor (``CAL_ACC0_ID`` of the vehicle): written as ``CAL_*n_ID``, and
        required for thermal terms, which PX4 applies by ``TC_*n_ID``. Without one, the id the
        log recorded for the part is used (a part fitted on a PX4 log); with neither,
        ``CAL_*n_ID`` is not written and :func:`px4_params_file` says so.
    sensor_model : str or list of str, optional
        The part(s) whose datasheet scale converts raw counts (see :func:`ardupilot_params`).
    force : bool
        Write parts the validity gate refuses; :func:`px4_params_file` marks the file.

    A part fitted on readings PX4 had already corrected is written as the composed absolute
    calibration, or refused with the reason.

    Returns
    -------
    list of (name, value, type)
        ``type`` is ``MAV_PARAM_TYPE_REAL32`` (9) or ``MAV_PARAM_TYPE_INT32`` (6).
    """
    return _px4(cal, instance=instance, sensors=sensors, counts_per_unit=counts_per_unit,
                device_ids=device_ids, sensor_model=sensor_model, force=force)[0]


def _px4(cal: Calibration, *, instance: int = 0, sensors: Iterable[str] | None = None,
         counts_per_unit: Mapping[str, Any] | None = None,
         device_ids: Mapping[str, int] | None = None,
         sensor_model: str | Sequence[str] | None = None, force: bool = False
         ) -> tuple[list[tuple[str, float, int]], Prepared, list[str]]:
    chosen = pick_sensors(cal, sensors, ("accel", "gyro", "mag"), FMT)
    original = cal
    prep = prepare(cal, chosen, fmt="PX4 parameters", force=force)
    cal = prep.cal
    scales = Scales(counts_per_unit, sensor_model)
    omitted: list[str] = []
    if isinstance(instance, bool) or not isinstance(instance, int) or not 0 <= instance <= 3:
        raise CalibrationError(f"instance must be 0..3 (PX4's calibration slots), got {instance!r}")
    n = instance
    out: list[tuple[str, float, int]] = []
    real, i32 = MAV_PARAM_TYPE_REAL32, MAV_PARAM_TYPE_INT32
    for sensor in chosen:
        cp, tp = px4_prefix(sensor, n), px4_tc_prefix(sensor, n)
        p: Physical = physical(cal.part(sensor), sensor, _UNITS[sensor], _UNITS[sensor],
                               scales, fmt=FMT)
        dev, _ = _device_id(device_ids, sensor, original.part(sensor))
        if dev is not None:
            out.append((f"{cp}ID", float(dev), i32))
        else:
            omitted.append(
                f"{cp}ID not written: the {sensor}'s device id is not known (give it with "
                + (f"--device-id {sensor}=ID" if in_command_line() else
                   f"device_ids={{{sensor!r}: ID}}")
                + f", the vehicle's {cp}ID), "
                f"so these values apply to whichever device the vehicle's {cp}ID names")
        offset = p.offset
        for i, a in enumerate("XYZ"):
            out.append((f"{cp}{a}OFF", float(offset[i]), real))
        if sensor == "accel":
            scale = _positive(require_diagonal(p, FMT, f"{cp}xSCALE"),
                              f"{cp}{{a}}SCALE")
            for i, a in enumerate("XYZ"):
                out.append((f"{cp}{a}SCALE", float(scale[i]), real))
        elif sensor == "gyro":
            require_identity(p, FMT)
        else:
            require_symmetric(p, FMT)
            m = p.matrix
            _positive(np.diag(m).copy(), f"{cp}{{a}}SCALE")
            for i, a in enumerate("XYZ"):
                out.append((f"{cp}{a}SCALE", float(m[i, i]), real))
            for (i, j), a in zip(((0, 1), (0, 2), (1, 2)), "XYZ"):
                out.append((f"{cp}{a}ODIAG", float(m[i, j]), real))
            mnt = mag_mounting(cal, FMT, f"{cp}ROT")
            if mnt is not None:
                out.append((f"{cp}ROT", float(mnt.number), i32))
            out += _power_compensation(cal.part("mag"), p, n)
        if p.offset_poly is None:
            # fitted without thermal terms: the vehicle's own would be subtracted on top
            out.append((PX4_TC_ENABLE[sensor], 0.0, i32))
            continue
        require_no_gain_poly(p, FMT)
        require_degree(p, FMT, 3)
        if dev is None:
            raise CalibrationError(
                f"PX4 applies thermal terms {tp}* only to the sensor whose device id is "
                f"{tp}ID: pass device_ids={{'{sensor}': <{cp}ID of the vehicle>}} "
                "(--device-id on the command line)"
            )
        poly = np.zeros((4, 3))
        poly[: len(p.offset_poly)] = p.offset_poly
        lo, hi = p.temp_range_c or (p.temp_ref_c, p.temp_ref_c)
        out += [(PX4_TC_ENABLE[sensor], 1.0, i32), (f"{tp}ID", float(dev), i32),
                (f"{tp}TREF", float(p.temp_ref_c or 0.0), real),
                (f"{tp}TMIN", float(lo or 0.0), real),
                (f"{tp}TMAX", float(hi or 0.0), real)]
        for k in range(4):
            for i in range(3):
                out.append((f"{tp}X{k}_{i}", float(poly[k, i]), real))
    return out, prep, omitted


def px4_params_file(
    cal: Calibration, *, system_id: int = 1, component_id: int = 1, **kwargs: Any
) -> str:
    """QGroundControl ``.params`` text of :func:`px4_params` (same keyword options).

    Examples
    --------
    >>> import numpy as np, triaxcal as tc
    >>> part = tc.SensorCalibration(offset=[0.1, -0.2, 0.05], matrix=np.diag([1.01, 0.99, 1.0]),
    ...                             raw_unit="m/s^2", unit="m/s^2")
    >>> text = tc.px4_params_file(tc.Calibration(accel=part))
    >>> [ln.split("\\t")[2:4] for ln in text.splitlines() if "XSCALE" in ln]
    [['CAL_ACC0_XSCALE', '1.01']]
    """
    for name, v in (("system_id", system_id), ("component_id", component_id)):
        if isinstance(v, bool) or not isinstance(v, int) or not 1 <= v <= 255:
            raise CalibrationError(f"{name} must be a MAVLink id 1..255, got {v!r}")
    params, prep, omitted = _px4(cal, **kwargs)
    lines = [
        f"# Onboard parameters for Vehicle {system_id}",
        "#",
        f"# Calibration written by triaxcal {__version__}; sensor id "
        f"{_comment(cal.sensor_id) or '(none)'}; created {_comment(cal.created_utc)}",
        "# accel = (raw - thermal - CAL_ACCn_OFF) * CAL_ACCn_SCALE; gyro = raw - thermal - "
        "CAL_GYROn_OFF; mag = R S (raw - CAL_MAGn_OFF), R = CAL_MAGn_ROT (external magnetometers)",
        *(["# with CAL_MAG_COMP_TYP: mag = R S ((raw + power * CAL_MAGn_xCOMP) - OFF), power = "
           "battery current in kA (2) or throttle 0..1 (1)"]
          if any(name == PX4_COMP_TYPE for name, _, _ in params) else []),
        *comment_lines((*mark_lines(prep.invalid), *prep.notes, *omitted)),
        "#",
        "# Vehicle-Id Component-Id Name Value Type",
    ]
    for name, value, kind in params:
        text = str(int(value)) if kind == MAV_PARAM_TYPE_INT32 else f32(value, name)
        lines.append(f"{system_id}\t{component_id}\t{name}\t{text}\t{kind}")
    return "\n".join(lines) + "\n"


def px4_omitted(cal: Calibration, **kwargs: Any) -> list[str]:
    """What :func:`px4_params` leaves out for want of information (the device ids it does
    not know), in words; the same lines :func:`px4_params_file` writes as comments."""
    return _px4(cal, **kwargs)[2]
