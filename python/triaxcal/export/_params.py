"""Shared by the parameter exports (ArduPilot, PX4, Kalibr, Adafruit): unit conversion to the
consumer's units, the checks of what a format can hold, and number formatting.

A part calibrates ``calibrated = (raw - offset) @ matrix.T`` with ``raw`` in ``raw_unit`` and
``calibrated`` in ``unit``. A consumer sees ``raw_c = k * raw`` (its driver's units) and wants
``calibrated_c = c * calibrated``; then ``calibrated_c = (raw_c - k * offset) @ (c / k *
matrix).T``. ``k`` comes from the units (or, for raw counts, from the driver's counts per unit,
as for the MotionCal packet); ``c`` from ``unit`` (or ``c = k`` when the part kept the data's
own scale, ``unit == raw_unit``).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._checks.spelling import opt
from ..calibration.file import Calibration
from ..calibration.part import SensorCalibration
from ..conventions.units import per_unit, unit_factor
from ..errors import CalibrationError
from ._trust import Scales

__all__ = ["Physical", "f32", "interference", "physical", "pick_sensors"]

_FLOAT32_MAX = 3.4028234663852886e38


@dataclass(frozen=True)
class Physical:
    """A part in the consumer's units: ``calibrated = (raw - offset) @ matrix.T``.

    ``offset_poly`` / ``gain_poly`` are the temperature terms (``None`` without), in
    ``dT = T - temp_ref_c``; ``offset_poly`` in the consumer's raw unit.
    """

    sensor: str
    offset: np.ndarray
    matrix: np.ndarray
    raw_unit: str
    unit: str
    radius: float | None
    temp_ref_c: float | None = None
    temp_range_c: tuple[float, float] | None = None
    offset_poly: np.ndarray | None = None
    gain_poly: np.ndarray | None = None
    scale_source: str | None = None
    composed: bool = False

    def apply(self, raw: Any, temperature: Any = None) -> np.ndarray:
        d = np.asarray(raw, float) - self.offset
        if self.offset_poly is not None:
            dt = np.asarray(temperature, float).reshape(-1, 1) - float(self.temp_ref_c or 0.0)
            powers = dt ** np.arange(len(self.offset_poly))
            d = d - powers @ self.offset_poly
            if self.gain_poly is not None:
                d = d * (1.0 + (dt ** np.arange(len(self.gain_poly))) @ self.gain_poly)
        return d @ self.matrix.T


def physical(part: SensorCalibration, sensor: str, raw_unit: str, unit: str,
             scales: Scales | None = None, *, fmt: str) -> Physical:
    """``part`` converted to a consumer whose raw readings are in ``raw_unit`` and whose
    calibrated readings are in ``unit`` (see the module docstring). A part in raw counts takes
    the driver's scale from ``scales`` (refused without one: no scale is assumed)."""
    source = None
    if part.raw_unit == "counts":
        sc = (scales or Scales()).get(sensor, fmt, raw_unit)
        k = unit_factor(sc.unit, raw_unit) / sc.counts_per_unit
        source = sc.source
    else:
        k = _factor(part.raw_unit, raw_unit, sensor, fmt, "raw")
    c = k if part.unit == part.raw_unit else _factor(part.unit, unit, sensor, fmt, "calibrated")
    radius = part.radius if part.radius is not None else part.stats.get("radius")
    t = part.temperature
    return Physical(
        sensor=sensor,
        offset=np.asarray(part.offset) * k,
        matrix=np.asarray(part.matrix) * (c / k),
        raw_unit=raw_unit,
        unit=unit,
        radius=None if radius is None else float(radius) * c,
        temp_ref_c=None if t is None else t.temp_ref_c,
        temp_range_c=None if t is None else t.temp_range_c,
        offset_poly=None if t is None else np.asarray(t.offset_poly) * k,
        gain_poly=None if t is None or t.gain_poly is None else np.asarray(t.gain_poly),
        scale_source=source,
        composed=bool(part.stats.get("composed_with_autopilot")),
    )


