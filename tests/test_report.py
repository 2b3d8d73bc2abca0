"""Quality report, model selection (BIC), robust fitting, and the report figure."""

from __future__ import annotations

import os
import runpy
from pathlib import Path

import numpy as np
import pytest
import triaxcal as tc
from triaxcal.fit.select import fit_auto, fit_robust
from triaxcal.quality.coverage import coverage
from triaxcal.report import (
    direction_words,
    empty_regions,
    plot_report,
    quality_report,
)

ROOT = Path(__file__).resolve().parent.parent


def _sphere(n, seed=0):
    rng = np.random.default_rng(seed)
    u = rng.normal(size=(n, 3))
    return u / np.linalg.norm(u, axis=1, keepdims=True)


def test_coverage_equal_area_cells():
    u = _sphere(100_000)
    cov = coverage(u)
    counts, pct = cov.counts, cov.percent
    assert counts.shape == (24,) and pct == 100.0
    # equal-area cells: uniform directions fill them evenly (within sampling noise)
    assert counts.min() > 0.85 * counts.mean() and counts.max() < 1.15 * counts.mean()
    # the lower half: the south cap, its collar and the equator's collar (1 + 6 + 10 cells)
    half = coverage(u[u[:, 2] < 0]).percent
    assert half == pytest.approx(100 * 17 / 24)


def test_empty_regions_named_in_words():
    u = _sphere(2000)
    holes = empty_regions(u[u[:, 2] < 0.3])  # the top cap is missing
    assert holes and holes[0][0][2] > 0.95 and holes[0][1] > 60
    assert direction_words(holes[0][0]) == "the top (+Z)"
    assert direction_words([0, 0, -1]) == "the bottom (-Z)"
    assert direction_words([-1, 0.1, 0]) == "the -X side"
    assert direction_words([0.7, 0.05, -0.7]) == "between +X and -Z (bottom)"
    assert empty_regions(u) == []


def _hull_largest_cap(u):
    """The largest empty cap from the convex hull of the unit directions (scipy's Qhull): the
    hull face whose plane is nearest the origin on the empty side."""
    from scipy.spatial import ConvexHull

    u = u / np.linalg.norm(u, axis=1, keepdims=True)
    eq = ConvexHull(u).equations  # n . x + d <= 0 inside, n outward
    i = int(np.argmin(-eq[:, 3]))
    return eq[i, :3], float(np.degrees(np.arccos(np.clip(-eq[i, 3], -1, 1))))


def test_empty_cap_named_by_its_real_centre_and_radius(realdata):
    """icm20948 magnetometer: the cap is 41.3 deg around a centre 19 deg from -X (readings lie
    25-30 deg from -X, so "the -X side, nothing within 40 deg" was untrue)."""
    raw = np.loadtxt(realdata / "icm20948-magneto" / "icm_20948_cal_mag.csv", delimiter=",")
    r = fit_robust(raw, model="auto", rule="sigma")  # the rule these numbers were pinned with
    part = tc.SensorCalibration.from_fit(r.fit, points=raw[r.inliers], rejected=r.rejected)
    rep = quality_report(raw, part, sensor="mag")
    keep = np.setdiff1d(np.arange(len(raw)), rep.rejected)
    u = part.apply(raw)[keep]
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    (cen, ang, words), = rep.empty
    ref_c, ref_ang = _hull_largest_cap(u)
    assert ang == pytest.approx(ref_ang, abs=1e-6) and ang == pytest.approx(41.31, abs=0.01)
    np.testing.assert_allclose(cen, ref_c, atol=1e-6)
    # the cap really is empty: three readings on its rim, none inside
    dist = np.degrees(np.arccos(np.clip(u @ np.asarray(cen), -1, 1)))
    assert dist.min() == pytest.approx(ang, abs=1e-6) and np.sum(dist < ang + 1e-6) == 3
    # the words give the centre and the radius, and how far the centre is from -X
    assert words == "no reading within 41 deg of (-0.94, -0.26, -0.20), 19 deg from -X towards -Y"
    assert any(words in w for w in rep.warnings)
    from_minus_x = np.degrees(np.arccos(np.clip(-u[:, 0], -1, 1)))
    assert np.sum(from_minus_x < 30.5) >= 6  # the readings the old wording denied


