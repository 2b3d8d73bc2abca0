"""Export a :class:`~triaxcal.Calibration` for firmware: C headers, JSON, the MotionCal packet.

Error model of every export: ``calibrated = matrix @ (raw - offset)`` (the matrix
**multiplies**; numpy form ``(raw - offset) @ matrix.T``), with the parameter names ``offset``,
``diag``, ``offdiag`` (``xy, xz, yz``; ``yx, zx, zy`` for the lower triangle) and ``radius``
kept in the C macros.

* :func:`c_header` -- float C99 header: ``#define`` macros, ``static const float`` arrays and
  ``static inline void <prefix>_<sensor>_apply(const float raw[3], float out[3])`` (plus
  ``..._apply_t(raw, temp_c, out)`` when the part has temperature terms).
* :func:`c_fixed_header` -- the same with no floating point anywhere: integer offsets (rounded
  to the nearest count, halves away from zero; the rounding is undone by a Q-format correction
  term, so it costs no accuracy), the matrix in **Q7.24** (``int32_t``, 24 fractional bits),
  ``int64_t`` accumulation and round-half-up of the result:
  ``<prefix>_<sensor>_apply_q(const int16_t raw[3], int32_t out[3])`` writes calibrated values
  in units of ``1 / <PREFIX>_<SENSOR>_Q_OUT_SCALE`` (default: the power of two that puts the
  largest matrix entry in [1, 2), so the output keeps at least the raw resolution). Right
  shifts of negative ``int64_t`` are arithmetic (floor), as gcc, clang and avr-gcc do.
  :func:`apply_fixed` is the bit-exact Python model of that C code.
* :func:`motioncal_packet` / :func:`decode_motioncal` -- the 68-byte PJRC MotionCal packet
  (``117, 84``, 16 float32 LE, CRC-16/MODBUS LE) that Adafruit_Sensor_Calibration sketches
  accept, and :func:`parse_motioncal_echo` for the board's ``Cal1:``/``Cal2:`` reply.
* :func:`write_outputs` -- everything for a calibration into one folder (``triaxcal demo``).
"""

from __future__ import annotations

import math
import re
import struct
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ._core import __version__
from .calibration import SENSORS, Calibration, SensorCalibration
from .errors import CalibrationError

__all__ = [
    "EXPORT_FORMATS",
    "FixedPoint",
    "MotionCalPacket",
    "apply_fixed",
    "c_fixed_header",
    "c_header",
    "crc16_modbus",
    "decode_motioncal",
    "encode_motioncal",
    "export",
    "fixed_point",
    "motioncal_packet",
    "parse_motioncal_echo",
    "unit_factor",
    "write_outputs",
]

EXPORT_FORMATS = ("c", "c-fixed", "json", "motioncal")

#: Q format of the fixed-point matrix: Q7.24 in int32_t.
FRAC_BITS = 24
#: Fractional bits of the temperature argument of ``..._apply_qt`` (``temp_c_q8 = T * 256``).
TEMP_FRAC_BITS = 8

# Unit -> (quantity, factor to the SI-ish base unit of that quantity).
_UNITS: dict[str, tuple[str, float]] = {
    "g": ("accel", 9.80665),
    "m/s^2": ("accel", 1.0),
    "m/s2": ("accel", 1.0),
    "mg": ("accel", 9.80665e-3),
    "deg/s": ("gyro", math.pi / 180.0),
    "dps": ("gyro", math.pi / 180.0),
    "rad/s": ("gyro", 1.0),
    "uT": ("mag", 1.0),
    "nT": ("mag", 1e-3),
    "mT": ("mag", 1e3),
    "gauss": ("mag", 100.0),
    "G": ("mag", 100.0),
    "mG": ("mag", 0.1),
}

#: Device scales of the project's simulator / firmware (docs/TEAM.md): counts per unit.
DEVICE_COUNTS_PER_UNIT: dict[str, tuple[float, str]] = {
    "accel": (16384.0, "g"),
    "gyro": (131.0, "deg/s"),
    "mag": (10.0, "uT"),
}


def unit_factor(src: str, dst: str) -> float:
    """Factor that converts a value in ``src`` to ``dst`` (it multiplies).

    >>> round(unit_factor("g", "m/s^2"), 5)
    9.80665
    """
    if src == dst:
        return 1.0
    if src not in _UNITS or dst not in _UNITS or _UNITS[src][0] != _UNITS[dst][0]:
        raise CalibrationError(
            f"cannot convert {src!r} to {dst!r}: known units are {sorted(_UNITS)}"
        )
    return _UNITS[src][1] / _UNITS[dst][1]


# --------------------------------------------------------------------------------------------
# C helpers


