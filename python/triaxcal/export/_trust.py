"""What every export checks before it writes: the validity gate, the driver's scale, and
whether a part is a correction on top of an autopilot's stored calibration.

* **The gate.** Every part written goes through
  :func:`triaxcal.calibration.gate.require_valid`: a part marked ``valid: false`` is refused
  with its stored reasons, one never judged is judged now. ``force`` writes it anyway, and the
  writer marks what it writes (:func:`mark_lines`) with the reasons.
* **No silent scale** (:class:`Scales`). A part in raw counts written in physical units needs
  the driver's counts per unit: from the user (``counts_per_unit``, ``--counts-per-unit``) or
  from a named part (``sensor_model``, ``--sensor-model``, :mod:`triaxcal.conventions.sensors`).
  There is no default: without one the export is refused, naming the sensor and the options.
* **Corrections stay corrections** (:func:`absolute`). A part fitted on readings an autopilot
  had already corrected (``stats["log"]["calibrated_by_autopilot"]``) calibrates the corrected
  readings, not the sensor. With the autopilot's stored calibration recorded in
  ``stats["autopilot"]`` (triaxcal's convention, ``corrected = R @ A @ (raw - o)``, ``R`` the
  rotation the autopilot applies after its correction; :mod:`triaxcal.io.logs.autopilot`
  cites each autopilot's equation) and the fit ``cal = M @ (corrected - o_fit)``, the sensor's
  absolute calibration in the frame the autopilot corrects in is ::

      cal_sensor = R.T @ cal = (R.T @ M @ R @ A) @ (raw - (o + inv(R @ A) @ o_fit))

  which is what is written; a part whose stored calibration cannot be rebuilt (temperature
  terms, a rotation triaxcal does not know, not recorded) is refused with the reason.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._checks.spelling import in_command_line, opt
from ..calibration.file import Calibration
from ..calibration.gate import Verdict, require_valid
from ..calibration.part import SensorCalibration
from ..conventions.sensors import Scale, known_models, model_scale
from ..conventions.units import UNITS, unit_factor
from ..errors import CalibrationError

__all__ = ["DEFAULT_COUNT_UNIT", "Prepared", "Scales", "absolute", "comment_lines", "mark_lines",
           "parse_counts_per_unit", "prepare"]

#: The unit of ``--counts-per-unit SENSOR=COUNTS`` when ``:UNIT`` is left out (a unit, not a
#: scale: the number is always the user's).
DEFAULT_COUNT_UNIT = {"accel": "g", "gyro": "deg/s", "mag": "uT"}

_SENSORS = ("accel", "gyro", "mag")


def parse_counts_per_unit(text: str) -> dict[str, tuple[float, str]]:
    """``SENSOR=COUNTS[:UNIT][,SENSOR=COUNTS[:UNIT]...]`` -> ``{sensor: (counts, unit)}``.

    ``UNIT`` defaults to g, deg/s and uT (accel, gyro, mag).

    >>> parse_counts_per_unit("accel=16384:g,mag=6.6667")
    {'accel': (16384.0, 'g'), 'mag': (6.6667, 'uT')}
    """
    out: dict[str, tuple[float, str]] = {}
    for item in str(text).split(","):
        item = item.strip()
        if not item:
            continue
        sensor, eq, rest = item.partition("=")
        sensor = sensor.strip()
        value, _, unit = rest.partition(":")
        if not eq or sensor not in _SENSORS:
            raise CalibrationError(
                f"{opt('counts_per_unit')} {item[:60]!r}: use SENSOR=COUNTS[:UNIT] with SENSOR "
                "accel, gyro or mag, e.g. accel=16384:g, gyro=131:deg/s, mag=6.6667:uT")
        out[sensor] = _check_scale(sensor, value.strip(), unit.strip() or
                                   DEFAULT_COUNT_UNIT[sensor])
    if not out:
        raise CalibrationError(f"{opt('counts_per_unit')} is empty: use SENSOR=COUNTS[:UNIT]")
    return out


def _check_scale(sensor: str, value: Any, unit: Any) -> tuple[float, str]:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise CalibrationError(f"counts per unit of the {sensor} must be a number, got "
                               f"{str(value)[:40]!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise CalibrationError(f"counts per unit of the {sensor} must be a finite number > 0, "
                               f"got {v!r}")
    u = str(unit)
    if u not in UNITS or UNITS[u][0] != sensor:
        good = sorted(k for k, (q, _) in UNITS.items() if q == sensor)
        raise CalibrationError(f"counts per unit of the {sensor}: {u[:20]!r} is not a unit of "
                               f"the {sensor} (use one of {', '.join(good)})")
    return v, u


class Scales:
    """The drivers' scales an export may use: the user's ``counts_per_unit`` (wins) and the
    named parts' ``sensor_model``; :meth:`get` refuses a sensor with neither."""

    def __init__(self, counts_per_unit: Mapping[str, Any] | str | None = None,
                 sensor_model: str | Sequence[str] | None = None) -> None:
        self.user: dict[str, tuple[float, str]] = {}
        if isinstance(counts_per_unit, str):
            self.user = parse_counts_per_unit(counts_per_unit)
        elif counts_per_unit is not None:
            if not isinstance(counts_per_unit, Mapping):
                raise CalibrationError("counts_per_unit must map a sensor to (counts, unit), "
                                       f"got {type(counts_per_unit).__name__}")
            for sensor, spec in counts_per_unit.items():
                if sensor not in _SENSORS:
                    raise CalibrationError(f"counts_per_unit: unknown sensor {sensor!r} (accel, "
                                           "gyro or mag)")
                if isinstance(spec, str):
                    value, _, unit = spec.partition(":")
                    self.user[sensor] = _check_scale(sensor, value, unit or
                                                     DEFAULT_COUNT_UNIT[sensor])
                elif isinstance(spec, (tuple, list)) and len(spec) == 2:
                    self.user[sensor] = _check_scale(sensor, spec[0], spec[1])
                else:
                    raise CalibrationError(
                        f"counts_per_unit of the {sensor} must be (counts, unit), e.g. "
                        f"(16384, 'g'), got {spec!r}: a bare number does not say its unit")
        if sensor_model is None:
            models: tuple[str, ...] = ()
        elif isinstance(sensor_model, str):
            models = (sensor_model,)
        elif isinstance(sensor_model, Sequence):
            models = tuple(sensor_model)
        else:
            raise CalibrationError(f"sensor_model must be a part name such as 'ICM-20948' (or a "
                                   f"list of them), got {sensor_model!r}")
        self.models = models
        for m in models:  # an unknown name is refused at once, not only when a scale is needed
            from ..conventions.sensors import _parse, find_model

            find_model(_parse(m)[1])

    def __bool__(self) -> bool:
        return bool(self.user or self.models)

    def get(self, sensor: str, fmt: str, target: str) -> Scale:
        """The scale of ``sensor``'s raw counts; refuses, naming what is missing, without."""
        if sensor in self.user:
            cpu, unit = self.user[sensor]
            return Scale(cpu, unit, source=f"{opt('counts_per_unit')} {sensor}={cpu:g}:{unit}")
        found: list[Scale] = []
        errors: list[str] = []
        for spec in self.models:
            try:
                found.append(model_scale(spec, sensor))
            except CalibrationError as exc:
                errors.append(str(exc))
        if len(found) > 1 and len({(s.counts_per_unit, s.unit) for s in found}) > 1:
            raise CalibrationError(
                f"two sensor models give the {sensor}'s scale ({found[0].source}; "
                f"{found[1].source}): say which with {opt('sensor_model')} {sensor}=PART")
        if found:
            return found[0]
        if self.models and errors and not all("has no " + sensor in e for e in errors):
            raise CalibrationError(errors[0])
        n, u, who = _EXAMPLE[sensor]
        if in_command_line():
            give, eg = f"--counts-per-unit {sensor}=COUNTS:UNIT", f"{sensor}={n:g}:{u}"
            name = "--sensor-model PART"
        else:
            give = f"counts_per_unit={{'{sensor}': (COUNTS, 'UNIT')}}"
            eg, name = f"({n:g}, '{u}')", "sensor_model='PART'"
        raise CalibrationError(
            f"the {sensor} part is in raw counts and {fmt} needs it in {target}: triaxcal does "
            f"not guess the driver's scale. Give it with {give} (e.g. {eg} for {who}), or "
            f"name the part with {name} (known: {known_models()})")


