"""One pose detection for a session: PoseSettings, session_poses, and the CLI options."""

from __future__ import annotations

import argparse
import doctest

import numpy as np
import pytest
import triaxcal as tc
import triaxcal.detect.session as poses_mod
from triaxcal.cli._pose_options import add_pose_options, settings_from_args
from triaxcal.detect.session import (
    HEAD_ROWS,
    PoseSettings,
    sensor_columns,
    session_poses,
    stored_settings,
)

NAMES = ("t", "ax", "ay", "az", "gx", "gy", "gz", "mx", "my", "mz", "temp")


def _session(seed: int, **kw):
    imu = tc.sim.SimIMU(seed)
    rec = imu.record(tc.sim.globe_script(hold_s=1.0, seed=seed, **kw), rate_hz=100)
    data = np.hstack([rec.t[:, None] + 1.7e9, rec.frames(10)])
    return imu, rec, data


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_globe_scheme_gives_84_poses_offline_and_online(seed):
    imu, rec, data = _session(seed)
    det, how = session_poses(NAMES, data)
    assert len(det.poses) == 84 and how.sensors == ("accel", "gyro", "mag")
    # the live detector (the capture's: registers at the 4th window) on random chunks
    live = how.detector(max_windows=4)
    rng = np.random.default_rng(seed)
    got, i = [], 0
    while i < len(data):
        n = int(rng.integers(1, 400))
        got += live.update(data[i:i + n])
        i += n
    got += live.finish()
    assert [p.start for p in got] == [p.start for p in det.poses]
    # the magnetometer's offset from these poses is within the simulator's noise
    mag = np.array([p.mean[7:10] for p in det.poses])
    fit = tc.fit_ellipsoid(mag, model="full")
    err = np.abs(fit.offset - imu.truth.mag.offset)
    assert np.all(err < 4 * fit.stderr[:3]) and err.max() < 1.0, (err, fit.stderr[:3])


def test_the_seeds_rule_alone_merges_the_twists_and_biases_the_magnetometer():
    # what the detector did before it used every sensor: 62 poses, offset z several counts off
    imu, _, data = _session(1)
    det, _ = session_poses(NAMES, data, PoseSettings(use_gyro=False, use_mag=False))
    assert len(det.poses) < 70
    mag = np.array([p.mean[7:10] for p in det.poses])
    fit = tc.fit_ellipsoid(mag, model="full")
    assert np.abs(fit.offset - imu.truth.mag.offset).max() > 3.0


def test_resolve_decides_counts_per_g_and_rate_from_the_first_rows():
    _, _, data = _session(0)
    how = PoseSettings().resolve(NAMES, data[:HEAD_ROWS])
    # the board lies still at the start: the median length is 1 g in counts (about 16384,
    # with the simulated scale and offset errors)
    assert abs(how.counts_per_g / 16384 - 1) < 0.08
    assert how.kwargs["threshold"] == pytest.approx(0.07 * how.counts_per_g)
    assert how.kwargs["columns"] == (1, 2, 3) and how.kwargs["holdoff_samples"] == 0
    held = PoseSettings(holdoff_s=2.0).resolve(NAMES, data)
    assert held.rate_hz == pytest.approx(100.0) and held.kwargs["holdoff_samples"] == 200
    given = PoseSettings(holdoff_s=2.0, rate_hz=50.0, counts_per_g=8192.0).resolve(NAMES, data)
    assert given.kwargs["holdoff_samples"] == 100 and given.counts_per_g == 8192.0
    # a board that prints g: 1 per g, found by itself
    g = data.copy()
    g[:, 1:4] /= 16384.0
    assert abs(PoseSettings().resolve(NAMES, g).counts_per_g - 1) < 0.08
    # the resolved settings replay exactly
    again = PoseSettings().with_resolved(how).resolve(NAMES, data)
    assert again.kwargs == how.kwargs


