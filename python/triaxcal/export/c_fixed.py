"""Fixed-point C99 header for FPU-less parts: Q7.24 matrix, int64 accumulation, no float.

Integer offsets (rounded to the nearest count, halves away from zero; the rounding is undone
by a Q-format correction term, so it costs no accuracy), the matrix in **Q7.24** (``int32_t``,
24 fractional bits), ``int64_t`` accumulation and round-half-up of the result:
``<prefix>_<sensor>_apply_q(const int16_t raw[3], int32_t out[3])`` writes calibrated values in
units of ``1 / <PREFIX>_<SENSOR>_Q_OUT_SCALE``. Right shifts of negative ``int64_t`` are
arithmetic (floor), as gcc, clang and avr-gcc do. :func:`apply_fixed` is the bit-exact Python
model of that C code.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._checks import options
from ..calibration.file import Calibration
from ..calibration.part import SensorCalibration
from ..errors import CalibrationError
from ._cgen import (
    _AX,
    _OFFD,
    _blocks,
    _c_comment,
    _c_poly_array,
    _fmt,
    _guard,
    _header_comment,
    _ident,
    _stats_lines,
    _test_raw,
    _vec,
    _wrap_header,
)
from ._trust import mark_lines, prepare

__all__ = ["FRAC_BITS", "TEMP_FRAC_BITS", "FixedPoint", "apply_fixed", "c_fixed_header",
           "fixed_point"]

#: Q format of the fixed-point matrix: Q7.24 in int32_t.
FRAC_BITS = 24
#: Fractional bits of the temperature argument of ``..._apply_qt`` (``temp_c_q8 = T * 256``).
TEMP_FRAC_BITS = 8


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
    out_scale = options.magnitude(out_scale, "out_scale",
                                  hint="output counts per calibrated unit")
    one = 1 << FRAC_BITS
    ms = m * out_scale
    if np.max(np.abs(ms)) >= 127:
        raise CalibrationError(
            f"matrix * out_scale reaches {np.max(np.abs(ms)):.3g}, beyond Q7.24 (|x| < 128): "
            "choose a smaller out_scale"
        )
    mq = tuple(tuple(_round_half_away(v * one) for v in row) for row in ms)
    num, den = _fraction(out_scale)
    if num < 1 or num >= 2**31 or abs(num / den - out_scale) > 1e-9 * out_scale:
        raise CalibrationError(
            f"the output scale {out_scale:.4g} counts per unit cannot be written as the "
            "fraction OUT_SCALE_NUM/OUT_SCALE_DEN (int32, denominator up to 2^20): the matrix "
            f"entries ({np.max(np.abs(m)):.4g} at most) are too far from 1 for Q7.24; refit in "
            "units that keep the gains near 1 (or export --format c)")
    for i, row in enumerate(mq):
        big = max(abs(v) for v in row)
        if big < 1 << 14:  # under 14 significant bits: that axis's output is coarse or 0
            raise CalibrationError(
                f"row {i} of the matrix is {float(np.max(np.abs(m[i]))):.4g} at most, against "
                f"{float(np.max(np.abs(m))):.4g} for the largest entry: in Q7.24 at one "
                "output scale its coefficients keep fewer than 14 significant bits (its "
                "output would be 0 or coarse); export --format c")
    off = tuple(_round_half_away(v) for v in part.offset)
    if max(abs(v) for v in off) > 2**31 - 65536:
        raise CalibrationError("offset is too large for int32 arithmetic")
    dmax = 32768 + max(abs(v) for v in off)
    worst = max(sum(abs(v) for v in row) for row in mq) * dmax
    if worst + (1 << FRAC_BITS) >= 2**31 * (1 << FRAC_BITS):
        raise CalibrationError(
            f"an int16 reading can give an output of {worst / one:.4g} counts, beyond int32: "
            "choose a smaller out_scale (or export --format c)")
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
    force: bool = False,
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
    force : bool
        Write parts the validity gate refuses; the header then says so and defines
        ``<PREFIX>_CALIBRATION_NOT_VALID``.
    """
    p = _ident(prefix)
    P = p.upper()
    guard = _guard(p, "CALIBRATION_FIXED")
    prep = prepare(cal, fmt="a fixed-point C header", force=force)
    cal = prep.cal
    comment: list[str] = [*(x for n in prep.notes for x in ("", n)),
        "",
        "Fixed point: offsets are whole raw counts (rounded half away from zero; the fraction",
        "is put back by the Q24 BIAS term, so the rounding costs nothing); the matrix is Q7.24",
        "in int32_t (value * 2^24); products accumulate in int64_t; the result is rounded half",
        "up by an arithmetic right shift. out = calibrated value * OUT_SCALE (within 1 count).",
    ]
    code: list[str] = []
    for sensor, part, note in _blocks(cal):
        if part.raw_unit != "counts":
            raise CalibrationError(
                f"the fixed-point header needs integer raw readings; the {sensor} part's raw "
                f"unit is {part.raw_unit!r}. Fit raw counts, or use --format c"
            )
        base = sensor.removesuffix("_aligned")
        sc = out_scale.get(base) if isinstance(out_scale, Mapping) else out_scale
        fp = fixed_point(part, out_scale=sc)
        num, den = _fraction(fp.out_scale)
        S = f"{P}_{sensor.upper()}"
        s = f"{p}_{sensor}"
        traw = np.asarray(_test_raw(part), dtype=np.int64)
        texp = apply_fixed(fp, traw)[0]
        tt = part.temperature.temp_ref_c if part.temperature is not None else None
        exact = part.apply(traw.astype(float), temperature=tt) * fp.out_scale
        comment += ["", note] if note else []
        comment += [
            "",
            (f"{sensor}: raw {part.raw_unit} (int16_t) -> out in 1/{_fmt(fp.out_scale)} "
            f"{part.unit} (OUT_SCALE = {num}/{den} counts per {part.unit})"),
            *_stats_lines(part),
            (f"test vector: {s}_apply_q({_vec(traw)}) -> {_vec(texp)} "
            f"(exact {_vec(exact)})"),
        ]
        code.append(_c_comment(
            f"---- {sensor}: int16_t {part.raw_unit} -> int32_t in 1/{_fmt(fp.out_scale)} "
            f"{part.unit} ----"
        ))
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
            _c_comment(f"out = round(OUT_SCALE * matrix * (raw - offset)), raw int16_t "
                       f"{part.raw_unit}."),
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
        _header_comment(cal, "Calibration header (fixed point)", comment,
                        tuple(mark_lines(prep.invalid))),
        guard,
        code,
        includes=("<stdint.h>",),
        not_valid=f"{P}_CALIBRATION_NOT_VALID" if prep.invalid else None,
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

