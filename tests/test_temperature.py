"""Temperature compensation: simulator drift and the sunsided MPU-6050 temperature channel."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import triaxcal as tc
from _realdata import load_sunsided
from triaxcal.sim import SimIMU, globe_script, temp_c_from_raw

UNMOVED = ("unmoved-x-pointing-forward", "unmoved-x-pointing-up", "unmoved-z-pointing-left")


@pytest.fixture(scope="module")
def warm_up():
    """A globe-scheme session recorded while the die warms from 10 to 45 degC."""
    imu = SimIMU(3, accel={"tempco": [4.0, -3.0, 2.0], "gain_tempco": 3e-4},
                 gyro={"tempco": [2.0, -1.5, 1.0]})
    rec = imu.record(globe_script(), rate_hz=50, temp_c=(10.0, 45.0))
    return imu, rec, temp_c_from_raw(rec.temp_raw)  # the measured temperature channel


def test_gyro_offset_drift_is_recovered(warm_up):
    imu, rec, temp = warm_up
    st = rec.still
    model = tc.fit_temperature(rec.gyro[st], temp[st], reference_degC=25.0)
    truth = imu.truth.gyro
    np.testing.assert_allclose(model.offset_coef[0], truth.offset, atol=0.5)
    np.testing.assert_allclose(model.offset_coef[1], truth.tempco, atol=0.05)  # counts/degC
    assert model.gain == "none" and model.degree == 1
    assert model.t_min_degC < 11 and model.t_max_degC > 44
    # compensated rest readings have no trend left; uncompensated ones drift by ~70 counts
    left = model.apply(rec.gyro[st], temp[st])
    slope = np.polyfit(temp[st], left, 1)[0]
    assert np.all(np.abs(slope) < 0.05)
    raw_slope = np.polyfit(temp[st], rec.gyro[st], 1)[0]
    assert np.all(np.abs(raw_slope) > 0.9)


def test_accel_offsets_and_gains_over_temperature(warm_up):
    imu, rec, temp = warm_up
    st = rec.still
    model = tc.fit_temperature(rec.accel[st], temp[st], truth=rec.accel_g[st],
                               reference_degC=25.0, gain="full")
    truth = imu.truth.accel
    np.testing.assert_allclose(model.offset_coef[1], truth.tempco, atol=0.5)
    for t in (12.0, 25.0, 44.0):
        np.testing.assert_allclose(model.matrix(t) @ np.linalg.inv(truth.matrix_at(t)),
                                   np.eye(3), atol=5e-4)
    # per-pose means (noise averaged out): compensated error well below the uncompensated one
    poses = range(int(rec.pose.max()) + 1)
    raw = np.array([rec.accel[rec.pose == j].mean(axis=0) for j in poses])
    tp = np.array([temp[rec.pose == j].mean() for j in poses])
    true_g = np.array([rec.accel_g[rec.pose == j].mean(axis=0) for j in poses])
    err = np.linalg.norm(model.apply(raw, tp) - true_g, axis=1)
    fixed = np.linalg.norm(truth.apply(raw) - true_g, axis=1)  # reference-temperature truth
    assert np.sqrt(np.mean(err**2)) < 0.25 * np.sqrt(np.mean(fixed**2))
    assert err.max() < 1e-3  # g
    # cubic and quadratic models fit too and reproduce the data as well
    for degree in (2, 3):
        m = tc.fit_temperature(rec.gyro[st], temp[st], degree=degree)
        assert m.offset_coef.shape == (degree + 1, 3)
        assert np.all(m.rms < 1.1 * imu.truth.gyro.noise)


def test_outside_the_fitted_range_warns(warm_up):
    _, rec, temp = warm_up
    st = rec.still
    model = tc.fit_temperature(rec.gyro[st], temp[st])
    with pytest.warns(tc.TemperatureRangeWarning, match="outside the fitted range"):
        model.apply(rec.gyro[:5], 60.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        model.apply(rec.gyro[:5], 30.0)  # inside: no warning


def test_unusable_input_is_rejected():
    rng = np.random.default_rng(0)
    raw = rng.normal(0, 1, (100, 3))
    with pytest.raises(tc.CalibrationError, match="temperature range of 0 degC"):
        tc.fit_temperature(raw, np.full(100, 25.0))
    with pytest.raises(tc.CalibrationError, match="degree"):
        tc.fit_temperature(raw, np.linspace(20, 30, 100), degree=4)
    with pytest.raises(tc.CalibrationError, match="NaN"):
        tc.fit_temperature(np.full((100, 3), np.nan), np.linspace(20, 30, 100))
    with pytest.raises(tc.CalibrationError, match="shape"):
        tc.fit_temperature(raw[:, :2], np.linspace(20, 30, 100))
    with pytest.raises(tc.CalibrationError, match="distinct temperatures"):
        tc.fit_temperature(raw, np.repeat([20.0, 30.0], 50), degree=2)
    with pytest.raises(tc.CalibrationError, match="needs the true values"):
        tc.fit_temperature(raw, np.linspace(20, 30, 100), gain="diag")
    # one pose only: offset and gain cannot be told apart
    with pytest.raises(tc.CalibrationError, match="cannot be told apart"):
        tc.fit_temperature(raw, np.linspace(20, 30, 100), truth=np.tile([0.0, 0.0, 1.0], (100, 1))
                           + [1e-9, 1e-9, 0], gain="diag")


def _unmoved(realdata):
    out = []
    for name in UNMOVED:
        g = load_sunsided(realdata, name, "gyroscope")
        temp = load_sunsided(realdata, name, "temperature")
        out.append((g[:, 1:], np.interp(g[:, 0], temp[:, 0], temp[:, 1])))
    return out


def test_sunsided_gyro_offset_against_its_temperature_channel(realdata):
    data = _unmoved(realdata)
    gyro = np.vstack([d[0] for d in data])
    temp = np.concatenate([d[1] for d in data])
    model = tc.fit_temperature(gyro, temp)
    # three rests at 23.9-24.4 degC: a narrow range, as its README warns
    assert 23.8 < model.t_min_degC < 24.0 and 24.3 < model.t_max_degC < 24.5
    # MPU-6050 gyro offset drift is well under 1 deg/s per degC
    assert np.all(np.abs(model.offset_coef[1]) < 1.0)
    assert np.all(model.rms <= gyro.std(axis=0))
    # the tumbling recording was 1 degC cooler: applying the model there warns
    sphere = load_sunsided(realdata, "tilt-sphere", "temperature")
    with pytest.warns(tc.TemperatureRangeWarning):
        model.offset(sphere[:, 1])
    # one quantisation step of the temperature channel only: a range of zero
    t0 = data[0][1]
    mode = np.round(t0, 6) == np.round(np.median(data[0][1]), 6)
    if mode.sum() < 100:  # the median lies between two steps: take the most common one
        vals, counts = np.unique(np.round(t0, 6), return_counts=True)
        mode = np.round(t0, 6) == vals[np.argmax(counts)]
    with pytest.raises(tc.CalibrationError, match="temperature range of 0 degC"):
        tc.fit_temperature(data[0][0][mode], t0[mode])


def test_docstrings_run():
    import doctest

    import triaxcal.methods.temperature as mod

    assert doctest.testmod(mod, raise_on_error=True).attempted > 0