def test_settings_are_validated():
    for bad in ({"window": 0}, {"window": 2.5}, {"accel_threshold_g": 0},
                {"counts_per_g": -1.0}, {"gyro_threshold": float("nan")},
                {"holdoff_s": -1}, {"holdoff_s": True}, {"rate_hz": 0.0}, {"use_gyro": "no"}):
        with pytest.raises(tc.CalibrationError):
            PoseSettings(**bad)
    with pytest.raises(tc.CalibrationError, match="unknown pose setting"):
        PoseSettings.from_dict({"window": 25, "mystery": 1})
    with pytest.raises(tc.CalibrationError, match="accelerometer"):
        PoseSettings().resolve(("t", "gx", "gy", "gz"), np.zeros((10, 4)))
    # the API's names; a command's flags when a command runs
    from triaxcal._checks.spelling import command_line

    with pytest.raises(tc.CalibrationError, match=r"holdoff_s needs .* \(rate_hz;"):
        PoseSettings(holdoff_s=2).resolve(("ax", "ay", "az"), np.ones((10, 3)))
    with pytest.raises(tc.CalibrationError, match=r"\(counts_per_g\)"):
        PoseSettings().resolve(("ax", "ay", "az"), np.zeros((10, 3)))
    with command_line(), pytest.raises(tc.CalibrationError, match=r"--holdoff needs .*--rate-hz"):
        PoseSettings(holdoff_s=2).resolve(("ax", "ay", "az"), np.ones((10, 3)))
    with command_line(), pytest.raises(tc.CalibrationError, match="--counts-per-g"):
        PoseSettings().resolve(("ax", "ay", "az"), np.zeros((10, 3)))
    assert PoseSettings.from_dict(PoseSettings(holdoff_s=2.0).to_dict()) == PoseSettings(
        holdoff_s=2.0)


def test_sensor_columns_by_name():
    assert sensor_columns(NAMES) == {"accel": (1, 2, 3), "gyro": (4, 5, 6), "mag": (7, 8, 9)}
    assert sensor_columns(("mx", "my", "mz")) == {"mag": (0, 1, 2)}
    assert sensor_columns(None) == {}
    # a headerless table: the accelerometer's columns are given
    _, _, data = _session(0)
    det, how = session_poses(None, data[:, 1:4], accel=(0, 1, 2))
    assert how.sensors == ("accel",) and len(det.poses) > 30


def test_command_line_options_map_to_settings():
    p = argparse.ArgumentParser()
    add_pose_options(p)
    s = settings_from_args(p.parse_args([]))
    assert s == PoseSettings()
    s = settings_from_args(p.parse_args(["--window", "50", "--accel-threshold", "0.05",
                                         "--gyro-threshold", "40", "--mag-threshold", "off",
                                         "--holdoff", "2", "--rate-hz", "100",
                                         "--counts-per-g", "8192"]))
    assert s == PoseSettings(window=50, accel_threshold_g=0.05, gyro_threshold=40.0,
                             use_mag=False, holdoff_s=2.0, rate_hz=100.0, counts_per_g=8192.0)
    for bad in (["--window", "0"], ["--gyro-threshold", "-3"], ["--holdoff", "nan"],
                ["--mag-threshold", "x"]):
        with pytest.raises(SystemExit):
            p.parse_args(bad)


def test_parts_written_before_store_only_window_and_units():
    old = stored_settings({"poses": True, "pose_window": 30, "units_per_g": 8192.0})
    assert old == PoseSettings(window=30, counts_per_g=8192.0, use_gyro=False, use_mag=False,
                               hold_windows=None)
    new = PoseSettings(holdoff_s=1.0).to_dict()
    assert stored_settings({"pose_detection": new}) == PoseSettings(holdoff_s=1.0)


def test_docstrings_run():
    assert doctest.testmod(poses_mod, raise_on_error=True).failed == 0


@pytest.mark.slow
def test_capture_with_poses_84_stops_by_itself_and_fit_agrees(tmp_path, capsys):
    # `triaxcal capture --poses 84` on the globe scheme ends by itself (it stopped at 63 when
    # only the accelerometer ended a pose), and `fit --poses` on the file finds the same poses
    from triaxcal.capture.run import capture
    from triaxcal.cli import main
    from triaxcal.io.serial import SerialReader

    imu = tc.sim.SimIMU(1)
    # held 1.5 s: long enough for the bell (4 windows) even in the last pose, after which the
    # simulated board stops sending
    script = tc.sim.globe_script(hold_s=1.5, seed=1)
    out = tmp_path / "s.csv"
    with tc.sim.SimDevice(imu, script, rate_hz=100, speed=40, loop=False, seed=1) as dev:
        res = capture(SerialReader(dev.port, protocol="framed", channels=10, stream=True), out,
                      poses=84, duration_s=60, progress=None, bell=False, handle_sigint=False)
    assert res.stopped_by == "poses" and len(res.poses) == 84 and res.coverage == 1.0
    assert res.elapsed_s < 30
    assert res.detection is not None and set(res.thresholds) == {"accel", "gyro", "mag"}
    cal = tmp_path / "c.json"
    capsys.readouterr()
    assert main(["fit", str(out), "--poses", "-o", str(cal)]) == 0
    part = tc.Calibration.load(cal).accel
    # the capture stopped at the 84th bell: that pose is cut short in the file, but counts
    assert part.stats["n_poses"] == 84
    det, _ = session_poses(NAMES, np.loadtxt(out, delimiter=",", skiprows=1),
                           res.detection)
    assert [p.start for p in det.poses] == [p.start for p in res.poses]