def _ident(prefix: str) -> str:
    s = re.sub(r"[^0-9A-Za-z_]", "_", prefix.strip())
    if not s or s[0].isdigit():
        raise CalibrationError(
            f"prefix {prefix!r} is not a C identifier: use letters, digits and _ (e.g. 'imu')"
        )
    return s


def _cf(v: float) -> str:
    """A float literal that reads back to the nearest float32 (9 significant digits)."""
    v = float(np.float32(v))
    s = f"{v:.9g}"
    if "e" not in s and "." not in s and "inf" not in s and "nan" not in s:
        s += ".0"
    return s + "f"


def _fmt(v: float) -> str:
    return f"{v:.6g}"


def _vec(v: Any) -> str:
    return "{" + ", ".join(_fmt(x) for x in v) + "}"


_AX = "XYZ"
_OFFD = (("XY", 0, 1), ("XZ", 0, 2), ("YZ", 1, 2), ("YX", 1, 0), ("ZX", 2, 0), ("ZY", 2, 1))


def _test_raw(part: SensorCalibration) -> np.ndarray:
    """A test vector: the raw reading that calibrates to ``radius`` along +Z, in whole counts
    when the raw unit is counts."""
    r = part.radius if part.radius is not None else float(
        np.mean(np.linalg.norm(np.linalg.inv(part.matrix), axis=0)) ** -1
    )
    target = np.array([0.3, -0.4, 0.866]) * r
    raw = part.offset + np.linalg.solve(part.matrix, target)
    if part.raw_unit == "counts":
        raw = np.clip(np.round(raw), -32768, 32767)
    return raw


def _stats_lines(part: SensorCalibration) -> list[str]:
    s = part.stats
    lines = []
    if "rms" in s:
        rms = s["rms"]
        pct = s.get("rms_pct_of_radius")
        lines.append(
            f"fit: model {part.model}, n = {s.get('n')}, residual RMS {_fmt(rms)} {part.unit}"
            + (f" ({pct:.3g} % of radius)" if pct is not None else "")
        )
    if "norms" in s:
        n = s["norms"]
        lines.append(
            f"calibrated norms: min {_fmt(n['min'])}, max {_fmt(n['max'])}, mean "
            f"{_fmt(n['mean'])}, std {_fmt(n['std'])} {part.unit}"
        )
    if s.get("coverage_pct") is not None:
        lines.append(f"sphere coverage: {s['coverage_pct']:.0f} % of equal-area cells")
    if s.get("rejected"):
        lines.append(f"outliers rejected before the fit: {len(s['rejected'])}")
    return lines


def _header_comment(cal: Calibration, kind: str, body: list[str]) -> str:
    out = [
        "/*",
        f" * {kind} generated by triaxcal {__version__} -- do not edit; regenerate with",
        " *   triaxcal export CAL.json --format " + ("c-fixed" if "fixed" in kind else "c"),
        (f" * sensor id: {cal.sensor_id or '(none)'}; calibration created {cal.created_utc} "
        f"(triaxcal {cal.library_version})"),
        " * Model: calibrated = matrix * (raw - offset); the matrix MULTIPLIES.",
    ]
    out += [(" * " + line).rstrip() for line in body]
    out.append(" */")
    return "\n".join(out)


def _guard(prefix: str, suffix: str) -> str:
    return f"{prefix.upper()}_{suffix}_H"


# --------------------------------------------------------------------------------------------
# Float header


def c_header(cal: Calibration, *, prefix: str = "triaxcal") -> str:
    """C99 header with the calibration as float constants and inline apply functions.

    For each part ``<sensor>`` of ``cal``: macros ``<PREFIX>_<SENSOR>_OFFSET_X..Z`` (raw
    units), ``_DIAG_X..Z``, ``_OFFDIAG_XY, _XZ, _YZ, _YX, _ZX, _ZY`` (calibrated units per raw
    unit), ``_RADIUS``; arrays ``<prefix>_<sensor>_offset[3]`` and ``_matrix[3][3]``; and
    ``static inline void <prefix>_<sensor>_apply(const float raw[3], float out[3])``. Parts with
    temperature terms add ``_TEMP_REF_C``, ``<prefix>_<sensor>_offset_poly[K][3]`` (and
    ``_gain_poly``) and ``<prefix>_<sensor>_apply_t(raw, temp_c, out)``; ``_apply`` then
    applies the calibration at the reference temperature. The comment block gives units, the
    fit quality and a test vector (also as ``_test_raw`` / ``_test_out`` arrays).

    Parameters
    ----------
    cal : Calibration
    prefix : str
        C identifier prefix (``"imu"`` gives ``IMU_ACCEL_OFFSET_X`` and ``imu_accel_apply``).

    Returns
    -------
    str
        The header text.
    """
    p = _ident(prefix)
    P = p.upper()
    guard = _guard(p, "CALIBRATION")
    comment: list[str] = []
    code: list[str] = []
    for sensor in cal.sensors:
        part = cal.part(sensor)
        S = f"{P}_{sensor.upper()}"
        s = f"{p}_{sensor}"
        traw = _test_raw(part)
        tt = part.temperature.temp_ref_c if part.temperature is not None else None
        tout = part.apply(traw, temperature=tt)
        comment += [
            "",
            f"{sensor}: raw {part.raw_unit} -> calibrated {part.unit}; offset in "
            f"{part.raw_unit}, matrix in {part.unit} per {part.raw_unit}"
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
        code.append(f"/* ---- {sensor}: {part.raw_unit} -> {part.unit} ---- */")
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
            f"/* out = matrix * (raw - offset): raw in {part.raw_unit}, out in {part.unit}. */",
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
        _header_comment(cal, "Calibration header (float)", comment), guard, code, includes=()
    )


