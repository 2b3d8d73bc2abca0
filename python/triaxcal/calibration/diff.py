"""What changed between two calibrations, in units of their uncertainty.

Error model (:mod:`triaxcal.calibration`): ``calibrated = (raw - offset) @ matrix.T``, the
matrix **multiplies**. Two calibrations of the same sensor are compared coefficient by
coefficient -- ``offset_x..z`` (raw units), ``diag_x..z`` and ``offdiag_xy, xz, yz``
(calibrated units per raw unit) -- as

    change = new - old,    sigmas = |change| / sqrt(se_old^2 + se_new^2),

with each standard error the larger of the fit's asymptotic one (``stats["stderr"]``) and the
bootstrap spread (``stats["intervals"]``, from ``triaxcal fit --bootstrap``). Each coefficient
gets a verdict:

* ``same``: within ``threshold`` standard errors (default 3): noise, the same calibration;
* ``changed``: beyond it, and physically plausible (a sensor that aged, a board that was
  reassembled, a magnetometer near new iron);
* ``suspicious``: beyond it and larger than a sensor drifts (by default a gain by more than
  5 %, an offset by more than 25 % of the radius, a cross-axis term by more than 5 % of the
  gain) -- a different sensor, range setting or unit; also any change between two fits of the
  very same data (same input SHA-256), and calibrations in raw units that do not match.

A coefficient without any recorded uncertainty can only be ``same`` if it did not change at
all. The calibration's verdict is the worst of its coefficients'; :attr:`CalibrationDiff.exit_code`
is 0 (same), 3 (changed) or 4 (suspicious) for production scripts.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._checks import options
from ..conventions.names import CELL, COEFFICIENTS
from ..conventions.units import UNITS, unit_factor
from ..errors import CalibrationError
from .file import SENSORS, Calibration
from .part import SensorCalibration

__all__ = ["CalibrationDiff", "CoefficientChange", "PartDiff", "compare"]

NAMES = COEFFICIENTS
_CELL = CELL
_RANK = {"same": 0, "changed": 1, "suspicious": 2}
EXIT_CODES = {"same": 0, "changed": 3, "suspicious": 4}


@dataclass(frozen=True)
class CoefficientChange:
    """One coefficient: ``old``, ``new``, ``change = new - old`` (in ``unit``),
    ``uncertainty`` (1-sigma of the change; NaN when neither calibration recorded one),
    ``sigmas = |change| / uncertainty``, the ``verdict`` and its ``reason``."""

    name: str
    old: float
    new: float
    change: float
    uncertainty: float
    sigmas: float
    unit: str
    verdict: str
    reason: str


@dataclass(frozen=True)
class PartDiff:
    """The comparison of one sensor's calibrations."""

    sensor: str
    coefficients: tuple[CoefficientChange, ...]
    verdict: str
    notes: tuple[str, ...] = ()

    def text(self) -> str:
        lines = [f"{self.sensor}: {_VERDICT_WORDS[self.verdict]}"]
        lines.append(f"  {'coefficient':<12} {'old':>13} {'new':>13} {'change':>11} "
                     f"{'sigmas':>7}  verdict")
        for c in self.coefficients:
            sig = f"{c.sigmas:7.2f}" if math.isfinite(c.sigmas) else "      -"
            lines.append(f"  {c.name:<12} {c.old:>13.6g} {c.new:>13.6g} {c.change:>+11.3g} "
                         f"{sig}  {c.verdict}{'' if c.verdict == 'same' else ': ' + c.reason}"
                         f"  ({c.unit})")
        lines += [f"  note: {n}" for n in self.notes]
        return "\n".join(lines)


_VERDICT_WORDS = {
    "same": "the same calibration (every change within the noise)",
    "changed": "a real change (beyond the noise, within what a sensor drifts)",
    "suspicious": "a suspicious change (see the coefficients and notes)",
}