_EXAMPLE = {"accel": (16384, "g", "an MPU-6050 at +-2 g"),
            "gyro": (131, "deg/s", "an MPU-6050 at +-250 deg/s"),
            "mag": (6.6667, "uT", "an ICM-20948's AK09916")}


# ------------------------------------------------------------------------------ autopilots


def absolute(part: SensorCalibration, sensor: str) -> tuple[SensorCalibration, str | None]:
    """``part`` as the sensor's absolute calibration, and a note saying what was composed
    (``None`` when ``part`` already is absolute). See the module docstring."""
    stats = part.stats
    log = stats.get("log") if isinstance(stats.get("log"), Mapping) else None
    ap = stats.get("autopilot") if isinstance(stats.get("autopilot"), Mapping) else None
    if log is None:
        return part, None
    corrected = log.get("calibrated_by_autopilot")
    if corrected is False or (corrected is None and ap is None):
        return part, None
    refit = ("fit the raw sensor instead (--undo-autopilot-cal; undo_autopilot_cal=True), or "
             "the per-sensor topic (--instance N)")
    if corrected is None:
        who = ap.get("autopilot", "the autopilot") if ap is not None else "the autopilot"
        raise CalibrationError(
            f"the {sensor} part was fitted on a {log.get('format', 'log')} stream that may or may "
            f"not have been corrected by {who} already (the log "
            "does not say): whether it is a correction or the sensor's calibration cannot be "
            f"told, so it is not exported; {refit}")
    if ap is None:
        raise CalibrationError(
            f"the {sensor} part was fitted on readings the autopilot had already corrected, and "
            "the stored calibration it corrects is not recorded in the file: it is a correction, "
            f"not the sensor's calibration, so it is not exported; {refit}")
    if part.temperature is not None:
        raise CalibrationError(
            f"the {sensor} part is a correction on top of {ap.get('autopilot')}'s stored "
            "calibration and has temperature terms of its own: composing them is not "
            f"supported; {refit}")
    stored = _stored_part(ap, sensor, refit)
    A, o, R = stored.triaxcal_matrix, stored.triaxcal_offset, stored.rotation
    f = unit_factor(stored.unit, part.raw_unit)  # the fit's raw unit per autopilot unit
    RA = f * (R @ A)
    matrix = R.T @ np.asarray(part.matrix) @ RA
    offset = o + np.linalg.solve(RA, np.asarray(part.offset))
    if not (np.isfinite(matrix).all() and np.isfinite(offset).all()):
        raise CalibrationError(f"composing the {sensor} correction with the stored calibration "
                               "gave values that are not finite")
    s = dict(stats)
    s["composed_with_autopilot"] = True
    out = part.replace(offset=offset, matrix=matrix, raw_unit=stored.unit, unit=part.unit, stats=s)
    name = str(ap.get("autopilot"))
    note = (f"{sensor}: fitted on readings {name} had already corrected with its stored "
            f"calibration ({stored.equation}; {stored.citation}); written here is the "
            "composed absolute calibration, stored then correction: matrix = R^T M R A, "
            "offset = o + (R A)^-1 o_fit (A, o: the stored scale and offset in triaxcal's form; "
            "M, o_fit: the fit; R: the rotation the autopilot applies after its correction)")
    return out, note