def _c_poly_array(name: str, poly: np.ndarray, fmt: Any, ctype: str) -> list[str]:
    rows = ", ".join("{" + ", ".join(fmt(v) for v in row) + "}" for row in poly)
    return [f"TRIAXCAL_UNUSED static const {ctype} {name}[{len(poly)}][3] = {{{rows}}};"]


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


# --------------------------------------------------------------------------------------------
# Fixed point


def _round_half_away(x: float) -> int:
    return int(math.copysign(math.floor(abs(x) + 0.5), x))


@dataclass(frozen=True)
class FixedPoint:
    """Integer coefficients of one part for the fixed-point header (see :func:`fixed_point`).

    ``offset`` (int, raw counts, rounded half away from zero), ``matrix_q`` (3x3 int, Q7.24 of
    ``matrix * out_scale``), ``bias_q`` (3 int, Q24 output correction for the offset rounding,
    including the rounding constant 2^23), ``out_scale`` (output counts per calibrated unit),
    ``offset_frac_q`` (3 int, Q24 raw counts: ``offset - round(offset)``), ``offset_poly_q`` and
    ``gain_poly_q`` (Q24 per degC^k, or None), ``temp_ref_q8`` (reference temperature * 256).
    """

    offset: tuple[int, int, int]
    matrix_q: tuple[tuple[int, ...], ...]
    bias_q: tuple[int, int, int]
    out_scale: float
    offset_frac_q: tuple[int, int, int]
    offset_poly_q: tuple[tuple[int, int, int], ...] | None
    gain_poly_q: tuple[tuple[int, int, int], ...] | None
    temp_ref_q8: int | None


def fixed_point(part: SensorCalibration, *, out_scale: float | None = None) -> FixedPoint:
    """Integer coefficients for :func:`c_fixed_header` / :func:`apply_fixed`.

    Parameters
    ----------
    part : SensorCalibration
        Raw readings must be integers (``int16_t``).
    out_scale : float, optional
        Output counts per calibrated unit (e.g. 1000 for milli-g). Default: the power of two
        that puts the largest ``|matrix|`` entry times the scale in [1, 2).
    """
    m = np.asarray(part.matrix, dtype=float)
    if out_scale is None:
        mx = float(np.max(np.abs(m)))
        out_scale = 2.0 ** (-math.floor(math.log2(mx)))
    out_scale = float(out_scale)
    if not (math.isfinite(out_scale) and out_scale > 0):
        raise CalibrationError(f"out_scale must be a positive number, got {out_scale}")
    one = 1 << FRAC_BITS
    ms = m * out_scale
    if np.max(np.abs(ms)) >= 127:
        raise CalibrationError(
            f"matrix * out_scale reaches {np.max(np.abs(ms)):.3g}, beyond Q7.24 (|x| < 128): "
            "choose a smaller out_scale"
        )
    mq = tuple(tuple(_round_half_away(v * one) for v in row) for row in ms)
    off = tuple(_round_half_away(v) for v in part.offset)
    if max(abs(v) for v in off) > 2**31 - 65536:
        raise CalibrationError("offset is too large for int32 arithmetic")
    frac = part.offset - np.array(off, dtype=float)
    frac_q = tuple(_round_half_away(v * one) for v in frac)
    bias = -(ms @ frac) * one
    bias_q = tuple(_round_half_away(v) + (1 << (FRAC_BITS - 1)) for v in bias)
    opq = gpq = None
    tref = None
    t = part.temperature
    if t is not None:
        opq = tuple(tuple(_round_half_away(v * one) for v in row) for row in t.offset_poly)
        if t.gain_poly is not None:
            gpq = tuple(tuple(_round_half_away(v * one) for v in row) for row in t.gain_poly)
        tref = _round_half_away(t.temp_ref_c * (1 << TEMP_FRAC_BITS))
    return FixedPoint(
        offset=off,  # type: ignore[arg-type]
        matrix_q=mq,
        bias_q=bias_q,  # type: ignore[arg-type]
        out_scale=out_scale,
        offset_frac_q=frac_q,  # type: ignore[arg-type]
        offset_poly_q=opq,  # type: ignore[arg-type]
        gain_poly_q=gpq,  # type: ignore[arg-type]
        temp_ref_q8=tref,
    )


