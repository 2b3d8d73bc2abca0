"""The command line with logs: ``triaxcal fit LOG --sensor mag``, ``report``, ``export --format
ardupilot|px4|kalibr|adafruit``, and the log options on every command that reads a session."""

from __future__ import annotations

import json

import numpy as np
import pytest
import triaxcal as tc
from triaxcal.cli import main

pytest.importorskip("pyulog")
pytest.importorskip("pymavlink")
pytest.importorskip("rosbags")

LOGS = {
    "sample.ulg": ("px4-pyulog-samples/sample.ulg", "gauss", "px4"),
    "sample_log_small.ulg": ("px4-pyulog-samples/sample_log_small.ulg", "gauss", "px4"),
    "Erle-Brain3.BIN": ("ardupilot-erle-logs/Erle-Brain3.BIN", "mG", "ardupilot"),
    "PXFv2.0b+Rpi.BIN": ("ardupilot-erle-logs/PXFv2.0b+Rpi.BIN", "mG", "ardupilot"),
    "ardrone_imu.bag": ("ros1-imu-tools-madgwick/ardrone_imu.bag", "uT", None),
    "phidgets_imu_upside_down.bag": ("ros1-imu-tools-madgwick/phidgets_imu_upside_down.bag",
                                     "uT", None),
    "sparkfun_razor.bag": ("ros1-imu-tools-madgwick/sparkfun_razor.bag", "uT", None),
}


@pytest.mark.slow
@pytest.mark.parametrize("name", list(LOGS))
def test_fit_magnetometer_from_each_log(name, realdata, tmp_path, capsys):
    """A magnetometer fit from every real log, as the command line makes it. None of these
    logs turned the sensor through enough orientations (flights turn mostly about the
    vertical; two bags hold only the field's direction): the fit is written, and the report
    says so instead of passing a band of the sphere off as a calibration."""
    rel, unit, autopilot = LOGS[name]
    out = tmp_path / "cal.json"
    argv = ["fit", str(realdata / rel), "--sensor", "mag", "-o", str(out)]
    rc = main(argv)
    if rc == 2:  # a cap of the sphere is not written as a calibration unless forced
        assert "not written" in capsys.readouterr().err and not out.exists()
        assert main([*argv, "--force"]) == 0
    else:
        assert rc == 0
    text = capsys.readouterr().out
    part = tc.Calibration.load(out).part("mag")
    assert part.raw_unit == unit and part.unit == unit
    assert part.source == str(realdata / rel) and len(part.input_sha256) == 64
    log = part.stats["log"]
    assert log["format"] in ("px4-ulog", "ardupilot-dataflash", "ros1-bag")
    if name != "sparkfun_razor.bag":  # that one turned more, but holds only directions
        # the shared measure's warning level; or, when the fit wrapped a small sphere round
        # a sensor that hardly turned (the coverage about that centre is meaningless), the
        # report says that the readings do not lie on the surface and the radius is implausible
        if part.stats["coverage_pct"] >= 50:
            warned = " ".join(part.stats["warnings"])
            assert "do not lie on" in warned and "not plausible" in warned
    if autopilot:
        assert part.stats["autopilot"]["autopilot"] == autopilot
        assert f"{autopilot} stored calibration of this mag" in text
        assert "already calibrated" in text
    if name in ("ardrone_imu.bag", "sparkfun_razor.bag"):
        assert "same length" in text and part.radius == pytest.approx(100.0, rel=1e-6)
    else:
        assert any("empty" in w or "covered" in w or "poorly determined" in w
                   for w in part.stats["warnings"]) or part.stats["coverage_pct"] < 10


def test_fit_undo_report_and_export_from_an_ardupilot_log(realdata, tmp_path, capsys):
    log = realdata / "ardupilot-erle-logs" / "Erle-Brain3.BIN"
    cal = tmp_path / "cal.json"
    assert main(["fit", str(log), "--sensor", "accel", "--undo-autopilot-cal", "--model",
                 "sphere", "--radius", "9.80665m/s^2", "--force", "-o", str(cal)]) == 0
    text = capsys.readouterr().out
    part = tc.Calibration.load(cal).part("accel")
    assert part.raw_unit == "m/s^2" and part.stats["log"]["undo_autopilot_cal"] is True
    assert "already calibrated" not in text and "ardupilot stored calibration" in text
    stored = part.stats["autopilot"]
    assert np.allclose(stored["offset"], [0.18896, -0.02392, -0.18050], atol=1e-5)
    # report re-reads the log with the same options and checks it is the same file
    assert main(["report", str(cal)]) == 0
    assert "accel calibration report (m/s^2 -> m/s^2" in capsys.readouterr().out