def _stored_part(ap: Mapping[str, Any], sensor: str, refit: str) -> Any:
    from ..io.logs.autopilot import ardupilot_part, px4_part

    name = ap.get("autopilot")
    params = ap.get("params")
    slot = ap.get("slot")
    if name not in ("px4", "ardupilot") or not isinstance(params, Mapping) or \
            isinstance(slot, bool) or not isinstance(slot, int):
        raise CalibrationError(f"the {sensor} part's recorded autopilot calibration is "
                               f"incomplete (autopilot, slot, params): {refit}")
    try:
        stored = (px4_part if name == "px4" else ardupilot_part)(dict(params), sensor, slot)
    except CalibrationError as exc:
        raise CalibrationError(f"the {sensor} part's stored {name} calibration cannot be "
                               f"rebuilt: {exc}; {refit}") from None
    if stored.thermal is not None:
        raise CalibrationError(
            f"{name}'s stored {sensor} calibration has temperature terms "
            f"({', '.join(k for k in params if 'TCAL' in k)[:80]}): a constant calibration "
            f"cannot stand for it, so the correction is not exported; {refit}")
    if stored.not_undoable:
        raise CalibrationError(f"{stored.not_undoable}; so the correction is not exported")
    rec_o = np.asarray(ap.get("offset", stored.triaxcal_offset), float)
    rec_m = np.asarray(ap.get("matrix", stored.triaxcal_matrix), float)
    if rec_o.shape != (3,) or rec_m.shape != (3, 3) or not (
            np.allclose(rec_o, stored.triaxcal_offset, rtol=1e-9, atol=1e-12)
            and np.allclose(rec_m, stored.triaxcal_matrix, rtol=1e-9, atol=1e-12)):
        raise CalibrationError(f"the {sensor} part's recorded {name} calibration does not "
                               "match its recorded parameters: the file was edited; fit again")
    return stored


