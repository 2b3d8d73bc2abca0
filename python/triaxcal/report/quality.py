"""Quality report of a calibration: numbers, plain-language warnings and a PNG figure.

For readings ``raw`` and a calibration (``calibrated = (raw - offset) @ matrix.T``, the matrix
**multiplies**, ``|calibrated|`` should be ``radius``) the report gives

* the residual ``|calibrated| - radius``: RMS in calibrated units and in % of the radius;
* min / max / mean / std of the calibrated norms (the "descriptive statistics" of the spreadsheet
method);
* the standard error of every fitted coefficient (``offset_x``... ``offdiag_yz``);
* coverage of the sphere: the share of the equal-area cells of :mod:`triaxcal.quality.coverage` (the
  measure ``capture``, ``demo`` and ``fit`` report too) that hold at least one calibrated
  direction, of every reading given (rejected ones too: coverage says where the board went);
* the outliers rejected before the fit, by index;
* warnings in plain language, each with what to do; the largest empty caps of the sphere
  (found exactly, see :mod:`triaxcal.quality.caps`) are named by their centre and radius ("no
  reading within 41 deg of (-0.94, -0.26, -0.20), 19 deg from -X towards -Y");
* for a magnetometer: the field the World Magnetic Model expects where it was calibrated
  (total, horizontal, inclination, declination) beside the strength the readings show, its
  alignment with the accelerometer (rotation, mounting, dip angle and its spread before and
  after, the heading error on held-out poses), and for a yaw-only calibration what it
  determines and what not (:func:`context_lines`).

The figure is drawn by :mod:`triaxcal.report.figure`.
"""

from __future__ import annotations

import importlib.util
import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from .._checks import options as opt
from .._checks.arrays import as_points, as_samples
from ..calibration.part import SensorCalibration
from ..conventions.units import per_unit
from ..errors import CalibrationError
from ..quality.caps import largest_empty_caps
from ..quality.coverage import Coverage, coverage, coverage_warning
from .text import coefficient_table, context_lines, printable

__all__ = [
    "QualityReport",
    "cap_words",
    "context_lines",
    "direction_words",
    "empty_regions",
    "have_matplotlib",
    "quality_report",
]

#: An empty cap of the sphere at least this wide (angular radius, degrees) is warned about.
HOLE_DEG = 40.0


def have_matplotlib() -> bool:
    """Whether the optional ``plot`` extra (matplotlib) is installed."""
    return importlib.util.find_spec("matplotlib") is not None


# --------------------------------------------------------------------------------------------
# Geometry of directions


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n == 0, 1.0, n)


def empty_regions(
    directions: Any, *, min_deg: float = HOLE_DEG, max_regions: int = 3
) -> list[tuple[np.ndarray, float]]:
    """The largest empty caps of the sphere: ``[(centre unit vector, angular radius deg)]``.

    The first is the largest cap that holds no reading (exact: its rim passes through three
    readings); further caps are the largest centred more than 1.5 radii from the ones found.
    Only caps of at least ``min_deg`` are returned, largest first.

    >>> import numpy as np
    >>> pts = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, -1.0]])
    >>> [(c.round(3).tolist(), round(r, 3)) for c, r in empty_regions(pts, max_regions=1)]
    [([0.0, 0.0, 1.0], 90.0)]
    """
    lo = opt.number(min_deg, "min_deg", ge=0, le=180, hint="degrees")
    most = opt.integer(max_regions, "max_regions", ge=1, le=100)
    pts = as_points(directions, name="directions")
    if not np.isfinite(pts).all():
        raise CalibrationError("directions contain NaN or inf; drop those readings first")
    return largest_empty_caps(pts, min_deg=lo, max_regions=most)


_AXIS_WORDS = {
    (2, 1): "top", (2, -1): "bottom", (0, 1): "+X side", (0, -1): "-X side",
    (1, 1): "+Y side", (1, -1): "-Y side",
}


