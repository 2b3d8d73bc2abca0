"""The coefficients of a part as a table, and what ``triaxcal fit`` says after a fit: the lines
the command line prints and the live page shows (one text, two places). Parts that are not a
fit of readings to a sphere (gyro gains, temperature terms, a bias) are reported by the numbers
stored with them (:func:`summary_text`), and so is any part whose readings are not at hand
(:func:`stored_text`)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .._checks import options
from ..calibration.part import SensorCalibration
from ..conventions.names import SENSORS
from ..conventions.units import per_unit
from ..errors import CalibrationError

__all__ = ["SUMMARY_METHODS", "SUMMARY_MODELS", "coefficient_table", "context_lines", "fit_lines",
           "printable",
           "stderr_lines", "stored_text", "summary_only", "summary_text"]

#: Parts whose readings do not lie on a sphere: reported by their stored numbers.
SUMMARY_METHODS = ("gyro-gains", "temperature")
SUMMARY_MODELS = ("bias",)


def printable(text: Any, limit: int = 2000) -> str:
    """``text`` safe for a terminal: control characters (ESC, BEL, CR, CSI ...) shown as
    ``\\xNN`` escapes, and at most ``limit`` characters -- for text that came from a file.

    >>> printable("ok\\x1b[2Jgone\\a")
    'ok\\\\x1b[2Jgone\\\\x07'
    """
    import unicodedata

    s = str(text)
    out = "".join(c if c in " \t" or unicodedata.category(c)[0] not in "CZ"
                  else c.encode("unicode_escape").decode("ascii") for c in s[:limit])
    return out + ("..." if len(s) > limit else "")


def _num(v: float) -> str:
    v = float(v)
    if v == 0:
        return "0"
    if not math.isfinite(v):
        return str(v)
    return f"{v:.6g}" if 1e-3 <= abs(v) < 1e6 else f"{v:.5e}"


def _stat(record: dict[str, Any], key: str, fmt: str) -> str:
    """``record[key]`` formatted as a number, or ``?`` when the record has none there (a
    file written by hand or by another version)."""
    v = record.get(key)
    ok = isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v)
    return format(v, fmt) if ok else "?"


def coefficient_table(part: SensorCalibration, sensor: str) -> list[str]:
    """The part's coefficients as a table: offset, matrix, radius, units, and which way the
    matrix works.

    >>> import numpy as np, triaxcal as tc
    >>> part = tc.SensorCalibration(offset=[110, -25, 400], matrix=np.eye(3) / 16384,
    ...                             raw_unit="counts", unit="g", radius=1.0, model="axis")
    >>> print("\\n".join(coefficient_table(part, "accel")))
    accel (counts -> g), model axis: calibrated = (raw - offset) @ matrix.T
      the matrix multiplies: g per count; the offset is in counts, subtracted first
                         x             y             z
      offset           110           -25           400  counts
      matrix   6.10352e-05             0             0  g/count
                         0   6.10352e-05             0
                         0             0   6.10352e-05
      radius             1 g
    """
    options.instance(part, SensorCalibration, "part", "a SensorCalibration")
    if not isinstance(sensor, str):
        raise CalibrationError(f"sensor must name the part ({', '.join(SENSORS)}), got "
                               f"{sensor!r:.60}")
    rows = [
        f"{sensor} ({part.raw_unit} -> {part.unit}), model {part.model or '?'}: "
        "calibrated = (raw - offset) @ matrix.T",
        f"  the matrix multiplies: {per_unit(part.unit, part.raw_unit)}; the offset is in "
        f"{part.raw_unit}, subtracted first",
        f"  {'':6s}{'x':>14s}{'y':>14s}{'z':>14s}",
        f"  {'offset':6s}" + "".join(f"{_num(v):>14s}" for v in part.offset)
        + f"  {part.raw_unit}",
    ]
    for i, row in enumerate(np.asarray(part.matrix)):
        label = "matrix" if i == 0 else ""
        unit = f"  {per_unit(part.unit, part.raw_unit, short=True)}" if i == 0 else ""
        rows.append(f"  {label:6s}" + "".join(f"{_num(v):>14s}" for v in row) + unit)
    if part.radius is not None:
        rows.append(f"  {'radius':6s}{_num(part.radius):>14s} {part.unit}")
    if part.temperature is not None:
        t = part.temperature
        rows.append(f"  temperature terms about {t.temp_ref_c:g} deg C (see the calibration "
                    "file)")
    if part.valid is False:
        rows.append("  NOT VALID (written with --force): " + "; ".join(part.invalid_reasons))
    return rows


def stderr_lines(part: SensorCalibration) -> list[str]:
    """The standard errors of the fitted coefficients, labelled as such (1 sigma)."""
    se = part.stats.get("stderr") or {}
    if not se:
        return []
    unit = {"offset": part.raw_unit, "diag": per_unit(part.unit, part.raw_unit, short=True),
            "offdiag": per_unit(part.unit, part.raw_unit, short=True)}
    out = []
    for name, v in se.items():
        kind = name.split("_")[0]
        u = unit.get(kind, part.raw_unit if name == "data_radius" else "")
        out.append(f"{name} +-{float(v):.3g} {u}".rstrip())
    return ["  standard errors (1 sigma, not the values): " + ", ".join(out)]


def fit_lines(saved: Any) -> list[str]:
    """What ``triaxcal fit`` prints after writing a part (a
    :class:`~triaxcal.calibration.session.Saved`): the summary line, the coefficient table, the
    model choice, the field, the alignment, every warning and the autopilot's own calibration."""
    from ..calibration.source import autopilot_lines

    out = saved.outcome
    part = out.part
    s = part.stats
    som = (s.get("norms") or {}).get("std_over_mean")
    rms_pct = s.get("rms_pct_of_radius")
    lines = [
        f"{saved.stored.verb} {saved.stored.path}: {out.sensor} ({part.raw_unit} -> "
        f"{part.unit}), model {part.model}, {s['n']} readings used, {len(out.rejected)} "
        f"rejected; residual RMS {s['rms']:.4g} {part.unit}"
        + ("" if rms_pct is None else f" ({rms_pct:.3g} % of radius)")
        + f"; std/mean of |v| {'n/a' if som is None else f'{100 * som:.3g} %'}"
        + ("" if s.get("coverage_pct") is None else f"; coverage {s['coverage_pct']:.0f} %")
        + ("" if part.valid is not False else "; NOT VALID (written with --force)"),
    ]
    lines += ["  " + r for r in coefficient_table(part, out.sensor)]
    lines += stderr_lines(part)
    if out.reason:
        lines.append(f"  model: {out.reason}")
    if out.expected is not None:
        lines.append(f"  expected field: {out.expected.text()}")
        if s.get("field_strength_ut") is not None:
            lines.append(f"  the readings show {s['field_strength_ut']:.4g} uT")
    if "yaw" in s:
        from ..methods.yaw import yaw_text

        lines.append("  " + yaw_text(s["yaw"], part.unit).replace("\n", "\n  "))
    if saved.alignment_text:
        lines.append("  " + saved.alignment_text.replace("\n", "\n  "))
    for w in s.get("warnings", []):
        lines.append(f"  warning: {printable(w)}")
    if out.source is not None and out.source.recording is not None:
        lines += autopilot_lines(out.source, out.sensor, part.offset, part.matrix, part.unit)
        for w in out.source.recording.meta.get("warnings", []):
            lines.append(f"  warning: {printable(w)}")
    return lines