# ------------------------------------------------------------------------------ the gate


@dataclass(frozen=True)
class Prepared:
    """A calibration ready to write: ``cal`` (parts composed to absolute), ``invalid`` (the
    parts written although the gate refused them: ``(sensor, verdict)``), ``notes`` (what was
    composed)."""

    cal: Calibration
    invalid: tuple[tuple[str, Verdict], ...] = ()
    notes: tuple[str, ...] = field(default=())


def prepare(cal: Calibration, sensors: Iterable[str] | None = None, *, fmt: str,
            force: bool = False, compose: bool = True, action: str = "export") -> Prepared:
    """Gate every part in ``sensors`` (default: all) for ``fmt``, then (``compose``) turn
    autopilot corrections into absolute calibrations. See the module docstring. ``action``
    is the verb the gate's refusal names (``"export"``, ``"send"``)."""
    if not isinstance(cal, Calibration):
        raise CalibrationError(f"expected a Calibration, got {type(cal).__name__}")
    if not isinstance(force, bool):
        raise CalibrationError(f"force must be True or False, got {force!r}")
    chosen = tuple(cal.sensors if sensors is None else sensors)
    invalid: list[tuple[str, Verdict]] = []
    parts: dict[str, SensorCalibration] = {}
    notes: list[str] = []
    for sensor in chosen:
        part = cal.part(sensor)
        verdict = require_valid(part, sensor, force=force, action=action)
        if not verdict.valid:
            invalid.append((sensor, verdict))
        if compose:
            new, note = absolute(part, sensor)
            if note is not None:
                parts[sensor] = new
                notes.append(note)
    out = cal.replace(**parts) if parts else cal
    return Prepared(cal=out, invalid=tuple(invalid), notes=tuple(notes))


def mark_lines(invalid: Iterable[tuple[str, Verdict]]) -> list[str]:
    """Lines that say a written part is not a valid calibration, and why (empty for none)."""
    out = []
    for sensor, v in invalid:
        out.append(f"NOT A VALID CALIBRATION: the {sensor} part was refused by the validity "
                   "gate and written only because it was forced (--force): "
                   + "; ".join(v.reasons))
    return out


def comment_lines(lines: Iterable[str], lead: str = "# ", width: int = 90) -> list[str]:
    """``lines`` as comment lines of at most ``width`` characters, printable ASCII only (a
    loader that reads a parameter file into a short line buffer never sees a comment's tail
    as a line of its own)."""
    import textwrap

    out: list[str] = []
    for line in lines:
        out += [lead + w for w in textwrap.wrap(plain(line), width - len(lead),
                                                break_long_words=True) or [""]]
    return out


def plain(text: str, limit: int = 4000) -> str:
    """``text`` on one line of printable ASCII (for comments of parameter files)."""
    t = "".join(ch if " " <= ch <= "~" else "?" for ch in str(text))
    t = re.sub(r"\s+", " ", t)
    return t if len(t) <= limit else t[: limit - 3] + "..."