@dataclass(frozen=True)
class CalibrationDiff:
    """The comparison of two calibrations, part by part."""

    parts: tuple[PartDiff, ...]
    verdict: str
    threshold: float
    notes: tuple[str, ...] = ()

    @property
    def exit_code(self) -> int:
        """0: the same; 3: a real change; 4: a suspicious one."""
        return EXIT_CODES[self.verdict]

    def text(self) -> str:
        lines = [f"verdict: {_VERDICT_WORDS[self.verdict]} (threshold {self.threshold:g} "
                 "standard errors)"]
        lines += [f"note: {n}" for n in self.notes]
        for p in self.parts:
            lines.append(p.text())
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        return {
            "verdict": self.verdict,
            "exit_code": self.exit_code,
            "threshold": self.threshold,
            "notes": list(self.notes),
            "parts": {
                p.sensor: {
                    "verdict": p.verdict,
                    "notes": list(p.notes),
                    "coefficients": {
                        c.name: {k: _json(getattr(c, k)) for k in (
                            "old", "new", "change", "uncertainty", "sigmas", "unit", "verdict",
                            "reason")}
                        for c in p.coefficients
                    },
                }
                for p in self.parts
            },
        }


def _json(v: Any) -> Any:
    return None if isinstance(v, float) and not math.isfinite(v) else v


def _stderrs(part: SensorCalibration) -> dict[str, float]:
    """Standard error of each of :data:`NAMES` the part recorded (the larger of the fit's
    and the bootstrap's)."""
    se = {str(k): float(v) for k, v in (part.stats.get("stderr") or {}).items()
          if isinstance(v, (int, float)) and math.isfinite(v)}
    iv = (part.stats.get("intervals") or {}).get("coefficients") or {}
    for k, c in iv.items():
        b = c.get("boot_std") if isinstance(c, dict) else None
        if isinstance(b, (int, float)) and math.isfinite(b):
            se[k] = max(se.get(k, 0.0), float(b))
    if "data_radius" in se and "diag_x" not in se and part.radius:
        # sphere model: matrix = (radius / data_radius) I
        r_data = part.radius / float(part.matrix[0, 0])
        for n in ("diag_x", "diag_y", "diag_z"):
            se[n] = float(part.matrix[0, 0]) * se["data_radius"] / r_data
    return se


def _values(part: SensorCalibration, factor: float = 1.0) -> dict[str, float]:
    v = {f"offset_{a}": float(part.offset[i]) for i, a in enumerate("xyz")}
    for n, (i, j) in _CELL.items():
        v[n] = float(part.matrix[i, j]) * factor
    return v


def _raw_radius(part: SensorCalibration) -> float | None:
    gain = float(np.mean(np.diag(part.matrix)))
    r = part.radius
    if r is None:
        norms = part.stats.get("norms") or {}
        r = norms.get("mean") if isinstance(norms, dict) else None
    if not r or not gain:
        return None
    return abs(float(r) / gain)