def summary_only(part: SensorCalibration) -> bool:
    """Whether ``part`` is reported by its stored numbers rather than on its readings (gyro
    gains, temperature terms, a bias: their readings do not lie on a sphere)."""
    return part.stats.get("method") in SUMMARY_METHODS or part.model in SUMMARY_MODELS


def _opt_num(v: Any, fmt: str = ".4g") -> str:
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else format(v, fmt)


def summary_text(sensor: str, part: SensorCalibration) -> str:
    """The report of a gyro-gains, temperature or bias part: the numbers stored with it.

    >>> import numpy as np, triaxcal as tc
    >>> part = tc.SensorCalibration(offset=[12, -7, 3], matrix=np.eye(3) / 131, raw_unit="counts",
    ...                             unit="deg/s", model="bias", stats={"n_samples": 500})
    >>> print(summary_text("gyro", part))  # doctest: +NORMALIZE_WHITESPACE
    gyro calibration (counts -> deg/s, bias): the numbers stored when it was made
      offset          x 12  y -7  z 3 counts
      scale           x 0.00763359  y 0.00763359  z 0.00763359 deg/s per counts (multiplies)
      samples         500
    """
    s = part.stats
    method = s.get("method") or part.model
    lines = [f"{sensor} calibration ({part.raw_unit} -> {part.unit}, {method}): the numbers "
             "stored when it was made"]
    lines.append("  offset          " + "  ".join(f"{a} {v:.6g}" for a, v in
                                               zip("xyz", part.offset)) + f" {part.raw_unit}")
    d = np.diag(part.matrix)
    lines.append("  scale           " + "  ".join(f"{a} {v:.6g}" for a, v in zip("xyz", d))
                 + f" {part.unit} per {part.raw_unit} (multiplies)")
    if "gain_counts_per_dps" in s:
        none3: list[Any] = [None] * 3
        cw = s.get("gain_cw_counts_per_dps", none3)
        ccw = s.get("gain_ccw_counts_per_dps", none3)
        for i, a in enumerate("xyz"):
            lines.append(f"  gain {a}          {_opt_num(s['gain_counts_per_dps'][i])} counts per "
                         f"deg/s (clockwise {_opt_num(cw[i])}, counter-clockwise "
                         f"{_opt_num(ccw[i])})")
    if part.temperature is not None:
        t = part.temperature
        lines.append(f"  temperature     degree {len(t.offset_poly) - 1} about {t.temp_ref_c:.2f} "
                     f"deg C, fitted over {t.temp_range_c[0]:.2f} .. {t.temp_range_c[1]:.2f}")
        lines.append("  drift           " + "  ".join(
            f"{a} {v:.4g}" for a, v in zip("xyz", t.offset_poly[1])) + f" {part.raw_unit} per "
            "deg C")
    if "n_samples" in s:
        lines.append(f"  samples         {s['n_samples']}")
    if s.get("warnings"):
        lines.append("  warnings")
        lines += [f"    - {printable(w)}" for w in s["warnings"]]
    return "\n".join(lines)


