"""Export a :class:`~triaxcal.Calibration` for firmware and for the stacks that consume it.

One module per target format:

* :mod:`~triaxcal.export.c` -- :func:`c_header`, a float C99 header: ``#define`` macros,
  ``static const float`` arrays and ``static inline void <prefix>_<sensor>_apply(const float
  raw[3], float out[3])`` (plus ``..._apply_t(raw, temp_c, out)`` with temperature terms).
* :mod:`~triaxcal.export.c_fixed` -- :func:`c_fixed_header`, the same with no floating point
  (Q7.24 matrix, int64 accumulation), and :func:`apply_fixed`, its bit-exact Python model.
* :mod:`~triaxcal.export.motioncal` -- :func:`motioncal_packet`, the 68-byte PJRC MotionCal
  packet that Adafruit_Sensor_Calibration sketches accept.
* :mod:`~triaxcal.export.js` -- :func:`js_module`, a JavaScript module with the coefficients and
  ``apply``: an ES module (``js``) or plain ECMAScript 5.1 for Espruino (``js-espruino``).
* :mod:`~triaxcal.export.ardupilot` -- :func:`ardupilot_parm`, ArduPilot ``COMPASS_*``,
  ``INS_ACC*``, ``INS_GYR*``, ``INS_TCALn_*`` parameters (``.parm``).
* :mod:`~triaxcal.export.px4` -- :func:`px4_params_file`, PX4 ``CAL_*`` and ``TC_*``
  parameters as a QGroundControl ``.params`` file.
* :mod:`~triaxcal.export.kalibr` -- :func:`kalibr_imu_yaml`, Kalibr's ``imu.yaml`` (topic,
  rate, noise figures, intrinsics).
* :mod:`~triaxcal.export.adafruit` -- :func:`adafruit_calib_json`,
  Adafruit_Sensor_Calibration's ``sensor_calib.json``.
* :func:`write_outputs` -- everything for a calibration into one folder (``triaxcal demo``).

Error model of every export: ``calibrated = matrix @ (raw - offset)`` (the matrix
**multiplies**; numpy form ``(raw - offset) @ matrix.T``).

What every export checks first (:mod:`triaxcal.export._trust`): each part written passes the
validity gate (:func:`triaxcal.calibration.gate.require_valid`) or is written only with
``force=True`` and then marked as not valid, with the reasons; a part in raw counts written in
physical units needs the driver's scale (``counts_per_unit``, or ``sensor_model`` from
:mod:`triaxcal.conventions.sensors`), never a default; a part fitted on readings an autopilot
had already corrected is written as the composed absolute calibration, or refused.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from .._checks import options
from ..calibration.file import SENSORS, Calibration
from ..conventions.units import unit_factor
from ..errors import CalibrationError
from ..io.files import os_error_message, write_file
from ..io.motioncal import (
    MotionCalPacket,
    decode_motioncal,
    echo_matches,
    encode_motioncal,
    parse_motioncal_echo,
)
from ..io.protocol import crc16_modbus
from ._cgen import _ident
from ._trust import DEFAULT_COUNT_UNIT, parse_counts_per_unit, prepare
from .adafruit import adafruit_calib, adafruit_calib_json, adafruit_left_out
from .ardupilot import ardupilot_params, ardupilot_parm
from .c import c_header
from .c_fixed import FixedPoint, apply_fixed, c_fixed_header, fixed_point
from .js import js_module
from .kalibr import KALIBR_MODELS, KALIBR_NOISE_KEYS, kalibr_imu_yaml, kalibr_intrinsics
from .motioncal import motioncal_losses, motioncal_packet
from .px4 import px4_omitted, px4_params, px4_params_file

#: The public names (``triaxcal.__all__`` gathers them); the formats' helpers (the parameter
#: dicts, the fixed-point and MotionCal pieces, ``EXPORT_FORMATS``, :func:`export` itself) stay
#: importable from here (``export`` is not gathered: it would hide this package at the top).
__all__ = [
    "adafruit_calib_json",
    "ardupilot_parm",
    "c_fixed_header",
    "c_header",
    "decode_motioncal",
    "encode_motioncal",
    "js_module",
    "kalibr_imu_yaml",
    "motioncal_packet",
    "px4_params_file",
    "write_outputs",
]

EXPORT_FORMATS = ("c", "c-fixed", "json", "motioncal", "ardupilot", "px4", "kalibr", "adafruit",
                  "js", "js-espruino")


def export(
    cal: Calibration,
    fmt: str,
    path: str | Path,
    *,
    prefix: str = "triaxcal",
    counts_per_unit: Mapping[str, Any] | None = None,
    offsets_only: bool = False,
    sensor_model: str | Sequence[str] | None = None,
    force: bool = False,
    **options: Any,
) -> Path:
    """Write ``cal`` in format ``fmt`` (one of :data:`EXPORT_FORMATS`) to ``path``.

    ``options`` go to the parameter writers: :func:`ardupilot_parm` (``imu``, ``compass``,
    ``sensors``, ``compass_scale``, ``offsets_max``), :func:`px4_params_file` (``instance``,
    ``sensors``, ``device_ids``, ``system_id``, ``component_id``), :func:`kalibr_imu_yaml`
    (``topic``, ``rate_hz``, ``noise``, ``model``), :func:`adafruit_calib_json` (``sensors``,
    ``mag_field``). ``offsets_only`` is :func:`motioncal_packet`'s (accept the terms the packet
    cannot hold). ``counts_per_unit`` / ``sensor_model``: the driver's scale of parts in raw
    counts, for the formats in physical units (none is assumed). ``force``: write parts the
    validity gate refuses, marked as not valid (see the module docstring).

    The file is written whole and atomically (:func:`triaxcal.io.files.write_file`); a
    failure (missing folder, full disk) raises :class:`CalibrationError` saying what to do.
    """
    if options and fmt not in _PARAM_WRITERS:
        raise CalibrationError(
            f"options {sorted(options)} apply to the parameter formats "
            f"({', '.join(_PARAM_WRITERS)}), not to {fmt!r}"
        )
    if offsets_only and fmt != "motioncal":
        raise CalibrationError(f"offsets_only applies to the motioncal format, not to {fmt!r}")
    if (counts_per_unit is not None or sensor_model is not None) and \
            fmt not in _PHYSICAL:
        raise CalibrationError(f"counts_per_unit / sensor_model (the driver's scale) apply to "
                               f"the formats in physical units ({', '.join(_PHYSICAL)}); "
                               f"{fmt!r} writes the parts in their own units")
    data: str | bytes
    if fmt == "c":
        data = c_header(cal, prefix=prefix, force=force)
    elif fmt == "c-fixed":
        data = c_fixed_header(cal, prefix=prefix, force=force)
    elif fmt == "json":
        data = _json(cal, force)
    elif fmt == "motioncal":
        data = motioncal_packet(cal, counts_per_unit=counts_per_unit, offsets_only=offsets_only,
                                sensor_model=sensor_model, force=force)
    elif fmt in ("js", "js-espruino"):
        form = "esm" if fmt == "js" else "espruino"
        data = js_module(cal, prefix=prefix, form=form, force=force)
    elif fmt in _PARAM_WRITERS:
        data = _PARAM_WRITERS[fmt](cal, counts_per_unit=counts_per_unit,
                                   sensor_model=sensor_model, force=force, **options)
    else:
        raise CalibrationError(f"unknown export format {fmt!r}: use one of {EXPORT_FORMATS}")
    return write_file(path, data, what=f"{fmt} export")


def _json(cal: Calibration, force: bool) -> str:
    """The calibration file, each part gated; a forced invalid part carries ``"valid": false``
    and its reasons (as ``triaxcal fit --force`` writes them)."""
    from ..calibration.gate import judged

    prep = prepare(cal, fmt="JSON", force=force, compose=False)
    bad = dict(prep.invalid)
    if not bad:
        return cal.to_json()
    return cal.replace(**{s: (judged(cal.part(s), v, force=True) if cal.part(s).valid is not False
                              else cal.part(s)) for s, v in bad.items()}).to_json()


def exported_sensors(cal: Calibration, fmt: str, **options: Any) -> tuple[str, ...]:
    """The parts of ``cal`` that :func:`export` writes in format ``fmt`` with ``options`` (the
    same keyword options): what a summary should list, and what the gate judges.

    >>> import numpy as np, triaxcal as tc
    >>> p = tc.SensorCalibration(offset=[0, 0, 0], matrix=np.eye(3), raw_unit="uT", unit="uT")
    >>> exported_sensors(tc.Calibration(accel=p.replace(raw_unit="g", unit="g"), mag=p),
    ...                  "ardupilot", sensors=["mag"])
    ('mag',)
    """
    from ._params import pick_sensors

    if fmt in ("ardupilot", "px4", "adafruit"):
        return pick_sensors(cal, options.get("sensors"), ("accel", "gyro", "mag"), fmt)
    if fmt == "kalibr":
        return tuple(s for s in ("accel", "gyro") if getattr(cal, s) is not None)
    if fmt in EXPORT_FORMATS:
        return cal.sensors
    raise CalibrationError(f"unknown export format {fmt!r}: use one of {EXPORT_FORMATS}")


#: The formats that write physical units (and so need a driver's scale for raw counts).
_PHYSICAL = ("motioncal", "ardupilot", "px4", "kalibr", "adafruit")

_PARAM_WRITERS: dict[str, Any] = {
    "ardupilot": ardupilot_parm,
    "px4": px4_params_file,
    "kalibr": kalibr_imu_yaml,
    "adafruit": adafruit_calib_json,
}


def write_outputs(
    cal: Calibration,
    points_by_sensor: Mapping[str, Any] | None,
    out_dir: str | Path,
    *,
    prefix: str = "triaxcal",
    plot: bool = True,
    counts_per_unit: Mapping[str, Any] | None = None,
) -> dict[str, Path]:
    """Write everything for ``cal`` into ``out_dir``; returns the paths by kind.

    Files: ``calibration.json``, ``<prefix>_calibration.h`` (float),
    ``<prefix>_calibration_fixed.h`` (only when every part has raw counts), ``motioncal.bin``
    (when the magnetometer's matrix is symmetric and unrotated and, for parts in raw counts,
    ``counts_per_unit`` gives the driver's scale; it carries the accelerometer's and
    gyroscope's offsets only, see :func:`motioncal_losses`), and per
    sensor in ``points_by_sensor`` (raw (N, 3) readings) ``report_<sensor>.txt`` and, when
    ``plot`` and matplotlib is installed, ``report_<sensor>.png``.
    """
    from ..report.figure import plot_report
    from ..report.quality import have_matplotlib, quality_report

    if not isinstance(cal, Calibration):
        raise CalibrationError(f"expected a Calibration, got {type(cal).__name__}")
    points_by_sensor = options.mapping(points_by_sensor, "points_by_sensor")
    plot = options.flag(plot, "plot")
    out = Path(options.path(out_dir, "out_dir"))
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise CalibrationError(os_error_message(exc, out, "create")) from None
    paths: dict[str, Path] = {}
    paths["json"] = cal.save(out / "calibration.json")
    p = _ident(prefix)
    paths["c"] = export(cal, "c", out / f"{p}_calibration.h", prefix=p)
    if all(cal.part(s).raw_unit == "counts" for s in cal.sensors):
        paths["c-fixed"] = export(cal, "c-fixed", out / f"{p}_calibration_fixed.h", prefix=p)
    try:
        paths["motioncal"] = export(cal, "motioncal", out / "motioncal.bin", offsets_only=True,
                                    counts_per_unit=counts_per_unit)
    except CalibrationError:
        pass  # e.g. a non-symmetric magnetometer matrix: the headers still carry it
    for sensor, pts in (points_by_sensor or {}).items():
        if sensor not in SENSORS or getattr(cal, sensor) is None:
            continue
        rep = quality_report(pts, cal.part(sensor), sensor=sensor)
        txt = out / f"report_{sensor}.txt"
        write_file(txt, rep.text() + "\n", what="report")
        paths[f"report_{sensor}"] = txt
        if plot and have_matplotlib():
            paths[f"figure_{sensor}"] = plot_report(
                pts, cal.part(sensor), out / f"report_{sensor}.png", report=rep
            )
    return paths
