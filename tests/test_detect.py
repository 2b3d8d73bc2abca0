"""Stationary detection: seed window method (offline and online) and the variance detector."""

from __future__ import annotations

import doctest

import numpy as np
import pytest
import triaxcal as tc
import triaxcal.detect as detect_mod
from _realdata import load_imutk_xsens
from hypothesis import given, settings
from hypothesis import strategies as st
from triaxcal.detect import TOO_CLOSE, TOO_NOISY, TOO_SHORT


def _recording(seed: int, n_poses: int = 12, units: float = 1.0, repeat_first: bool = False):
    """Still poses joined by smooth moves; returns samples and the true pose vectors."""
    rng = np.random.default_rng(seed)
    segs, truth = [], []
    prev = np.array([0.0, 0.0, 1.0])
    for i in range(n_poses):
        v = rng.normal(size=3)
        v /= np.linalg.norm(v)
        if repeat_first and i == n_poses - 1:
            v = truth[0]
        segs.append(np.linspace(prev, v, int(rng.integers(15, 35))))
        segs.append(v + rng.normal(0, 0.004, (int(rng.integers(150, 400)), 3)))
        truth.append(v)
        prev = v
    return np.vstack(segs) * units, np.array(truth) * units


def test_offline_finds_every_pose_and_its_mean():
    x, truth = _recording(0)
    det = tc.detect_poses(x)
    assert det.points.shape == (len(truth), 3)
    np.testing.assert_allclose(det.points, truth, atol=0.01)
    assert all(p.n == p.end - p.start and p.n > 0 for p in det.poses)
    assert det.rejected == [] or all(r.reason == TOO_SHORT for r in det.rejected)


def test_units_per_g_scales_the_default_threshold():
    x, truth = _recording(1, units=16384.0)
    det = tc.detect_poses(np.round(x).astype(np.int16), units_per_g=16384)
    assert det.threshold == pytest.approx(0.07 * 16384)
    np.testing.assert_allclose(det.points, truth, atol=0.01 * 16384)
    # with units_per_g left at 1 the threshold (0.07 counts) is far below the noise
    assert len(tc.detect_poses(x).poses) < len(truth) // 2


def test_revisited_pose_is_rejected_as_too_close():
    x, truth = _recording(2, repeat_first=True)
    det = tc.detect_poses(x)
    assert len(det.poses) == len(truth) - 1
    assert [r.reason for r in det.rejected if r.reason != TOO_SHORT] == [TOO_CLOSE]
    assert len(tc.detect_poses(x, min_separation=0).poses) == len(truth)


def test_short_and_noisy_candidates_have_reasons():
    flat = np.tile([0.0, 0.0, 1.0], (200, 1))
    brief = np.tile([1.0, 0.0, 0.0], (50, 1))  # two windows: one steady comparison
    shaky = np.tile([0.0, 1.0, 0.0], (300, 1))
    shaky[:, 0] += np.where(np.arange(300) % 2, 0.2, -0.2)  # steady means, std 0.2
    last = np.tile([-1.0, 0.0, 0.0], (200, 1))
    x = np.vstack([flat, brief, shaky, last])  # instant moves at window boundaries
    det = tc.detect_poses(x, min_windows=3)
    assert [(r.start, r.end, r.reason) for r in det.rejected] == [
        (225, 250, TOO_SHORT), (275, 550, TOO_NOISY)]
    np.testing.assert_allclose(det.points, [[0, 0, 1], [-1, 0, 0]], atol=1e-12)
    assert [(p.start, p.end) for p in det.poses] == [(25, 200), (575, 750)]
    for r in det.rejected:
        assert r.detail
    # with min_windows=2 the brief pose counts (the seed's rule)
    assert len(tc.detect_poses(x).poses) == 3


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), cuts=st.lists(st.integers(0, 6000), max_size=30),
       max_windows=st.sampled_from([None, 12, 15]), min_windows=st.sampled_from([2, 12]))
def test_online_equals_offline_for_any_chunking(seed, cuts, max_windows, min_windows):
    x, _ = _recording(seed % 50, n_poses=8)
    x = np.hstack([x, np.arange(len(x))[:, None] * 1e-3])  # a 4th channel rides along
    opts = {"max_windows": max_windows, "min_windows": min_windows, "window": 20}
    off = tc.detect_poses(x, **opts)
    on = tc.PoseDetector(**opts)
    got = []
    bounds = sorted({0, len(x), *[c % (len(x) + 1) for c in cuts]})
    for a, b in zip(bounds[:-1], bounds[1:]):
        got += on.update(x[a:b])
    got += on.finish()
    assert [(p.start, p.end) for p in got] == [(p.start, p.end) for p in off.poses]
    np.testing.assert_allclose([p.mean for p in got], [p.mean for p in off.poses], rtol=1e-12,
                               atol=1e-12)
    assert [(r.start, r.end, r.reason) for r in on.rejected] == [
        (r.start, r.end, r.reason) for r in off.rejected
    ]