def stored_text(sensor: str, part: SensorCalibration,
                why: str = "pass the data file for the full report and figure") -> str:
    """The statistics stored with a fitted part when its readings are not at hand (``why``
    says so in the first line)."""

    s = part.stats
    lines = [(f"{sensor} calibration ({part.raw_unit} -> {part.unit}, model {part.model}): "
             f"statistics stored at fit time ({why})")]
    if "rms" in s:
        lines.append(f"  residual RMS    {s['rms']:.4g} {part.unit} "
                     f"({s.get('rms_pct_of_radius', float('nan')):.3g} % of radius)")
    if "norms" in s:
        n = s["norms"]
        lines.append(f"  calibrated |v|  min {n['min']:.6g}  max {n['max']:.6g}  mean "
                     f"{n['mean']:.6g}  std {n['std']:.4g} {part.unit}")
    if s.get("coverage_pct") is not None:
        lines.append(f"  coverage        {s['coverage_pct']:.0f} % of the sphere")
    if s.get("rejected") is not None:
        lines.append(f"  outliers        {len(s['rejected'])} rejected")
    lines += context_lines(part)
    for w in s.get("warnings", []):
        lines.append(f"    - {printable(w)}")
    return "\n".join(lines)


def context_lines(part: SensorCalibration) -> list[str]:
    """Report lines on a magnetometer's surroundings: the expected field, the alignment with
    the accelerometer and the heading check, a yaw-only calibration's limits (empty for
    other parts)."""
    lines: list[str] = []
    f = part.expected_field
    if f is not None:
        lines.append(f"  expected field  {f.model} at {f.lat_deg:.4f}, {f.lon_deg:.4f}, "
                     f"{f.alt_m:.0f} m on {f.date}:")
        lines.append(f"                  total {f.total_ut:.2f} uT, horizontal "
                     f"{f.horizontal_ut:.2f} uT, inclination {f.inclination_deg:.2f} deg, "
                     f"declination {f.declination_deg:.2f} deg")
        shown = part.stats.get("field_strength_ut")
        if shown is not None:
            what = "horizontal" if part.model == "yaw" else "total"
            ref = f.horizontal_ut if part.model == "yaw" else f.total_ut
            lines.append(f"                  the readings show {shown:.4g} uT {what} "
                         f"({100 * (shown / ref - 1):+.1f} %)")
        elif part.raw_unit == "counts":
            lines.append("                  (raw counts: their strength is not compared; "
                         "--raw-unit names a physical unit)")
    al = part.alignment
    if al is not None:
        st = al.stats
        from ..conventions.rotations import rotation_angle_deg

        mnt = (f"{al.mounting} + {al.mounting_residual_deg:.2f} deg" if al.mounting
               else "not a right-angle mounting")
        ang = rotation_angle_deg(al.rotation)
        lines.append(f"  alignment       into the {al.to} frame: {ang:.2f} deg ({mnt})")
        if "dip_deg" in st:
            lines.append(f"                  dip {_stat(st, 'dip_deg', '.2f')} deg; spread over "
                         f"{st.get('n_fit', '?')} poses {_stat(st, 'dip_std_before_deg', '.3f')} "
                         f"deg before, {_stat(st, 'dip_std_after_deg', '.3f')} deg after")
        if st.get("heading_rms_est_deg") is not None:
            lines.append(f"  heading check   {st.get('n_heldout', '?')} held-out poses: dip "
                         f"spread {_stat(st, 'dip_std_heldout_before_deg', '.3f')} -> "
                         f"{_stat(st, 'dip_std_heldout_after_deg', '.3f')} deg; heading error "
                         f"about {_stat(st, 'heading_rms_est_deg', '.2f')} deg rms (from the dip "
                         "residuals)")
    y = part.stats.get("yaw")
    if isinstance(y, dict) and "determined" in y:
        from ..methods.yaw import yaw_text

        lines += ["  " + ln for ln in yaw_text(y, part.unit).splitlines()]
    return lines
