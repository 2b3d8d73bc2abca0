"""The report figure: raw and calibrated points in the XY, XZ and YZ projections with the
fitted ellipse / circle, a histogram of residuals, the coverage map and the norms over time.
matplotlib is an optional extra (``pip install triaxcal[plot]``), imported only here, with the
Agg backend.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from .._checks import options as opt
from .._checks.arrays import as_points
from ..calibration.part import SensorCalibration
from ..errors import CalibrationError
from ..quality.coverage import coverage, sphere_cells
from .quality import (
    QualityReport,
    _check_sensor,
    _resolve,
    _unit,
    have_matplotlib,
    quality_report,
)

__all__ = ["plot_report", "report_figure"]


def _ellipse(part: SensorCalibration, radius: float, i: int, j: int) -> np.ndarray:
    """Outline (2, K) of the fitted ellipsoid's projection onto raw axes (i, j)."""
    a = part.matrix.T @ part.matrix / radius**2
    k = 3 - i - j
    idx = [i, j]
    a2 = a[np.ix_(idx, idx)] - np.outer(a[idx, k], a[k, idx]) / a[k, k]
    w, v = np.linalg.eigh(a2)
    t = np.linspace(0, 2 * np.pi, 200)
    circ = np.vstack([np.cos(t), np.sin(t)])
    return v @ (circ / np.sqrt(w)[:, None]) + part.offset[idx][:, None]