@pytest.mark.parametrize("seed", range(12))
def test_largest_empty_cap_equals_the_hull(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(5, 600))
    pts = rng.normal(size=(n, 3)) * rng.uniform(0.3, 3.0, size=3)
    if seed % 3 == 0:  # a missing region
        pts = pts[pts[:, 2] < rng.uniform(-0.3, 0.6) * np.linalg.norm(pts, axis=1)]
    caps = empty_regions(pts, min_deg=0, max_regions=2)
    c, ang = _hull_largest_cap(pts)
    assert caps[0][1] == pytest.approx(ang, abs=1e-7)
    np.testing.assert_allclose(caps[0][0], c, atol=1e-6)
    if len(caps) > 1:  # the next region: smaller, and away from the first
        assert caps[1][1] <= caps[0][1]
        assert np.degrees(np.arccos(caps[0][0] @ caps[1][0])) > 1.5 * caps[0][1]


def test_empty_cap_of_readings_on_one_circle():
    """A magnetometer turned on a flat table: every reading on the equator, both poles empty."""
    t = np.linspace(0, 2 * np.pi, 2000, endpoint=False)
    ring = np.column_stack([np.cos(t), np.sin(t), np.zeros_like(t)])
    caps = empty_regions(ring)
    assert [round(a, 9) for _, a in caps] == [90.0, 90.0]
    assert sorted(round(float(c[2]), 9) for c, _ in caps) == [-1.0, 1.0]
    tilted = ring.copy()
    tilted[:, 2] = 0.3 + 0.01 * np.random.default_rng(0).normal(size=len(t))
    c, ang = _hull_largest_cap(tilted)
    assert empty_regions(tilted, max_regions=1)[0][1] == pytest.approx(ang, abs=1e-7)


def test_report_figure_is_readable(realdata):
    """Residual histogram: few, non-overlapping tick labels; coverage map: a colour legend."""
    pytest.importorskip("matplotlib")
    from triaxcal.report import report_figure

    rng = np.random.default_rng(3)
    u = _sphere(84, seed=5)
    raw = u * 16384 + [300, -150, 80] + rng.normal(scale=4, size=u.shape)  # tiny residuals
    fit = tc.fit_ellipsoid(raw, model="full", radius=1.0)
    part = tc.SensorCalibration.from_fit(fit, unit="g", points=raw)
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    fig = report_figure(raw, part, sensor="accel")
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    renderer = canvas.get_renderer()
    hist = next(a for a in fig.axes if a.get_title().startswith("residuals"))
    labels = [t for t in hist.get_xticklabels() if t.get_text() and t.get_visible()]
    boxes = [t.get_window_extent(renderer) for t in labels]
    inside = [b for b in boxes if hist.get_window_extent(renderer).x0 - 5 <= b.x0
              and b.x1 <= hist.get_window_extent(renderer).x1 + 5]
    assert 3 <= len(inside) <= 8
    inside.sort(key=lambda b: b.x0)
    assert all(b1.x0 - b0.x1 > 2 for b0, b1 in zip(inside[:-1], inside[1:]))  # pixels apart
    # short numbers ("-4", "0", "4"), the power of ten written once at the end of the axis
    digits = [t.get_text().replace("\\mathdefault", "").strip("${}") for t in labels]
    assert all(len(d) <= 3 for d in digits), digits
    assert "10^" in hist.xaxis.get_offset_text().get_text()
    # the coverage map has a colour bar saying what the colours count
    bars = [a for a in fig.axes if a.get_ylabel() == "readings per cell"]
    assert len(bars) == 1
    cover = next(a for a in fig.axes if a.get_title().startswith("coverage"))
    assert [t.get_text() for t in cover.get_legend().get_texts()][0] == "no reading"


def test_report_numbers_and_warnings():
    rng = np.random.default_rng(1)
    u = _sphere(400, seed=2)
    u = u[u[:, 2] < 0.2]  # the board was never turned right side up
    raw = u * 16384 / [1.02, 0.98, 1.0] + [300, -150, 80] + rng.normal(scale=30, size=u.shape)
    fit = tc.fit_ellipsoid(raw, model="axis", radius=1.0)
    part = tc.SensorCalibration.from_fit(fit, unit="g", points=raw)
    rep = quality_report(raw, part, sensor="accel")
    norms = np.linalg.norm(part.apply(raw), axis=1)
    assert rep.norm_min == pytest.approx(norms.min()) and rep.norm_max == pytest.approx(norms.max())
    assert rep.rms == pytest.approx(np.sqrt(np.mean((norms - 1.0) ** 2)))
    assert rep.rms_pct == pytest.approx(100 * rep.rms)
    assert set(rep.stderr) == set(fit.param_names)
    assert rep.coverage_pct == pytest.approx(100 * 17 / 24)  # the top cap and collar empty
    text = rep.text()
    (cen, ang, words), = rep.empty
    assert cen[2] > 0.9 and words.startswith(f"no reading within {ang:.0f} deg of (")
    assert f"the sphere has an empty cap ({words})" in text
    assert "pointing straight up (flat, right side up)" in text
    assert "coverage" in text and "standard errors" in text
    d = rep.to_dict()
    assert d["uniformity"] == pytest.approx(rep.norm_std / rep.norm_mean)