def apply_fixed(fp: FixedPoint, raw: Any, temp_c_q8: Any = None) -> np.ndarray:
    """Bit-exact Python model of ``<prefix>_<sensor>_apply_q`` (and ``_apply_qt`` when
    ``temp_c_q8``, the temperature in degC * 256, is given). Returns int64 (N, 3) in units of
    ``1 / out_scale``."""
    raw = np.asarray(raw, dtype=np.int64).reshape(-1, 3)
    out = np.zeros(raw.shape, dtype=np.int64)
    temps = None
    if temp_c_q8 is not None:
        temps = np.broadcast_to(np.asarray(temp_c_q8, dtype=np.int64).ravel(), (raw.shape[0],))
    half = 1 << (FRAC_BITS - 1)
    for n, r in enumerate(raw.tolist()):
        d = [int(r[i]) - fp.offset[i] for i in range(3)]
        if temps is None:
            for i in range(3):
                acc = fp.bias_q[i] + sum(fp.matrix_q[i][j] * d[j] for j in range(3))
                out[n, i] = acc >> FRAC_BITS
            continue
        assert fp.offset_poly_q is not None and fp.temp_ref_q8 is not None
        dt = int(temps[n]) - fp.temp_ref_q8
        d8 = [0, 0, 0]
        for i in range(3):
            off = fp.offset_poly_q[-1][i]
            for row in fp.offset_poly_q[-2::-1]:
                off = ((off * dt) >> TEMP_FRAC_BITS) + row[i]
            dq = (d[i] << FRAC_BITS) - fp.offset_frac_q[i] - off
            if fp.gain_poly_q is not None:
                g = fp.gain_poly_q[-1][i]
                for row in fp.gain_poly_q[-2::-1]:
                    g = ((g * dt) >> TEMP_FRAC_BITS) + row[i]
                dq = dq + ((dq >> 8) * g >> (FRAC_BITS - 8))
            d8[i] = dq >> (FRAC_BITS - 8)
        for i in range(3):
            acc = sum(fp.matrix_q[i][j] * d8[j] for j in range(3)) + (half << 8)
            out[n, i] = acc >> (FRAC_BITS + 8)
    return out


