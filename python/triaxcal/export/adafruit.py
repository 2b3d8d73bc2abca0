"""Adafruit_Sensor_Calibration's ``sensor_calib.json`` (the SdFat / flash file backend).

The library loads exactly five keys (``Adafruit_Sensor_Calibration_SDFat.cpp``
``loadCalibration``): ``mag_hardiron`` (3, uT), ``mag_softiron`` (9, row-major), ``mag_field``
(uT), ``gyro_zerorate`` (3, rad/s), ``accel_zerog`` (3, m/s^2), into a
``StaticJsonDocument<512>`` (``Adafruit_Sensor_Calibration.h``), so the file holds nothing
else. ``Adafruit_Sensor_Calibration::calibrate`` applies them to the driver's event values::

    mag   = softiron @ (raw - hardiron)      (uT; the matrix MULTIPLIES)
    gyro  = raw - zerorate                    (rad/s)
    accel = raw - zerog                       (m/s^2)

so accelerometer and gyroscope gains other than 1 cannot be held and are refused. A
magnetometer alignment (``cal.mag.alignment``) is folded into the soft-iron matrix, which the
library applies as a full 3x3: ``softiron = rotation @ matrix`` gives the field in the
accelerometer's frame. Raw counts
are converted with the driver's nominal scale (``counts_per_unit``, as for the MotionCal
packet). Parts left out keep the library's defaults (zeros, identity).
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np

from ..calibration.file import Calibration
from ..errors import CalibrationError
from ._params import f32, physical, pick_sensors, require_identity

__all__ = ["adafruit_calib", "adafruit_calib_json"]

FMT = "Adafruit_Sensor_Calibration"


def adafruit_calib(
    cal: Calibration,
    *,
    sensors: Iterable[str] | None = None,
    counts_per_unit: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """The five values of ``sensor_calib.json`` for ``cal`` (see the module docstring)."""
    chosen = pick_sensors(cal, sensors, ("accel", "gyro", "mag"), FMT)
    out: dict[str, Any] = {
        "mag_hardiron": [0.0, 0.0, 0.0],
        "mag_softiron": [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        "mag_field": 0.0,
        "gyro_zerorate": [0.0, 0.0, 0.0],
        "accel_zerog": [0.0, 0.0, 0.0],
    }
    for sensor in chosen:
        unit = {"accel": "m/s^2", "gyro": "rad/s", "mag": "uT"}[sensor]
        p = physical(cal.part(sensor), sensor, unit, unit, counts_per_unit, fmt=FMT)
        if p.offset_poly is not None:
            raise CalibrationError(f"{FMT} has no temperature terms; this calibration's "
                                   f"{sensor} has them")
        if sensor == "mag":
            out["mag_hardiron"] = [float(v) for v in p.offset]
            soft = np.asarray(p.matrix)
            if cal.mag is not None and cal.mag.alignment is not None:
                if cal.mag.alignment.to != "accel":
                    raise CalibrationError(f"{FMT} fuses the magnetometer with the accelerometer; "
                                           "this alignment turns it into the "
                                           f"{cal.mag.alignment.to}'s frame")
                soft = cal.mag.alignment.rotation @ soft
            out["mag_softiron"] = [float(v) for v in soft.ravel()]
            out["mag_field"] = float(p.radius) if p.radius is not None else 0.0
        else:
            require_identity(p, FMT)
            out["gyro_zerorate" if sensor == "gyro" else "accel_zerog"] = [
                float(v) for v in p.offset]
    for key, v in out.items():
        for x in np.ravel(v):
            f32(x, key)  # finite and within float32
    return out


def adafruit_calib_json(cal: Calibration, **kwargs: Any) -> str:
    """``sensor_calib.json`` text of :func:`adafruit_calib` (same options).

    Examples
    --------
    >>> import json, numpy as np, triaxcal as tc
    >>> part = tc.SensorCalibration(offset=[12.5, -3.0, 40.0], matrix=np.eye(3),
    ...                             raw_unit="uT", unit="uT", radius=48.0)
    >>> d = json.loads(tc.adafruit_calib_json(tc.Calibration(mag=part)))
    >>> d["mag_hardiron"], d["mag_field"]
    ([12.5, -3.0, 40.0], 48.0)
    """
    d = adafruit_calib(cal, **kwargs)
    # 9 significant digits: every value reads back as the same float32 the board stores
    text = json.dumps({k: ([float(f32(x, k)) for x in v] if isinstance(v, list)
                           else float(f32(v, k))) for k, v in d.items()})
    return text + "\n"
