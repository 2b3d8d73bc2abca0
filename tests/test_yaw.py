"""Yaw-only magnetometer calibration: simulated turns about the vertical with a known truth,
the nliaudat HMC5883L recording, and hostile input."""

from __future__ import annotations

import numpy as np
import pytest
import triaxcal as tc
from triaxcal.calibration.parts import part_from_yaw
from triaxcal.sim import Script, SimIMU, rotvec_to_matrix

FIELD_UT, INC_DEG = 48.4, 63.5
H = FIELD_UT * np.cos(np.radians(INC_DEG))
V = -FIELD_UT * np.sin(np.radians(INC_DEG))


def _rms(e: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.asarray(e) ** 2)))


@pytest.fixture(scope="module")
def boat():
    """Two turns in 10-deg steps, rolling and pitching by ~3 deg, and 12 poses tilted 10 deg."""
    rng = np.random.default_rng(7)
    k = np.arange(72)
    poses = np.array([rotvec_to_matrix([0, 0, 2 * np.pi * i / 36])
                      @ rotvec_to_matrix(np.radians(rng.normal(0, 3, 3))) for i in k])
    imu = SimIMU(seed=3, field_ut=FIELD_UT, inclination_deg=INC_DEG)
    rec = imu.record(Script.from_poses(poses, hold_s=0.5, settle_s=1.0), rate_hz=50)
    tilted = np.array([rotvec_to_matrix([0, 0, 2 * np.pi * i / 12])
                       @ rotvec_to_matrix(np.radians([10 * np.cos(i), 10 * np.sin(i), 0]))
                       for i in range(12)])
    rec2 = imu.record(Script.from_poses(tilted, hold_s=0.5, settle_s=1.0), rate_hz=50)
    return imu.truth, rec, rec2


def _poses(rec, truth):
    n = int(rec.pose.max()) + 1
    att = np.array([rec.orientation[rec.pose == j][0] for j in range(n)])
    return rec.pose_means("mag"), truth.accel.apply(rec.pose_means("accel")), att


def test_yaw_only_recovers_the_horizontal_calibration_and_headings(boat):
    truth, rec, rec2 = boat
    mag, acc, att = _poses(rec, truth)
    fit = np.arange(len(mag)) % 4 != 1  # every 4th pose held out
    y = tc.fit_yaw(mag[fit], accel=acc[fit], horizontal=H, vertical=V)
    assert y.unit == "uT" and y.vertical == pytest.approx(V)
    # the ellipse: horizontal offsets and the 2x2 soft iron as the simulator drew them
    np.testing.assert_allclose(y.offset[:2], truth.mag.offset[:2], atol=1.0)   # counts
    np.testing.assert_allclose(y.matrix[:2, :2], truth.mag.matrix[:2, :2], rtol=3e-3,
                               atol=3e-4)
    # the vertical offset is off by (gain mismatch) x V, as the limits say
    gz_true = truth.mag.matrix[2, 2]
    mismatch = gz_true / y.matrix[2, 2] - 1
    assert abs(mismatch) > 0.01  # the simulator's z gain differs: the assumption is tested
    z_err_ut = (y.offset[2] - truth.mag.offset[2]) * gz_true
    assert abs(z_err_ut) == pytest.approx(abs(mismatch * V), rel=0.15)
    # heading error on the held-out poses, against the simulator's attitude
    before = tc.heading_errors(acc[~fit], mag[~fit], att[~fit])
    after = tc.heading_errors(acc[~fit], y.apply(mag[~fit]), att[~fit])
    assert _rms(before) > 20 and _rms(after) < 0.3
    # at 10 deg of tilt the heading stays within the stated sensitivity
    m2, a2, att2 = _poses(rec2, truth)
    tilted = tc.heading_errors(a2, y.apply(m2), att2)
    assert _rms(tilted) < y.tilt_heading_deg
    assert any("5 % mismatch" in t for t in y.limits)
    part = part_from_yaw(y, source="sim")
    assert part.model == "yaw" and part.stats["yaw"]["vertical"] == pytest.approx(V)
    assert tc.Calibration.from_json(tc.Calibration(mag=part).to_json()).mag == part


def test_yaw_with_the_wmm_field(boat, monkeypatch):
    truth, rec, _ = boat
    mag, acc, _ = _poses(rec, truth)
    f = tc.ExpectedField(
        model="WMM2025", backend="test", date="2026-05-17", decimal_year=2026.37,
        lat_deg=47.37, lon_deg=8.54, alt_m=408.0, total_ut=FIELD_UT, horizontal_ut=H,
        north_ut=H, east_ut=0.0, down_ut=-V, inclination_deg=INC_DEG, declination_deg=0.0)
    y = tc.fit_yaw(mag, accel=acc, field=f)
    assert y.horizontal == pytest.approx(H) and y.vertical == pytest.approx(V)
    assert "WMM2025 at 47.370, 8.540" in "; ".join(y.assumed)
    with pytest.raises(tc.CalibrationError, match="not both"):
        tc.fit_yaw(mag, field=f, horizontal=20.0)


def test_nliaudat_hmc5883l_yaw_only(realdata):
    """243 HMC5883L readings turned about one axis: the full ellipsoid fit refuses them; the
    yaw-only fit gives a usable horizontal calibration and says what it cannot know."""
    d = np.loadtxt(realdata / "hmc5883l-yaw-nliaudat" / "mag_out_sample.txt", delimiter=",")
    with pytest.raises(tc.CalibrationError, match="do not determine"):
        tc.fit_ellipsoid(d, model="full")
    y = tc.fit_yaw(d, raw_unit="uT")
    # the hard iron: the centre of the horizontal circle (about (40, -89))
    assert y.offset[:2] == pytest.approx([40.6, -89.1], abs=1.0)
    assert y.offset[2] == 0.0 and y.vertical is None
    cal = y.apply(d)
    h_after = np.hypot(cal[:, 0], cal[:, 1])
    h_raw = np.hypot(d[:, 0], d[:, 1])
    assert np.std(h_raw) / np.mean(h_raw) > 0.3           # raw: a circle far off the origin
    assert np.std(h_after) / np.mean(h_after) < 0.025     # calibrated: round within 2.5 %
    assert y.heading_rms_est_deg < 1.5
    text = y.text()
    assert "NOT determined" in text and "level" in text and "data's own" in text
    # a horizontal field of ~187 "uT" exists nowhere on Earth (at most about 42 uT): the
    # readings are not uT, or the sensor sits in a magnetised place
    assert y.horizontal > 150


@pytest.mark.parametrize("mag, kw, match", [
    (np.ones((5, 3)), {}, "at least one full turn"),
    (np.full((50, 3), np.nan), {}, "finite"),
    (np.column_stack([np.cos(np.linspace(0, 1, 60)), np.sin(np.linspace(0, 1, 60)),
                      np.zeros(60)]) * 20, {}, "unvisited|ellipse"),
    (np.random.default_rng(0).normal(size=(60, 3)), {"accel": np.ones((59, 3))}, "pair"),
    (np.random.default_rng(0).normal(size=(60, 3)), {"accel": np.zeros((60, 3))}, "non-zero"),
])
def test_yaw_rejects(mag, kw, match):
    with pytest.raises(tc.CalibrationError, match=match):
        tc.fit_yaw(mag, **kw)