def c_fixed_header(
    cal: Calibration,
    *,
    prefix: str = "triaxcal",
    out_scale: float | Mapping[str, float] | None = None,
) -> str:
    """C99 header for microcontrollers without an FPU: integers only, no ``float`` anywhere.

    Per part: ``<PREFIX>_<SENSOR>_Q_OFFSET_X..Z`` (raw counts, rounded half away from zero),
    ``_Q_DIAG_*`` / ``_Q_OFFDIAG_*`` (Q7.24 of ``matrix * OUT_SCALE``), ``_Q_OUT_SCALE_NUM`` /
    ``_Q_OUT_SCALE_DEN`` (output counts per calibrated unit, as a fraction), arrays and
    ``static inline void <prefix>_<sensor>_apply_q(const int16_t raw[3], int32_t out[3])``.
    ``out`` is the calibrated value times the output scale, rounded to the nearest integer
    (within one count of the exact result). Parts with temperature terms add
    ``<prefix>_<sensor>_apply_qt(raw, temp_c_q8, out)`` with ``temp_c_q8 = T_degC * 256``.

    Parameters
    ----------
    cal : Calibration
        Parts must have integer raw readings (``raw_unit == "counts"``).
    prefix : str
        C identifier prefix.
    out_scale : float or dict of sensor -> float, optional
        Output counts per calibrated unit; see :func:`fixed_point`.
    """
    p = _ident(prefix)
    P = p.upper()
    guard = _guard(p, "CALIBRATION_FIXED")
    comment: list[str] = [
        "",
        "Fixed point: offsets are whole raw counts (rounded half away from zero; the fraction",
        "is put back by the Q24 BIAS term, so the rounding costs nothing); the matrix is Q7.24",
        "in int32_t (value * 2^24); products accumulate in int64_t; the result is rounded half",
        "up by an arithmetic right shift. out = calibrated value * OUT_SCALE (within 1 count).",
    ]
    code: list[str] = []
    for sensor in cal.sensors:
        part = cal.part(sensor)
        if part.raw_unit != "counts":
            raise CalibrationError(
                f"the fixed-point header needs integer raw readings; the {sensor} part's raw "
                f"unit is {part.raw_unit!r}. Fit raw counts, or use --format c"
            )
        sc = out_scale.get(sensor) if isinstance(out_scale, Mapping) else out_scale
        fp = fixed_point(part, out_scale=sc)
        num, den = _fraction(fp.out_scale)
        S = f"{P}_{sensor.upper()}"
        s = f"{p}_{sensor}"
        traw = np.asarray(_test_raw(part), dtype=np.int64)
        texp = apply_fixed(fp, traw)[0]
        tt = part.temperature.temp_ref_c if part.temperature is not None else None
        exact = part.apply(traw.astype(float), temperature=tt) * fp.out_scale
        comment += [
            "",
            (f"{sensor}: raw {part.raw_unit} (int16_t) -> out in 1/{_fmt(fp.out_scale)} "
            f"{part.unit} (OUT_SCALE = {num}/{den} counts per {part.unit})"),
            *_stats_lines(part),
            (f"test vector: {s}_apply_q({_vec(traw)}) -> {_vec(texp)} "
            f"(exact {_vec(exact)})"),
        ]
        code.append(
            f"/* ---- {sensor}: int16_t {part.raw_unit} -> int32_t in 1/{_fmt(fp.out_scale)} "
            f"{part.unit} ---- */"
        )
        code.append(f"#define {S}_Q_FRAC_BITS {FRAC_BITS}")
        code.append(f"#define {S}_Q_OUT_SCALE_NUM {num}L")
        code.append(f"#define {S}_Q_OUT_SCALE_DEN {den}L")
        for i, a in enumerate(_AX):
            code.append(f"#define {S}_Q_OFFSET_{a} {_cl(fp.offset[i])}")
        for i, a in enumerate(_AX):
            code.append(f"#define {S}_Q_DIAG_{a} {_cl(fp.matrix_q[i][i])}")
        for name, i, j in _OFFD:
            code.append(f"#define {S}_Q_OFFDIAG_{name} {_cl(fp.matrix_q[i][j])}")
        for i, a in enumerate(_AX):
            code.append(f"#define {S}_Q_BIAS_{a} {_cl(fp.bias_q[i])}")
        code += [
            (f"TRIAXCAL_UNUSED static const int32_t {s}_q_offset[3] = "
            f"{{{S}_Q_OFFSET_X, {S}_Q_OFFSET_Y, {S}_Q_OFFSET_Z}};"),
            f"TRIAXCAL_UNUSED static const int32_t {s}_q_matrix[3][3] = {{",
            f"    {{{S}_Q_DIAG_X, {S}_Q_OFFDIAG_XY, {S}_Q_OFFDIAG_XZ}},",
            f"    {{{S}_Q_OFFDIAG_YX, {S}_Q_DIAG_Y, {S}_Q_OFFDIAG_YZ}},",
            f"    {{{S}_Q_OFFDIAG_ZX, {S}_Q_OFFDIAG_ZY, {S}_Q_DIAG_Z}}}};",
            (f"TRIAXCAL_UNUSED static const int32_t {s}_q_bias[3] = "
            f"{{{S}_Q_BIAS_X, {S}_Q_BIAS_Y, {S}_Q_BIAS_Z}};"),
            (f"TRIAXCAL_UNUSED static const int16_t {s}_q_test_raw[3] = "
            f"{{{', '.join(str(int(v)) for v in traw)}}};"),
            (f"TRIAXCAL_UNUSED static const int32_t {s}_q_test_out[3] = "
            f"{{{', '.join(_cl(int(v)) for v in texp)}}};"),
            "",
            f"/* out = round(OUT_SCALE * matrix * (raw - offset)), raw int16_t {part.raw_unit}. */",
            f"static inline void {s}_apply_q(const int16_t raw[3], int32_t out[3])",
            "{",
            f"    const int32_t d0 = (int32_t)raw[0] - {s}_q_offset[0];",
            f"    const int32_t d1 = (int32_t)raw[1] - {s}_q_offset[1];",
            f"    const int32_t d2 = (int32_t)raw[2] - {s}_q_offset[2];",
            "    int i;",
            "    for (i = 0; i < 3; i++) {",
            f"        int64_t acc = (int64_t){s}_q_bias[i];",
            f"        acc += (int64_t){s}_q_matrix[i][0] * d0;",
            f"        acc += (int64_t){s}_q_matrix[i][1] * d1;",
            f"        acc += (int64_t){s}_q_matrix[i][2] * d2;",
            f"        out[i] = (int32_t)(acc >> {FRAC_BITS});",
            "    }",
            "}",
        ]
        if part.temperature is not None:
            code += _c_temperature_fixed(fp, s, S)
            comment.append(
                f"temperature: {s}_apply_qt(raw, temp_c_q8, out) with temp_c_q8 = T_degC * 256; "
                "offset/gain polynomials in Q24 per degC^k (Horner, int64_t)"
            )
        code.append("")
    return _wrap_header(
        _header_comment(cal, "Calibration header (fixed point)", comment),
        guard,
        code,
        includes=("<stdint.h>",),
    )


