"""`triaxcal demo` end to end: simulated board on a pty -> capture -> detect -> fit."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest
from triaxcal import sim
from triaxcal.capture.run import read_session
from triaxcal.cli import main


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo")
    t0 = time.monotonic()
    rc = main(["demo", "--out-dir", str(out), "--quiet"])
    elapsed = time.monotonic() - t0
    return rc, out, json.loads((out / "results.json").read_text()), elapsed


def test_demo_runs_and_writes_session_and_results(demo, capsys):
    rc, out, res, elapsed = demo
    assert rc == 0
    assert elapsed < 45  # "well under a minute"; typically ~4 s
    cols, data = read_session(out / "session.csv")
    assert cols == ("t", *sim.CHANNELS_10)
    assert len(data) == res["capture"]["rows"] > 10000
    # the session holds what the simulated board sent (frames, not simulator arrays)
    assert res["capture"]["frames_sent"] >= len(data)
    assert res["capture"]["dropped_frames"] == 0 and res["capture"]["lost_frames"] == 0
    assert res["poses"] == 84
    assert np.all(np.diff(data[:, 0]) >= 0)  # host time, in order


def test_demo_recovers_accelerometer_within_noise(demo):
    _, _, res, _ = demo
    truth = sim.SimIMU(res["seed"]).truth.accel
    acc = res["recovered"]["accel"]
    assert acc["within_noise"]
    rec_off = np.array(acc["offset"])
    rec_m = np.array(acc["matrix"])
    # independent of the fit's own standard errors: 84 poses of ~50 samples at 30 counts rms
    # noise put each pose mean within ~4 counts, so offsets within ~6 counts (5 sigma) and
    # the matrix within ~2e-4 relative
    np.testing.assert_allclose(rec_off, truth.offset, atol=6.0)
    np.testing.assert_allclose(rec_m * 16384, truth.matrix * 16384, atol=6e-4)
    for p in acc["params"]:
        assert abs(p["error"]) <= 4 * p["stderr"], p
    # and the recovered calibration beats the nominal one by far
    assert np.abs(rec_off - truth.offset).max() < 0.05 * np.abs(truth.offset).max()


def test_demo_recovers_magnetometer_and_gyro_bias(demo):
    _, _, res, _ = demo
    truth = sim.SimIMU(res["seed"]).truth
    mag = res["recovered"]["mag"]
    assert mag["within_noise"]
    np.testing.assert_allclose(mag["offset"], truth.mag.offset, atol=2.0)  # counts (0.2 uT)
    gyro = res["recovered"]["gyro"]
    np.testing.assert_allclose(gyro["offset"], truth.gyro.offset, atol=1.5)  # counts
    assert res["truth"]["accel"]["offset"] == pytest.approx(truth.accel.offset.tolist())


def test_demo_writes_calibration_headers_and_report(demo):
    _, out, res, _ = demo
    import triaxcal as tc

    cal = tc.Calibration.load(out / "calibration.json")
    assert set(cal.sensors) == {"accel", "gyro", "mag"}
    truth = sim.SimIMU(res["seed"]).truth.accel
    # the shipped calibration maps a true 1 g reading back to 1 g
    raw = np.array([[0.0, 0.0, 1.0]]) @ np.linalg.inv(truth.matrix).T + truth.offset
    np.testing.assert_allclose(cal.apply(raw, sensor="accel"), [[0, 0, 1]], atol=1e-3)
    header = (out / "triaxcal_calibration.h").read_text()
    assert "triaxcal_accel_apply" in header and "triaxcal_mag_apply" in header
    assert "int" in (out / "triaxcal_calibration_fixed.h").read_text()
    assert tc.decode_motioncal((out / "motioncal.bin").read_bytes()) is not None
    assert "warnings" in (out / "report_accel.txt").read_text()
    png = (out / "report_accel.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 20_000
    for kind in ("json", "c", "c-fixed", "motioncal", "figure_accel", "figure_mag"):
        assert kind in res["outputs"], kind


def test_demo_prints_a_table_with_units(tmp_path, capsys):
    rc = main(["demo", "--out-dir", str(tmp_path), "--quiet", "--protocol", "binary", "--seed", "2",
               "--speed", "60"])
    assert rc == 0
    text = capsys.readouterr().out
    for word in ("accelerometer", "magnetometer", "gyroscope", "offset_x", "scale_x",
                 "counts", "g/count", "uT/count", "deg/s", "within 4 standard errors: yes"):
        assert word in text, word
    res = json.loads((tmp_path / "results.json").read_text())
    assert res["protocol"] == "binary" and res["ok"]


def test_capture_page_simulator_example_runs(tmp_path, monkeypatch):
    import re

    from conftest import doc_page

    code = re.findall(r"```python\n(.*?)```", doc_page("guide/capture.md"), re.S)[0]
    monkeypatch.chdir(tmp_path)
    env: dict = {}
    exec(compile(code, "docs/guide/capture.md", "exec"), env)
    assert env["result"].stopped_by == "poses" and len(env["result"].poses) == 10
    assert abs(np.linalg.norm(env["g"], axis=1).mean() - 1.0) < 1e-3
    assert (tmp_path / "session.csv").read_text().startswith("t,ax,ay,az,")


# --- the same poses and the same coverage in capture, demo, fit and report ------------------


def test_capture_and_demo_count_the_84_poses_and_cover_the_sphere(demo):
    _, _, res, _ = demo
    assert res["capture"]["poses_online"] == res["poses"] == 84
    assert res["capture"]["coverage_pct"] == res["coverage_pct"] == 100.0
    # the demo detected with nothing but the command line's defaults
    import argparse

    from triaxcal.cli._pose_options import add_pose_options, settings_from_args

    p = argparse.ArgumentParser()
    add_pose_options(p)
    defaults = settings_from_args(p.parse_args([]))
    d = res["pose_detection"]
    assert {k: v for k, v in d.items() if k != "counts_per_g"} == {
        k: v for k, v in defaults.to_dict().items() if k != "counts_per_g"}
    assert set(res["thresholds"]) == {"accel", "gyro", "mag"}


def test_magnetometer_offset_from_the_poses_is_within_the_noise(demo):
    _, _, res, _ = demo
    truth = sim.SimIMU(res["seed"]).truth.mag
    rows = {r["name"]: r for r in res["recovered"]["mag"]["params"]}
    for i, axis in enumerate("xyz"):
        r = rows[f"offset_{axis}"]
        assert abs(r["recovered"] - truth.offset[i]) < 4 * r["stderr"] < 1.0, r  # counts


def test_fit_and_report_find_the_same_poses_and_coverage(demo, tmp_path, capsys):
    _, out, res, _ = demo
    session = out / "session.csv"
    cal = tmp_path / "cal.json"
    capsys.readouterr()
    assert main(["fit", str(session), "--poses", "-o", str(cal)]) == 0
    assert main(["fit", str(session), "--poses", "--sensor", "mag", "-o", str(cal)]) == 0
    printed = capsys.readouterr().out
    assert printed.count("coverage 100 %") == 1 and "coverage 96 %" in printed
    import triaxcal as tc

    fitted = tc.Calibration.load(cal)
    for part in (fitted.accel, fitted.mag):
        assert part.stats["n_poses"] == 84 and part.stats["n_input"] == 84
        assert part.stats["pose_sensors"] == ["accel", "gyro", "mag"]
    assert fitted.accel.stats["coverage_pct"] == 100.0
    truth = sim.SimIMU(res["seed"]).truth.mag
    np.testing.assert_allclose(fitted.mag.offset, truth.offset, atol=1.0)  # counts (0.1 uT)
    # report on the fit's calibration file, and on the demo's own: 84 readings, same coverage
    for path in (cal, out / "calibration.json"):
        jpath = tmp_path / f"{path.stem}-report.json"
        assert main(["report", str(path), "-o", str(jpath)]) == 0
        rep = json.loads(jpath.read_text())
        assert rep["accel"]["n"] == 84 and rep["accel"]["coverage_pct"] == 100.0
        assert rep["mag"]["n"] == 84
        assert rep["mag"]["coverage_pct"] == fitted.mag.stats["coverage_pct"]
    # and `report SESSION --poses` fits and reports the same 84
    jpath = tmp_path / "session-report.json"
    assert main(["report", str(session), "--poses", "-o", str(jpath)]) == 0
    rep = json.loads(jpath.read_text())["accel"]
    assert rep["n"] == 84 and rep["coverage_pct"] == 100.0


def test_demo_takes_the_pose_options_of_the_command_line(tmp_path):
    # the seed's rule alone (no gyro, no magnetometer) merges the twists at the poles, in the
    # capture and in the detection on the saved session alike
    rc = main(["demo", "--out-dir", str(tmp_path), "--quiet", "--no-plot", "--gyro-threshold",
               "off", "--mag-threshold", "off"])
    assert rc == 0
    res = json.loads((tmp_path / "results.json").read_text())
    assert res["poses"] == res["capture"]["poses_online"] < 70
    assert res["pose_detection"]["use_gyro"] is False
