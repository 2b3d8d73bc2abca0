"""``triaxcal diff`` and the ``previous`` history of a calibration: the demo's calibration
against itself, against a second session of the same simulated board, and against a board
whose offset or gain changed."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
import triaxcal as tc
from triaxcal.calibration import MAX_PREVIOUS
from triaxcal.cli import main
from triaxcal.sim import SimIMU, globe_script


@pytest.fixture(scope="module")
def demo_cal(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo")
    assert main(["demo", "--out-dir", str(out), "--quiet", "--no-plot"]) == 0
    return out / "calibration.json"


def session_cal(imu: SimIMU, path, *, sessions: int = 1) -> tc.Calibration:
    """Fit accel and mag to the still-pose means of the ``sessions``-th recording of ``imu``
    along the demo's script, and save the calibration to ``path``."""
    script = globe_script(hold_s=1.0, seed=1)
    for _ in range(sessions):
        rec = imu.record(script, rate_hz=100.0)
    acc = rec.pose_means("accel")
    mag = rec.pose_means("mag")
    cal = tc.Calibration(
        accel=tc.SensorCalibration.from_fit(tc.fit_ellipsoid(acc, model="full", radius=1.0),
                                            unit="g", points=acc),
        mag=tc.SensorCalibration.from_fit(
            tc.fit_ellipsoid(mag, model="full", radius=imu.truth.field_ut), unit="uT",
            points=mag),
        sensor_id="triaxcal-sim-seed1",
    )
    cal.save(path)
    return cal


def test_the_demo_calibration_against_itself_is_the_same(demo_cal, capsys):
    assert main(["diff", str(demo_cal), str(demo_cal)]) == 0
    out = capsys.readouterr().out
    assert out.startswith("verdict: the same calibration")
    for s in ("accel", "gyro", "mag"):
        assert f"\n{s}: the same calibration" in out


def test_a_second_session_of_the_same_board_is_the_same_within_uncertainty(
        demo_cal, tmp_path, capsys):
    second = tmp_path / "second.json"
    session_cal(SimIMU(1), second, sessions=2)  # the 2nd recording: new noise, same board
    rc = main(["diff", str(demo_cal), str(second), "--sensor", "accel", "--sensor", "mag",
               "--format", "json"])
    d = json.loads(capsys.readouterr().out)
    assert rc == 0, d
    for s in ("accel", "mag"):
        coefs = d["parts"][s]["coefficients"]
        assert all(c["verdict"] == "same" for c in coefs.values()), coefs
        # the coefficients did move (new noise), by up to a few standard errors
        assert max(abs(c["change"]) for c in coefs.values()) > 0
        assert 0 < max(c["sigmas"] for c in coefs.values()) <= 3.0


def test_a_board_whose_offset_changed_is_flagged(demo_cal, tmp_path, capsys):
    imu = SimIMU(1)
    moved = imu.with_truth(accel=replace(imu.truth.accel,
                                         offset=imu.truth.accel.offset + [300.0, 0.0, 0.0]))
    path = tmp_path / "moved.json"
    session_cal(moved, path, sessions=2)
    rc = main(["diff", str(demo_cal), str(path), "--sensor", "accel", "--format", "json"])
    d = json.loads(capsys.readouterr().out)
    assert rc == 3 and d["verdict"] == "changed"
    coefs = d["parts"]["accel"]["coefficients"]
    assert coefs["offset_x"]["verdict"] == "changed" and coefs["offset_x"]["sigmas"] > 10
    assert coefs["offset_x"]["change"] == pytest.approx(300.0, abs=30.0)
    assert all(c["verdict"] == "same" for n, c in coefs.items() if n != "offset_x")


def test_a_gain_change_larger_than_drift_is_suspicious(demo_cal, tmp_path, capsys):
    imu = SimIMU(1)
    other = imu.with_truth(accel=replace(imu.truth.accel, matrix=imu.truth.accel.matrix * 2))
    path = tmp_path / "range.json"
    session_cal(other, path, sessions=2)
    assert main(["diff", str(demo_cal), str(path), "--sensor", "accel"]) == 4
    out = capsys.readouterr().out
    assert "suspicious" in out and "the gain changed by 100" in out


