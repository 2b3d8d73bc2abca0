"""Calibration files: exact JSON round trip, clear errors, apply with temperature terms."""

from __future__ import annotations

import json

import numpy as np
import pytest
import triaxcal as tc
from hypothesis import given, settings
from hypothesis import strategies as st
from triaxcal.calibration import SCHEMA, sha256_points

finite = st.floats(allow_nan=False, allow_infinity=False, min_value=-1e12, max_value=1e12)


def _part(**kw):
    base = {"offset": [12.5, -3.25, 100.0], "matrix": np.eye(3) / 16384 * [1.01, 0.99, 1.0],
                "unit": "g", "radius": 1.0, "model": "axis"}
    base.update(kw)
    return tc.SensorCalibration(**base)


@settings(max_examples=60, deadline=None)
@given(off=st.lists(finite, min_size=3, max_size=3),
       m=st.lists(st.floats(min_value=-10, max_value=10, allow_nan=False), min_size=9,
                  max_size=9),
       r=st.floats(min_value=1e-9, max_value=1e9))
def test_json_round_trip_is_exact(off, m, r):
    mat = np.array(m).reshape(3, 3) + np.eye(3) * 30  # keep it non-singular
    part = tc.SensorCalibration(offset=off, matrix=mat, unit="uT", radius=r)
    cal = tc.Calibration(mag=part, sensor_id="x")
    back = tc.Calibration.from_json(cal.to_json())
    assert back == cal
    assert np.array_equal(back.mag.matrix, mat) and np.array_equal(back.mag.offset, off)
    assert back.mag.radius == r