def test_fit_log_options_errors(realdata, tmp_path, capsys):
    csv = tmp_path / "t.csv"
    csv.write_text("1,2,3\n4,5,6\n")
    bag = realdata / "ros1-imu-tools-madgwick" / "sparkfun_razor.bag"
    ulg = realdata / "px4-pyulog-samples" / "sample_log_small.ulg"
    cases = [
        (["fit", str(csv), "--instance", "1"], "apply to logs"),
        (["fit", str(bag), "--columns", "0,1,2"], "--columns applies to tables"),
        (["fit", str(ulg), "--topic", "/imu"], "--instance"),
        (["fit", str(bag), "--undo-autopilot-cal", "--sensor", "mag"], "nothing triaxcal"),
        (["fit", str(bag), "--topic", "/imu/mag", "--sensor", "accel"], "no accel readings"),
        (["fit", str(ulg), "--sensor", "mag", "--undo-autopilot-cal"], "v1.11"),
    ]
    for argv, match in cases:
        assert main([*argv, "-o", str(tmp_path / "o.json")]) == 1
        assert match in capsys.readouterr().err


def test_fit_with_poses_from_a_bag(tmp_path, capsys):
    """--poses on a log: still poses found on the accelerometer, the sensor's pose means."""
    from test_logs import _write_sim_bag
    from triaxcal.sim import SimIMU, globe_script

    imu = SimIMU(seed=4)
    script = globe_script(hold_s=1.0)
    sim = imu.record(script, rate_hz=30)
    bag = tmp_path / "globe"
    _write_sim_bag(bag, sim)
    cal = tmp_path / "cal.json"
    assert main(["fit", str(bag), "--sensor", "accel", "--poses", "--window", "10",
                 "--model", "axis", "-o", str(cal)]) == 0
    part = tc.Calibration.load(cal).part("accel")
    # the globe's twists at the poles give the same gravity direction: fewer distinct poses
    assert part.stats["n_input"] >= 40 and part.unit == "g"
    # the bag holds counts times 9.80665/16384: the simulator's true calibration, rescaled
    truth = imu.truth.accel
    k = 9.80665 / 16384
    assert np.allclose(part.offset, truth.offset * k, atol=0.01)          # m/s^2 (~0.001 g)
    assert np.allclose(np.diag(part.matrix), np.diag(truth.matrix) / k, rtol=0.01)


def test_export_parameter_formats_cli(tmp_path, capsys):
    acc = tc.SensorCalibration(offset=[0.12, -0.2, 0.31], matrix=np.diag([1.01, 0.99, 1.02]),
                               raw_unit="m/s^2", unit="m/s^2")
    gyr = tc.SensorCalibration(offset=[0.01, -0.02, 0.003], matrix=np.eye(3),
                               raw_unit="rad/s", unit="rad/s")
    mag = tc.SensorCalibration(offset=[120, -40, 15], matrix=np.eye(3) * 1.02, raw_unit="mG",
                               unit="mG", radius=480.0)
    cal = tmp_path / "cal.json"
    tc.Calibration(accel=acc, gyro=gyr, mag=mag).save(cal)
    noise = tmp_path / "noise.json"
    noise.write_text(json.dumps({"accelerometer_noise_density": 1.86e-3,
                                 "accelerometer_random_walk": 4.33e-4,
                                 "gyroscope_noise_density": 1.87e-4,
                                 "gyroscope_random_walk": 2.66e-5}))
    runs = [
        (["--format", "ardupilot", "--instance", "1"], "x.parm", "COMPASS_OFS2_X,-120"),
        (["--format", "px4", "--instance", "2", "--device-id", "accel=2424842"], "x.params",
         "1\t1\tCAL_ACC2_ID\t2424842\t6"),
        (["--format", "kalibr", "--rate", "200", "--topic", "/imu/data_raw", "--noise",
          str(noise)], "imu.yaml", "gyroscope_random_walk: 2.66e-05"),
        (["--format", "adafruit", "--sensors", "mag,gyro"], "sensor_calib.json",
         '"gyro_zerorate": [0.01, -0.02, 0.003]'),
    ]
    for args, name, expect in runs:
        out = tmp_path / name
        assert main(["export", str(cal), *args, "-o", str(out)]) == 0, capsys.readouterr().err
        assert expect in out.read_text()
    assert main(["export", str(cal), "--format", "adafruit", "-o", str(tmp_path / "a")]) == 1
    assert "offsets only" in capsys.readouterr().err     # accelerometer gains: refused
    assert main(["export", str(cal), "--format", "c", "--rate", "5", "-o",
                 str(tmp_path / "c.h")]) == 1
    assert "does not apply" in capsys.readouterr().err