def _cap_outline(centre: np.ndarray, radius_deg: float) -> np.ndarray:
    """The rim of a cap in the coverage map's (longitude deg, z) coordinates, (2, K), with
    NaN where it wraps around at +-180 deg."""
    c = centre / np.linalg.norm(centre)
    a = np.array([1.0, 0.0, 0.0]) if abs(c[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(c, a)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(c, e1)
    t = np.linspace(0, 2 * np.pi, 361)
    rr = math.radians(radius_deg)
    pts = (math.cos(rr) * c[None] + math.sin(rr) * (np.cos(t)[:, None] * e1
                                                      + np.sin(t)[:, None] * e2))
    lon = np.degrees(np.arctan2(pts[:, 1], pts[:, 0]))
    z = pts[:, 2].copy()
    jump = np.flatnonzero(np.abs(np.diff(lon)) > 180) + 1
    lon = np.insert(lon, jump, np.nan)
    z = np.insert(z, jump, np.nan)
    return np.vstack([lon, z])


def _empty_legend() -> Any:
    from matplotlib.lines import Line2D

    return Line2D([], [], color="#d62728", ls="--", marker="*", mec="k", ms=10,
                  label="largest empty cap (rim)")


def plot_report(
    points: Any,
    cal: Any,
    path: str | Path,
    *,
    report: QualityReport | None = None,
    sensor: str | None = None,
    title: str | None = None,
    dpi: int = 80,
) -> Path:
    """Save the report figure (PNG) to ``path``.

    Panels: raw readings in the XY, XZ and YZ projections with the outline of the fitted
    ellipsoid; calibrated readings with the circle of the radius; a histogram of residuals;
    the coverage map (equal-area cylindrical projection of the directions, grey cells empty);
    the calibrated norms over the reading index with the rejected ones marked.

    Raises
    ------
    CalibrationError
        If matplotlib (the ``plot`` extra) is not installed.
    """
    if not have_matplotlib():
        raise CalibrationError(
            "the report figure needs matplotlib: pip install 'triaxcal[plot]' (or matplotlib)"
        )
    dots = opt.integer(dpi, "dpi", ge=20, le=600, hint="dots per inch of the PNG")
    opt.path(path, "path")
    fig = report_figure(points, cal, report=report, sensor=sensor, title=title, dpi=dots)
    out = Path(path)
    fig.savefig(out, format="png", dpi=dots)
    return out


def report_figure(
    points: Any,
    cal: Any,
    *,
    report: QualityReport | None = None,
    sensor: str | None = None,
    title: str | None = None,
    dpi: int = 80,
) -> Any:
    """The report figure of :func:`plot_report` as a matplotlib ``Figure`` (not saved).

    Raises
    ------
    CalibrationError
        If matplotlib (the ``plot`` extra) is not installed.
    """
    if not have_matplotlib():
        raise CalibrationError(
            "the report figure needs matplotlib: pip install 'triaxcal[plot]' (or matplotlib)"
        )
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure

    dpi = opt.integer(dpi, "dpi", ge=20, le=600, hint="dots per inch of the PNG")
    _check_sensor(sensor)
    if title is not None and not isinstance(title, str):
        raise CalibrationError(f"title must be text or None, got {title!r}")
    if report is not None and not isinstance(report, QualityReport):
        raise CalibrationError(
            f"report must be a QualityReport (triaxcal.quality_report) or None, got "
            f"{type(report).__name__}"
        )
    pts = as_points(points)
    part, _ = _resolve(cal)
    rep = report if report is not None else quality_report(pts, cal, sensor=sensor)
    keep = np.ones(len(pts), dtype=bool)
    keep[rep.rejected] = False
    t = part.temperature.temp_ref_c if part.temperature is not None else None
    c = part.apply(pts, temperature=t)
    norms = np.linalg.norm(c, axis=1)
    r = rep.radius
    u, ru = part.unit, part.raw_unit

    fig = Figure(figsize=(13, 12.5), dpi=dpi, layout="constrained")
    engine: Any = fig.get_layout_engine()
    engine.set(wspace=0.06)  # room between the colour bar and the next panel
    gs = fig.add_gridspec(3, 3)
    name = rep.sensor or sensor or "sensor"
    fig.suptitle(
        title or (f"{name}: model {rep.model}, residual RMS {rep.rms:.3g} {u} "
                  f"({rep.rms_pct:.2g} % of radius {r:.4g} {u}), coverage "
                  f"{rep.coverage_pct:.0f} %, {len(rep.rejected)} outliers of {rep.n}"),
        fontsize=13,
    )
    kw_in: dict[str, Any] = {
        "s": 9, "c": "#1f77b4", "alpha": 0.55, "linewidths": 0, "label": "used"
    }
    kw_out: dict[str, Any] = {
        "s": 30, "c": "#d62728", "marker": "x", "linewidths": 1.2, "label": "rejected"
    }
    for col, (i, j) in enumerate(((0, 1), (0, 2), (1, 2))):
        ax = fig.add_subplot(gs[0, col])
        ax.scatter(pts[keep, i], pts[keep, j], **kw_in)
        if (~keep).any():
            ax.scatter(pts[~keep, i], pts[~keep, j], **kw_out)
        e = _ellipse(part, r, i, j)
        ax.plot(e[0], e[1], color="#ff7f0e", lw=1.8, label="fitted ellipsoid (outline)")
        ax.plot(*part.offset[[i, j]], marker="+", color="#ff7f0e", ms=12, mew=2, ls="none",
                label="offset")
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel(f"raw {'XYZ'[i]} ({ru})")
        ax.set_ylabel(f"raw {'XYZ'[j]} ({ru})")
        ax.set_title(f"raw {'XYZ'[i]}{'XYZ'[j]}")
        ax.grid(alpha=0.3)

        ax = fig.add_subplot(gs[1, col])
        ax.scatter(c[keep, i], c[keep, j], **kw_in)
        if (~keep).any():
            ax.scatter(c[~keep, i], c[~keep, j], **kw_out)
        tt = np.linspace(0, 2 * np.pi, 200)
        ax.plot(r * np.cos(tt), r * np.sin(tt), color="#2ca02c", lw=1.8,
                label=f"radius {r:.4g} {u}")
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel(f"calibrated {'XYZ'[i]} ({u})")
        ax.set_ylabel(f"calibrated {'XYZ'[j]} ({u})")
        ax.set_title(f"calibrated {'XYZ'[i]}{'XYZ'[j]}")
        ax.grid(alpha=0.3)
        if col == 0:
            handles = fig.axes[0].get_legend_handles_labels()
            h2 = ax.get_legend_handles_labels()
            fig.legend(handles[0] + h2[0][-1:], handles[1] + h2[1][-1:],
                       loc="outside lower center", ncol=5, fontsize=10, frameon=False)

    # residual histogram: at most 5 ticks, the common power of ten written once at the axis end
    from matplotlib.ticker import MaxNLocator, ScalarFormatter

    ax = fig.add_subplot(gs[2, 0])
    res_in = norms[keep] - r
    bins = np.histogram_bin_edges(norms - r, bins=40).tolist()
    ax.hist(res_in, bins=bins, color="#1f77b4", alpha=0.8, label="used")
    if (~keep).any():
        ax.hist(norms[~keep] - r, bins=bins, color="#d62728", alpha=0.8, label="rejected")
    ax.axvline(0, color="k", lw=0.8)
    ax.xaxis.set_major_locator(MaxNLocator(nbins=5, symmetric=True))
    fmt = ScalarFormatter(useMathText=True)
    fmt.set_powerlimits((-2, 3))
    ax.xaxis.set_major_formatter(fmt)
    ax.yaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel(f"residual |calibrated| - radius ({u})")
    ax.set_ylabel("readings")
    ax.set_title(f"residuals: RMS {rep.rms:.3g} {u}, std/mean of |v| "
                 f"{100 * rep.uniformity:.2g} %")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)

    # coverage map: Lambert cylindrical equal-area (x = longitude, y = z), cells are rectangles
    ax = fig.add_subplot(gs[2, 1])
    cu = _unit(c)  # every reading, as the coverage number
    counts = coverage(cu).counts
    import matplotlib.colors as mcolors
    from matplotlib.cm import ScalarMappable
    from matplotlib.patches import Patch, Rectangle

    cmap = matplotlib.colormaps["viridis"]
    top = int(counts.max()) if counts.size else 1
    cnorm = mcolors.Normalize(vmin=math.log1p(1), vmax=max(math.log1p(top), math.log1p(2)))
    for n_hits, (lo, hi, z_lo, z_hi) in zip(counts.tolist(), sphere_cells().rectangles()):
        face = "#d9d9d9" if n_hits == 0 else cmap(cnorm(math.log1p(n_hits)))
        for shift in (0.0, -360.0):  # a cell that runs past +180 deg shows on both edges
            ax.add_patch(Rectangle((lo + shift, z_lo), hi - lo, z_hi - z_lo, facecolor=face,
                                   edgecolor="white", linewidth=0.6))
    ticks = [t for t in (1, 2, 5, 10, 20, 50, 100, 200, 500, 1000, 2000, 5000, 10000)
             if t <= max(top, 1)]
    cbar = fig.colorbar(ScalarMappable(norm=cnorm, cmap=cmap), ax=ax,
                        ticks=[math.log1p(t) for t in ticks], pad=0.02, fraction=0.06)
    cbar.ax.set_yticklabels([str(t) for t in ticks])
    cbar.set_label("readings per cell")
    ax.scatter(np.degrees(np.arctan2(cu[:, 1], cu[:, 0])), cu[:, 2], s=4, c="k", alpha=0.5)
    for cen, ang, _words in rep.empty:
        cv = np.asarray(cen, dtype=float)
        lon = float(np.degrees(np.arctan2(cv[1], cv[0])))
        ax.plot(lon, cv[2], marker="*", ms=16, color="#d62728", mec="k", ls="none",
                clip_on=False)
        rim = _cap_outline(cv, ang)
        ax.plot(rim[0], rim[1], color="#d62728", lw=1.4, ls="--")
        ax.annotate(f"empty cap, radius {ang:.0f} deg", (lon, cv[2]),
                    textcoords="offset points", xytext=(-8 if lon > 60 else 8, 8),
                    ha="right" if lon > 60 else "left", fontsize=9, color="#d62728",
                    bbox={"boxstyle": "round,pad=0.2", "fc": "white", "ec": "#d62728",
                          "alpha": 0.9})
    keys: list[Any] = [Patch(facecolor="#d9d9d9", edgecolor="white", label="no reading")]
    if rep.empty:
        keys.append(_empty_legend())
    ax.legend(handles=keys, loc="lower left", fontsize=8, framealpha=0.9)
    ax.set_xlim(-180, 180)
    ax.set_ylim(-1, 1)
    ax.set_xticks([-180, -90, 0, 90, 180])
    ax.set_xticklabels(["-X", "-Y", "+X", "+Y", "-X"])
    ax.set_yticks([-1, 0, 1])
    ax.set_yticklabels(["-Z", "0", "+Z"])
    ax.set_xlabel("longitude (direction in the XY plane)")
    ax.set_ylabel("z component (equal-area)")
    ax.set_title(f"coverage {rep.coverage_pct:.0f} % ({rep.cells_hit}/{rep.cells_total} "
                 "equal-area cells)")

    # norms over time
    ax = fig.add_subplot(gs[2, 2])
    idx = np.arange(len(pts))
    ax.plot(idx, norms, color="#7f7f7f", lw=0.6)
    ax.scatter(idx[keep], norms[keep], s=6, c="#1f77b4")
    if (~keep).any():
        ax.scatter(idx[~keep], norms[~keep], s=30, c="#d62728", marker="x", linewidths=1.2)
    ax.axhline(r, color="#2ca02c", lw=1.2)
    ax.set_xlabel("reading index")
    ax.set_ylabel(f"|calibrated| ({u})")
    ax.set_title("|calibrated| per reading (x: rejected)")
    ax.grid(alpha=0.3)

    return fig
