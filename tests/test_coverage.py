"""The one coverage measure: equal-area cells of the sphere (triaxcal.quality.coverage)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import triaxcal
import triaxcal as tc
from triaxcal.quality.bounds import LOW_COVERAGE_PCT
from triaxcal.quality.coverage import (
    N_CELLS,
    coverage,
    coverage_warning,
    sphere_cells,
    suggest_turn,
)


def _uniform(n: int, seed: int = 0) -> np.ndarray:
    u = np.random.default_rng(seed).normal(size=(n, 3))
    return u / np.linalg.norm(u, axis=1, keepdims=True)


@pytest.mark.parametrize("n", [2, 3, 6, 12, 24, 30, 48, 100, 500])
def test_cells_have_equal_areas_and_tile_the_sphere(n):
    cells = sphere_cells(n)
    assert int(cells.sectors.sum()) == n == cells.n
    # every collar's area 2 pi (z_hi - z_lo) splits evenly into its sectors: area 4 pi / n each
    areas = 2 * math.pi * -np.diff(cells.z_edges) / cells.sectors
    np.testing.assert_allclose(areas, 4 * math.pi / n, rtol=1e-12)
    # and the cell index agrees: uniform directions fill the cells evenly
    idx = cells.index(_uniform(400 * n))
    counts = np.bincount(idx, minlength=n)
    assert counts.min() > 0.75 * 400 and counts.max() < 1.25 * 400
    # the rectangles of the plot cover the (lon, z) strip exactly once
    rect = cells.rectangles()
    assert len(rect) == n
    assert sum((hi - lo) * (z1 - z0) for lo, hi, z0, z1 in rect) == pytest.approx(720.0)


def test_centres_fall_in_their_own_cells():
    for n in (24, 60):
        cells = sphere_cells(n)
        assert cells.index(cells.centres()).tolist() == list(range(n))


def test_axes_are_not_on_cell_boundaries():
    # a board placed by hand near an axis must not flip between cells: the six axes lie at
    # least 9 degrees inside their cells
    cells = sphere_cells()
    axes = np.vstack([np.eye(3), -np.eye(3)])
    base = cells.index(axes)
    rng = np.random.default_rng(3)
    for _ in range(200):
        tilt = tc.sim.rotvec_to_matrix(rng.normal(0, 1, 3) * np.radians(3.0) / math.sqrt(3))
        assert (cells.index(axes @ tilt.T) == base).all()


def test_schemes_covered():
    for seed in range(3):
        imu = tc.sim.SimIMU(seed)
        rec = imu.record(tc.sim.globe_script(hold_s=0.5, seed=seed), rate_hz=50)
        raw = rec.pose_means("accel")
        assert coverage(raw).percent == 100.0  # raw counts from the origin...
        assert coverage(imu.truth.accel.apply(raw)).percent == 100.0  # ...and calibrated
        six = imu.record(tc.sim.six_face_script(seed=seed), rate_hz=50).pose_means("accel")
        assert coverage(six).cells_hit == 6
    # a level turn (yaw only) covers the equator's collar: 10 of 24 cells
    yaw = np.radians(np.arange(0, 360, 5))
    ring = np.column_stack([np.cos(yaw), np.sin(yaw), np.zeros_like(yaw)])
    cov = coverage(ring)
    assert cov.cells_hit == 10 and cov.percent == pytest.approx(100 * 10 / 24)
    assert coverage_warning(cov, "mag").startswith("only 42 % of the sphere is covered")
    assert coverage_warning(coverage(_uniform(1000))) is None


def test_center_and_text_and_empty():
    pts = np.vstack([np.eye(3), -np.eye(3)]) * 5 + [10, 20, 30]
    cov = coverage(pts, center=[10, 20, 30])
    assert cov.cells_hit == 6 and len(cov.empty) == N_CELLS - 6
    assert cov.text() == "coverage 25 % (6 of 24 equal-area cells)"
    assert coverage(pts).cells_hit < 6  # from the origin they all point one way
    assert coverage(np.zeros((0, 3))).cells_hit == 0
    assert coverage([[0, 0, 0]]).cells_hit == 0  # a zero vector has no direction
    assert LOW_COVERAGE_PCT == 50.0


@pytest.mark.parametrize("bad", [
    {"points": [[np.nan, 0, 1]]},
    {"points": [[0, 1]]},
    {"points": "xyz"},
    {"points": [[0, 0, 1]], "center": [0, 0]},
    {"points": [[0, 0, 1]], "center": [0, 0, np.inf]},
    {"points": [[0, 0, 1]], "n_cells": 1},
    {"points": [[0, 0, 1]], "n_cells": True},
    {"points": [[0, 0, 1]], "n_cells": 2.5},
])
def test_bad_input_is_a_calibration_error(bad):
    with pytest.raises(tc.CalibrationError):
        coverage(**bad)


def test_suggestions_aim_at_empty_cells():
    assert suggest_turn([]) == "hold it still to register the first pose"
    assert suggest_turn([[0, 0, 1.0]]) == "turn it upside down (-Z up)"
    assert suggest_turn([[0, 0, 1.0], [0, 0, -1.0]], [0, 0, 1.0]).startswith("tilt the ")
    assert suggest_turn(_uniform(2000)).startswith("every direction covered")
    # following the advice fills the sphere: simulate a user who does what it says
    pts = [np.array([0.0, 0.0, 1.0])]
    cells = sphere_cells()
    for _ in range(40):
        if suggest_turn(pts).startswith("every direction"):
            break
        hit = set(cells.index(np.array(pts)).tolist())
        empty = [i for i in range(cells.n) if i not in hit]
        cen = cells.centres()[empty]
        u = np.array(pts) / np.linalg.norm(pts, axis=1, keepdims=True)
        pts.append(cen[int(np.argmin((cen @ u.T).max(axis=1)))])
    assert coverage(pts).percent == 100.0 and len(pts) == N_CELLS


def test_one_coverage_measure_in_the_package():
    """Capture's status line, the fit, the report, batch and the live page all call
    triaxcal.quality.coverage.coverage: no module defines another function of that name."""
    import ast

    pkg = Path(triaxcal.__file__).parent
    defs = []
    for path in pkg.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and "coverage" in (
                    node.name.strip("_")):
                if node.name.strip("_") == "coverage":
                    defs.append(f"{path.relative_to(pkg)}:{node.name}")
    assert defs == ["quality/coverage.py:coverage"]

