"""Bootstrap intervals of the fit coefficients: coverage of the simulator's truth, poses,
flags for firmware, the report and ``triaxcal fit --bootstrap``."""

from __future__ import annotations

import json

import numpy as np
import pytest
import triaxcal as tc
from triaxcal.cli import main
from triaxcal.methods.bootstrap import bootstrap, fit_params
from triaxcal.sim import SimIMU


def sim_points(seed: int, n: int = 200, noise: float = 0.01):
    """Readings in counts of the simulated accelerometer ``SimIMU(seed)`` in ``n`` random
    orientations with Gaussian noise of ``noise`` times the radius (in counts), and the true
    coefficients (offset, diag, offdiag for radius 1 g)."""
    truth = SimIMU(seed).truth.accel
    rng = np.random.default_rng([seed, 99])
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    raw = u @ np.linalg.inv(truth.matrix).T + truth.offset
    raw_radius = 1.0 / np.mean(np.diag(truth.matrix))
    raw = raw + rng.normal(0, noise * raw_radius, raw.shape)
    return raw, fit_params("full", truth.offset, truth.matrix, [1.0], 1.0)[0]


@pytest.mark.slow
def test_intervals_cover_the_truth_at_their_stated_rate():
    """400 simulated calibrations (200 readings, 1 % noise), 500 refits each: the 95 %
    intervals of the nine coefficients cover the truth 95 % +- 3 % of the time (pooled over
    3600 intervals); per coefficient within +- 5 % (400 trials have a binomial SD of 1.1 %)."""
    hits = []
    for seed in range(400):
        raw, truth = sim_points(seed)
        ci = bootstrap(raw, radius=1.0, n_boot=500, seed=seed)
        hits.append((ci.lower <= truth) & (truth <= ci.upper))
    rate = np.mean(hits, axis=0)
    assert abs(np.mean(hits) - 0.95) <= 0.03, rate
    assert np.all(np.abs(rate - 0.95) <= 0.05), rate


def test_bootstrap_spread_agrees_with_the_asymptotic_standard_errors():
    raw, truth = sim_points(3)
    ci = bootstrap(raw, radius=1.0, n_boot=400, seed=1, unit="g")
    np.testing.assert_allclose(ci.boot_std / ci.stderr, 1.0, atol=0.2)
    assert ci.param_names == ("offset_x", "offset_y", "offset_z", "diag_x", "diag_y", "diag_z",
                              "offdiag_xy", "offdiag_xz", "offdiag_yz")
    assert ci.n_boot == 400 and ci.n_failed == 0 and ci.resample == "readings"
    assert np.all(ci.lower < ci.estimate) and np.all(ci.estimate < ci.upper)
    assert ci.units["offset_x"] == "counts" and ci.units["diag_x"] == "g/counts"
    # fixed seed: the same data give the same intervals; another seed, others
    again = bootstrap(raw, radius=1.0, n_boot=400, seed=1)
    np.testing.assert_array_equal(again.lower, ci.lower)
    other = bootstrap(raw, radius=1.0, n_boot=400, seed=2)
    assert not np.array_equal(other.lower, ci.lower)


def test_resampling_poses_keeps_correlated_readings_together():
    """20 poses of 10 readings each; every pose carries its own error (a board that settles
    differently each time): resampling readings pretends there are 200 independent readings
    and gives intervals too narrow; resampling poses does not."""
    truth = SimIMU(5).truth.accel
    rng = np.random.default_rng(7)
    u = rng.normal(size=(20, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    pose = u @ np.linalg.inv(truth.matrix).T + truth.offset + rng.normal(0, 160, (20, 3))
    raw = np.repeat(pose, 10, axis=0) + rng.normal(0, 20, (200, 3))
    groups = np.repeat(np.arange(20), 10)
    by_reading = bootstrap(raw, radius=1.0, n_boot=300, seed=0)
    by_pose = bootstrap(raw, radius=1.0, n_boot=300, seed=0, groups=groups)
    assert by_pose.resample == "poses"
    assert np.all(by_pose.half_width[:3] > 2.0 * by_reading.half_width[:3])


def test_wide_intervals_are_flagged_with_what_to_do():
    raw, _ = sim_points(8, n=25, noise=0.04)
    ci = bootstrap(raw, radius=1.0, n_boot=300, model="axis")
    assert "offset_x" in ci.flagged
    w = ci.warnings()
    assert any(s.startswith("offset_x is uncertain by") and "% of the radius" in s for s in w)
    fit = tc.fit_ellipsoid(raw, model="axis", radius=1.0)
    rep = tc.quality_report(raw, fit, sensor="accel", intervals=ci)
    text = rep.text()
    assert "95 % bootstrap intervals (300 refits over readings)" in text
    assert "<- wider than firmware needs" in text
    assert any(s.startswith("offset_x is uncertain") for s in rep.warnings)
    assert json.loads(json.dumps(rep.to_dict()))["intervals"]["level"] == 0.95
    # a good calibration is not flagged
    raw, _ = sim_points(9, n=300, noise=0.005)
    assert bootstrap(raw, radius=1.0, n_boot=100).flagged == ()


def test_sphere_model_and_own_scale():
    raw, _ = sim_points(4)
    ci = bootstrap(raw, model="sphere", n_boot=100)
    assert ci.param_names[-1] == "data_radius"
    assert ci.lower[-1] < ci.estimate[-1] < ci.upper[-1]
    ci = bootstrap(raw, model="axis", n_boot=100)  # det(matrix) = 1: the data's own scale
    assert np.all(ci.lower[3:] < 1.1) and np.all(ci.upper[3:] > 0.9)


def test_bad_options_say_what_to_do():
    raw, _ = sim_points(1)
    with pytest.raises(tc.CalibrationError, match="n_boot"):
        bootstrap(raw, radius=1.0, n_boot=5)
    with pytest.raises(tc.CalibrationError, match="level"):
        bootstrap(raw, radius=1.0, n_boot=50, level=1.5)
    with pytest.raises(tc.CalibrationError, match="readings that were fitted"):
        bootstrap(raw[:100], fit=tc.fit_ellipsoid(raw, radius=1.0), n_boot=50)
    with pytest.raises(tc.CalibrationError, match="one label per reading"):
        bootstrap(raw, radius=1.0, n_boot=50, groups=[1, 2, 3])
    with pytest.raises(tc.CalibrationError, match="at least 10"):
        bootstrap(raw, radius=1.0, n_boot=50, groups=np.arange(len(raw)) % 4)
    with pytest.raises(tc.CalibrationError, match="offset_tol"):
        bootstrap(raw, radius=1.0, n_boot=50, offset_tol=0)


def test_cli_fit_stores_intervals_and_report_shows_them(tmp_path, capsys):
    raw, _ = sim_points(2, n=150, noise=0.01)
    data = tmp_path / "poses.csv"
    np.savetxt(data, np.round(raw), delimiter=",", header="ax,ay,az", comments="", fmt="%d")
    cal = tmp_path / "cal.json"
    assert main(["fit", str(data), "-o", str(cal), "--model", "full", "--sigma", "0",
                 "--bootstrap", "200"]) == 0
    part = tc.Calibration.load(cal).accel
    iv = part.stats["intervals"]
    assert iv["n_boot"] == 200 and set(iv["coefficients"]) >= {"offset_x", "offdiag_yz"}
    c = iv["coefficients"]["offset_x"]
    assert c["lower"] < part.offset[0] < c["upper"]
    capsys.readouterr()
    assert main(["report", str(cal)]) == 0
    out = capsys.readouterr().out
    assert "95 % bootstrap intervals (200 refits over readings)" in out
