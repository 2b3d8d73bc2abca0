"""The AK8963 factory sensitivity adjustment (ASA) as an input option, before fitting."""

from __future__ import annotations

import doctest

import numpy as np
import pytest
import triaxcal as tc
import triaxcal.io.akm as akm
from triaxcal.calibration.parts import fold_asa
from triaxcal.cli import main
from triaxcal.io.akm import apply_asa, asa_factors

ASA = (176, 177, 165)  # the fuse-ROM bytes of an AK8963: k = 1.1875, 1.1914, 1.1445


def _session(tmp_path, asa=ASA):
    """An AK8963 whose axes differ in sensitivity by its ASA factors (and nothing else)."""
    k = asa_factors(asa)
    # register counts = 10 counts/uT / k: the adjusted counts k * raw are a sphere
    imu = tc.sim.SimIMU(4, mag={"scale": list(k), "noise": 2.0})
    rec = imu.record(tc.sim.globe_script(hold_s=0.5, seed=4), rate_hz=50)
    f = tmp_path / "mag.csv"
    np.savetxt(f, rec.pose_means("mag"), delimiter=",", header="mx,my,mz", comments="")
    return imu, rec, f


def test_factors_follow_the_datasheet_formula():
    assert asa_factors([128, 0, 255]).tolist() == [1.0, 0.5, 1 + 127 / 256]
    np.testing.assert_allclose(apply_asa([[256, 256, 256]], [0, 128, 255]), [[128, 256, 383]])
    for bad in ([128, 128], [128, 128, 256], [128, 128, -1], [128.5, 128, 128], "abc",
                [True, 128, 128], [[128, 128, 128]], [np.nan, 128, 128]):
        with pytest.raises(tc.CalibrationError, match="asa"):
            asa_factors(bad)


def test_asa_before_fitting_lets_the_sphere_model_fit(tmp_path, capsys):
    imu, _, f = _session(tmp_path)
    out = tmp_path / "cal.json"
    assert main(["fit", str(f), "--sensor", "mag", "--model", "sphere", "--radius", "50uT",
                 "--asa", ",".join(map(str, ASA)), "--sigma", "0", "-o", str(out)]) == 0
    with_asa = tc.Calibration.load(out).mag
    assert main(["fit", str(f), "--sensor", "mag", "--model", "sphere", "--radius", "50uT",
                 "--sigma", "0", "-o", str(out), "--new"]) == 0
    without = tc.Calibration.load(out).mag
    # the register counts differ by up to 4 % between axes; adjusted, they are a sphere
    assert with_asa.stats["rms"] < 0.06  # uT: the noise of the pose means, 0.04
    assert without.stats["rms"] > 10 * with_asa.stats["rms"]
    assert with_asa.stats["asa"] == list(ASA)
    # the part takes the register counts: it recovers the true field from them
    truth = imu.truth.mag
    raw = truth.offset + np.linalg.solve(truth.matrix, [30.0, -40.0, 0.0])
    np.testing.assert_allclose(with_asa.apply(raw), [30, -40, 0], atol=0.05)  # uT
    np.testing.assert_allclose(with_asa.offset, truth.offset, atol=0.5)  # counts
    # report judges the part on the register counts of the file, as it was fitted
    capsys.readouterr()
    assert main(["fit", str(f), "--sensor", "mag", "--model", "sphere", "--radius", "50uT",
                 "--asa", ",".join(map(str, ASA)), "--sigma", "0", "-o", str(out)]) == 0
    assert main(["report", str(out), "-o", str(tmp_path / "r.json")]) == 0
    import json

    rep = json.loads((tmp_path / "r.json").read_text())["mag"]
    assert rep["rms"] == pytest.approx(with_asa.stats["rms"], rel=1e-6)


def test_asa_with_the_full_model_changes_nothing_but_the_start(tmp_path):
    _, _, f = _session(tmp_path)
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    assert main(["fit", str(f), "--sensor", "mag", "--model", "full", "--sigma", "0",
                 "--asa", "176,177,165", "-o", str(a)]) == 0
    assert main(["fit", str(f), "--sensor", "mag", "--model", "full", "--sigma", "0",
                 "-o", str(b)]) == 0
    pa, pb = tc.Calibration.load(a).mag, tc.Calibration.load(b).mag
    # a full matrix absorbs the factors: the same offset and calibrated directions, to the
    # fit's tolerance (the noise correction of the residual sees other coordinates)
    np.testing.assert_allclose(pa.offset, pb.offset, atol=1e-3)  # counts
    pts = np.loadtxt(f, delimiter=",", skiprows=1)
    ca, cb = pa.apply(pts), pb.apply(pts)
    np.testing.assert_allclose(ca / np.linalg.norm(ca, axis=1, keepdims=True),
                               cb / np.linalg.norm(cb, axis=1, keepdims=True), atol=2e-5)


def test_fold_asa_equals_adjusting_first():
    rng = np.random.default_rng(2)
    part = tc.SensorCalibration(offset=[40.0, -25.0, 60.0],
                                matrix=np.array([[0.15, 0.002, 0], [0.002, 0.16, 0.001],
                                                 [0, 0.001, 0.14]]), unit="uT")
    raw = rng.uniform(-300, 300, (20, 3))
    folded = fold_asa(part, ASA)
    np.testing.assert_allclose(folded.apply(raw), part.apply(apply_asa(raw, ASA)), rtol=1e-12)
    with pytest.raises(tc.CalibrationError, match="already"):
        fold_asa(folded, ASA)


def test_cli_refuses_asa_for_other_sensors_and_bad_bytes(tmp_path, capsys):
    _, _, f = _session(tmp_path)
    capsys.readouterr()
    assert main(["fit", str(f), "--columns", "0,1,2", "--asa", "128,128,128", "-o",
                 str(tmp_path / "x.json")]) == 1
    assert "--sensor mag" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["fit", str(f), "--sensor", "mag", "--asa", "128,300,128", "-o",
              str(tmp_path / "x.json")])
    assert "fuse-ROM bytes" in capsys.readouterr().err


def test_docstrings_run():
    assert doctest.testmod(akm, raise_on_error=True).failed == 0