def direction_words(v: Any) -> str:
    """Name a direction: ``"+Z (top)"``, ``"-X (the -X side)"`` or ``"between +X and -Z"``.

    >>> direction_words([0.1, -0.1, 0.99])
    'the top (+Z)'
    >>> direction_words([0.7, 0.0, -0.7])
    'between +X and -Z (bottom)'
    """
    v = np.asarray(v, dtype=float)
    v = v / np.linalg.norm(v)
    order = np.argsort(-np.abs(v))
    names = []
    for k in order:
        if abs(v[k]) >= 0.5 * abs(v[order[0]]) and abs(v[k]) > 0.3:
            names.append((int(k), 1 if v[k] > 0 else -1))
    label = [f"{'+' if s > 0 else '-'}{'XYZ'[k]}" for k, s in names]
    if len(names) == 1:
        k, s = names[0]
        w = _AXIS_WORDS[(k, s)]
        return f"the {w} ({label[0]})" if k == 2 else f"the {label[0]} side"
    z = [s for k, s in names if k == 2]
    extra = f" ({_AXIS_WORDS[(2, z[0])]})" if z else ""
    return "between " + " and ".join(label) + extra


def cap_words(centre: Any, radius_deg: float) -> str:
    """Name an empty cap by its centre and radius, and say how far the centre is from the
    nearest sensor axis.

    >>> cap_words([-0.9435, -0.2647, -0.1992], 41.31)
    'no reading within 41 deg of (-0.94, -0.26, -0.20), 19 deg from -X towards -Y'
    >>> cap_words([0.0, 0.0, 1.0], 72.6)
    'no reading within 73 deg of (+0.00, +0.00, +1.00), the +Z axis'
    """
    v = np.asarray(centre, dtype=float)
    v = v / np.linalg.norm(v)
    k = int(np.argmax(np.abs(v)))
    axis = f"{'+' if v[k] > 0 else '-'}{'XYZ'[k]}"
    off = math.degrees(math.acos(min(1.0, abs(float(v[k])))))
    where = f"({v[0]:+.2f}, {v[1]:+.2f}, {v[2]:+.2f})"
    if off < 1.0:
        pos = f"the {axis} axis"
    else:
        rest = v.copy()
        rest[k] = 0.0
        j = int(np.argmax(np.abs(rest)))
        pos = f"{off:.0f} deg from {axis} towards {'+' if v[j] > 0 else '-'}{'XYZ'[j]}"
    return f"no reading within {radius_deg:.0f} deg of {where}, {pos}"


def _axis_phrase(v: np.ndarray) -> str:
    v = v / np.linalg.norm(v)
    parts = [f"{'+' if v[k] > 0 else '-'}{'XYZ'[k]}" for k in np.argsort(-np.abs(v))
             if abs(v[k]) > 0.3]
    return " / ".join(parts[:2])


def _hole_action(sensor: str | None, v: np.ndarray) -> str:
    ax = _axis_phrase(v)
    if sensor == "accel":
        if v[2] > 0.8:
            how = " (flat, right side up)"
        elif v[2] < -0.8:
            how = " (turn the board upside down)"
        else:
            how = ""
        return f"hold the board still with its {ax} axis pointing straight up{how}"
    if sensor == "mag":
        return (f"turn the board so that its {ax} axis points along the local magnetic field "
                "(north, and downward in the northern hemisphere)")
    if sensor == "gyro":
        return f"add rotations about the {ax} axis, in the positive sense"
    return f"add readings with the {ax} direction"


# --------------------------------------------------------------------------------------------
# The report


