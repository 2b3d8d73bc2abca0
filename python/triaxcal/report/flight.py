"""The held-out check of a compass calibrated from a flight (``--method attitude``), as numbers
and a figure: the field error and the heading error over the half of the flight the fit did not
see, before (the log's own calibration) and after (the fit on the other half), against time
and against the battery current.

The part records the held-out fit (``stats["attitude"]["held_out"]["fit"]``: offset, matrix,
interference and field, in the body frame) and where the flight was split; the readings come
from the log again (:func:`triaxcal.calibration.flight.flight_source`), which
``triaxcal report CAL.json`` finds by the part's source path and checks by its SHA-256.

The field error is the one the fit minimised: with the attitude's yaw (``heading="attitude"``)
the distance between the calibrated reading and the field turned into the body by the logged
attitude; with roll and pitch only (``heading="free"``) the distance to the field turned by the
logged roll and pitch and the compass's own heading (MAGFit's measure), since the yaw is then
the compass's. The heading error is the tilt-compensated compass heading minus the attitude's
yaw. matplotlib (the ``plot`` extra) is imported only to draw.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .._checks import options as opt
from ..calibration.flight import (
    MIN_CURRENT_SPAN_A,
    FlightSource,
    field_error,
    heading_error_deg,
)
from ..calibration.part import SensorCalibration
from ..conventions.units import unit_factor
from ..errors import CalibrationError
from .quality import have_matplotlib
from .text import printable

__all__ = ["FlightCheck", "flight_check", "flight_text", "plot_flight"]


@dataclass(frozen=True, eq=False)
class FlightCheck:
    """The held-out half of a flight, reading by reading (errors in mG, angles in deg)."""

    t: np.ndarray                    # s from the log's first sensor sample
    error_before: np.ndarray         # field error of the log's own calibration, mG
    error_after: np.ndarray          # field error of the fit on the other half, mG
    heading_before: np.ndarray       # heading error, deg
    heading_after: np.ndarray
    current: np.ndarray | None       # battery current, A (None: the throttle is drawn)
    throttle: np.ndarray | None      # throttle 0..1 (or None)
    heading: str                     # "attitude" or "free"
    n_fitted: int

    @property
    def measure(self) -> str:
        """What the field error measures, in words."""
        return ("the field turned into the body by the logged attitude" if
                self.heading == "attitude" else
                "the field turned by the logged roll and pitch and the compass's own heading")

    def rms(self, name: str) -> float:
        v = getattr(self, name)
        return float(np.sqrt(np.mean(v ** 2)))

    def to_dict(self) -> dict[str, Any]:
        """The RMS numbers (for ``report --json``)."""
        return {"model": "attitude", "heading": self.heading, "n_fitted": self.n_fitted,
                "n_held_out": len(self.t), "field_error_measure": self.measure,
                **{f"{k}_rms": self.rms(k) for k in ("error_before", "error_after",
                                                      "heading_before", "heading_after")},
                "field_error_unit": "mG", "heading_error_unit": "deg"}


def _held_fit(part: SensorCalibration) -> tuple[dict[str, Any], dict[str, Any]]:
    a = part.stats.get("attitude")
    held = a.get("held_out") if isinstance(a, dict) else None
    if part.model != "attitude" or not isinstance(a, dict) or not isinstance(held, dict):
        raise CalibrationError("this part is not a compass calibration from a flight (model "
                               "'attitude' with a held-out check): fit one with --method "
                               "attitude")
    fit = held.get("fit")
    if not isinstance(fit, dict) or "split_index" not in held:
        why = held.get("error", "the part was made by an older triaxcal without it")
        raise CalibrationError(f"this part carries no held-out fit to draw ({why})")
    return a, held


def flight_check(part: SensorCalibration, src: FlightSource) -> FlightCheck:
    """The held-out half of ``src`` judged with the part's held-out fit (module docstring).

    Raises
    ------
    CalibrationError
        When the part is not a flight calibration with a held-out fit, or ``src`` is not the
        log it was fitted on (another number of readings).
    """
    a, held = _held_fit(part)
    n_in = part.stats.get("n_input")
    if isinstance(n_in, int) and n_in != len(src.t):
        raise CalibrationError(f"the log has {len(src.t)} compass readings with attitude; the "
                               f"part was fitted on {n_in}: not the same log or options")
    fit = held["fit"]
    split = int(held["split_index"])
    if not 0 < split < len(src.t):
        raise CalibrationError(f"held-out split {split} outside the log's {len(src.t)} readings")
    sel = np.arange(split, len(src.t))
    o, m = np.asarray(fit["offset"], float), np.asarray(fit["matrix"], float)
    after = (src.raw[sel] - o) @ m.T
    if fit.get("interference") is not None:
        if src.x is None:
            raise CalibrationError("the part has an interference term but the log gives no "
                                   "current or throttle now: not the same log or options")
        after = after + src.x[sel, None] * np.asarray(fit["interference"], float)
    before = src.logged[sel] @ src.to_body.T
    b = np.asarray(fit["field_ned"], float)
    k = unit_factor(part.unit, "mG")
    heading = str(a.get("heading", "attitude"))
    decl = held.get("declination_deg")
    dcm = src.dcm[sel]
    cur = src.flight.current.at(src.t[sel]) if src.flight.current is not None else None
    thr = src.flight.throttle.at(src.t[sel]) if src.flight.throttle is not None else None
    inter = part.stats.get("interference")
    if thr is not None and (cur is None or np.ptp(cur) < MIN_CURRENT_SPAN_A or (
            isinstance(inter, dict) and inter.get("per") == "throttle")):
        cur = None  # the throttle is what varied (and what the fit used)
    return FlightCheck(
        t=src.t[sel], error_before=field_error(before, dcm, b, heading) * k,
        error_after=field_error(after, dcm, b, heading) * k,
        heading_before=heading_error_deg(before, dcm, decl),
        heading_after=heading_error_deg(after, dcm, decl), current=cur, throttle=thr,
        heading=heading, n_fitted=split)


def flight_text(part: SensorCalibration, check: FlightCheck, sensor: str = "mag") -> str:
    """The held-out check in words and numbers."""
    a = part.stats.get("attitude") or {}
    held = a.get("held_out") or {}
    how = ("with the attitude's yaw" if check.heading == "attitude" else
           "with roll and pitch only: the yaw came from this compass")
    lines = [f"{sensor} calibration from a flight (model attitude, {how}): held-out check",
             f"  fitted on the first {check.n_fitted} readings, judged on the other "
             f"{len(check.t)} ({check.t[0]:.0f}..{check.t[-1]:.0f} s)",
             f"  field error RMS      before {check.rms('error_before'):8.1f} mG   after "
             f"{check.rms('error_after'):8.1f} mG   (against {check.measure})",
             f"  heading error RMS    before {check.rms('heading_before'):8.1f} deg  after "
             f"{check.rms('heading_after'):8.1f} deg  (against the attitude's yaw)"]
    if isinstance(held.get("scatter_gain"), (int, float)):
        k = unit_factor(part.unit, "mG")
        lines.append(f"  scatter of the field turned to NED  before "
                     f"{held['scatter_before'] * k:.1f} mG  after {held['scatter_after'] * k:.1f}"
                     f" mG  ({held['scatter_gain']:.2f} times smaller)")
    if a.get("field"):
        lines.append(f"  field: {a['field']}")
    return "\n".join(lines)


def plot_flight(part: SensorCalibration, check: FlightCheck, path: str | Path, *,
                title: str | None = None, dpi: int = 80) -> Path:
    """Save the held-out figure (PNG) to ``path``: field error against time and against the
    battery current (or throttle), before and after, and the heading error against time.

    Raises
    ------
    CalibrationError
        If matplotlib (the ``plot`` extra) is not installed.
    """
    if not have_matplotlib():
        raise CalibrationError(
            "the report figure needs matplotlib: pip install 'triaxcal[plot]' (or matplotlib)")
    dots = opt.integer(dpi, "dpi", ge=20, le=600, hint="dots per inch of the PNG")
    if title is not None and not isinstance(title, str):
        raise CalibrationError(f"title must be text or None, got {title!r}")
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure

    fig = Figure(figsize=(12, 9), dpi=dots, layout="constrained")
    ax = fig.subplots(2, 2)
    before = dict(color="#d62728", s=4, alpha=0.5, lw=0, label="before (the log's calibration)")
    after = dict(color="#1f77b4", s=4, alpha=0.6, lw=0, label="after (fit on the first half)")
    t = check.t
    p = ax[0, 0]
    p.scatter(t, check.error_before, **before)
    p.scatter(t, check.error_after, **after)
    p.set_xlabel("time (s)")
    p.set_ylabel("field error (mG)")
    p.set_title(f"field error against {check.measure}", fontsize=9)
    p.legend(loc="upper right", markerscale=4, fontsize=8)
    p = ax[0, 1]
    x, xname = (check.current, "battery current (A)") if check.current is not None else (
        check.throttle, "throttle (0..1)")
    if x is not None:
        p.scatter(x, check.error_before, **before)
        p.scatter(x, check.error_after, **after)
        p.set_xlabel(xname)
        p.set_ylabel("field error (mG)")
        p.set_title(f"field error against the {xname.split(' (')[0]}", fontsize=9)
    else:
        p.text(0.5, 0.5, "the log has no battery current or throttle", ha="center",
               va="center", transform=p.transAxes)
        p.set_axis_off()
    p = ax[1, 0]
    p.scatter(t, check.heading_before, **before)
    p.scatter(t, check.heading_after, **after)
    p.axhline(0, color="k", lw=0.5)
    p.set_xlabel("time (s)")
    p.set_ylabel("heading error (deg)")
    p.set_title("compass heading minus the attitude's yaw"
                + ("" if check.heading == "attitude" else
                   " (the yaw came from this compass)"), fontsize=9)
    p = ax[1, 1]
    hi = float(np.percentile(np.concatenate([check.error_before, check.error_after]), 99.5))
    bins = np.linspace(0, hi if hi > 0 else 1.0, 60)
    p.hist(check.error_before, bins=bins, color="#d62728", alpha=0.5,
           label=f"before: RMS {check.rms('error_before'):.1f} mG")
    p.hist(check.error_after, bins=bins, color="#1f77b4", alpha=0.6,
           label=f"after: RMS {check.rms('error_after'):.1f} mG")
    p.set_xlabel("field error (mG)")
    p.set_ylabel("readings")
    p.legend(fontsize=8)
    p.set_title("held-out field errors", fontsize=9)
    fig.suptitle(title or f"compass from a flight ({printable(part.source or 'log', 120)}): "
                 f"held-out half, {len(t)} readings", fontsize=10)
    out = Path(path)
    fig.savefig(out, format="png", dpi=dots)
    return out