def _wrap_header(head: str, guard: str, code: list[str], *, includes: tuple[str, ...]) -> str:
    """The parts every generated header shares: comment, include guard, includes, the
    ``TRIAXCAL_UNUSED`` attribute for the static tables, then ``code``."""
    inc = [f"#include {i}" for i in includes]
    return "\n".join(
        [
            head,
            f"#ifndef {guard}",
            f"#define {guard}",
            "",
            *inc,
            *([""] if inc else []),
            "#ifndef TRIAXCAL_UNUSED",
            "#if defined(__GNUC__)",
            "#define TRIAXCAL_UNUSED __attribute__((unused))",
            "#else",
            "#define TRIAXCAL_UNUSED",
            "#endif",
            "#endif",
            "",
            *code,
            f"#endif /* {guard} */",
            "",
        ]
    )


def _cl(v: int) -> str:
    """An int32 literal (INT32_MIN cannot be written directly)."""
    v = int(v)
    if v == -(2**31):
        return "(-2147483647L - 1)"
    return f"{v}L"


def _cll(v: int) -> str:
    v = int(v)
    return f"(int64_t){v}LL" if abs(v) >= 2**31 else f"(int64_t){v}L"


def _fraction(x: float) -> tuple[int, int]:
    from fractions import Fraction

    f = Fraction(x).limit_denominator(1 << 20)
    return f.numerator, f.denominator


def _c_temperature_fixed(fp: FixedPoint, s: str, S: str) -> list[str]:
    assert fp.offset_poly_q is not None and fp.temp_ref_q8 is not None
    k = len(fp.offset_poly_q)
    fb = FRAC_BITS
    lines = [
        f"#define {S}_Q_TEMP_REF_Q8 {_cl(fp.temp_ref_q8)}",
        *_c_poly_array(f"{s}_q_offset_poly", np.array(fp.offset_poly_q), _cll, "int64_t"),
        (f"TRIAXCAL_UNUSED static const int32_t {s}_q_offset_frac[3] = "
        f"{{{', '.join(_cl(v) for v in fp.offset_frac_q)}}};"),
    ]
    if fp.gain_poly_q is not None:
        lines += _c_poly_array(f"{s}_q_gain_poly", np.array(fp.gain_poly_q), _cll, "int64_t")
    lines += [
        "",
        "/* Temperature-compensated; temp_c_q8 = temperature in degC * 256. */",
        (f"static inline void {s}_apply_qt(const int16_t raw[3], int32_t temp_c_q8,"
        " int32_t out[3])"),
        "{",
        f"    const int64_t dt = (int64_t)temp_c_q8 - {S}_Q_TEMP_REF_Q8;",
        "    int64_t d8[3];",
        "    int i, k;",
        "    for (i = 0; i < 3; i++) {",
        f"        int64_t off = {s}_q_offset_poly[{k - 1}][i];",
        f"        int64_t dq = (int64_t)((int32_t)raw[i] - {s}_q_offset[i])"
        f" * ((int64_t)1 << {fb});",
        (f"        for (k = {k - 2}; k >= 0; k--) off = ((off * dt) >> {TEMP_FRAC_BITS})"
        f" + {s}_q_offset_poly[k][i];"),
        f"        dq = dq - {s}_q_offset_frac[i] - off;",
    ]
    if fp.gain_poly_q is not None:
        kg = len(fp.gain_poly_q)
        lines += [
            "        {",
            f"            int64_t g = {s}_q_gain_poly[{kg - 1}][i];",
            (f"            for (k = {kg - 2}; k >= 0; k--) g = ((g * dt) >> {TEMP_FRAC_BITS})"
            f" + {s}_q_gain_poly[k][i];"),
            f"            dq = dq + (((dq >> 8) * g) >> {fb - 8});",
            "        }",
        ]
    lines += [
        f"        d8[i] = dq >> {fb - 8};",
        "    }",
        "    for (i = 0; i < 3; i++) {",
        f"        int64_t acc = (int64_t)1 << {fb + 7};",
        f"        acc += (int64_t){s}_q_matrix[i][0] * d8[0];",
        f"        acc += (int64_t){s}_q_matrix[i][1] * d8[1];",
        f"        acc += (int64_t){s}_q_matrix[i][2] * d8[2];",
        f"        out[i] = (int32_t)(acc >> {fb + 8});",
        "    }",
        "}",
    ]
    return lines