def interference(part: SensorCalibration) -> tuple[str, np.ndarray] | None:
    """A part's interference term: ``(per, vector)`` -- ``per`` ``"A"`` (battery current) or
    ``"throttle"`` (0..1), ``vector`` the field in ``part.unit`` ADDED after the matrix per unit
    of it (:mod:`triaxcal.methods.attitude`) -- or None."""
    inter = part.stats.get("interference")
    if not isinstance(inter, dict):
        return None
    if inter.get("unit") != part.unit:
        raise CalibrationError(f"the interference term is in {inter.get('unit')!r} but the part "
                               f"is in {part.unit!r}: the file was edited; fit again")
    return str(inter["per"]), np.asarray(inter["vector"], dtype=float)


def _factor(src: str, dst: str, sensor: str, fmt: str, what: str) -> float:
    try:
        return unit_factor(src, dst)
    except CalibrationError:
        raise CalibrationError(
            f"{fmt} needs the {sensor} {what} readings in {dst}, but this calibration's {what} "
            f"unit is {src!r}, which cannot be converted to it; refit with readings in a "
            "physical unit (or in raw counts, exported with the driver's scale)"
        ) from None


def pick_sensors(cal: Calibration, sensors: Iterable[str] | None, supported: tuple[str, ...],
                 fmt: str) -> tuple[str, ...]:
    """The parts to export: ``sensors`` (checked) or every part ``fmt`` supports."""
    if not isinstance(cal, Calibration):
        raise CalibrationError(f"expected a Calibration, got {type(cal).__name__}")
    if sensors is not None and (isinstance(sensors, (str, bytes)) or not isinstance(
            sensors, Iterable)):
        raise CalibrationError(f"{opt('sensors')} must be a list of sensor names ("
                               f"{', '.join(supported)}), got {sensors!r:.60}")
    if sensors is None:
        chosen = tuple(s for s in cal.sensors if s in supported)
    else:
        chosen = tuple(dict.fromkeys(sensors))
        for s in chosen:
            if not isinstance(s, str) or s not in supported:
                raise CalibrationError(f"{fmt} holds no {s} calibration (it holds: "
                                       f"{', '.join(supported)})")
            cal.part(s)  # a clear error when missing
    if not chosen:
        raise CalibrationError(f"this calibration has none of the parts {fmt} holds "
                               f"({', '.join(supported)}); it has: {', '.join(cal.sensors)}")
    return chosen


_COMPOSED = ("; this part is a correction fitted on readings the autopilot had already "
             "corrected, and the stored calibration followed by the correction has a form "
             "the parameters cannot hold: fit the raw sensor instead (--undo-autopilot-cal; "
             "undo_autopilot_cal=True)")


def require_diagonal(p: Physical, fmt: str, what: str, *, rel: float = 1e-9) -> np.ndarray:
    """The diagonal of ``p.matrix``; refuses any off-diagonal term a per-axis format drops."""
    m = p.matrix
    off = np.abs(m - np.diag(np.diag(m))).max()
    if off > rel * np.abs(np.diag(m)).max():
        if p.composed:
            raise CalibrationError(
                f"{fmt} stores only per-axis {p.sensor} scales ({what}); the composed "
                f"calibration has cross-axis terms up to {off:.3g}" + _COMPOSED)
        raise CalibrationError(
            f"{fmt} stores only per-axis {p.sensor} scales ({what}); this calibration has "
            f"cross-axis terms up to {off:.3g} {per_unit(p.unit, p.raw_unit)} that it would drop: "
            "refit with --model axis (or sphere), or export another format"
        )
    return np.diag(m).copy()


def require_identity(p: Physical, fmt: str, *, rel: float = 1e-9) -> None:
    """Refuses a gain matrix other than 1 where the format stores offsets only."""
    dev = np.abs(p.matrix - np.eye(3)).max()
    if dev > rel:
        raise CalibrationError(
            f"{fmt} applies no {p.sensor} gains (offsets only), but this calibration's gains "
            f"in {per_unit(p.unit, p.raw_unit)} differ from 1 by up to {dev:.3g}; it would drop "
            "them: export only the other sensors (--sensors), or use another format"
        )


