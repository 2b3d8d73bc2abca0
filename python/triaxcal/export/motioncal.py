"""The PJRC MotionCal packet for a :class:`~triaxcal.Calibration`.

The packet itself (bytes, CRC, the board's ``Cal1:``/``Cal2:`` echo) is
:mod:`triaxcal.io.motioncal`; this module converts a calibration into its values.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from .._checks.spelling import opt
from ..calibration.file import Calibration
from ..calibration.part import SensorCalibration
from ..conventions.rotations import rotation_angle_deg
from ..conventions.units import unit_factor
from ..errors import CalibrationError
from ..io.motioncal import encode_motioncal
from ._trust import Scales, prepare

__all__ = ["motioncal_losses", "motioncal_packet"]

#: A gain or cross-axis term further than this from the driver's nominal scale (relative) is
#: a calibration term the packet would lose.
GAIN_TOLERANCE = 1e-3


def _driver_scale(part: SensorCalibration, sensor: str, scales: Scales) -> tuple[float, str]:
    """(driver units per raw unit, driver unit name) for converting ``part`` to MotionCal; a
    part in raw counts needs the driver's scale from ``scales`` (none is assumed)."""
    if part.raw_unit != "counts":
        return 1.0, part.raw_unit
    target = {"accel": "m/s^2", "gyro": "rad/s", "mag": "uT"}[sensor]
    sc = scales.get(sensor, "the MotionCal packet", target)
    return 1.0 / sc.counts_per_unit, sc.unit


def motioncal_losses(
    cal: Calibration, *, counts_per_unit: Mapping[str, Any] | None = None,
    sensor_model: str | Sequence[str] | None = None,
) -> list[str]:
    """What of ``cal`` the MotionCal packet cannot carry, in words (empty: nothing is lost).

    The packet (Adafruit_Sensor_Calibration's ``accel_zerog``, ``gyro_zerorate``, ``mag_hardiron``,
    ``mag_softiron``, ``mag_field``) holds offsets for the accelerometer and the gyroscope and
    no temperature terms: their gains and cross-axis terms beyond the driver's nominal scale,
    and every temperature polynomial, stay out.

    >>> import numpy as np, triaxcal as tc
    >>> part = tc.SensorCalibration(offset=[10, 0, 0], matrix=np.diag([1.02, 1, 1]) / 16384,
    ...                             unit="g")
    >>> motioncal_losses(tc.Calibration(accel=part), counts_per_unit={"accel": (16384, "g")}
    ...                  )[0][:62]
    'accelerometer: gains and cross-axis terms up to 2 % from the d'
    """
    out: list[str] = []
    scales = Scales(counts_per_unit, sensor_model)
    for sensor, name in (("accel", "accelerometer"), ("gyro", "gyroscope")):
        part = cal.part(sensor) if sensor in cal.sensors else None
        if part is None:
            continue
        k, u = _driver_scale(part, sensor, scales)
        # the correction left after the driver's nominal scale, in calibrated units per unit
        conv = 1.0 if part.unit == part.raw_unit else unit_factor(u, part.unit)
        corr = part.matrix / (k * conv)
        dev = float(abs(corr - np.eye(3)).max())
        if dev > GAIN_TOLERANCE:
            out.append(
                f"{name}: gains and cross-axis terms up to {100 * dev:.3g} % from the driver's "
                "nominal scale (the packet holds its offsets only)")
    for sensor in cal.sensors:
        if cal.part(sensor).temperature is not None:
            out.append(f"{sensor}: temperature terms (the packet has none)")
    return out


def motioncal_packet(
    cal: Calibration,
    *,
    counts_per_unit: Mapping[str, Any] | None = None,
    offsets_only: bool = False,
    sensor_model: str | Sequence[str] | None = None,
    force: bool = False,
) -> bytes:
    """The MotionCal packet for ``cal``.

    The packet's model is Adafruit_Sensor_Calibration's: the board's driver turns counts into
    m/s^2, rad/s and uT with its fixed nominal scale, then subtracts the offsets and (for the
    magnetometer) multiplies by the soft-iron matrix. So, with ``k`` the driver's units per
    count: offsets are ``k * offset`` and the soft-iron matrix is ``matrix / k`` (converted to
    uT per uT). Missing parts give zero offsets / the identity.

    Parameters
    ----------
    cal : Calibration
    counts_per_unit : dict, optional
        The driver's scale per sensor, as ``{"accel": (16384, "g"), "mag": (10, "uT")}``.
        There is no default: a part in raw counts without a scale (here or from
        ``sensor_model``) is refused, naming the sensor. Ignored for parts whose raw unit is
        already physical.
    sensor_model : str or list of str, optional
        The part(s) whose datasheet scale converts raw counts
        (:mod:`triaxcal.conventions.sensors`).
    force : bool
        Write parts the validity gate refuses (a binary packet cannot say so: the caller
        must).
    offsets_only : bool
        Accept that the packet loses what :func:`motioncal_losses` lists (the accelerometer's
        and gyroscope's gains, temperature terms). Without it such a calibration is refused,
        so that no term is dropped unnoticed.
    """
    if not isinstance(offsets_only, bool):
        raise CalibrationError(f"offsets_only must be True or False, got {offsets_only!r}")
    cal = prepare(cal, fmt="a MotionCal packet", force=force).cal
    scales = Scales(counts_per_unit, sensor_model)
    lost = motioncal_losses(cal, counts_per_unit=counts_per_unit, sensor_model=sensor_model)
    if lost and not offsets_only:
        raise CalibrationError(
            "the MotionCal packet cannot carry all of this calibration: " + "; ".join(lost)
            + f". Export {opt('fmt', 'c', flag='--format')} (or c-fixed) to keep every term, "
            f"or accept the loss with {opt('offsets_only', True)}")
    kw: dict[str, Any] = {}
    if cal.accel is not None:
        k, u = _driver_scale(cal.accel, "accel", scales)
        kw["accel_offset"] = cal.accel.offset * k * unit_factor(u, "m/s^2")
    if cal.gyro is not None:
        k, u = _driver_scale(cal.gyro, "gyro", scales)
        kw["gyro_offset"] = cal.gyro.offset * k * unit_factor(u, "rad/s")
    if cal.mag is not None:
        al = cal.mag.alignment
        if al is not None and rotation_angle_deg(al.rotation) > 0.01:
            raise CalibrationError(
                "the MotionCal packet holds a symmetric soft-iron matrix and no rotation; this "
                f"magnetometer is aligned to the {al.to} by {rotation_angle_deg(al.rotation):.2f}"
                " deg: export --format adafruit (its soft-iron matrix holds the rotation) or c, "
                "or drop the alignment on purpose (--no-alignment; cal.mag.replace("
                "alignment=None))")
        k, u = _driver_scale(cal.mag, "mag", scales)
        ku = k * unit_factor(u, "uT")  # uT per raw unit, as the driver sees it
        # calibrated units -> uT (a part left in raw counts is scaled like the driver)
        cu = ku if cal.mag.unit == cal.mag.raw_unit else unit_factor(cal.mag.unit, "uT")
        kw["mag_offset"] = cal.mag.offset * ku
        kw["soft_iron"] = cal.mag.matrix * cu / ku
        r = cal.mag.radius if cal.mag.radius is not None else cal.mag.stats.get("radius")
        if r is not None:
            kw["field"] = float(r) * cu
    return encode_motioncal(**kw)

