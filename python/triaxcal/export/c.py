"""Float C99 header: ``#define`` macros, ``static const float`` arrays and inline apply functions.

Model: ``out = matrix * (raw - offset)`` (the matrix **multiplies**), with the parameter names
``offset``, ``diag``, ``offdiag`` (``xy, xz, yz``; ``yx, zx, zy`` for the lower triangle) and
``radius`` kept in the macros.
"""

from __future__ import annotations

from ..calibration.file import Calibration
from ..calibration.part import SensorCalibration
from ..conventions.units import per_unit
from ._cgen import (
    _AX,
    _OFFD,
    _blocks,
    _c_comment,
    _c_poly_array,
    _cf,
    _fmt,
    _guard,
    _header_comment,
    _ident,
    _stats_lines,
    _test_raw,
    _vec,
    _wrap_header,
    check_float_range,
)
from ._trust import mark_lines, prepare

__all__ = ["c_header"]


def c_header(cal: Calibration, *, prefix: str = "triaxcal", force: bool = False) -> str:
    """C99 header with the calibration as float constants and inline apply functions.

    For each part ``<sensor>`` of ``cal``: macros ``<PREFIX>_<SENSOR>_OFFSET_X..Z`` (raw
    units), ``_DIAG_X..Z``, ``_OFFDIAG_XY, _XZ, _YZ, _YX, _ZX, _ZY`` (calibrated units per raw
    unit), ``_RADIUS``; arrays ``<prefix>_<sensor>_offset[3]`` and ``_matrix[3][3]``; and
    ``static inline void <prefix>_<sensor>_apply(const float raw[3], float out[3])``. Parts with
    temperature terms add ``_TEMP_REF_C``, ``<prefix>_<sensor>_offset_poly[K][3]`` (and
    ``_gain_poly``) and ``<prefix>_<sensor>_apply_t(raw, temp_c, out)``; ``_apply`` then
    applies the calibration at the reference temperature. The comment block gives units, the
    fit quality and a test vector (also as ``_test_raw`` / ``_test_out`` arrays). A part with an
    alignment (magnetometer to accelerometer) adds a block ``<sensor>_aligned`` whose matrix is
    ``rotation @ matrix``: ``<prefix>_mag_aligned_apply`` gives the field in the accelerometer's
    frame.

    Parameters
    ----------
    cal : Calibration
    prefix : str
        C identifier prefix (``"imu"`` gives ``IMU_ACCEL_OFFSET_X`` and ``imu_accel_apply``).
    force : bool
        Write parts the validity gate refuses
        (:func:`triaxcal.calibration.gate.require_valid`); the header then says so at the top
        and defines ``<PREFIX>_CALIBRATION_NOT_VALID``.

    A part fitted on readings an autopilot had already corrected is written as the composed
    absolute calibration (:mod:`triaxcal.export._trust`); a coefficient beyond a float's
    range is refused.

    Returns
    -------
    str
        The header text.
    """
    p = _ident(prefix)
    P = p.upper()
    guard = _guard(p, "CALIBRATION")
    prep = prepare(cal, fmt="a C header", force=force)
    cal = prep.cal
    comment: list[str] = [*(x for n in prep.notes for x in ("", n))]
    code: list[str] = []
    for sensor, part, note in _blocks(cal):
        check_float_range(part, sensor)
        S = f"{P}_{sensor.upper()}"
        s = f"{p}_{sensor}"
        traw = _test_raw(part)
        tt = part.temperature.temp_ref_c if part.temperature is not None else None
        tout = part.apply(traw, temperature=tt)
        comment += ["", note] if note else []
        comment += [
            "",
            f"{sensor}: raw {part.raw_unit} -> calibrated {part.unit}; offset in "
            f"{part.raw_unit}, matrix in {per_unit(part.unit, part.raw_unit)}"
            + (f"; radius {_fmt(part.radius)} {part.unit}" if part.radius else ""),
            *_stats_lines(part),
            f"test vector: {s}_apply({_vec(traw)}) -> {_vec(tout)} {part.unit}",
        ]
        if part.temperature is not None:
            t = part.temperature
            comment.append(
                f"temperature terms: reference {_fmt(t.temp_ref_c)} degC, fitted over "
                f"{_fmt(t.temp_range_c[0])}..{_fmt(t.temp_range_c[1])} degC; offset(T) = "
                "offset + sum_k offset_poly[k] * dT^k"
                + ("; raw gain 1 + sum_k gain_poly[k] * dT^k" if t.gain_poly is not None else "")
            )
        code.append(_c_comment(f"---- {sensor}: {part.raw_unit} -> {part.unit} ----"))
        for i, a in enumerate(_AX):
            code.append(f"#define {S}_OFFSET_{a} {_cf(part.offset[i])}")
        for i, a in enumerate(_AX):
            code.append(f"#define {S}_DIAG_{a} {_cf(part.matrix[i, i])}")
        for name, i, j in _OFFD:
            code.append(f"#define {S}_OFFDIAG_{name} {_cf(part.matrix[i, j])}")
        if part.radius is not None:
            code.append(f"#define {S}_RADIUS {_cf(part.radius)}")
        code += [
            (f"TRIAXCAL_UNUSED static const float {s}_offset[3] = "
            f"{{{S}_OFFSET_X, {S}_OFFSET_Y, {S}_OFFSET_Z}};"),
            f"TRIAXCAL_UNUSED static const float {s}_matrix[3][3] = {{",
            f"    {{{S}_DIAG_X, {S}_OFFDIAG_XY, {S}_OFFDIAG_XZ}},",
            f"    {{{S}_OFFDIAG_YX, {S}_DIAG_Y, {S}_OFFDIAG_YZ}},",
            f"    {{{S}_OFFDIAG_ZX, {S}_OFFDIAG_ZY, {S}_DIAG_Z}}}};",
            (f"TRIAXCAL_UNUSED static const float {s}_test_raw[3] = "
            f"{{{', '.join(_cf(v) for v in traw)}}};"),
            (f"TRIAXCAL_UNUSED static const float {s}_test_out[3] = "
            f"{{{', '.join(_cf(v) for v in tout)}}};"),
            "",
            _c_comment(f"out = matrix * (raw - offset): raw in {part.raw_unit}, out in "
                       f"{part.unit}."),
            f"static inline void {s}_apply(const float raw[3], float out[3])",
            "{",
            f"    const float d0 = raw[0] - {s}_offset[0];",
            f"    const float d1 = raw[1] - {s}_offset[1];",
            f"    const float d2 = raw[2] - {s}_offset[2];",
            f"    out[0] = {s}_matrix[0][0] * d0 + {s}_matrix[0][1] * d1 + {s}_matrix[0][2] * d2;",
            f"    out[1] = {s}_matrix[1][0] * d0 + {s}_matrix[1][1] * d1 + {s}_matrix[1][2] * d2;",
            f"    out[2] = {s}_matrix[2][0] * d0 + {s}_matrix[2][1] * d1 + {s}_matrix[2][2] * d2;",
            "}",
        ]
        if part.temperature is not None:
            code += _c_temperature_float(part, s, S)
        code.append("")
    return _wrap_header(
        _header_comment(cal, "Calibration header (float)", comment,
                        tuple(mark_lines(prep.invalid))), guard, code, includes=(),
        not_valid=f"{P}_CALIBRATION_NOT_VALID" if prep.invalid else None)