def test_online_max_windows_registers_early_like_the_seed_beep():
    x, truth = _recording(5, n_poses=6)
    on = tc.PoseDetector(max_windows=4)
    first_seen = {}
    for i in range(0, len(x), 10):
        for p in on.update(x[i:i + 10]):
            first_seen[p.start] = i + 10
    off = tc.detect_poses(x, max_windows=4)
    assert sorted(first_seen) == [p.start for p in off.poses]
    assert all(p.n == 3 * 25 for p in off.poses)  # three steady windows after the opener
    # registered (the beep) long before the sensor moves again
    for p in off.poses:
        assert first_seen[p.start] <= p.end + 10
    np.testing.assert_allclose(off.points, truth, atol=0.01)


def test_bad_input_is_rejected():
    with pytest.raises(tc.CalibrationError, match="shape"):
        tc.detect_poses(np.zeros((10, 2)))
    with pytest.raises(tc.CalibrationError, match="NaN"):
        tc.detect_poses(np.array([[0, 0, 1.0], [np.nan, 0, 1]]))
    with pytest.raises(tc.CalibrationError, match="window"):
        tc.detect_poses(np.zeros((10, 3)), window=0)
    with pytest.raises(tc.CalibrationError, match="threshold"):
        tc.detect_poses(np.zeros((10, 3)), threshold=-1)
    with pytest.raises(tc.CalibrationError, match="channels"):
        det = tc.PoseDetector()
        det.update(np.zeros((10, 3)))
        det.update(np.zeros((10, 4)))
    with pytest.raises(tc.CalibrationError, match="rest"):
        tc.still_intervals(np.zeros((1000, 3)), rate_hz=100, rest_s=0.1)
    assert tc.detect_poses(np.zeros((0, 3))).points.shape == (0, 3)


def test_variance_detector_on_synthetic_motion():
    rng = np.random.default_rng(7)
    x = rng.normal(0, 0.002, (3000, 3)) + [0, 0, 1]
    x[1000:1400] += np.sin(np.linspace(0, 20, 400))[:, None] * 0.3
    x[2000:2100] += rng.normal(0, 0.2, (100, 3))
    det = tc.detect_still(x, rate_hz=100, window_s=0.5, rest_s=5.0, k=3.0, min_duration_s=1.0)
    assert len(det.intervals) == 3
    (a0, b0), (a1, b1), (a2, b2) = det.intervals
    assert a0 == 0 and 960 <= b0 <= 1000 and 1400 <= a1 <= 1440 and 1960 <= b1 <= 2000
    assert 2100 <= a2 <= 2140 and b2 == 3000
    assert det.intervals == tc.still_intervals(x, rate_hz=100, window_s=0.5, rest_s=5.0, k=3.0,
                                               min_duration_s=1.0)
    short = tc.detect_still(x, rate_hz=100, window_s=0.5, rest_s=5.0, min_duration_s=12.0)
    assert short.intervals == [] and {r.reason for r in short.rejected} == {TOO_SHORT}


def test_imutk_xsens_has_its_static_poses(realdata):
    t, acc, _ = load_imutk_xsens(realdata)
    rate = 1.0 / np.median(np.diff(t))
    iv = tc.still_intervals(acc, rate_hz=rate, window_s=1.0, rest_s=45.0, k=6.0)
    # imu_tk's recording: an initial rest of about 50 s, then roughly 37 static poses
    assert iv[0][0] == 0 and iv[0][1] / rate > 40
    assert 30 <= len(iv) <= 45
    upg = np.linalg.norm(acc[:100].mean(0) - 32768)  # counts per g, about 3723
    det = tc.detect_poses(acc, units_per_g=upg, window=50, threshold=0.02 * upg, min_separation=0)
    assert 30 <= len(det.poses) <= 45
    # the two detectors agree: most seed-method poses lie inside a variance-detector interval
    inside = [any(a <= (p.start + p.end) // 2 < b for a, b in iv) for p in det.poses]
    assert np.mean(inside) > 0.9
    # some poses of this recording were revisited: the default separation rejects them
    again = tc.detect_poses(acc, units_per_g=upg, window=50, threshold=0.02 * upg)
    assert {r.reason for r in again.rejected} >= {"too close to an earlier pose"}
    assert len(again.poses) + sum(r.reason == "too close to an earlier pose"
                                  for r in again.rejected) == len(det.poses)


def test_docstrings_run():
    assert doctest.testmod(detect_mod, raise_on_error=True).failed == 0
