"""Fitting one sensor of a recorded session the way ``triaxcal fit`` does, from a
:class:`~triaxcal.calibration.request.FitRequest`: reading the session or log, pose detection,
the robust fit with model choice, units and plausibility, the Earth's field, and the checks that
refuse a fit which is not a calibration (:func:`undetermined`). ``triaxcal fit``, ``report``,
``batch`` and the live page share it; each builds the request its own way.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._checks import options
from ..conventions.units import UNITS, unit_factor
from ..errors import CalibrationError
from ..io.akm import apply_asa
from ..io.tables import Table
from ..methods.field import ExpectedField
from ..quality.bounds import implausible_radius
from ..quality.coverage import coverage, coverage_warning
from .gate import Verdict, check_part, direction_stats, judged
from .part import SensorCalibration
from .parts import fold_asa
from .request import FitRequest
from .source import Source, autopilot_stats, load_source, table_source
from .store import Stored, existing_calibration, store_part
from .surroundings import alignment_for, expected_for, field_stats, yaw_part

__all__ = ["FitOutcome", "Saved", "fit_session", "fit_to_file"]

#: Default radius per sensor when --radius is not given (None: keep the data's own scale).
DEFAULT_RADIUS = {"accel": (1.0, "g"), "gyro": None, "mag": None}

@dataclass
class FitOutcome:
    """Everything ``fit`` and ``report`` need after fitting a file."""

    part: SensorCalibration
    points: np.ndarray
    sensor: str
    rejected: np.ndarray
    reason: str | None
    table: Table | None
    source: Source | None = None
    #: Things to tell the user about the input (skipped lines, an implausible radius).
    notes: list[str] = field(default_factory=list)
    expected: ExpectedField | None = None
    #: ``--method attitude``: the flight log's readings with attitude (a FlightSource).
    flight: Any = None


def fit_session(
    data: Any,
    request: FitRequest | None = None,
    *,
    accel: SensorCalibration | None = None,
) -> FitOutcome:
    """Fit one sensor of a recorded session as ``triaxcal fit`` does.

    Parameters
    ----------
    data : str, Path or Table
        A session CSV or any table of numbers (read by :func:`triaxcal.read_table`), a log
        (``.ulg``, ``.bin``, ``.bag``, ``.db3``, ``.mcap``), or a table already read.
    request : FitRequest, optional
        What to fit and how (default: ``FitRequest()``, the accelerometer to 1 g).
    accel : SensorCalibration, optional
        The accelerometer's calibration, for ``request.field.yaw_only`` (the vertical from the
        calibrated accelerometer) and ``request.field.align`` (required there).

    Returns
    -------
    FitOutcome
        The part (not yet judged by the validity gate:
        :func:`~triaxcal.calibration.gate.check_part`), the points fitted, the rejected indices and
        what to tell the user.
    """
    from ..fit.select import fit_robust

    req = options.instance(request if request is not None else FitRequest(), FitRequest,
                           "request", "a FitRequest (or None)")
    if not isinstance(data, (Table, str, os.PathLike)):
        raise CalibrationError(f"data must be a file name or a Table (from read_table), got "
                               f"{type(data).__name__}")
    if accel is not None:
        options.instance(accel, SensorCalibration, "accel", "a SensorCalibration or None")
    sensor = req.sensor
    notes: list[str] = []
    if req.method == "attitude":
        from .flight import fit_flight

        if isinstance(data, Table):
            raise CalibrationError("--method attitude needs a flight log (.bin, .ulg) with the "
                                   "vehicle's attitude, not a table")
        part, fsrc = fit_flight(os.fspath(data), req)
        return FitOutcome(part=part, points=fsrc.raw, sensor=sensor,
                          rejected=np.asarray(part.stats.get("rejected", []), dtype=np.int64),
                          reason=None, table=None, source=None, notes=notes,
                          expected=part.expected_field, flight=fsrc)
    expected = expected_for(req)
    src = table_source(data, sensor, req.source) if isinstance(data, Table) else load_source(
        os.fspath(data), sensor, req.source)
    table, pts = src.table, src.points
    if table is not None:
        notes += [f"note: {n}" for n in table.notes]
    raw_unit = req.raw_unit or src.raw_unit or "counts"
    if req.field.yaw_only:
        part = yaw_part(src, expected, raw_unit, accel=accel)
        if expected is not None:
            part, _ = field_stats(part, expected)
        return FitOutcome(part=part, points=pts, sensor=sensor,
                          rejected=np.zeros(0, dtype=np.int64), reason=None, table=table,
                          source=src, expected=expected)
    if expected is not None and req.radius_is_wmm:
        unit = req.unit or "uT"
        radius: float | None = expected.total_ut * unit_factor("uT", unit)
    elif req.radius is not None:
        radius, unit = req.radius_value, req.radius_unit  # type: ignore[assignment]
        warn = implausible_radius(sensor, radius, unit)  # type: ignore[arg-type]
        if warn:
            notes.append(f"warning: {warn}")
    elif DEFAULT_RADIUS[sensor] is not None:
        radius, unit = DEFAULT_RADIUS[sensor]  # type: ignore[misc]
    else:
        radius, unit = None, raw_unit
    if req.unit:
        unit = req.unit
    fitted = pts
    if req.asa is not None:
        fitted = apply_asa(pts, req.asa)  # adjusted before fitting, folded back below
    rob = fit_robust(fitted, model=req.model, radius=radius, **req.rejection(),
                     fixed=dict(req.fixed) or None)
    extra: dict[str, Any] = {
        "columns": src.columns,
        "poses": bool(req.source.poses),
        "n_input": len(pts),
        "outliers": req.outliers,
        "sigma": float(req.sigma),
        "rejection_rounds": int(rob.rounds),
    }
    if table is not None and table.skipped:
        extra["lines_skipped"] = int(table.skipped)
    if rob.model_reason:
        extra["model_reason"] = rob.model_reason
    extra.update(src.extra)
    extra.update(autopilot_stats(src, sensor))
    part = SensorCalibration.from_fit(
        rob.fit, raw_unit=raw_unit, unit=unit, points=fitted[rob.inliers],
        rejected=rob.rejected, input_sha256=src.sha256, source=str(src.path),
        extra_stats=extra,
    )
    if req.asa is not None:  # the part takes the register counts the chip reports
        part = fold_asa(part, req.asa)
    stats = dict(part.stats)
    cov = coverage(part.apply(pts))  # of the session: every reading, outliers too
    stats["coverage_pct"] = cov.percent
    low = coverage_warning(cov, sensor)
    if radius is None and part.radius is not None and UNITS.get(unit, ("",))[0] == sensor:
        odd = implausible_radius(sensor, part.radius, unit)
        if odd:
            notes.append(f"warning: fitted radius: {odd}")
    stats["warnings"] = [*stats.get("warnings", []), *([low] if low else []),
                         *(n[len("warning: "):] for n in notes if n.startswith("warning: "))]
    if req.bootstrap:
        from ..methods.bootstrap import bootstrap

        ci = bootstrap(fitted[rob.inliers], fit=rob.fit, radius=radius, n_boot=req.bootstrap,
                       raw_unit=raw_unit, unit=unit)
        stats["intervals"] = ci.as_dict()
        stats["warnings"] = list(stats.get("warnings", [])) + ci.warnings()
    stats["directions"] = direction_stats(part, pts[rob.inliers])
    part = part.replace(stats=stats)
    if expected is not None:
        part, _ = field_stats(part, expected)
    return FitOutcome(part=part, points=pts, sensor=sensor, rejected=rob.rejected,
                      reason=rob.model_reason, table=table, source=src, notes=notes,
                      expected=expected)


@dataclass
class Saved:
    """What :func:`fit_to_file` did: the fit, the gate's verdict and the file written."""

    outcome: FitOutcome
    verdict: Verdict
    stored: Stored
    #: The alignment's text when ``request.field.align`` found one.
    alignment_text: str | None = None


