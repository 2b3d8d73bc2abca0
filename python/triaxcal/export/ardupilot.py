"""ArduPilot parameter file (``.parm``): ``COMPASS_*``, ``INS_ACC*``, ``INS_GYR*``, ``INS_TCALn_*``.

The equations ArduPilot applies (read from its source; the same are in
:mod:`triaxcal.io.logs.autopilot`):

* compass, ``libraries/AP_Compass/AP_Compass_Backend.cpp`` ``correct_field``::

      field = M @ ((raw + COMPASS_OFS) * COMPASS_SCALE),
      M = [[DIA_X, ODI_X, ODI_Y], [ODI_X, DIA_Y, ODI_Z], [ODI_Y, ODI_Z, DIA_Z]]

  in milligauss, in the body frame (the rotation is applied before the correction). The
  offsets are ADDED, so ``COMPASS_OFS = -offset``. ``COMPASS_SCALE`` is used only within
  0.85..1.4 (``Compass::have_scale_factor``; its documented range is 0..1.3).
* accelerometer / gyroscope, ``libraries/AP_InertialSensor/AP_InertialSensor_Backend.cpp``
  ``_rotate_and_correct_accel`` / ``_rotate_and_correct_gyro``, in the sensor frame::

      accel = (raw - tcal(T) - INS_ACCOFFS) * INS_ACCSCAL     (m/s^2; offsets SUBTRACTED)
      gyro  =  raw - tcal(T) - INS_GYROFFS                    (rad/s; no gyro scale)

* temperature, ``libraries/AP_InertialSensor/AP_InertialSensor_tempcal.cpp``
  ``TCal::correct_sensor`` / ``polynomial_eval``::

      tcal(T) = P(clamp(T) - 35) - P(clamp(INS_ACCn_CALTEMP) - 35)
      P(x) = (ACC1 * x + ACC2 * x^2 + ACC3 * x^3) * 1e-6,  clamp to [TMIN, TMAX]

  (35 deg C is ``TEMP_REFERENCE``; the coefficients are stored times 1e6, ``SCALE_FACTOR``).
  triaxcal writes ``CALTEMP`` = its reference temperature and re-expands its offset
  polynomial about 35 deg C, so both agree exactly inside ``[TMIN, TMAX]`` (set to the fitted
  range); ArduPilot holds the correction constant outside it, triaxcal extrapolates.

A magnetometer alignment (``cal.mag.alignment``, magnetometer frame to accelerometer frame)
goes to ``COMPASS_ORIENTn``, which ArduPilot applies to external compasses *before* the
correction (``AP_Compass_Backend::rotate_field``, ``Vector3::rotate``; internal compasses
follow the board orientation instead): ``field = M_b ((R raw + OFS_b) * SCALE)`` with
``M_b = R M R^T`` and ``OFS_b = -R offset``, which is the aligned calibration
``R M (raw - offset)`` exactly. Only the right-angle part ``R`` is held: more than 1 deg left
over warns (``AlignmentWarning``), no right-angle rotation within 20 deg is refused.

What the format cannot hold is refused with the reason: cross-axis accelerometer terms, any
gyroscope gain, a non-symmetric compass matrix, temperature-dependent gains, polynomials of
degree above 3, and values outside ArduPilot's accepted ranges (``INS_ACCSCAL`` 0.8..1.2,
``INS_ACCOFFS`` +-3.5 m/s^2; compass ``DIA`` 0.2..5, ``|ODI|`` < 1, offsets within
``COMPASS_OFFS_MAX`` (default 1800 mG), field 150..950 mG -- ``CompassCalibrator::
fit_acceptable``). The file is ``NAME,VALUE`` lines with ``#`` comments, which Mission
Planner, MAVProxy (``param load``) and ArduPilot's own defaults parser
(``AP_Param::parse_param_line``) read.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from .._core import __version__
from ..calibration.file import Calibration
from ..conventions.autopilot import (
    AP_MOTCT_CURRENT,
    AP_MOTCT_THROTTLE,
    ardupilot_names,
)
from ..errors import CalibrationError
from ._params import (
    Physical,
    _factor,
    check_range,
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
    shift_poly,
)
from ._trust import Prepared, Scales, comment_lines, mark_lines, prepare

__all__ = ["ardupilot_params", "ardupilot_parm"]

FMT = "ArduPilot"
TEMP_REFERENCE_C = 35.0  # AP_InertialSensor_tempcal.cpp TEMP_REFERENCE
TCAL_SCALE = 1.0e6  # AP_InertialSensor_tempcal.cpp SCALE_FACTOR


def _compass(p: Physical, index: int, scale_mode: Any, offsets_max: float) -> dict[str, float]:
    require_symmetric(p, FMT)
    if p.offset_poly is not None:
        raise CalibrationError("ArduPilot applies no temperature correction to the compass; "
                               "this calibration's magnetometer has temperature terms")
    names = ardupilot_names("mag", index)
    ofs, dia, odi, sc = names["offset"], names["dia"], names["odi"], names["scale"]
    m = p.matrix
    det = float(np.linalg.det(m))
    if det <= 0:
        raise CalibrationError("the magnetometer matrix is not positive definite (determinant "
                               f"{det:.3g}): ArduPilot's soft-iron matrix cannot hold a reflection")
    if scale_mode == "auto":
        s = det ** (1.0 / 3.0)
        scale = s if 0.85 <= s <= 1.3 else 0.0
    elif scale_mode in (None, False, 0):
        scale = 0.0
    else:
        scale = float(scale_mode)
        check_range(scale, 0.85, 1.3, sc,
                    "ArduPilot ignores COMPASS_SCALE outside 0.85..1.4 (Compass::"
                    "have_scale_factor) and documents 0..1.3")
    shape = m / scale if scale else m
    out: dict[str, float] = {}
    if p.scale_source is not None:
        why = (f"the part is in raw counts, converted with {p.scale_source}: if that is not "
               "the scale the vehicle's compass driver uses, every offset is wrong by the "
               "ratio; if it is, the hard iron is larger than ArduPilot accepts (a magnet or "
               "steel next to the compass)")
    else:
        why = ("the hard iron is larger than ArduPilot accepts: a magnet or steel next to the "
               "compass; move the compass away from it (or raise COMPASS_OFFS_MAX, offsets_max=)")
    for i, a in enumerate("XYZ"):
        out[f"{ofs}{a}"] = check_range(
            -float(p.offset[i]), -offsets_max, offsets_max, f"{ofs}{a}",
            f"ArduPilot refuses compass offsets beyond COMPASS_OFFS_MAX ({offsets_max:g} mG; "
            f"default 1800, at most 3000); {why}")
    for i, a in enumerate("XYZ"):
        out[f"{dia}{a}"] = check_range(
            float(shape[i, i]), 0.2, 5.0, f"{dia}{a}",
            "ArduPilot accepts soft-iron diagonals only within 0.2..5 "
            "(CompassCalibrator::fit_acceptable)" + ("" if p.scale_source is None else
                                                     f"; the scale used: {p.scale_source}"))
    for (i, j), a in zip(((0, 1), (0, 2), (1, 2)), "XYZ"):
        v = float(shape[i, j])
        if not abs(v) < 1.0:
            raise CalibrationError(f"{odi}{a} = {v:.6g}: ArduPilot accepts soft-iron "
                                   "off-diagonals only within (-1, 1) "
                                   "(CompassCalibrator::fit_acceptable)")
        out[f"{odi}{a}"] = v
    out[sc] = scale
    if p.radius is not None:
        check_range(p.radius, 150.0, 950.0, "the calibrated field strength (mG)",
                    "ArduPilot's calibrator accepts fields of 150..950 mG only "
                    "(CompassCalibrator::fit_acceptable); check the calibration's units")
    return out


def _motor(part: Any, index: int, mounting: Any) -> dict[str, float]:
    """``COMPASS_MOTn_*`` and ``COMPASS_MOTCT`` of a part with an interference term
    (``stats["interference"]``: the field per A or per unit of throttle ADDED after the matrix,
    exactly where ``correct_field`` adds ``COMPASS_MOT * current`` or ``* throttle``); nothing
    for a part without one."""
    inter = interference(part)
    if inter is None:
        return {}
    per, vec = inter
    mg = vec * _factor(part.unit, "mG", "mag", FMT, "calibrated")
    if mounting is not None:
        mg = mounting.matrix @ mg
    names = ardupilot_names("mag", index)
    out = {f"{names['mot']}{a}": check_range(
        float(mg[i]), -1000.0, 1000.0, f"{names['mot']}{a}",
        "ArduPilot's range of COMPASS_MOT is -1000..1000 mG per A (or per full throttle)")
        for i, a in enumerate("XYZ")}
    out[names["motct"]] = float(AP_MOTCT_CURRENT if per == "A" else AP_MOTCT_THROTTLE)
    return out


def _tcal_coeff(p: Physical) -> tuple[np.ndarray, float]:
    """ArduPilot ``ACC1..3`` (or ``GYR1..3``) rows and the offset at the reference."""
    require_no_gain_poly(p, FMT)
    require_degree(p, FMT, 3)
    assert p.offset_poly is not None and p.temp_ref_c is not None
    poly = np.zeros((4, 3))
    poly[: len(p.offset_poly)] = p.offset_poly
    q = shift_poly(poly, TEMP_REFERENCE_C - p.temp_ref_c)  # q(x) = poly(x + 35 - Tref)
    return q[1:4] * TCAL_SCALE, poly[0]


def ardupilot_params(
    cal: Calibration,
    *,
    imu: int = 0,
    compass: int = 0,
    sensors: Iterable[str] | None = None,
    counts_per_unit: Mapping[str, Any] | None = None,
    sensor_model: str | Sequence[str] | None = None,
    compass_scale: Any = "auto",
    offsets_max: float = 1800.0,
    force: bool = False,
) -> dict[str, float]:
    """ArduPilot parameters (name -> value) for the parts of ``cal``.

    Parameters
    ----------
    cal : Calibration
        Readings must be in (or convertible to) ArduPilot's units: m/s^2, rad/s, milligauss
        (raw counts are converted with ``counts_per_unit``, as for the MotionCal packet).
        Fit the accelerometer and gyroscope in the sensor frame and the compass in the body
        frame, as ArduPilot applies them (``read_log(..., undo_autopilot_cal=True)`` gives
        exactly those readings from a DataFlash log).
    imu, compass : int
        Which IMU / compass (0-based): 0 writes ``INS_ACCOFFS_*``, ``COMPASS_OFS_*``; 1 writes
        ``INS_ACC2OFFS_*``, ``COMPASS_OFS2_*``; 2 the third.
    sensors : iterable of str, optional
        Which parts to write (default: every part present).
    counts_per_unit : dict, optional
        The driver's scale for parts in raw counts: ``{"mag": (6.6667, "uT")}``. No scale is
        assumed: a part in counts without one (here or from ``sensor_model``) is refused.
    sensor_model : str or list of str, optional
        The part(s), e.g. ``"ICM-20948"`` or ``"MPU-6050:2g,250dps"``: their datasheet scales
        (:mod:`triaxcal.conventions.sensors`); ``counts_per_unit`` wins.
    compass_scale : "auto", float or None
        ``"auto"``: the matrix's geometric-mean gain goes to ``COMPASS_SCALE`` when within
        0.85..1.3 (``DIA``/``ODI`` keep the shape, as ArduPilot's calibrator stores them),
        otherwise into ``DIA``/``ODI`` with ``COMPASS_SCALE = 0`` (off). ``None``: always the
        latter. A number: that scale. Firmware without ``COMPASS_SCALE`` (before 4.0) needs
        ``None``.
    offsets_max : float
        The vehicle's ``COMPASS_OFFS_MAX`` in mG (default 1800, ArduPilot's default).
    force : bool
        Write parts the validity gate refuses (:func:`triaxcal.calibration.gate.require_valid`);
        :func:`ardupilot_parm` then marks the file.

    A part fitted on readings ArduPilot had already corrected is written as the composed
    absolute calibration (:mod:`triaxcal.export._trust`), or refused with the reason.

    Returns
    -------
    dict
        Parameter name -> value, in the order written.
    """
    return _ardupilot(cal, imu=imu, compass=compass, sensors=sensors,
                      counts_per_unit=counts_per_unit, sensor_model=sensor_model,
                      compass_scale=compass_scale, offsets_max=offsets_max, force=force)[0]


def _ardupilot(cal: Calibration, *, imu: int = 0, compass: int = 0,
               sensors: Iterable[str] | None = None,
               counts_per_unit: Mapping[str, Any] | None = None,
               sensor_model: str | Sequence[str] | None = None, compass_scale: Any = "auto",
               offsets_max: float = 1800.0, force: bool = False
               ) -> tuple[dict[str, float], Prepared]:
    chosen = pick_sensors(cal, sensors, ("accel", "gyro", "mag"), FMT)
    prep = prepare(cal, chosen, fmt="ArduPilot parameters", force=force)
    cal = prep.cal
    scales = Scales(counts_per_unit, sensor_model)
    for name, v in (("imu", imu), ("compass", compass)):
        if not isinstance(v, int) or not 0 <= v <= 2:
            raise CalibrationError(f"{name} must be 0, 1 or 2 (ArduPilot's first three), got {v!r}")
    out: dict[str, float] = {}
    tcal: dict[str, tuple[np.ndarray, Physical]] = {}
    acc_names, gyr_names = ardupilot_names("accel", imu), ardupilot_names("gyro", imu)
    if "accel" in chosen:
        p = physical(cal.part("accel"), "accel", "m/s^2", "m/s^2", scales, fmt=FMT)
        scale = require_diagonal(p, FMT, "INS_ACCSCAL")
        offset = p.offset.copy()
        if p.offset_poly is not None:
            coeff, const = _tcal_coeff(p)
            offset = offset + const
            tcal[acc_names["coeff"]] = (coeff, p)
        for i, a in enumerate("XYZ"):
            out[f"{acc_names['offset']}{a}"] = check_range(
                float(offset[i]), -3.5, 3.5, f"{acc_names['offset']}{a}",
                "ArduPilot's accelerometer offsets range is +-3.5 m/s^2")
        for i, a in enumerate("XYZ"):
            out[f"{acc_names['scale']}{a}"] = check_range(
                float(scale[i]), 0.8, 1.2, f"{acc_names['scale']}{a}",
                "ArduPilot accepts accelerometer scales within 0.8..1.2 (AccelCalibrator "
                "accept_result); check the calibration's units")
    if "gyro" in chosen:
        p = physical(cal.part("gyro"), "gyro", "rad/s", "rad/s", scales, fmt=FMT)
        require_identity(p, FMT)
        offset = p.offset.copy()
        if p.offset_poly is not None:
            coeff, const = _tcal_coeff(p)
            offset = offset + const
            tcal[gyr_names["coeff"]] = (coeff, p)
        name = gyr_names["offset"]
        for i, a in enumerate("XYZ"):
            out[f"{name}{a}"] = float(offset[i])
    if "accel" in chosen or "gyro" in chosen:
        prefix = acc_names["tcal"]
        if tcal:
            temps = [float(t) for _, p in tcal.values()
                     for t in (*(p.temp_range_c or ()), p.temp_ref_c) if t is not None]
            lo, hi = min(temps), max(temps)
            check_range(lo, -70.0, 80.0, f"{prefix}TMIN", "ArduPilot's range is -70..80 degC")
            check_range(hi, -70.0, 80.0, f"{prefix}TMAX", "ArduPilot's range is -70..80 degC")
            out[f"{prefix}ENABLE"] = 1.0
            out[f"{prefix}TMIN"] = lo
            out[f"{prefix}TMAX"] = hi
            for kind in (acc_names["coeff"], gyr_names["coeff"]):
                coeff = tcal[kind][0] if kind in tcal else np.zeros((3, 3))
                for k in range(3):
                    for i, a in enumerate("XYZ"):
                        out[f"{prefix}{kind}{k + 1}_{a}"] = float(coeff[k, i])
            for kind, (_, p) in tcal.items():
                caltemp = (acc_names if kind == acc_names["coeff"] else gyr_names)["caltemp"]
                out[caltemp] = float(p.temp_ref_c or 0.0)
        else:
            # the fit knows no temperature terms: a vehicle's old ones would be applied on top
            out[f"{prefix}ENABLE"] = 0.0
    if "mag" in chosen:
        p = physical(cal.part("mag"), "mag", "mG", "mG", scales, fmt=FMT)
        mag_names = ardupilot_names("mag", compass)
        mnt = mag_mounting(cal, FMT, mag_names["orient"])
        if mnt is not None:  # ArduPilot corrects after rotating: offsets and matrix turn too
            r = mnt.matrix
            p = replace(p, offset=r @ p.offset, matrix=r @ p.matrix @ r.T)
        out.update(_compass(p, compass, compass_scale, float(offsets_max)))
        if mnt is not None:
            out[mag_names["orient"]] = float(mnt.number)
        out.update(_motor(cal.part("mag"), compass, mnt))
    return out, prep


def ardupilot_parm(cal: Calibration, **kwargs: Any) -> str:
    """The ``.parm`` text (``NAME,VALUE`` lines) of :func:`ardupilot_params` (same options).

    Examples
    --------
    >>> import numpy as np, triaxcal as tc
    >>> part = tc.SensorCalibration(offset=[120, -40, 15], matrix=np.eye(3) * 1.02,
    ...                             raw_unit="mG", unit="mG")
    >>> text = tc.ardupilot_parm(tc.Calibration(mag=part))
    >>> [ln for ln in text.splitlines() if ln.startswith("COMPASS_OFS_")]
    ['COMPASS_OFS_X,-120', 'COMPASS_OFS_Y,40', 'COMPASS_OFS_Z,-15']
    """
    params, prep = _ardupilot(cal, **kwargs)
    head = [
        f"# ArduPilot parameters written by triaxcal {__version__}",
        f"# sensor id: {_comment(cal.sensor_id) or '(none)'}; created "
        f"{_comment(cal.created_utc)}",
        "# compass: field = M @ ((raw + COMPASS_OFS) * COMPASS_SCALE)   [mG, body frame]",
        "#          (COMPASS_ORIENT, when written, rotates raw first; external compasses only)",
        *(["#          + COMPASS_MOT * (battery current in A if COMPASS_MOTCT = 2, throttle "
           "0..1 if 1)"] if "COMPASS_MOTCT" in params else []),
        "# accel:   (raw - tcal(T) - INS_ACCOFFS) * INS_ACCSCAL          [m/s^2, sensor frame]",
        "# gyro:     raw - tcal(T) - INS_GYROFFS                          [rad/s, sensor frame]",
        "# Gyro offsets are measured again at every boot unless INS_GYR_CAL = 0.",
        *comment_lines((*mark_lines(prep.invalid), *prep.notes)),
    ]
    lines = [f"{name},{f32(v, name)}" for name, v in params.items()]
    return "\n".join(head + lines) + "\n"


def _comment(text: str) -> str:
    """Text safe inside a one-line ``#`` comment."""
    return "".join(ch if ch.isprintable() else "?" for ch in str(text))[:120]
