"""Adafruit_Sensor_Calibration's ``sensor_calib.json`` (the SdFat / flash file backend).

The library loads exactly five keys (``Adafruit_Sensor_Calibration_SDFat.cpp``
``loadCalibration``): ``mag_hardiron`` (3, uT), ``mag_softiron`` (9, row-major), ``mag_field``
(uT), ``gyro_zerorate`` (3, rad/s), ``accel_zerog`` (3, m/s^2), into a
``StaticJsonDocument<512>`` (``Adafruit_Sensor_Calibration_SDFat.h``), so the file holds
nothing else. ``Adafruit_Sensor_Calibration::calibrate`` applies them to the driver's event
values::

    mag   = softiron @ (raw - hardiron)      (uT; the matrix MULTIPLIES)
    gyro  = raw - zerorate                    (rad/s)
    accel = raw - zerog                       (m/s^2)

so accelerometer and gyroscope gains other than 1 cannot be held and are refused. A
magnetometer alignment (``cal.mag.alignment``) is folded into the soft-iron matrix, which the
library applies as a full 3x3: ``softiron = rotation @ matrix`` gives the field in the
accelerometer's frame. Raw counts are converted with the driver's scale, which must be given
(``counts_per_unit`` or ``sensor_model``): none is assumed.

Only the parts chosen (``sensors``; default every part present) are written; the keys of the
others are left out. ``loadCalibration`` reads a missing key as its default (``| 0.0``; the
identity for ``mag_softiron``), so loading the file still resets those values on the board:
:func:`adafruit_left_out` says which, and ``triaxcal export`` prints it. ``mag_field`` is the
field the magnetometer part was fitted to (its ``radius``, as ``--radius 48uT`` sets it) or
``mag_field`` given here; a part without either is refused rather than given the fitted
sphere's size in whatever units the data had.

A part written with ``force`` although the validity gate refused it is marked with
``"valid": false`` -- the one extra key the 512-byte document has room for; the reasons are
printed by ``triaxcal export`` and kept in the calibration file.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from ..calibration.file import Calibration
from ..conventions.units import unit_factor
from ..errors import CalibrationError
from ._params import f32, physical, pick_sensors, require_identity
from ._trust import Scales, prepare

__all__ = ["adafruit_calib", "adafruit_calib_json", "adafruit_left_out"]

_KEYS = {"mag": ("mag_hardiron", "mag_softiron", "mag_field"), "gyro": ("gyro_zerorate",),
         "accel": ("accel_zerog",)}

FMT = "Adafruit_Sensor_Calibration"


def adafruit_calib(
    cal: Calibration,
    *,
    sensors: Iterable[str] | None = None,
    counts_per_unit: Mapping[str, Any] | None = None,
    sensor_model: str | Sequence[str] | None = None,
    mag_field: Any = None,
    force: bool = False,
) -> dict[str, Any]:
    """The values of ``sensor_calib.json`` for the chosen parts of ``cal`` (see the module
    docstring): only the keys of the parts written.

    ``mag_field``: the local field in uT (a number, or text such as ``"48uT"``) when the
    magnetometer part has no radius. ``force`` writes parts the validity gate refuses, marked
    ``"valid": false``.
    """
    chosen = pick_sensors(cal, sensors, ("accel", "gyro", "mag"), FMT)
    prep = prepare(cal, chosen, fmt=FMT, force=force)
    cal = prep.cal
    scales = Scales(counts_per_unit, sensor_model)
    out: dict[str, Any] = {}
    for sensor in ("mag", "gyro", "accel"):
        if sensor not in chosen:
            continue
        unit = {"accel": "m/s^2", "gyro": "rad/s", "mag": "uT"}[sensor]
        p = physical(cal.part(sensor), sensor, unit, unit, scales, fmt=FMT)
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
            out["mag_field"] = _field(cal.part("mag"), mag_field)
        else:
            require_identity(p, FMT)
            out["gyro_zerorate" if sensor == "gyro" else "accel_zerog"] = [
                float(v) for v in p.offset]
    if mag_field is not None and "mag" not in chosen:
        raise CalibrationError("mag_field (--mag-field) is written with the magnetometer part, "
                               "which is not exported")
    for key, v in out.items():
        for x in np.ravel(v):
            f32(x, key)  # finite and within float32
    if prep.invalid:
        out["valid"] = False
    return out


def _field(part: Any, given: Any) -> float:
    """``mag_field`` in uT: the part's radius (the field it was fitted to), or ``given``."""
    import re

    if given is not None:
        if isinstance(given, str):
            m = re.fullmatch(r"\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([A-Za-z]+)\s*",
                             given[:64])
            if not m or m.group(2) not in ("uT", "nT", "mT", "gauss", "G", "mG"):
                raise CalibrationError(f"mag_field {given[:64]!r}: give the field with its unit, "
                                       "e.g. 48uT, 0.48gauss, 480mG")
            v = float(m.group(1)) * unit_factor(m.group(2), "uT")
        elif isinstance(given, (int, float)) and not isinstance(given, bool):
            v = float(given)
        else:
            raise CalibrationError(f"mag_field must be a field in uT (or text such as '48uT'), "
                                   f"got {given!r}")
        if not 1.0 <= v <= 1000.0:
            raise CalibrationError(f"mag_field = {v:g} uT is not a magnetic field near the "
                                   "Earth's (about 22..67 uT): check its unit")
        return v
    if part.radius is not None:
        try:
            return float(part.radius) * unit_factor(part.unit, "uT")
        except CalibrationError:
            pass
    raise CalibrationError(
        f"{FMT}'s mag_field is the local field in uT, and this magnetometer part was not "
        "fitted to one (no radius in uT): give it with --mag-field 48uT (mag_field= in Python; "
        "triaxcal field gives the local value), or refit with --radius")


def adafruit_left_out(sensors: Iterable[str]) -> list[str]:
    """The keys of ``sensor_calib.json`` not written when only ``sensors`` are: the board
    reads each as its default (0, or the identity soft-iron matrix) when it loads the file."""
    chosen = set(sensors)
    return [k for s in ("mag", "gyro", "accel") if s not in chosen for k in _KEYS[s]]


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
    text = json.dumps({k: (v if isinstance(v, bool) else [float(f32(x, k)) for x in v]
                           if isinstance(v, list) else float(f32(v, k))) for k, v in d.items()})
    return text + "\n"