def fit_to_file(
    data: Any,
    request: FitRequest,
    output: Any,
    *,
    new: bool = False,
    sensor_id: str | None = None,
    force: bool = False,
) -> Saved:
    """Fit one sensor of a session, judge it with the validity gate, and write it into the
    calibration file ``output`` -- what ``triaxcal fit`` and the live page's Save do.

    A fit the gate refuses raises :class:`~triaxcal.calibration.gate.InvalidCalibrationError`
    (nothing is written) unless ``force``: then it is written marked ``valid: false`` with the
    reasons. An existing file keeps its other parts (``new=True`` starts a new one); the part it
    had for this sensor is kept in the new part's ``previous``. The accelerometer part already
    in ``output`` gives the vertical of a yaw-only fit and the frame of ``field.align``.
    """
    options.instance(request, FitRequest, "request", "a FitRequest")
    options.path(output, "output")
    options.flag(new, "new")
    options.flag(force, "force")
    if sensor_id is not None and not isinstance(sensor_id, str):
        raise CalibrationError(f"sensor_id must be text or None, got {sensor_id!r:.60}")
    before = existing_calibration(output, new=new)
    accel = before.accel if before is not None else None
    out = fit_session(data, request, accel=accel)
    verdict = check_part(out.part, out.sensor)
    out.part = judged(out.part, verdict, force=force)
    align_text = None
    if request.field.align:
        al, align_text = alignment_for(out.source, out.part, out.expected, accel=accel,
                                       window=request.source.detection.window)
        out.part = out.part.replace(alignment=al)
    stored = store_part(output, out.sensor, out.part, new=new, sensor_id=sensor_id)
    return Saved(outcome=out, verdict=verdict, stored=stored, alignment_text=align_text)