@dataclass(frozen=True)
class QualityReport:
    """Numbers of a calibration's quality (see the module docstring); ``text()`` for the console.

    All lengths are in ``unit`` (calibrated units). ``rejected`` are indices into the
    readings given; statistics use the kept readings.
    """

    sensor: str | None
    unit: str
    model: str | None
    n: int
    n_used: int
    radius: float
    rms: float
    rms_pct: float
    norm_min: float
    norm_max: float
    norm_mean: float
    norm_std: float
    stderr: dict[str, float]
    coverage_pct: float
    cells_hit: int
    cells_total: int
    empty: list[tuple[list[float], float, str]]
    rejected: list[int]
    warnings: list[str]
    model_reason: str | None = None
    raw_unit: str = "counts"
    extra: dict[str, Any] = field(default_factory=dict)
    #: Bootstrap intervals (:meth:`triaxcal.methods.bootstrap.BootstrapIntervals.as_dict`).
    intervals: dict[str, Any] | None = None

    @property
    def uniformity(self) -> float:
        """``norm_std / norm_mean``: 0 for a perfect calibration."""
        return self.norm_std / self.norm_mean if self.norm_mean else float("nan")

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON values."""
        d = asdict(self)
        d["uniformity"] = self.uniformity
        return d

    def text(self) -> str:
        """The report as console text."""
        u = self.unit
        name = self.sensor or "sensor"
        lines = [
            f"{name} calibration report ({self.raw_unit} -> {u}, model {self.model})",
            f"  readings        {self.n} ({self.n_used} used, {len(self.rejected)} rejected)",
            f"  radius          {self.radius:.6g} {u}",
            f"  residual RMS    {self.rms:.4g} {u} ({self.rms_pct:.3g} % of radius)",
            (f"  calibrated |v|  min {self.norm_min:.6g}  max {self.norm_max:.6g}  "
            f"mean {self.norm_mean:.6g}  std {self.norm_std:.4g} {u}  "
            f"(std/mean {100 * self.uniformity:.3g} %)"),
            (f"  coverage        {self.coverage_pct:.0f} % of the sphere "
            f"({self.cells_hit} of {self.cells_total} equal-area cells)"),
        ]
        if self.model_reason:
            lines.append(f"  model choice    {self.model_reason}")
        lines += ["  " + r for r in self.extra.get("coefficients", [])]
        lines += self.extra.get("context", [])
        ci = (self.intervals or {}).get("coefficients") or {}
        if self.stderr:
            lines.append("  standard errors (1 sigma: how uncertain each coefficient is, not its "
                         "value)" + (
                f" and {round(100 * self.intervals['level'])} % bootstrap intervals "
                f"({self.intervals['n_boot']} refits over {self.intervals['resample']})"
                if ci and self.intervals else ""))
            for k, v in self.stderr.items():
                unit = (self.raw_unit if k.startswith("offset") or k == "data_radius"
                        else per_unit(u, self.raw_unit, short=True))
                c = ci.get(k)
                band = "" if c is None else (
                    f"   [{c['lower']:.6g}, {c['upper']:.6g}]"
                    + ("  <- wider than firmware needs" if (c["upper"] - c["lower"]) / 2
                       > c["tolerance"] else ""))
                lines.append(f"    {k:<12} +-{v:.3g} {unit}{band}")
        if self.rejected:
            shown = ", ".join(str(i) for i in self.rejected[:30])
            more = f", ... ({len(self.rejected)} in all)" if len(self.rejected) > 30 else ""
            lines.append(f"  outliers        rejected readings #{shown}{more}")
        else:
            lines.append("  outliers        none rejected")
        if self.warnings:
            lines.append("  warnings")
            lines += [f"    - {printable(w)}" for w in self.warnings]
        else:
            lines.append("  warnings        none: this calibration looks good")
        return "\n".join(lines)


def _resolve(cal: Any) -> tuple[SensorCalibration, Any]:
    """(part, fit or None) from a SensorCalibration or an EllipsoidFit."""
    if isinstance(cal, SensorCalibration):
        return cal, None
    if hasattr(cal, "offset") and hasattr(cal, "matrix") and hasattr(cal, "param_names"):
        return SensorCalibration.from_fit(cal), cal
    raise CalibrationError(
        f"expected a SensorCalibration or an EllipsoidFit, got {type(cal).__name__}"
    )


def quality_report(
    points: Any,
    cal: Any,
    *,
    sensor: str | None = None,
    rejected: Sequence[int] | None = None,
    model_reason: str | None = None,
    temperature: Any = None,
    intervals: Any = None,
) -> QualityReport:
    """Build the :class:`QualityReport` of calibration ``cal`` on raw readings ``points``.

    Parameters
    ----------
    points : array_like, shape (N, 3)
        The raw readings (all of them, including any rejected as outliers).
    cal : SensorCalibration or EllipsoidFit
        The calibration to judge.
    sensor : {"accel", "gyro", "mag"}, optional
        Names the advice ("hold the board with +Z up" for an accelerometer).
    rejected : sequence of int, optional
        Indices of readings rejected before the fit. Default: ``cal.stats["rejected"]`` when
        it fits the number of readings.
    model_reason : str, optional
        Why the model was chosen (from :func:`triaxcal.fit.select.fit_auto`).
    temperature : float or array_like, optional
        Temperatures (deg C) for parts with temperature terms.
    intervals : BootstrapIntervals or dict, optional
        Bootstrap intervals of the coefficients (:func:`triaxcal.bootstrap`), shown beside the
        standard errors; wide ones are warned about. Default: ``cal.stats["intervals"]``.

    Returns
    -------
    QualityReport
    """
    pts = as_samples(points, "points")
    part, fit = _resolve(cal)
    n = len(pts)
    _check_sensor(sensor)
    if model_reason is not None and not isinstance(model_reason, str):
        raise CalibrationError(f"model_reason must be text or None, got {model_reason!r}")
    if rejected is not None:
        if isinstance(rejected, (str, bytes)) or not hasattr(rejected, "__iter__"):
            raise CalibrationError(
                f"rejected must be a sequence of reading indices, got {rejected!r}"
            )
        rejected = [opt.integer(i, "rejected index", ge=0, le=max(n - 1, 0))
                    for i in rejected]
    if rejected is None:
        rej = part.stats.get("rejected") or []
        used = part.stats.get("n")
        if rej and used is not None and used + len(rej) != n:
            rej = []  # the stored indices belong to other data
    else:
        rej = list(rejected)
    rej = sorted({int(i) for i in rej})
    if rej and (rej[0] < 0 or rej[-1] >= n):
        raise CalibrationError(f"rejected indices must lie in 0..{n - 1}")
    keep = np.ones(n, dtype=bool)
    keep[rej] = False
    if keep.sum() < 2:
        raise CalibrationError("fewer than 2 readings left after rejection: nothing to report")
    if part.temperature is not None and temperature is None:
        temperature = part.temperature.temp_ref_c
    cal_pts = part.apply(pts, temperature=temperature)
    norms = np.linalg.norm(cal_pts, axis=1)
    nk = norms[keep]
    radius = part.radius if part.radius is not None else float(np.mean(nk))
    res = nk - radius
    rms = float(np.sqrt(np.mean(res**2)))
    cov = coverage(cal_pts)  # of the session: rejected readings were visited too
    holes = empty_regions(cal_pts[keep])
    stderr = dict(part.stats.get("stderr") or {})
    if fit is not None:
        stderr = fit.stderr_dict
    warnings = _warnings(part, fit, sensor, n, rej, rms / radius * 100, cov, holes, nk)
    if intervals is None:
        intervals = part.stats.get("intervals")
    elif hasattr(intervals, "as_dict"):
        intervals = intervals.as_dict()
    if intervals is not None:
        if not isinstance(intervals, dict) or not isinstance(intervals.get("coefficients"), dict):
            raise CalibrationError("intervals must come from triaxcal.bootstrap")
        warnings += [w for w in intervals.get("warnings", []) if w not in warnings]
    if part.model == "yaw":  # turns about the vertical cover a band of the sphere, on purpose
        warnings = [w for w in warnings if "sphere" not in w]
    return QualityReport(
        sensor=sensor,
        unit=part.unit,
        raw_unit=part.raw_unit,
        model=part.model,
        n=n,
        n_used=int(keep.sum()),
        radius=float(radius),
        rms=rms,
        rms_pct=100.0 * rms / radius,
        norm_min=float(nk.min()),
        norm_max=float(nk.max()),
        norm_mean=float(nk.mean()),
        norm_std=float(nk.std(ddof=1)),
        stderr={k: float(v) for k, v in stderr.items()},
        coverage_pct=cov.percent,
        cells_hit=cov.cells_hit,
        cells_total=cov.n_cells,
        empty=[(c.tolist(), a, cap_words(c, a)) for c, a in holes],
        rejected=rej,
        warnings=warnings,
        model_reason=model_reason or part.stats.get("model_reason"),
        intervals=intervals,
        extra={"context": context_lines(part),
               "coefficients": coefficient_table(part, sensor or "sensor")},
    )


SENSORS = ("accel", "gyro", "mag")


def _check_sensor(sensor: Any) -> None:
    if sensor is not None and (not isinstance(sensor, str) or sensor not in SENSORS):
        raise CalibrationError(
            f"sensor must be None or one of {', '.join(repr(x) for x in SENSORS)}, got "
            f"{sensor!r}"
        )


def _warnings(part: SensorCalibration, fit: Any, sensor: str | None, n: int, rej: list[int],
              rms_pct: float, cov: Coverage, holes: list, norms: np.ndarray) -> list[str]:
    w: list[str] = []
    for c, ang in holes:
        w.append(
            f"the sphere has an empty cap ({cap_words(c, ang)}): {_hole_action(sensor, c)}, "
            "then fit again"
        )
    low = coverage_warning(cov, sensor)
    if low:
        w.append(low)
    if n - len(rej) < 30:
        w.append(
            f"only {n - len(rej)} readings were used: collect at least 30 (better 100+) spread "
            "over the sphere"
        )
    limit = 3.0 if sensor != "accel" else 2.0
    if rms_pct > limit:
        what = ("readings taken while the board moved (accelerations add to gravity): hold the "
                "board still in each pose, or fit a capture with --poses" if sensor == "accel"
                else "noise, motion or magnetic disturbances (metal, motors, cables nearby): "
                "calibrate away from them and move slowly" if sensor == "mag"
                else "noisy readings: average more samples per pose")
        w.append(f"the residual RMS is {rms_pct:.2g} % of the radius, which suggests {what}")
    if rej and len(rej) > 0.1 * n:
        w.append(
            f"{len(rej)} of {n} readings ({100 * len(rej) / n:.0f} %) were rejected as "
            "outliers: the data are noisy or mixed; look at the norms-over-time plot and "
            "recapture the bad part"
        )
    d = np.abs(np.diag(part.matrix))
    if d.min() > 0 and d.max() / d.min() > 1.25:
        w.append(
            f"the axis gains differ by {100 * (d.max() / d.min() - 1):.0f} %: check that all "
            "three columns come from the same sensor and range setting"
        )
    if fit is not None:
        if not fit.converged:
            w.append("the fit did not converge: try more readings or model='axis'")
        if math.isfinite(fit.condition) and fit.condition > 1e6:
            w.append(
                f"the fit is poorly determined (condition {fit.condition:.2g}): cover more of "
                "the sphere or use a simpler model"
            )
    for msg in part.stats.get("warnings") or []:
        if holes and "sphere is empty" in str(msg):
            continue  # said above, with the direction in words
        if msg not in w:
            w.append(str(msg))
    return w


# --------------------------------------------------------------------------------------------
# Figure