def _c_temperature_float(part: SensorCalibration, s: str, S: str) -> list[str]:
    t = part.temperature
    assert t is not None
    k = len(t.offset_poly)
    lines = [
        f"#define {S}_TEMP_REF_C {_cf(t.temp_ref_c)}",
        f"#define {S}_TEMP_MIN_C {_cf(t.temp_range_c[0])}",
        f"#define {S}_TEMP_MAX_C {_cf(t.temp_range_c[1])}",
        *_c_poly_array(f"{s}_offset_poly", t.offset_poly, _cf, "float"),
    ]
    if t.gain_poly is not None:
        lines += _c_poly_array(f"{s}_gain_poly", t.gain_poly, _cf, "float")
    lines += [
        "",
        ("/* Temperature-compensated: temp_c in degC; offset(T) = offset + sum_k offset_poly[k]"
        " dT^k, dT = temp_c - TEMP_REF_C. */"),
        f"static inline void {s}_apply_t(const float raw[3], float temp_c, float out[3])",
        "{",
        f"    const float dt = temp_c - {S}_TEMP_REF_C;",
        "    float d[3];",
        "    int i, k;",
        "    for (i = 0; i < 3; i++) {",
        f"        float off = {s}_offset_poly[{k - 1}][i];",
        f"        for (k = {k - 2}; k >= 0; k--) off = off * dt + {s}_offset_poly[k][i];",
        f"        d[i] = (raw[i] - {s}_offset[i]) - off;",
    ]
    if t.gain_poly is not None:
        kg = len(t.gain_poly)
        lines += [
            "        {",
            f"            float g = {s}_gain_poly[{kg - 1}][i];",
            f"            for (k = {kg - 2}; k >= 0; k--) g = g * dt + {s}_gain_poly[k][i];",
            "            d[i] *= 1.0f + g;",
            "        }",
        ]
    lines += [
        "    }",
        (f"    out[0] = {s}_matrix[0][0] * d[0] + {s}_matrix[0][1] * d[1]"
        f" + {s}_matrix[0][2] * d[2];"),
        (f"    out[1] = {s}_matrix[1][0] * d[0] + {s}_matrix[1][1] * d[1]"
        f" + {s}_matrix[1][2] * d[2];"),
        (f"    out[2] = {s}_matrix[2][0] * d[0] + {s}_matrix[2][1] * d[1]"
        f" + {s}_matrix[2][2] * d[2];"),
        "}",
    ]
    return lines