def compare_parts(
    old: SensorCalibration,
    new: SensorCalibration,
    *,
    sensor: str = "sensor",
    threshold: float = 3.0,
    max_gain_change: float = 0.05,
    max_offset_change: float = 0.25,
) -> PartDiff:
    """Compare two calibrations of one sensor (see the module docstring)."""
    notes: list[str] = []
    worst_forced: str | None = None
    factor = 1.0
    if old.raw_unit != new.raw_unit:
        notes.append(f"raw units differ ({old.raw_unit} -> {new.raw_unit}): the coefficients "
                     "are not comparable; was the sensor's range or driver changed?")
        worst_forced = "suspicious"
    if old.unit != new.unit:
        if old.unit in UNITS and new.unit in UNITS and UNITS[old.unit][0] == UNITS[new.unit][0]:
            factor = unit_factor(old.unit, new.unit)
            notes.append(f"calibrated units differ ({old.unit} -> {new.unit}): the old matrix "
                         f"is converted (x {factor:.6g}) before comparing")
        else:
            notes.append(f"calibrated units differ ({old.unit} -> {new.unit}) and do not "
                         "convert: not comparable")
            worst_forced = "suspicious"
    if old.model != new.model:
        notes.append(f"the model changed ({old.model} -> {new.model})")
    if old.temperature is not None or new.temperature is not None:
        notes.append("temperature terms are not compared (only the coefficients at the "
                     "reference temperature)")
    same_data = (old.input_sha256 is not None and old.input_sha256 == new.input_sha256)
    vo, vn = _values(old, factor), _values(new)
    so, sn = _stderrs(old), _stderrs(new)
    so = {k: (v * factor if not k.startswith("offset") and k != "data_radius" else v)
          for k, v in so.items()}
    rr = _raw_radius(new)
    gain = float(np.mean(np.abs(np.diag(new.matrix))))
    coefs = []
    for n in NAMES:
        a, b = vo[n], vn[n]
        d = b - a
        u2 = [s**2 for s in (so.get(n), sn.get(n)) if s is not None]
        u = math.sqrt(sum(u2)) if u2 else math.nan
        unit = new.raw_unit if n.startswith("offset") else (
            f"{new.unit}/{new.raw_unit}" if new.unit != new.raw_unit else "ratio")
        tiny = abs(d) <= 1e-12 * max(abs(a), abs(b), 1e-300)
        sig = abs(d) / u if u and u > 0 else (0.0 if tiny else math.inf)
        if tiny or (math.isfinite(u) and sig <= threshold):
            verdict, reason = "same", "within the noise"
        else:
            verdict = "changed"
            reason = (f"{sig:.1f} standard errors" if math.isfinite(sig)
                      else "no uncertainty recorded: noise and change cannot be told apart")
            if n.startswith("offset"):
                if rr is not None and abs(d) > max_offset_change * rr:
                    verdict = "suspicious"
                    reason = (f"the offset moved by {100 * abs(d) / rr:.0f} % of the radius, "
                              "more than a sensor drifts")
            elif n.startswith("diag"):
                if a and abs(d / a) > max_gain_change:
                    verdict = "suspicious"
                    reason = (f"the gain changed by {100 * abs(d / a):.1f} %: a different "
                              "sensor, range or unit?")
            elif gain and abs(d) > max_gain_change * gain:
                verdict = "suspicious"
                reason = (f"the cross-axis term moved by {100 * abs(d) / gain:.1f} % of the "
                          "gain: was the sensor remounted?")
            if same_data:
                verdict = "suspicious"
                reason += "; both calibrations come from the same data (same SHA-256)"
        coefs.append(CoefficientChange(n, a, b, d, u, sig, unit, verdict, reason))
    if same_data and any(c.verdict != "same" for c in coefs):
        notes.append("both calibrations were fitted to the same data (same input SHA-256) but "
                     "differ: different options or versions")
    verdict = max((c.verdict for c in coefs), key=_RANK.__getitem__)
    if worst_forced is not None:
        verdict = worst_forced
    if not so and not sn:
        notes.append("neither calibration recorded standard errors (refit with triaxcal fit, "
                     "or add --bootstrap N): only identical coefficients count as the same")
    return PartDiff(sensor=sensor, coefficients=tuple(coefs), verdict=verdict,
                    notes=tuple(notes))


