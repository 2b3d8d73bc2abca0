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
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from ..calibration.file import SENSORS, Calibration
from ..conventions.units import DEVICE_COUNTS_PER_UNIT, unit_factor
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
from .adafruit import adafruit_calib, adafruit_calib_json
from .ardupilot import ardupilot_params, ardupilot_parm
from .c import c_header
from .c_fixed import FixedPoint, apply_fixed, c_fixed_header, fixed_point
from .js import js_module
from .kalibr import KALIBR_MODELS, KALIBR_NOISE_KEYS, kalibr_imu_yaml, kalibr_intrinsics
from .motioncal import motioncal_losses, motioncal_packet
from .px4 import px4_params, px4_params_file

__all__ = [
    "KALIBR_MODELS",
    "KALIBR_NOISE_KEYS",
    "adafruit_calib",
    "adafruit_calib_json",
    "ardupilot_params",
    "ardupilot_parm",
    "kalibr_imu_yaml",
    "kalibr_intrinsics",
    "px4_params",
    "px4_params_file",
    "DEVICE_COUNTS_PER_UNIT",
    "EXPORT_FORMATS",
    "FixedPoint",
    "MotionCalPacket",
    "apply_fixed",
    "c_fixed_header",
    "c_header",
    "crc16_modbus",
    "decode_motioncal",
    "echo_matches",
    "encode_motioncal",
    "export",
    "fixed_point",
    "js_module",
    "motioncal_losses",
    "motioncal_packet",
    "parse_motioncal_echo",
    "unit_factor",
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
    **options: Any,
) -> Path:
    """Write ``cal`` in format ``fmt`` (one of :data:`EXPORT_FORMATS`) to ``path``.

    ``options`` go to the parameter writers: :func:`ardupilot_parm` (``imu``, ``compass``,
    ``sensors``, ``compass_scale``, ``offsets_max``), :func:`px4_params_file` (``instance``,
    ``sensors``, ``device_ids``, ``system_id``, ``component_id``), :func:`kalibr_imu_yaml`
    (``topic``, ``rate_hz``, ``noise``, ``model``), :func:`adafruit_calib_json` (``sensors``).
    ``offsets_only`` is :func:`motioncal_packet`'s (accept the terms the packet cannot hold).

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
    data: str | bytes
    if fmt == "c":
        data = c_header(cal, prefix=prefix)
    elif fmt == "c-fixed":
        data = c_fixed_header(cal, prefix=prefix)
    elif fmt == "json":
        data = cal.to_json()
    elif fmt == "motioncal":
        data = motioncal_packet(cal, counts_per_unit=counts_per_unit, offsets_only=offsets_only)
    elif fmt in ("js", "js-espruino"):
        form = "esm" if fmt == "js" else "espruino"
        data = js_module(cal, prefix=prefix, form=form)
    elif fmt in _PARAM_WRITERS:
        data = _PARAM_WRITERS[fmt](cal, counts_per_unit=counts_per_unit, **options)
    else:
        raise CalibrationError(f"unknown export format {fmt!r}: use one of {EXPORT_FORMATS}")
    return write_file(path, data, what=f"{fmt} export")


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
) -> dict[str, Path]:
    """Write everything for ``cal`` into ``out_dir``; returns the paths by kind.

    Files: ``calibration.json``, ``<prefix>_calibration.h`` (float),
    ``<prefix>_calibration_fixed.h`` (only when every part has raw counts), ``motioncal.bin``
    (when the magnetometer's matrix is symmetric and unrotated; it carries the accelerometer's
    and gyroscope's offsets only, see :func:`motioncal_losses`), and per
    sensor in ``points_by_sensor`` (raw (N, 3) readings) ``report_<sensor>.txt`` and, when
    ``plot`` and matplotlib is installed, ``report_<sensor>.png``.
    """
    from .. import report as _report

    out = Path(out_dir)
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
        paths["motioncal"] = export(cal, "motioncal", out / "motioncal.bin", offsets_only=True)
    except CalibrationError:
        pass  # e.g. a non-symmetric magnetometer matrix: the headers still carry it
    for sensor, pts in (points_by_sensor or {}).items():
        if sensor not in SENSORS or getattr(cal, sensor) is None:
            continue
        rep = _report.quality_report(pts, cal.part(sensor), sensor=sensor)
        txt = out / f"report_{sensor}.txt"
        write_file(txt, rep.text() + "\n", what="report")
        paths[f"report_{sensor}"] = txt
        if plot and _report.have_matplotlib():
            paths[f"figure_{sensor}"] = _report.plot_report(
                pts, cal.part(sensor), out / f"report_{sensor}.png", report=rep
            )
    return paths