def test_fit_auto_picks_the_model_the_data_need():
    u = _sphere(600, seed=3)
    rng = np.random.default_rng(4)
    noise = rng.normal(scale=0.003, size=u.shape)
    plain = u + [0.1, 0.0, -0.05] + noise
    a = fit_auto(plain, radius=1.0)
    assert a.model == "sphere" and "do not lower the residuals enough" in a.reason
    gains = u / [1.08, 0.93, 1.0] + noise
    assert fit_auto(gains, radius=1.0).model == "axis"
    m = np.array([[1.0, 0.06, -0.04], [0.06, 1.0, 0.05], [-0.04, 0.05, 1.0]])
    skew = u @ np.linalg.inv(m).T + noise
    b = fit_auto(skew, radius=1.0)
    assert b.model == "full" and "lower the residuals by more than their price" in b.reason
    assert set(b.scores) == {"sphere", "axis", "full"}


def test_fit_robust_finds_planted_outliers():
    u = _sphere(300, seed=5)
    rng = np.random.default_rng(6)
    raw = u * 480 + [120, -60, 30] + rng.normal(scale=3, size=u.shape)
    bad = [10, 50, 51, 200, 280]
    raw[bad] = raw[bad] * 1.4 - np.array([120, -60, 30]) * 0.4  # spikes (40 % too long)
    r = fit_robust(raw, model="full")
    assert set(bad) <= set(r.rejected.tolist()) and len(r.rejected) < 30
    assert r.converged
    np.testing.assert_allclose(r.fit.offset, [120, -60, 30], atol=2)
    plain = tc.fit_ellipsoid(raw, model="full")
    assert r.fit.rms < plain.rms
    none = fit_robust(raw, model="full", sigma=0)
    assert len(none.rejected) == 0
    with pytest.raises(tc.CalibrationError, match="unknown model"):
        fit_robust(raw, model="round")


def test_magneto_rule_on_raw_lengths_reproduces_magneto(realdata):
    raw = np.loadtxt(realdata / "icm20948-magneto" / "icm_20948_cal_acc.csv", delimiter=",")
    r = fit_robust(raw, model="full", rule="sigma", sigma=2.0, lengths="raw", max_rounds=1)
    # Magneto 1.4's log (cal_acc_1.lis) lists these rejections at 2 sigma
    assert r.rejected.tolist() == [20, 67, 78, 79, 107, 153, 166, 195, 222, 242, 259]


def test_report_figure(realdata, tmp_path):
    """Produce the README figure from real data (looked at by eye when it changed)."""
    pytest.importorskip("matplotlib")
    raw = np.loadtxt(realdata / "icm20948-magneto" / "icm_20948_cal_mag.csv", delimiter=",")
    r = fit_robust(raw, model="auto")
    part = tc.SensorCalibration.from_fit(r.fit, points=raw[r.inliers], rejected=r.rejected)
    rep = quality_report(raw, part, sensor="mag", model_reason=r.model_reason)
    assert rep.rejected == r.rejected.tolist()
    out = plot_report(raw, part, tmp_path / "report.png", report=rep)
    data = out.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and 30_000 < len(data) < 300_000
    if os.environ.get("TRIAXCAL_UPDATE_DOCS"):
        (ROOT / "docs" / "report-example.png").write_bytes(data)


def test_plot_needs_matplotlib(monkeypatch, tmp_path):
    import triaxcal.report.figure as rp

    monkeypatch.setattr(rp, "have_matplotlib", lambda: False)
    part = tc.SensorCalibration(offset=[0, 0, 0], matrix=np.eye(3), radius=1.0)
    with pytest.raises(tc.CalibrationError, match=r"pip install 'triaxcal\[plot\]'"):
        plot_report(_sphere(50), part, tmp_path / "x.png")


def test_workflow_page_python_runs(realdata, tmp_path, monkeypatch, capsys):
    """The Python example of the workflow page (docs/guide/workflow.md) runs as written."""
    from conftest import doc_page

    section = doc_page("guide/workflow.md")
    code = section.split("```python\n", 1)[1].split("```", 1)[0]
    raw = np.loadtxt(realdata / "icm20948-magneto" / "icm_20948_cal_acc.csv", delimiter=",")
    monkeypatch.chdir(tmp_path)
    script = tmp_path / "workflow_example.py"
    script.write_text(code)
    runpy.run_path(str(script), init_globals={"raw": raw})
    assert tc.Calibration.load(tmp_path / "cal.json").sensor_id == "board-7"
    assert (tmp_path / "out" / "imu_calibration.h").is_file()
    assert "calibration report" in capsys.readouterr().out
