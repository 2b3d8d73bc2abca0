"""Multi-position accelerometer + gyro calibration (Tedaldi et al.): simulator and real data."""

from __future__ import annotations

import math

import numpy as np
import pytest
import triaxcal as tc
from _realdata import load_ferraris_session, load_imutk_xsens
from triaxcal.methods.imu import rotate_gravity
from triaxcal.sim import Script, SimIMU, rotvec_to_matrix

# The maker's calibration of the imu_tk Xsens MTi, as printed by the authors' calibrate.m
# (JzHuai0108/imu_tk_matlab, srcs/calibrate.m: "calibration parameter taken from Xsens MTi we
# use on our real tests"): gains in ADC counts per m/s^2 and per rad/s.
XSENS_ACC_GAIN = np.array([415.0, 413.0, 415.0])
XSENS_GYRO_GAIN = np.array([4778.0, 4758.0, 4766.0])
XSENS_ACC_ZERO = np.array([33123.0, 33276.0, 32360.0])  # the same script's accelerometer zeros
IMUTK_GRAVITY = 9.81744


def _hand_poses(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    poses = [np.eye(3)]
    for _ in range(n - 1):
        rv = rng.normal(size=3)
        rv *= math.radians(rng.uniform(40, 110)) / np.linalg.norm(rv)
        poses.append(poses[-1] @ rotvec_to_matrix(rv))
    return np.array(poses)


def _sim(seed=0, n=30, rate=100.0):
    imu = SimIMU(seed)
    script = Script.from_poses(_hand_poses(n, seed), hold_s=2.5, settle_s=6.0, peak_dps=150)
    return imu, imu.record(script, rate_hz=rate)


def test_recovers_the_simulator_truth():
    imu, rec = _sim()
    res = tc.calibrate_imu(rec.accel, rec.gyro, rate_hz=rec.rate_hz, gravity=1.0, rest_s=5.0)
    truth_a, truth_g = imu.truth.accel, imu.truth.gyro
    assert res.accel_model == "full"
    assert len(res.intervals) >= 28
    # the accelerometer fit is symmetric, the truth too: compare directly
    np.testing.assert_allclose(res.accel.offset, truth_a.offset, atol=15)
    np.testing.assert_allclose(res.accel.matrix, truth_a.matrix, atol=2e-3 / 16384)
    # the gyro: gains (frame-independent) and the full matrix (same frame as the accel)
    np.testing.assert_allclose(res.gyro.offset, truth_g.offset, atol=0.5)
    np.testing.assert_allclose(res.gyro.gains, np.linalg.norm(np.linalg.inv(truth_g.matrix),
                                                              axis=1), rtol=3e-3)
    np.testing.assert_allclose(res.gyro.matrix, truth_g.matrix, atol=3e-3 * truth_g.matrix[0, 0])
    assert res.gyro_rms_deg < 0.3 < res.gyro_rms_deg_before
    # calibrated readings: |acc| = 1 g when still, the integrated rotation matches the truth
    still = rec.still
    norms = np.linalg.norm(res.accel.apply(rec.accel[still]), axis=1)
    assert abs(norms.mean() - 1) < 1e-3
    w = res.gyro.apply(rec.gyro)
    np.testing.assert_allclose(w[~still], rec.gyro_rad_s[~still], atol=0.02)


def test_gravity_prediction_helper():
    # a 90 deg turn about x at a constant rate moves gravity from +z to +y (body frame)
    t = np.linspace(0, 1, 101)
    counts = np.tile([math.pi / 2 * 1000, 0, 0], (101, 1))
    g1 = rotate_gravity(np.eye(3) / 1000, counts, t, [0, 0, 1])
    np.testing.assert_allclose(g1, [0, 1, 0], atol=1e-9)


@pytest.fixture(scope="module")
def xsens(realdata):
    return load_imutk_xsens(realdata)


_XSENS_CAL: dict = {}


def _xsens_cal(xsens, **kw):
    """calibrate_imu on the Xsens recording, computed once per set of options."""
    key = tuple(sorted(kw.items()))
    if key not in _XSENS_CAL:
        t, acc, gyr = xsens
        _XSENS_CAL[key] = tc.calibrate_imu(acc, gyr, rate_hz=100, gravity=IMUTK_GRAVITY, t=t,
                                           **kw)
    return _XSENS_CAL[key]


@pytest.mark.parametrize("rest_s", [3.0, 45.0])  # the default and imu_tk's long initial rest
def test_imutk_xsens_matches_the_factory_calibration(xsens, rest_s):
    res = _xsens_cal(xsens, rest_s=rest_s)
    assert res.accel_model == "full" and 35 <= len(res.intervals) <= 42
    assert res.intervals[0][0] == 0 and res.intervals[0][1] > 4500  # the initial 50 s rest
    # the maker's gains are given to 3-4 digits (+-0.12 % accel, +-0.01 % gyro rounding)
    acc_err = res.accel.gains / XSENS_ACC_GAIN - 1
    gyro_err = res.gyro.gains / XSENS_GYRO_GAIN - 1
    assert np.all(np.abs(acc_err) < 2.5e-3), acc_err
    # x and z within 0.1 % (0.13 % for z with one constant gyro offset); y is +0.22 %, the same
    # on either half of the recording and with every detector setting: see the README
    assert np.all(np.abs(gyro_err[[0, 2]]) < 1e-3), gyro_err
    assert abs(gyro_err[1]) < 2.5e-3, gyro_err
    np.testing.assert_allclose(res.accel.offset, XSENS_ACC_ZERO, atol=8)
    assert res.accel_rms < 0.002 * IMUTK_GRAVITY
    # gravity-direction residual after the gyro fit: 0.13 deg with the g-sensitive offset
    # (0.48 deg with one mean offset, 3.1 deg with the nominal scale only)
    assert res.gyro_rms_deg < 0.2 and res.gyro_rms_deg_before > 2.5
    # the threshold sweep ran, and every threshold was scored
    assert len(res.sweep) == 9 and np.isfinite([s.accel_rms for s in res.sweep]).all()


def test_gyro_rest_reading_depends_on_orientation(xsens):
    """The Xsens gyro at rest reads 4-7 counts differently from pose to pose; offset +
    g-sensitivity @ acceleration explains the pose means to 1.6 counts."""
    t, acc, gyr = xsens
    res = _xsens_cal(xsens, rest_s=3.0)
    rest = np.array([gyr[s:e].mean(axis=0) for s, e in res.intervals])
    pose_acc = res.accel.apply(np.array([acc[s:e].mean(axis=0) for s, e in res.intervals]))
    model = res.gyro.offset + pose_acc @ res.gyro_g_sensitivity.T
    assert np.all(rest.std(axis=0) > 4.0)
    assert np.all(np.sqrt(np.mean((rest - model) ** 2, axis=0)) < 1.6)
    assert np.abs(res.gyro_g_sensitivity).max() * IMUTK_GRAVITY > 10  # counts per g
    # apply_gyro removes it: at rest every pose reads close to zero rate
    still = np.concatenate([np.arange(s, e) for s, e in res.intervals])
    w = res.apply_gyro(gyr[still], acc[still])
    assert np.degrees(np.abs(w.mean(axis=0))).max() < 0.01
    # without the model: one mean offset, and the larger direction residual
    plain = _xsens_cal(xsens, rest_s=3.0, gyro_g_sensitivity=False)
    assert not plain.gyro_g_sensitivity.any() and plain.gyro_rms_deg > 0.4


def _rk4_imu_tk(w, dt):
    """imu_tk's quatIntegrationStepRK4 (integration.h), one step at a time: (w, x, y, z)."""
    def omega(o):
        return np.array([[0, -o[0], -o[1], -o[2]], [o[0], 0, o[2], -o[1]],
                         [o[1], -o[2], 0, o[0]], [o[2], o[1], -o[0], 0]])

    q = np.array([1.0, 0.0, 0.0, 0.0])
    for k, h in enumerate(dt):
        o0, o1 = w[k], w[k + 1]
        om = 0.5 * (o0 + o1)
        k1 = 0.5 * omega(o0) @ q
        k2 = 0.5 * omega(om) @ (q + 0.5 * h * k1)
        k3 = 0.5 * omega(om) @ (q + 0.5 * h * k2)
        k4 = 0.5 * omega(o1) @ (q + h * k3)
        q = q + h * (k1 + 2 * k2 + 2 * k3 + k4) / 6
        q /= np.linalg.norm(q)
    return q


def test_integration_agrees_with_imu_tk_runge_kutta(xsens):
    """The quaternion integration is not where the gains differ: it equals imu_tk's RK4."""
    t, acc, gyr = xsens
    res = _xsens_cal(xsens, rest_s=3.0)
    g0 = np.array([0.0, 0.0, 1.0])
    for i in range(2, 8):
        a, b = res.intervals[i][1] - 1, res.intervals[i + 1][0] + 1
        u = gyr[a:b] - res.gyro.offset
        ours = rotate_gravity(res.gyro.matrix, u, t[a:b], g0)
        q = _rk4_imu_tk(u @ res.gyro.matrix.T, np.diff(t[a:b]))
        w_, v = q[0], q[1:]
        rk4 = g0 + 2 * w_ * np.cross(-v, g0) + 2 * np.cross(-v, np.cross(-v, g0))  # R.T @ g0
        np.testing.assert_allclose(ours, rk4, atol=1e-9)


def test_imucal_ferraris_session_agrees_with_the_closed_form(realdata):
    acc, gyr, sec = load_ferraris_session(realdata)
    imu = tc.calibrate_imu(acc, gyr, rate_hz=102.4, gravity=9.81)
    # only the six faces (with repeats): the full accelerometer model is not determined
    assert imu.accel_model == "axis"
    fer = tc.ferraris({k: (acc[a:b], gyr[a:b]) for k, (a, b) in sec.items()}, rate_hz=102.4,
                      gravity=9.81)
    np.testing.assert_allclose(imu.accel.gains, fer.accel_counts_per_g / 9.81, rtol=1e-3)
    np.testing.assert_allclose(imu.accel.offset, fer.accel.offset, atol=0.02)
    # gyro already in deg/s: both give gains of about 1 count per deg/s, within 1.5 %
    imu_dps = imu.gyro.gains * math.pi / 180
    np.testing.assert_allclose(imu_dps, fer.gyro_counts_per_dps, rtol=0.015)
    np.testing.assert_allclose(imu_dps, 1.0, atol=0.04)
    # both find a g-sensitivity below 0.001 deg/s per m/s^2 (Ferraris from the up/down pairs)
    assert np.abs(imu.gyro_g_sensitivity).max() < 1e-3 and np.abs(fer.g_sensitivity).max() < 1e-3


def test_unusable_input_is_rejected():
    _, rec = _sim(n=6)
    with pytest.raises(tc.CalibrationError, match="still poses"):
        tc.calibrate_imu(rec.accel, rec.gyro, rate_hz=100, rest_s=5.0)
    rng = np.random.default_rng(1)
    with pytest.raises(tc.CalibrationError, match="still poses"):  # no still period at all
        tc.calibrate_imu(rng.normal(0, 100, (3000, 3)) + np.linspace(0, 5e4, 3000)[:, None],
                         rng.normal(0, 5, (3000, 3)), rate_hz=100, rest_s=3.0)
    with pytest.raises(tc.CalibrationError, match="shape"):
        tc.calibrate_imu(np.zeros((10, 2)), np.zeros((10, 3)), rate_hz=100)
    with pytest.raises(tc.CalibrationError, match="NaN"):
        tc.calibrate_imu(np.full((10, 3), np.nan), np.zeros((10, 3)), rate_hz=100)
    with pytest.raises(tc.CalibrationError, match="rows"):
        tc.calibrate_imu(np.zeros((10, 3)), np.zeros((11, 3)), rate_hz=100)


def test_rotations_that_never_turn_an_axis_are_named():
    # poses reached by turns about the body x and y axes only: the z gyro never turns
    rng = np.random.default_rng(5)
    poses = [np.eye(3)]
    for i in range(30):
        rv = np.zeros(3)
        rv[i % 2] = math.radians(rng.uniform(40, 100)) * rng.choice([-1, 1])
        poses.append(poses[-1] @ rotvec_to_matrix(rv))
    rec = SimIMU(2).record(Script.from_poses(np.array(poses), hold_s=2.5, settle_s=6.0),
                           rate_hz=100)
    with pytest.raises(tc.CalibrationError, match="rotations about the gyro's z axis are missing"):
        tc.calibrate_imu(rec.accel, rec.gyro, rate_hz=100, gravity=1.0, rest_s=5.0)


def test_poses_in_one_plane_are_reported():
    poses = [rotvec_to_matrix([math.radians(a), 0, 0]) for a in range(0, 360, 30)]
    rec = SimIMU(2).record(Script.from_poses(np.array(poses), hold_s=2.5, settle_s=6.0),
                           rate_hz=100)
    with pytest.raises(tc.CalibrationError, match="accelerometer fit failed on the 12"):
        tc.calibrate_imu(rec.accel, rec.gyro, rate_hz=100, gravity=1.0, rest_s=5.0)


def test_a_gyro_that_saw_no_rotation_is_reported():
    _, rec = _sim(seed=4, n=15)
    flat = np.random.default_rng(0).normal(0, 4, rec.gyro.shape) + [100, -50, 20]
    with pytest.raises(tc.CalibrationError, match="rotations too small for the gyro: only 0 of"):
        tc.calibrate_imu(rec.accel, flat, rate_hz=100, gravity=1.0, rest_s=5.0)