def compare(
    old: Calibration | SensorCalibration,
    new: Calibration | SensorCalibration,
    *,
    sensors: tuple[str, ...] | None = None,
    threshold: float = 3.0,
    max_gain_change: float = 0.05,
    max_offset_change: float = 0.25,
) -> CalibrationDiff:
    """Compare two calibrations coefficient by coefficient (see the module docstring).

    Parameters
    ----------
    old, new : Calibration or SensorCalibration
        The earlier and the later calibration (whole files, or one part each).
    sensors : tuple of str, optional
        The parts to compare (default: those both calibrations have).
    threshold : float
        A change beyond this many standard errors is not noise (default 3).
    max_gain_change : float
        A gain changing by more than this fraction (default 0.05), or a cross-axis term by
        more than this fraction of the gain, is suspicious.
    max_offset_change : float
        An offset moving by more than this fraction of the radius (in raw units, default 0.25)
        is suspicious.

    Returns
    -------
    CalibrationDiff

    Examples
    --------
    >>> import numpy as np, triaxcal as tc
    >>> a = tc.SensorCalibration(offset=[10, 0, 0], matrix=np.eye(3) / 16384, unit="g",
    ...                          radius=1.0, stats={"stderr": {"offset_x": 2.0}})
    >>> b = tc.SensorCalibration(offset=[11, 0, 0], matrix=np.eye(3) / 16384, unit="g",
    ...                          radius=1.0, stats={"stderr": {"offset_x": 2.0}})
    >>> d = tc.compare(a, b)
    >>> d.verdict, d.exit_code, round(d.parts[0].coefficients[0].sigmas, 3)
    ('same', 0, 0.354)
    """
    kw = {"threshold": options.number(threshold, "threshold", gt=0,
                                      hint="standard errors"),
          "max_gain_change": options.number(max_gain_change, "max_gain_change", gt=0,
                                            hint="a fraction"),
          "max_offset_change": options.number(max_offset_change, "max_offset_change", gt=0,
                                              hint="a fraction of the radius")}
    if sensors is not None and (isinstance(sensors, (str, bytes)) or not isinstance(
            sensors, (tuple, list)) or not all(isinstance(x, str) for x in sensors)):
        raise CalibrationError(f"sensors must be a tuple of sensor names (accel, gyro, mag) or "
                               f"None, got {sensors!r:.60}")
    notes: list[str] = []
    if isinstance(old, SensorCalibration) and isinstance(new, SensorCalibration):
        parts: tuple[PartDiff, ...] = (
            compare_parts(old, new, sensor=sensors[0] if sensors else "sensor", **kw),)
    elif isinstance(old, Calibration) and isinstance(new, Calibration):
        if old.sensor_id and new.sensor_id and old.sensor_id != new.sensor_id:
            notes.append(f"the sensor ids differ ({old.sensor_id!r} -> {new.sensor_id!r}): "
                         "these may be different boards")
        both = [s for s in SENSORS if getattr(old, s) is not None and getattr(new, s) is not None]
        if sensors:
            bad = [s for s in sensors if s not in both]
            if bad:
                raise CalibrationError(
                    f"{', '.join(bad)}: not in both calibrations (both have: "
                    f"{', '.join(both) or 'nothing'})"
                )
            both = list(sensors)
        if not both:
            raise CalibrationError("the two calibrations have no sensor part in common")
        for s in SENSORS:
            if (getattr(old, s) is None) != (getattr(new, s) is None):
                notes.append(f"only the {'new' if getattr(old, s) is None else 'old'} "
                             f"calibration has a {s} part")
        parts = tuple(compare_parts(old.part(s), new.part(s), sensor=s, **kw) for s in both)
    else:
        raise CalibrationError("compare two Calibration objects or two SensorCalibration parts")
    verdict = max((p.verdict for p in parts), key=_RANK.__getitem__)
    if any("sensor ids differ" in n for n in notes) and verdict != "same":
        verdict = "suspicious"
    return CalibrationDiff(parts=parts, verdict=verdict, threshold=float(threshold),
                           notes=tuple(notes))


def compare_with_previous(cal: Calibration, **kw: Any) -> CalibrationDiff:
    """Compare each part of ``cal`` that keeps a ``previous`` summary with that summary."""
    have = [s for s in cal.sensors if cal.part(s).previous]
    if not have:
        raise CalibrationError(
            "this calibration keeps no previous one (triaxcal fit records it when it replaces "
            "a calibration): give two files, triaxcal diff OLD.json NEW.json"
        )
    sensors = kw.pop("sensors", None) or tuple(have)
    olds: dict[str, Any] = {s: cal.part(s).previous_part(0) for s in sensors}
    news: dict[str, Any] = {s: cal.part(s) for s in sensors}
    old = Calibration(**olds, sensor_id=cal.sensor_id)
    new = Calibration(**news, sensor_id=cal.sensor_id)
    return compare(old, new, sensors=tuple(sensors), **kw)