# --------------------------------------------------------------------------------------------
# MotionCal packet

MOTIONCAL_HEADER = bytes((117, 84))
MOTIONCAL_SIZE = 68


def crc16_modbus(data: bytes) -> int:
    """CRC-16/MODBUS: reflected polynomial 0xA001, initial value 0xFFFF, no final xor.

    >>> hex(crc16_modbus(b"123456789"))
    '0x4b37'
    """
    crc = 0xFFFF
    for byte in bytes(data):
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
    return crc


@dataclass(frozen=True)
class MotionCalPacket:
    """The values of a MotionCal calibration packet (float32 precision).

    ``accel_offset`` (m/s^2), ``gyro_offset`` (rad/s), ``mag_offset`` (hard iron, uT), ``field``
    (uT) and ``soft_iron`` (3x3 symmetric, dimensionless; it multiplies ``mag - mag_offset``),
    as Adafruit_Sensor_Calibration applies them.
    """

    accel_offset: tuple[float, float, float]
    gyro_offset: tuple[float, float, float]
    mag_offset: tuple[float, float, float]
    field: float
    soft_iron: tuple[tuple[float, float, float], ...]

    def values(self) -> list[float]:
        """The 16 packet floats in wire order (soft iron as xx, yy, zz, xy, xz, yz)."""
        s = self.soft_iron
        return [
            *self.accel_offset,
            *self.gyro_offset,
            *self.mag_offset,
            self.field,
            s[0][0], s[1][1], s[2][2], s[0][1], s[0][2], s[1][2],
        ]


def encode_motioncal(
    *,
    accel_offset: Any = (0.0, 0.0, 0.0),
    gyro_offset: Any = (0.0, 0.0, 0.0),
    mag_offset: Any = (0.0, 0.0, 0.0),
    field: float = 50.0,
    soft_iron: Any = None,
) -> bytes:
    """The 68-byte packet from values already in MotionCal's units (see MotionCalPacket)."""
    si = np.eye(3) if soft_iron is None else np.asarray(soft_iron, dtype=float)
    if si.shape != (3, 3):
        raise CalibrationError(f"soft_iron must be 3x3, got shape {si.shape}")
    if not np.allclose(si, si.T, rtol=1e-6, atol=1e-9):
        raise CalibrationError(
            "the MotionCal packet holds a symmetric soft-iron matrix (6 terms); this one is not "
            "symmetric: fit with model='full' or use the C header instead"
        )
    vals = [
        *np.asarray(accel_offset, float).ravel(),
        *np.asarray(gyro_offset, float).ravel(),
        *np.asarray(mag_offset, float).ravel(),
        float(field),
        si[0, 0], si[1, 1], si[2, 2], si[0, 1], si[0, 2], si[1, 2],
    ]
    if len(vals) != 16:
        raise CalibrationError("offsets must have 3 values each")
    if not all(math.isfinite(v) and abs(v) < 3.4e38 for v in vals):
        raise CalibrationError(f"packet values must be finite float32 numbers, got {vals}")
    body = MOTIONCAL_HEADER + struct.pack("<16f", *vals)
    return body + struct.pack("<H", crc16_modbus(body))


def decode_motioncal(data: bytes) -> MotionCalPacket:
    """Parse and check a 68-byte MotionCal packet (header bytes 117, 84 and the CRC)."""
    data = bytes(data)
    if len(data) != MOTIONCAL_SIZE:
        raise CalibrationError(f"a MotionCal packet has {MOTIONCAL_SIZE} bytes, got {len(data)}")
    if data[:2] != MOTIONCAL_HEADER:
        raise CalibrationError(
            f"not a MotionCal packet: starts with {data[:2].hex()}, expected 7554 (117, 84)"
        )
    want = struct.unpack("<H", data[66:68])[0]
    got = crc16_modbus(data[:66])
    if want != got:
        raise CalibrationError(
            f"MotionCal packet CRC mismatch: stored 0x{want:04X}, computed 0x{got:04X} "
            "(corrupted in transit?)"
        )
    v = struct.unpack("<16f", data[2:66])
    xx, yy, zz, xy, xz, yz = v[10:16]
    return MotionCalPacket(
        accel_offset=(v[0], v[1], v[2]),
        gyro_offset=(v[3], v[4], v[5]),
        mag_offset=(v[6], v[7], v[8]),
        field=v[9],
        soft_iron=((xx, xy, xz), (xy, yy, yz), (xz, yz, zz)),
    )


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
        bare number in the default unit). Default: the project's device scales (docs/TEAM.md):
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