def require_symmetric(p: Physical, fmt: str, *, rel: float = 1e-12) -> None:
    m = p.matrix
    asym = np.abs(m - m.T).max()
    if asym > rel * np.abs(m).max():
        if p.composed:
            raise CalibrationError(
                f"{fmt} stores a symmetric {p.sensor} matrix; the composed calibration's "
                f"matrix (the stored one times the fitted correction) is not symmetric (differs "
                f"by {asym:.3g})" + _COMPOSED)
        raise CalibrationError(
            f"{fmt} stores a symmetric {p.sensor} matrix (one value per off-diagonal pair); "
            f"this calibration's matrix is not symmetric (differs by {asym:.3g}): refit with "
            "a symmetric model (sphere, axis, full)"
        )


def require_no_gain_poly(p: Physical, fmt: str) -> None:
    if p.gain_poly is not None and np.any(p.gain_poly != 0):
        raise CalibrationError(
            f"{fmt} corrects {p.sensor} temperature effects with offsets only; this calibration "
            "also has temperature-dependent gains (gain_poly) that it would drop: refit the "
            "temperature model with offsets only"
        )


def require_degree(p: Physical, fmt: str, max_degree: int) -> None:
    if p.offset_poly is not None and len(p.offset_poly) - 1 > max_degree:
        raise CalibrationError(
            f"{fmt} holds temperature polynomials up to degree {max_degree}; this calibration's "
            f"{p.sensor} offset polynomial has degree {len(p.offset_poly) - 1}: refit with "
            f"degree <= {max_degree}"
        )


def shift_poly(poly: np.ndarray, shift: float) -> np.ndarray:
    """Coefficients of ``q(x) = p(x + shift)`` (lowest order first; rows are per-axis)."""
    n = len(poly)
    out = np.zeros_like(np.asarray(poly, float))
    for k in range(n):
        for j in range(k + 1):
            out[j] += poly[k] * math.comb(k, j) * shift ** (k - j)
    return out


def f32(value: Any, name: str) -> str:
    """``value`` as text that reads back as the nearest float32 (9 significant digits),
    refusing NaN, inf and values a float32 parameter cannot hold."""
    v = float(value)
    if not math.isfinite(v) or abs(v) > _FLOAT32_MAX:
        raise CalibrationError(f"{name} = {v!r} cannot be stored in a float parameter")
    if v == 0:
        return "0"
    return f"{v:.9g}"


def check_range(value: float, lo: float, hi: float, name: str, why: str) -> float:
    """``value`` if ``lo <= value <= hi`` (inclusive), else a CalibrationError saying ``why``."""
    if not (lo <= value <= hi):
        raise CalibrationError(f"{name} = {value:.6g} is outside {lo:g}..{hi:g}: {why}")
    return value


def mag_mounting(cal: Calibration, fmt: str, param: str) -> Any:
    """The right-angle mounting of the magnetometer's alignment, for ``COMPASS_ORIENTn`` /
    ``CAL_MAGn_ROT``: None without an alignment; refuses one no right-angle rotation is near;
    warns (:class:`~triaxcal.methods.alignment.AlignmentWarning`) when more than 1 deg of it
    is left out."""
    import warnings

    from ..conventions.rotations import mounting, nearest_mounting
    from ..methods.alignment import AlignmentWarning

    part = cal.mag
    if part is None or part.alignment is None:
        return None
    al = part.alignment
    if al.to != "accel":
        raise CalibrationError(f"{fmt}'s {param} turns the compass into the vehicle's frame; "
                               f"this alignment turns it into the {al.to}'s")
    if al.mounting is None:
        near, ang = nearest_mounting(al.rotation)
        raise CalibrationError(
            f"{fmt}'s {param} holds right-angle rotations only; this magnetometer's alignment "
            f"is {ang:.1f} deg from the nearest ({near.name}): mount the sensor square, or "
            "export without the alignment (--no-alignment; cal.mag.replace(alignment=None))")
    m = mounting(al.mounting)
    resid = float(al.mounting_residual_deg or 0.0)
    if resid > 1.0:
        warnings.warn(
            f"{fmt}'s {param} holds the right-angle mounting {m.name}; the remaining "
            f"{resid:.2f} deg of the magnetometer-to-accelerometer alignment are left out "
            "(headings may be off by about as much)", AlignmentWarning, stacklevel=4)
    return m
