"""The validity gate: the one function that decides whether a part is a calibration.

A fit can converge and still not be a calibration: readings that do not lie on an ellipsoid at
all, that cover a cap or a band of the sphere too small for the model, that carry only
directions, or coefficients no sensor has. :func:`check_part` says so, with the reasons in words
and what to record instead (the sensor's general advice, or the part's own when its method gave
one: ``stats["record_instead"]``). Everything that writes or ships a calibration calls it:
``triaxcal fit`` and ``batch``, the live page's Save, the methods' ``part_from_*``, every
export, ``send``.
Nothing refused is written unless the user forces it (``--force``, ``force=True``); then the
part is marked ``valid: false`` with the reasons, and every export of it is refused again unless
forced again, and then says so in what it writes.

The checks, each against a bound of :mod:`triaxcal.quality.bounds`:

======================  ===================================================================
check                   refused when
======================  ===================================================================
convergence             the fit did not converge
residual                the residual RMS exceeds ``MAX_RESIDUAL_PCT`` % of the radius
directions              the readings all point within a cap (``MAX_MEAN_DIRECTION``) or lie
                        in a band (``MIN_DIRECTION_SPREAD``) -- too little for the model
coverage                fewer than ``MIN_COVERAGE_PCT[model]`` % of the sphere's 24 cells
direction-only          the readings all have one length (a driver that publishes only the
                        direction): no offset or gain can be determined
gains                   raw and calibrated units measure the same quantity and a gain lies
                        outside ArduPilot's acceptance bounds (``PHYSICAL_DIAG``), or the gains
                        differ by more than ``CORE["MAX_AXIS_RATIO"]`` between axes
offset                  the accelerometer's offset exceeds ``MAX_ACCEL_OFFSET_G`` (raw
                        counts of an unsigned ADC: from its mid-scale code,
                        ``ADC_MIDSCALE_COUNTS``); the magnetometer's exceeds ArduPilot's
                        ``COMPASS_OFFS_MAX`` (raw field units; raw counts have no absolute
                        bound: a tumble determines any offset)
yaw-only                the calibrated headings leave an arc wider than
                        ``MAX_YAW_HEADING_GAP_DEG`` unvisited, the residual exceeds
                        ``MAX_RESIDUAL_PCT``, or the hard iron is more than
                        ``MAX_HARD_IRON_TO_FIELD`` times the horizontal field
undetermined            a method or source recorded what the data cannot determine
                        (``stats["undetermined"]``)
======================  ===================================================================
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._checks.arrays import as_points
from ..conventions.units import UNITS, unit_factor
from ..errors import CalibrationError, RefusedError
from ..quality import bounds as B
from .part import SensorCalibration

__all__ = [
    "RECORD_INSTEAD",
    "InvalidCalibrationError",
    "Verdict",
    "check_part",
    "direction_stats",
    "judged",
    "require_valid",
]

#: What to record instead, per sensor, when a fit is refused.
RECORD_INSTEAD = {
    "accel": "hold the board still in many orientations -- at least each of the six faces "
             "up in turn, better 20 or more spread over the sphere (triaxcal capture says "
             "which way to turn next) -- and fit the still poses with --poses",
    "mag": "turn the board slowly through every orientation (upside down and onto each "
           "side, e.g. figure eights), away from steel, magnets and currents",
    "gyro": "a sphere fit of gyroscope readings needs turns at one constant rate about many "
            "axes (a turntable); for the gyroscope bias record the board lying still "
            "(triaxcal temperature, or triaxcal.gyro_bias), for its gains record turns of "
            "known angle (triaxcal gyro-gains)",
}

_QUANTITY = {"accel": "acceleration", "gyro": "rotation rate", "mag": "magnetic field"}


@dataclass(frozen=True)
class Verdict:
    """The gate's answer for one part.

    Attributes
    ----------
    valid : bool
        Whether the part is a calibration.
    reasons : tuple of str
        Why not, in words (empty when valid).
    sensor : str
        The sensor judged (``"accel"``, ``"gyro"``, ``"mag"``).
    advice : str, optional
        What to record instead, when the part's method knows better than the sensor's
        general advice (a part's ``stats["record_instead"]``).
    """

    valid: bool
    reasons: tuple[str, ...]
    sensor: str
    advice: str | None = None

    @property
    def record_instead(self) -> str:
        """What to record instead: the part's own advice when its method gave one
        (``stats["record_instead"]``, e.g. a flight log's), else the sensor's."""
        return self.advice or RECORD_INSTEAD.get(self.sensor, RECORD_INSTEAD["mag"])

    def text(self, what: str = "this fit") -> str:
        """``"this accel fit is not a calibration: ...; record instead: ..."``."""
        if self.valid:
            return f"{what} passed every check of the validity gate"
        return (f"{what} is not a calibration: " + "; ".join(self.reasons)
                + f". Record instead: {self.record_instead}")


class InvalidCalibrationError(RefusedError):
    """A part the validity gate refused; ``verdict`` holds the reasons. The command line exits
    with status 2 for it (a refusal, not a failure to run)."""

    verb = "not written"

    def __init__(self, message: str, verdict: Verdict) -> None:
        super().__init__(message)
        self.verdict = verdict


def direction_stats(part: SensorCalibration, points: Any) -> dict[str, Any]:
    """How the calibrated directions of ``points`` spread over the sphere, for the gate:
    ``mean`` (length of the mean unit vector), ``spread`` (smallest eigenvalue of
    ``mean(d d^T)``), ``cap_deg`` (the widest angle from the mean direction) and
    ``direction_only`` (every raw reading has the same length). Stored in a part's
    ``stats["directions"]`` when it is fitted, so that the gate can judge the part later
    without the readings."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    pts = pts[np.isfinite(pts).all(axis=1)]
    out: dict[str, Any] = {"mean": 0.0, "spread": 0.0, "cap_deg": 0.0, "direction_only": False}
    if len(pts) == 0:
        return out
    raw_norms = np.linalg.norm(pts, axis=1)
    mean_norm = float(raw_norms.mean())
    out["direction_only"] = bool(len(pts) >= 10 and mean_norm > 0
                                 and float(raw_norms.std()) <= 1e-6 * mean_norm)
    d = part.apply(pts) if part.temperature is None else (pts - part.offset) @ part.matrix.T
    n = np.linalg.norm(d, axis=1)
    d = d[n > 0] / n[n > 0, None]
    if len(d):
        mean = d.mean(axis=0)
        m = float(np.linalg.norm(mean))
        out["mean"] = m
        out["spread"] = float(np.linalg.eigvalsh(d.T @ d / len(d))[0])
        if m > 0:
            out["cap_deg"] = float(np.degrees(np.arccos(np.clip(d @ (mean / m), -1, 1))).max())
    return out


def _quantity(unit: str) -> str | None:
    return UNITS[unit][0] if unit in UNITS else None


def _gain_reasons(part: SensorCalibration, sensor: str) -> list[str]:
    why: list[str] = []
    sv = np.linalg.svd(part.matrix, compute_uv=False)
    ratio = float(sv[0] / sv[-1]) if sv[-1] > 0 else math.inf
    if part.model not in ("yaw", "tilt-rig", "six-position", "turntable", "ferraris", "imu",
                          "bias") and not ratio <= B.CORE["MAX_AXIS_RATIO"]:
        why.append(f"its gains differ by a factor of {ratio:.3g} between axes (at most "
                   f"{B.CORE['MAX_AXIS_RATIO']:g}): the fit ran along a direction the data do "
                   "not determine")
    q_raw, q_cal = _quantity(part.raw_unit), _quantity(part.unit)
    if q_raw is not None and q_raw == q_cal and sensor in B.PHYSICAL_DIAG:
        lo, hi = B.PHYSICAL_DIAG[sensor]
        g = part.matrix * unit_factor(part.unit, part.raw_unit)  # dimensionless
        diag = np.diag(g)
        bad = [f"{a} {v:.4g}" for a, v in zip("xyz", diag) if not lo <= v <= hi]
        if bad:
            why.append(
                f"its readings are already in {part.raw_unit} ({_QUANTITY[sensor]}), so its "
                f"gains should lie near 1, within {lo:g}..{hi:g} (ArduPilot's acceptance "
                f"bounds); they are " + ", ".join(bad))
        off = [abs(g[0, 1]), abs(g[0, 2]), abs(g[1, 2])]
        if max(off) >= 1.0:
            why.append(f"its cross-axis terms reach {max(off):.3g} of a gain (below 1: "
                       "ArduPilot's bound)")
    return why


def _adc_zero(part: SensorCalibration) -> float:
    """The mid-scale code of an offset-binary ADC nearest the offset of a part in raw counts
    whose three offsets lie within a quarter of that code of it (0 otherwise)."""
    if part.raw_unit != "counts":
        return 0.0
    off = np.asarray(part.offset, dtype=np.float64)
    for mid in B.ADC_MIDSCALE_COUNTS:
        if np.all(np.abs(off - mid) < 0.25 * mid):
            return mid
    return 0.0


def _offset_reasons(part: SensorCalibration, sensor: str) -> list[str]:
    why: list[str] = []
    cal_off = part.matrix @ part.offset  # the offset in calibrated units
    if sensor == "accel":
        if _quantity(part.unit) == "accel":
            lim = B.MAX_ACCEL_OFFSET_G * unit_factor("g", part.unit)
        elif part.radius is not None:
            lim = B.MAX_ACCEL_OFFSET_G * part.radius  # the radius is 1 g in its units
        else:
            return why
        worst = float(np.max(np.abs(cal_off)))
        zero = _adc_zero(part)
        if zero:  # an unsigned ADC: 0 g reads mid-scale, the offset counts from there
            worst = min(worst, float(np.max(np.abs(part.matrix @ (part.offset - zero)))))
        if worst > lim:
            why.append(f"its offset reaches {worst:.4g} {part.unit} on one axis (at most "
                       f"{lim:.4g} {part.unit}, 1 g: ArduPilot's bound; MEMS offsets are tens "
                       "of mg)")
    elif sensor == "mag":
        if _quantity(part.raw_unit) == "mag":
            per_axis = np.abs(part.offset) * unit_factor(part.raw_unit, "mG")
            if float(per_axis.max()) > B.MAX_COMPASS_OFFSET_MG:
                why.append(
                    f"its hard iron reaches {float(per_axis.max()):.0f} mG on one axis (at most "
                    f"{B.MAX_COMPASS_OFFSET_MG:.0f} mG, ArduPilot's COMPASS_OFFS_MAX): a magnet "
                    "or steel next to the sensor, or a fit that ran away")
        field = _field_size(part) if part.model == "yaw" else None
        if field is not None and field > 0:
            ratio = float(np.linalg.norm(cal_off)) / field
            if ratio > B.MAX_HARD_IRON_TO_FIELD:
                why.append(f"its hard iron is {ratio:.2g} times the field it measures (at most "
                           f"{B.MAX_HARD_IRON_TO_FIELD:.2g}: ArduPilot's COMPASS_OFFS_MAX over "
                           "a typical field)")
    return why


def _field_size(part: SensorCalibration) -> float | None:
    if part.model == "yaw":
        y = part.stats.get("yaw") or {}
        h = y.get("horizontal")
        return float(h) if isinstance(h, (int, float)) and h > 0 else None
    return part.radius


def _yaw_reasons(part: SensorCalibration) -> list[str]:
    y = part.stats.get("yaw") or {}
    why: list[str] = []
    gap = y.get("heading_gap_deg")
    if isinstance(gap, (int, float)) and gap > B.MAX_YAW_HEADING_GAP_DEG:
        why.append(f"the calibrated headings leave {gap:.0f} deg of the circle unvisited (at "
                   f"most {B.MAX_YAW_HEADING_GAP_DEG:g} deg): the turns do not determine the "
                   "horizontal ellipse; turn through at least one full, even circle")
    rms = part.stats.get("rms_pct_of_radius")
    if isinstance(rms, (int, float)) and rms > B.MAX_RESIDUAL_PCT:
        why.append(f"its residual RMS is {rms:.3g} % of the field (at most "
                   f"{B.MAX_RESIDUAL_PCT:g} %): the readings do not lie on a horizontal ellipse")
    return why


def _direction_reasons(part: SensorCalibration, d: dict[str, Any]) -> list[str]:
    why: list[str] = []
    model = part.model or "fitted"
    if d.get("direction_only"):
        why.append("every reading has the same length: the source published only directions "
                   "(a normalised vector), from which no offset or gain can be recovered")
        return why
    m, spread = d.get("mean", 0.0), d.get("spread", 1.0)
    cov = part.stats.get("coverage_pct")
    if m > B.MAX_MEAN_DIRECTION:
        why.append(
            f"the readings all point within {d.get('cap_deg', 0.0):.0f} deg of one direction"
            + (f" (coverage {cov:.0f} % of the sphere)" if isinstance(cov, (int, float)) else "")
            + f", too little to determine the {model} model")
    elif spread < B.MIN_DIRECTION_SPREAD:
        why.append(f"the readings lie in a thin band round one axis (spread {spread:.3f}; 0.33 "
                   f"for readings all round the sphere), too little to determine the {model} "
                   "model")
    return why


_FIT_MODELS = ("sphere", "axis", "full")


def check_part(part: SensorCalibration, sensor: str, *, points: Any = None) -> Verdict:
    """Judge ``part`` (of ``sensor``): is it a calibration?

    Parameters
    ----------
    part : SensorCalibration
    sensor : {"accel", "gyro", "mag"}
    points : array_like (N, 3), optional
        The raw readings it was fitted on; without them the part's stored
        ``stats["directions"]`` (written when it was fitted) are used.

    Returns
    -------
    Verdict

    Examples
    --------
    >>> import numpy as np, triaxcal as tc
    >>> part = tc.SensorCalibration(offset=[0, 0, 20.0], matrix=np.eye(3), raw_unit="m/s^2",
    ...                             unit="m/s^2", radius=9.80665, model="axis")
    >>> v = tc.check_part(part, "accel")
    >>> v.valid, v.reasons[0][:39]
    (False, 'its offset reaches 20 m/s^2 on one axis')
    """
    if not isinstance(part, SensorCalibration):
        raise CalibrationError(f"the gate judges a SensorCalibration, got {type(part).__name__}")
    if points is not None:
        points = as_points(points, "points")
    s = part.stats
    why: list[str] = []
    if s.get("converged") is False:
        why.append(f"the fit did not converge ({s.get('iterations', '?')} iterations)")
    rms = s.get("rms_pct_of_radius")
    if part.model in _FIT_MODELS and isinstance(rms, (int, float)) and \
            rms > B.MAX_RESIDUAL_PCT:
        why.append(f"its residual RMS is {rms:.3g} % of the radius (at most "
                   f"{B.MAX_RESIDUAL_PCT:g} %): the readings do not lie on an ellipsoid at all "
                   "(a sensor that hardly turned, moving readings, mixed sensors or wrong "
                   "columns)")
    if part.model in _FIT_MODELS:
        d = direction_stats(part, points) if points is not None else s.get("directions")
        if isinstance(d, dict):
            why += _direction_reasons(part, d)
        cov = s.get("coverage_pct")
        need = B.MIN_COVERAGE_PCT.get(part.model or "", 0.0)
        if isinstance(cov, (int, float)) and cov < need:
            why.append(f"its readings cover {cov:.0f} % of the sphere; the {part.model} model "
                       f"needs at least {need:g} % (the six faces)")
    if part.model == "yaw":
        why += _yaw_reasons(part)
    why += _gain_reasons(part, sensor)
    why += _offset_reasons(part, sensor)
    und = s.get("undetermined")
    if isinstance(und, Sequence) and not isinstance(und, str):
        why += [str(u) for u in und]
    why = list(dict.fromkeys(why))
    return Verdict(valid=not why, reasons=tuple(why), sensor=sensor, advice=_advice(part))


def _advice(part: SensorCalibration) -> str | None:
    """The part's own advice on what to record instead (``stats["record_instead"]``)."""
    a = part.stats.get("record_instead")
    return a if isinstance(a, str) and a.strip() else None


def judged(part: SensorCalibration, verdict: Verdict, *, force: bool = False
           ) -> SensorCalibration:
    """``part`` marked with the verdict: ``valid=True``; or, for a refused part written with
    ``force``, ``valid=False`` and the reasons (also added to its warnings). A refused part
    without ``force`` raises :class:`InvalidCalibrationError`."""
    if verdict.valid:
        return part.replace(valid=True, invalid_reasons=())
    if not force:
        raise InvalidCalibrationError(
            verdict.text(f"this {verdict.sensor} fit") + ". (--force writes it anyway, marked "
            "\"valid\": false with these reasons.)", verdict)
    stats = dict(part.stats)
    stats["warnings"] = [*stats.get("warnings", []),
                         *(f"written with --force although {w}" for w in verdict.reasons)]
    stats["forced"] = True
    return part.replace(valid=False, invalid_reasons=verdict.reasons, stats=stats)


def require_valid(part: SensorCalibration, sensor: str, *, force: bool = False,
                  action: str = "export") -> Verdict:
    """Refuse to ``action`` a part that is not a calibration, unless ``force``.

    A part marked ``valid: false`` is refused with its stored reasons; one never judged is
    judged now from its coefficients and stored statistics. Returns the verdict (the caller
    marks what it writes when ``force`` let an invalid part through)."""
    if part.valid is False:
        verdict = Verdict(False, part.invalid_reasons or ("it is marked not valid",), sensor,
                          _advice(part))
    elif part.valid is True:
        verdict = Verdict(True, (), sensor, _advice(part))
    else:
        verdict = check_part(part, sensor)
    if not verdict.valid and not force:
        raise InvalidCalibrationError(
            f"refused to {action} it: the {sensor} part is not a valid calibration: "
            + "; ".join(verdict.reasons)
            + f". Fit it again ({verdict.record_instead}); --force {action}s it anyway, "
            "marked as not valid", verdict)
    return verdict