def test_fit_keeps_the_replaced_calibration_and_diff_compares_with_it(tmp_path, capsys):
    imu = SimIMU(3)
    rec = imu.record(globe_script(hold_s=1.0, seed=3), rate_hz=100.0)
    data = tmp_path / "poses.csv"
    np.savetxt(data, rec.pose_means("accel"), delimiter=",", header="ax,ay,az", comments="")
    cal = tmp_path / "cal.json"
    assert main(["fit", str(data), "-o", str(cal), "--model", "full"]) == 0
    assert tc.Calibration.load(cal).accel.previous == ()
    first = tc.Calibration.load(cal)
    assert main(["fit", str(data), "-o", str(cal), "--model", "axis"]) == 0
    part = tc.Calibration.load(cal).accel
    assert len(part.previous) == 1
    prev = part.previous[0]
    assert prev["model"] == "full" and prev["created_utc"] == first.created_utc
    assert prev["offset"] == first.accel.offset.tolist()
    np.testing.assert_array_equal(part.previous_part(0).matrix, first.accel.matrix)
    capsys.readouterr()
    rc = main(["diff", str(cal)])
    out = capsys.readouterr().out
    # a different model on the very same data: not noise, not drift -- suspicious
    assert rc == 4 and "the model changed (full -> axis)" in out
    assert "fitted to the same data (same input SHA-256) but differ" in out
    # the history is bounded, newest first, and survives --new
    for _ in range(MAX_PREVIOUS + 2):
        assert main(["fit", str(data), "-o", str(cal), "--model", "full", "--new"]) == 0
    part = tc.Calibration.load(cal).accel
    assert len(part.previous) == MAX_PREVIOUS
    times = [p["replaced_utc"] for p in part.previous]
    assert times == sorted(times, reverse=True)
    again = tc.Calibration.load(cal)
    assert tc.Calibration.from_json(again.to_json()) == again


@pytest.mark.parametrize(
    "entry, match",
    [
        ("not a list", "must be a list"),
        ([{"offset": [0, 0, 0]}], "lacks"),
        ([{"replaced_utc": "t", "raw_unit": "counts", "unit": "g", "offset": [0, 0, 0],
           "diag": [1, 1, 1], "offdiag": [0, 0, 0], "evil": 1}], "unknown field"),
        ([{"replaced_utc": "t", "raw_unit": "counts", "unit": "g", "offset": [0, 0, 1e999],
           "diag": [1, 1, 1], "offdiag": [0, 0, 0]}], "finite"),
        ([{"replaced_utc": "t", "raw_unit": "counts", "unit": "g", "offset": [0, 0],
           "diag": [1, 1, 1], "offdiag": [0, 0, 0]}], "shape"),
        ([{"replaced_utc": 5, "raw_unit": "counts", "unit": "g", "offset": [0, 0, 0],
           "diag": [1, 1, 1], "offdiag": [0, 0, 0]}], "must be text"),
        ([{"replaced_utc": "t", "raw_unit": "counts", "unit": "g", "offset": [0, 0, 0],
           "diag": [1, 1, 1], "offdiag": [0, 0, 0], "stderr": {"offset_x": -1}}], "zero or more"),
        ([{"replaced_utc": "t", "raw_unit": "counts", "unit": "g", "offset": [0, 0, 0],
           "diag": [1, 1, 1], "offdiag": [0, 0, 0]}] * 1000, "at most"),
    ],
)
def test_a_malformed_previous_is_refused_on_load(tmp_path, entry, match):
    cal = tc.Calibration(accel=tc.SensorCalibration(offset=[1, 2, 3], matrix=np.eye(3)))
    d = cal.to_dict()
    d["parts"]["accel"]["previous"] = entry
    path = tmp_path / "cal.json"
    path.write_text(json.dumps(d).replace("Infinity", "1e999"))
    with pytest.raises(tc.CalibrationError, match=match):
        tc.Calibration.load(path)


def test_compare_refuses_what_it_cannot_compare(tmp_path, capsys):
    a = tc.Calibration(accel=tc.SensorCalibration(offset=[1, 2, 3], matrix=np.eye(3)))
    b = tc.Calibration(mag=tc.SensorCalibration(offset=[1, 2, 3], matrix=np.eye(3)))
    with pytest.raises(tc.CalibrationError, match="no sensor part in common"):
        tc.compare(a, b)
    with pytest.raises(tc.CalibrationError, match="threshold"):
        tc.compare(a, a, threshold=0)
    a.save(tmp_path / "a.json")
    assert main(["diff", str(tmp_path / "a.json")]) == 1
    assert "keeps no previous" in capsys.readouterr().err
    # without uncertainties only identical coefficients are the same
    c = tc.Calibration(accel=tc.SensorCalibration(offset=[1, 2, 3.5], matrix=np.eye(3)))
    d = tc.compare(a, c)
    assert d.verdict == "changed" and d.exit_code == 3
    assert any("neither calibration recorded standard errors" in n for n in d.parts[0].notes)
    # calibrated units that convert are converted; raw units that differ are suspicious
    g = tc.SensorCalibration(offset=[0, 0, 0], matrix=np.eye(3) / 16384, unit="g", radius=1.0,
                             stats={"stderr": {n: 1e-9 for n in ("diag_x", "diag_y", "diag_z")}})
    ms2 = tc.SensorCalibration(offset=[0, 0, 0], matrix=np.eye(3) / 16384 * 9.80665,
                               unit="m/s^2", radius=9.80665)
    assert tc.compare(g, ms2).verdict == "same"
    other_raw = replace(g, raw_unit="mg")
    assert tc.compare(g, other_raw).verdict == "suspicious"
