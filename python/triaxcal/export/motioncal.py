"""The PJRC MotionCal packet for a :class:`~triaxcal.Calibration`.

The packet itself (bytes, CRC, the board's ``Cal1:``/``Cal2:`` echo) is
:mod:`triaxcal.io.motioncal`; this module converts a calibration into its values.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from ..calibration import Calibration, SensorCalibration
from ..errors import CalibrationError
from ..io.motioncal import encode_motioncal
from ..rotations import rotation_angle_deg
from ..units import DEVICE_COUNTS_PER_UNIT, unit_factor

__all__ = ["motioncal_packet"]


def _driver_scale(
    part: SensorCalibration, sensor: str, counts_per_unit: Mapping[str, Any] | None
) -> tuple[float, str]:
    """(driver units per raw unit, driver unit name) for converting ``part`` to MotionCal."""
    if part.raw_unit != "counts":
        return 1.0, part.raw_unit
    spec = (counts_per_unit or {}).get(sensor, DEVICE_COUNTS_PER_UNIT[sensor])
    if isinstance(spec, (int, float)):
        spec = (float(spec), DEVICE_COUNTS_PER_UNIT[sensor][1])
    cpu, unit = float(spec[0]), str(spec[1])
    if not (math.isfinite(cpu) and cpu > 0):
        raise CalibrationError(f"counts per unit for {sensor} must be positive, got {cpu}")
    return 1.0 / cpu, unit


def motioncal_packet(
    cal: Calibration, *, counts_per_unit: Mapping[str, Any] | None = None
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
        The driver's scale per sensor, as ``{"accel": (16384, "g"), "mag": (10, "uT")}`` (or a
        bare number in the default unit). Default: the project's device scales
        (:data:`triaxcal.units.DEVICE_COUNTS_PER_UNIT`):
        accel 16384 counts/g, gyro 131 counts/(deg/s), mag 10 counts/uT. Ignored for parts
        whose raw unit is already physical.
    """
    kw: dict[str, Any] = {}
    if cal.accel is not None:
        k, u = _driver_scale(cal.accel, "accel", counts_per_unit)
        kw["accel_offset"] = cal.accel.offset * k * unit_factor(u, "m/s^2")
    if cal.gyro is not None:
        k, u = _driver_scale(cal.gyro, "gyro", counts_per_unit)
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
        k, u = _driver_scale(cal.mag, "mag", counts_per_unit)
        ku = k * unit_factor(u, "uT")  # uT per raw unit, as the driver sees it
        # calibrated units -> uT (a part left in raw counts is scaled like the driver)
        cu = ku if cal.mag.unit == cal.mag.raw_unit else unit_factor(cal.mag.unit, "uT")
        kw["mag_offset"] = cal.mag.offset * ku
        kw["soft_iron"] = cal.mag.matrix * cu / ku
        r = cal.mag.radius if cal.mag.radius is not None else cal.mag.stats.get("radius")
        if r is not None:
            kw["field"] = float(r) * cu
    return encode_motioncal(**kw)