def test_save_load_from_fit(tmp_path):
    rng = np.random.default_rng(0)
    u = rng.normal(size=(300, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    raw = u @ np.diag([16000.0, 16600.0, 16300.0]) + [200, -100, 50]
    fit = tc.fit_ellipsoid(raw, model="full", radius=1.0)
    part = tc.SensorCalibration.from_fit(fit, unit="g", points=raw, rejected=[3, 7])
    cal = tc.Calibration(accel=part, sensor_id="board-1")
    p = cal.save(tmp_path / "cal.json")
    back = tc.Calibration.load(p)
    assert back == cal
    np.testing.assert_allclose(back.apply(raw, sensor="accel"), fit.apply(raw), rtol=1e-13)
    d = json.loads(p.read_text())
    assert d["schema"] == SCHEMA == "triaxcal.calibration/1"
    acc = d["parts"]["accel"]
    for key in ("offset", "diag", "offdiag", "radius", "raw_unit", "unit", "stats"):
        assert key in acc
    assert acc["stats"]["rejected"] == [3, 7]
    assert set(acc["stats"]["stderr"]) == set(fit.param_names)
    assert acc["input_sha256"] == sha256_points(raw)
    assert d["library_version"] == tc.__version__
    assert d["created_utc"].endswith("Z") and "T" in d["created_utc"]
    # single reading in, single reading out
    assert back.apply(raw[0], sensor="accel").shape == (3,)


def test_non_symmetric_matrix_round_trips():
    m = np.array([[1.0, 0.1, 0.2], [0.0, 1.0, 0.3], [0.05, 0.0, 1.0]])
    cal = tc.Calibration(gyro=tc.SensorCalibration(offset=[1, 2, 3], matrix=m, unit="deg/s"))
    d = cal.to_dict()["parts"]["gyro"]
    assert d["offdiag"] == [0.1, 0.2, 0.3] and d["offdiag_lower"] == [0.0, 0.05, 0.0]
    assert np.array_equal(tc.Calibration.from_dict(cal.to_dict()).gyro.matrix, m)


def test_sha256_independent_of_dtype():
    a = np.array([[1, 2, 3], [4, 5, 6]], dtype=np.int16)
    assert sha256_points(a) == sha256_points(a.astype(float))
    assert sha256_points(a) != sha256_points(a[::-1])


def test_temperature_terms_apply():
    t = tc.TemperatureTerms(temp_ref_c=25.0, temp_range_c=(0.0, 50.0),
                            offset_poly=[[0, 0, 0], [2.0, -1.0, 0.5], [0.1, 0.0, 0.0]],
                            gain_poly=[[0, 0, 0], [1e-3, 0, 0]])
    part = _part(temperature=t, matrix=np.eye(3))
    raw = np.array([[100.0, 50.0, 20.0]])
    with pytest.raises(tc.CalibrationError, match="pass temperature="):
        part.apply(raw)
    at_ref = part.apply(raw, temperature=25.0)
    np.testing.assert_allclose(at_ref, raw - part.offset)
    hot = part.apply(raw, temperature=35.0)  # dT = 10
    off = part.offset + [2.0 * 10 + 0.1 * 100, -10.0, 5.0]
    np.testing.assert_allclose(hot, (raw - off) * [1 + 1e-3 * 10, 1, 1])
    # one temperature per reading
    two = part.apply(np.vstack([raw, raw]), temperature=[25.0, 35.0])
    np.testing.assert_allclose(two, np.vstack([at_ref, hot]))
    with pytest.raises(tc.CalibrationError, match="one per reading"):
        part.apply(np.vstack([raw, raw]), temperature=[1.0, 2.0, 3.0])
    cal = tc.Calibration(accel=part)
    back = tc.Calibration.from_json(cal.to_json())
    assert back == cal and back.accel.temperature.gain_poly.shape == (2, 3)
    d = json.loads(cal.to_json())["parts"]["accel"]["temperature"]
    assert set(d) == {"temp_ref_c", "temp_range_c", "offset_poly", "gain_poly"}


@pytest.mark.parametrize(
    "mutate,msg",
    [
        (lambda d: d.update(schema="triaxcal.calibration/2"), "newer"),
        (lambda d: d.update(schema="something/1"), "not a triaxcal calibration"),
        (lambda d: d.pop("parts"), "lacks"),
        (lambda d: d["parts"].update(baro={}), "unknown sensor"),
        (lambda d: d["parts"]["accel"].pop("offset"), "lacks"),
        (lambda d: d["parts"]["accel"].update(offset=[1, 2]), "shape"),
        (lambda d: d["parts"]["accel"].update(diag=[1, "x", 2]), "numbers"),
        (lambda d: d["parts"]["accel"].update(diag=[0, 0, 0], offdiag=[0, 0, 0]), "all zero"),
        (lambda d: d["parts"]["accel"].update(diag=[1, 1, 1], offdiag=[1, 1, 1]), "singular"),
        (lambda d: d["parts"]["accel"].update(gain=2), "unknown field"),
        (lambda d: d["parts"]["accel"].update(radius=-1), "greater than zero"),
        (lambda d: d["parts"].clear(), "at least one"),
    ],
)
def test_malformed_files_raise_clear_errors(tmp_path, mutate, msg):
    d = tc.Calibration(accel=_part()).to_dict()
    mutate(d)
    p = tmp_path / "bad.json"
    p.write_text(json.dumps(d))
    with pytest.raises(tc.CalibrationError, match=msg):
        tc.Calibration.load(p)


def test_not_json_and_missing(tmp_path):
    p = tmp_path / "x.json"
    p.write_text("{not json")
    with pytest.raises(tc.CalibrationError, match="invalid JSON"):
        tc.Calibration.load(p)
    with pytest.raises(tc.CalibrationError, match="not found"):
        tc.Calibration.load(tmp_path / "nope.json")


def test_missing_part_and_bad_raw():
    cal = tc.Calibration(accel=_part())
    with pytest.raises(tc.CalibrationError, match="no mag part"):
        cal.apply([[1, 2, 3]], sensor="mag")
    with pytest.raises(tc.CalibrationError, match="unknown sensor"):
        cal.apply([[1, 2, 3]], sensor="baro")
    with pytest.raises(tc.CalibrationError, match="finite"):
        cal.apply([[1, np.nan, 3]])
    with pytest.raises(tc.CalibrationError, match="shape"):
        cal.apply([[1, 2]])


def test_from_temperature_model_matches_the_model():
    temperature = pytest.importorskip("triaxcal.methods.temperature")
    rng = np.random.default_rng(7)
    n = 600
    t = np.linspace(10.0, 50.0, n)
    dt = t - 30.0
    truth = rng.normal(size=(n, 3)) * 100.0  # deg/s
    sens = np.array([131.0, 130.0, 132.0])[None] * (1 + np.outer(dt, [2e-3, -1e-3, 1.5e-3]))
    off = np.array([20.0, -10.0, 5.0]) + np.outer(dt, [0.8, -0.5, 0.3]) + np.outer(dt**2,
                                                                               [0.01, 0, 0])
    raw = off + truth * sens + rng.normal(scale=0.05, size=(n, 3))
    model = temperature.fit_temperature(raw, t, degree=2, reference_degC=30.0, truth=truth,
                                        gain="diag")
    part = tc.SensorCalibration.from_temperature_model(model, unit="deg/s")
    assert part.temperature.temp_ref_c == 30.0
    assert part.temperature.temp_range_c == (10.0, 50.0)
    assert np.all(part.temperature.offset_poly[0] == 0)
    got = part.apply(raw, temperature=t)
    want = model.apply(raw, t)
    assert np.max(np.abs(got - want)) < 1e-3 * np.max(np.abs(want))
    assert part.stats["temperature_gain_error"] < 1e-3
    back = tc.Calibration.from_json(tc.Calibration(gyro=part).to_json())
    np.testing.assert_allclose(back.apply(raw, sensor="gyro", temperature=t), got, rtol=1e-12)