_ECHO = re.compile(rb"(Cal[12]):([-+0-9.eE, \tnaif]*)\r?\n")


def parse_motioncal_echo(data: bytes) -> tuple[list[float], list[float]] | None:
    """Find the ``Cal1:`` (10 values) and ``Cal2:`` (9 values) lines a board echoes.

    Other bytes around them (binary frames of a streaming board) are ignored. Returns ``None``
    until both lines are complete.
    """
    found: dict[bytes, list[float]] = {}
    for m in _ECHO.finditer(bytes(data)):
        try:
            vals = [float(x) for x in m.group(2).replace(b" ", b"").split(b",") if x.strip()]
        except ValueError:
            continue
        want = 10 if m.group(1) == b"Cal1" else 9
        if len(vals) == want:
            found[m.group(1)] = vals
    if b"Cal1" in found and b"Cal2" in found:
        return found[b"Cal1"], found[b"Cal2"]
    return None


def echo_matches(packet: bytes, cal1: list[float], cal2: list[float]) -> list[str]:
    """Differences between a packet and the board's echo (4-decimal text); empty if equal."""
    p = decode_motioncal(packet)
    want1 = [*p.accel_offset, *p.gyro_offset, *p.mag_offset, p.field]
    want2 = [v for row in p.soft_iron for v in row]
    bad = []
    for name, want, got in (("Cal1", want1, cal1), ("Cal2", want2, cal2)):
        for i, (w, g) in enumerate(zip(want, got)):
            if abs(w - g) > 0.5e-4 + 1e-6 * abs(w) + 1e-9:
                bad.append(f"{name}[{i}]: sent {w:.6g}, board has {g:.6g}")
    return bad


# --------------------------------------------------------------------------------------------
# One call for everything


def export(
    cal: Calibration,
    fmt: str,
    path: str | Path,
    *,
    prefix: str = "triaxcal",
    counts_per_unit: Mapping[str, Any] | None = None,
) -> Path:
    """Write ``cal`` in format ``fmt`` (one of :data:`EXPORT_FORMATS`) to ``path``."""
    p = Path(path)
    if fmt == "c":
        p.write_text(c_header(cal, prefix=prefix), encoding="utf-8")
    elif fmt == "c-fixed":
        p.write_text(c_fixed_header(cal, prefix=prefix), encoding="utf-8")
    elif fmt == "json":
        p.write_text(cal.to_json(), encoding="utf-8")
    elif fmt == "motioncal":
        p.write_bytes(motioncal_packet(cal, counts_per_unit=counts_per_unit))
    else:
        raise CalibrationError(f"unknown export format {fmt!r}: use one of {EXPORT_FORMATS}")
    return p


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
    (when there is a magnetometer or accelerometer part with a symmetric matrix), and per
    sensor in ``points_by_sensor`` (raw (N, 3) readings) ``report_<sensor>.txt`` and, when
    ``plot`` and matplotlib is installed, ``report_<sensor>.png``.
    """
    from . import report as _report

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths: dict[str, Path] = {}
    paths["json"] = cal.save(out / "calibration.json")
    p = _ident(prefix)
    paths["c"] = export(cal, "c", out / f"{p}_calibration.h", prefix=p)
    if all(cal.part(s).raw_unit == "counts" for s in cal.sensors):
        paths["c-fixed"] = export(cal, "c-fixed", out / f"{p}_calibration_fixed.h", prefix=p)
    try:
        paths["motioncal"] = export(cal, "motioncal", out / "motioncal.bin")
    except CalibrationError:
        pass  # e.g. a non-symmetric magnetometer matrix: the headers still carry it
    for sensor, pts in (points_by_sensor or {}).items():
        if sensor not in SENSORS or getattr(cal, sensor) is None:
            continue
        rep = _report.quality_report(pts, cal.part(sensor), sensor=sensor)
        txt = out / f"report_{sensor}.txt"
        txt.write_text(rep.text() + "\n", encoding="utf-8")
        paths[f"report_{sensor}"] = txt
        if plot and _report.have_matplotlib():
            paths[f"figure_{sensor}"] = _report.plot_report(
                pts, cal.part(sensor), out / f"report_{sensor}.png", report=rep
            )
    return paths
