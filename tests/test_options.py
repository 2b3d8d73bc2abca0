"""Every option of detect, methods and report is validated: a bad value is a CalibrationError
that names the option, shows the value and says what is valid; nothing is clipped or coerced."""

from __future__ import annotations

import math

import numpy as np
import pytest
import triaxcal as tc
from triaxcal._checks import options as opt
from triaxcal.methods import gyro as tg
from triaxcal.report import empty_regions, plot_report, quality_report

NAN = float("nan")
RNG = np.random.default_rng(0)
XYZ = RNG.normal(0, 0.01, (600, 3)) + [0, 0, 1]
GYRO = RNG.normal(0, 3, (600, 3))
TEMP = np.linspace(20, 40, 600)
SPHERE = RNG.normal(size=(60, 3))
PART = tc.SensorCalibration(offset=[0, 0, 0], matrix=np.eye(3), radius=1.0)
FACES = {"fore_down": [0.1, 0, 1], "aft_down": [-0.1, 0, 1], "left_down": [0, 0.1, 1],
         "right_down": [0, -0.1, 1]}
SIX = np.vstack([np.eye(3), -np.eye(3)]) * 1000
FER = {k: (np.tile([0.0, 0.0, 9.81], (50, 1)), np.zeros((50, 3)))
       for k in ("x_p", "x_a", "y_p", "y_a", "z_p", "z_a", "x_rot", "y_rot", "z_rot")}


def _calls():
    """(call with a bad option, option name, value shown in the message)."""
    d = [
        # detect.py
        (lambda kw: tc.detect_poses(XYZ, **kw), {"window": 0}, "window", "0"),
        (lambda kw: tc.detect_poses(XYZ, **kw), {"window": 2.5}, "window", "2.5"),
        (lambda kw: tc.detect_poses(XYZ, **kw), {"window": "25"}, "window", "'25'"),
        (lambda kw: tc.detect_poses(XYZ, **kw), {"window": True}, "window", "True"),
        (lambda kw: tc.detect_poses(XYZ, **kw), {"threshold": NAN}, "threshold", "nan"),
        (lambda kw: tc.detect_poses(XYZ, **kw), {"threshold": "0.1"}, "threshold", "'0.1'"),
        (lambda kw: tc.detect_poses(XYZ, **kw), {"units_per_g": 0}, "units_per_g", "0"),
        (lambda kw: tc.detect_poses(XYZ, **kw), {"units_per_g": math.inf}, "units_per_g",
         "inf"),
        (lambda kw: tc.detect_poses(XYZ, **kw), {"min_separation": -1}, "min_separation",
         "-1"),
        (lambda kw: tc.detect_poses(XYZ, **kw), {"min_windows": 1}, "min_windows", "1"),
        (lambda kw: tc.detect_poses(XYZ, **kw), {"min_windows": NAN}, "min_windows", "nan"),
        (lambda kw: tc.detect_poses(XYZ, **kw), {"max_std": 0}, "max_std", "0"),
        (lambda kw: tc.detect_poses(XYZ, **kw), {"max_windows": 1}, "max_windows", "1"),
        (lambda kw: tc.detect_poses(XYZ, **kw), {"columns": (0, 1)}, "columns", "(0, 1)"),
        (lambda kw: tc.detect_poses(XYZ, **kw), {"columns": (0, 1, "2")}, "columns",
         "'2'"),
        (lambda kw: tc.PoseDetector(**kw), {"window": -3}, "window", "-3"),
        (lambda kw: tc.PoseDetector(**kw), {"threshold": "x"}, "threshold", "'x'"),
        (lambda kw: tc.detect_still(XYZ, **kw), {"rate_hz": 0}, "rate_hz", "0"),
        (lambda kw: tc.detect_still(XYZ, rate_hz=100, **kw), {"window_s": 0}, "window_s",
         "0"),
        (lambda kw: tc.detect_still(XYZ, rate_hz=100, **kw), {"window_s": NAN}, "window_s",
         "nan"),
        (lambda kw: tc.detect_still(XYZ, rate_hz=100, **kw), {"window_s": 0.001}, "window_s",
         "0.001"),
        (lambda kw: tc.detect_still(XYZ, rate_hz=100, **kw), {"rest_s": -1}, "rest_s", "-1"),
        (lambda kw: tc.detect_still(XYZ, rate_hz=100, **kw), {"k": NAN}, "k", "nan"),
        (lambda kw: tc.detect_still(XYZ, rate_hz=100, **kw), {"k": 0}, "k", "0"),
        (lambda kw: tc.detect_still(XYZ, rate_hz=100, **kw), {"min_duration_s": -1},
         "min_duration_s", "-1"),
        (lambda kw: tc.detect_still(XYZ, rate_hz=100, **kw), {"rest_level": 0}, "rest_level",
         "0"),
        (lambda kw: tc.still_intervals(XYZ, rate_hz=100, **kw), {"k": "3"}, "k", "'3'"),
        # methods/gyro.py
        (lambda kw: tc.gyro_bias(GYRO, **kw), {"intervals": [(0, 10**9)]}, "intervals[0]",
         "1000000000"),
        (lambda kw: tc.gyro_bias(GYRO, **kw), {"intervals": [(-5, 10)]}, "intervals[0] start",
         "-5"),
        (lambda kw: tc.gyro_bias(GYRO, **kw), {"intervals": [(10, 5)]}, "intervals[0]",
         "(10, 5)"),
        (lambda kw: tc.gyro_bias(GYRO, **kw), {"intervals": [(0, 10), (5, 20)]}, "intervals",
         "(5, 20)"),
        (lambda kw: tc.gyro_bias(GYRO, **kw), {"intervals": "0-100"}, "intervals", "'0-100'"),
        (lambda kw: tc.gyro_bias(GYRO, **kw), {"intervals": [(0.5, 10)]},
         "intervals[0] start", "0.5"),
        (lambda kw: tc.gyro_bias(GYRO, rate_hz=100, **kw), {"rest_s": 0}, "rest_s", "0"),
        (lambda kw: tc.gyro_bias(GYRO, **kw), {"rate_hz": NAN}, "rate_hz", "nan"),
        (lambda kw: tc.find_rotations(GYRO, rate_hz=100, **kw), {"k": NAN}, "k", "nan"),
        (lambda kw: tc.find_rotations(GYRO, rate_hz=100, **kw), {"window_s": 0}, "window_s",
         "0"),
        (lambda kw: tc.find_rotations(GYRO, rate_hz=100, **kw), {"min_still_s": -1},
         "min_still_s", "-1"),
        (lambda kw: tc.find_rotations(GYRO, rate_hz=100, **kw), {"offset": [1, 2]}, "offset",
         "[1, 2]"),
        (lambda kw: tc.find_rotations(GYRO, rate_hz=100, **kw), {"offset": "abc"}, "offset",
         "'abc'"),
        (lambda kw: tc.find_rotations(GYRO, rate_hz=100, **kw), {"turns": "all"}, "turns",
         "'all'"),
        (lambda kw: tc.find_rotations(GYRO, rate_hz=100, offset=[0, 0, 0], **kw),
         {"turns": [(0, 10**6)]}, "turns[0]", "1000000"),
        (lambda kw: tc.gyro_gains(GYRO, rate_hz=100, **kw), {"angle_deg": NAN}, "angle_deg",
         "nan"),
        (lambda kw: tc.gyro_gains(GYRO, rate_hz=100, **kw), {"min_fraction": 1.5},
         "min_fraction", "1.5"),
        (lambda kw: tc.gyro_gains(GYRO, rate_hz=100, **kw), {"max_fraction": 0.5},
         "max_fraction", "0.5"),
        (lambda kw: tc.gyro_gains(GYRO, rate_hz=100, **kw), {"min_purity": 2}, "min_purity",
         "2"),
        (lambda kw: tc.gyro_gains(GYRO, rate_hz=100, **kw), {"require_both_directions": "no"},
         "require_both_directions", "'no'"),
        (lambda kw: tc.gyro_gains(GYRO, rate_hz=100, **kw), {"nominal_counts_per_dps": 0},
         "nominal_counts_per_dps", "0"),
        (lambda kw: tc.gyro_gains(GYRO, rate_hz=100, **kw), {"axes": "xq"}, "axes", "'xq'"),
        (lambda kw: tc.gyro_gains(GYRO, rate_hz=100, **kw), {"axes": "xx"}, "axes", "'xx'"),
        (lambda kw: tc.gyro_gains(GYRO, rate_hz=100, **kw), {"rest_s": 0}, "rest_s", "0"),
        (lambda kw: tc.gyro_gains(GYRO, rate_hz=100, **kw), {"intervals": [(0, 601)]},
         "intervals[0]", "601"),
        (lambda kw: tg.turntable_plateaus(GYRO, **kw), {"min_rate": 0}, "min_rate", "0"),
        (lambda kw: tg.turntable_plateaus(GYRO, min_rate=1.0, **kw), {"threshold": NAN},
         "threshold", "nan"),
        (lambda kw: tg.turntable_plateaus(GYRO, min_rate=1.0, **kw), {"window": 0}, "window",
         "0"),
        (lambda kw: tc.fit_turntable([GYRO], [1.0], offset=[0, 0, 0], **kw),
         {"model": "round"}, "model", "'round'"),
        (lambda kw: tc.fit_turntable([GYRO], [1.0], offset=[0, 0, 0], **kw), {"window": 0},
         "window", "0"),
        (lambda kw: tc.fit_turntable([GYRO], [1.0], offset=[0, 0, 0], **kw),
         {"min_fraction": NAN}, "min_fraction", "nan"),
        (lambda kw: tc.fit_turntable([GYRO], offset=[0, 0, 0], **kw), {"rates": ["a"]},
         "rates[0]", "'a'"),
        (lambda kw: tc.fit_turntable([GYRO], [1.0], **kw), {"offset": [NAN, 0, 0]}, "offset",
         "nan"),
        (lambda kw: tg.integrate_rate(GYRO, **kw), {"t": np.zeros(600, complex)}, "t",
         "complex"),
        # methods/imu.py
        (lambda kw: tc.calibrate_imu(XYZ, GYRO, **kw), {"rate_hz": 0}, "rate_hz", "0"),
        (lambda kw: tc.calibrate_imu(XYZ, GYRO, rate_hz=100, **kw), {"gravity": NAN},
         "gravity", "nan"),
        (lambda kw: tc.calibrate_imu(XYZ, GYRO, rate_hz=100, **kw), {"rest_s": 0}, "rest_s",
         "0"),
        (lambda kw: tc.calibrate_imu(XYZ, GYRO, rate_hz=100, **kw), {"window_s": 0},
         "window_s", "0"),
        (lambda kw: tc.calibrate_imu(XYZ, GYRO, rate_hz=100, **kw), {"min_still_s": NAN},
         "min_still_s", "nan"),
        (lambda kw: tc.calibrate_imu(XYZ, GYRO, rate_hz=100, **kw), {"k_values": []},
         "k_values", "0"),
        (lambda kw: tc.calibrate_imu(XYZ, GYRO, rate_hz=100, **kw), {"k_values": [2, NAN]},
         "k_values[1]", "nan"),
        (lambda kw: tc.calibrate_imu(XYZ, GYRO, rate_hz=100, **kw), {"k_values": "23"},
         "k_values", "'23'"),
        (lambda kw: tc.calibrate_imu(XYZ, GYRO, rate_hz=100, **kw), {"min_poses": 2},
         "min_poses", "2"),
        (lambda kw: tc.calibrate_imu(XYZ, GYRO, rate_hz=100, **kw), {"min_poses": 9.5},
         "min_poses", "9.5"),
        (lambda kw: tc.calibrate_imu(XYZ, GYRO, rate_hz=100, **kw), {"accel_model": "best"},
         "accel_model", "'best'"),
        (lambda kw: tc.calibrate_imu(XYZ, GYRO, rate_hz=100, **kw),
         {"gyro_g_sensitivity": "yes"}, "gyro_g_sensitivity", "'yes'"),
        (lambda kw: tc.calibrate_imu(XYZ, GYRO, rate_hz=100, **kw), {"gyro_scale_guess": 0},
         "gyro_scale_guess", "0"),
        (lambda kw: tc.calibrate_imu(XYZ, GYRO, rate_hz=100, **kw), {"max_iter": 2**70},
         "max_iter", str(2**70)),
        (lambda kw: tc.calibrate_imu(XYZ, GYRO, rate_hz=100, **kw), {"max_iter": 0},
         "max_iter", "0"),
        (lambda kw: tc.calibrate_imu(XYZ, GYRO, rate_hz=100, **kw), {"tol": "x"}, "tol",
         "'x'"),
        (lambda kw: tc.calibrate_imu(XYZ, GYRO, rate_hz=100, **kw), {"tol": NAN}, "tol",
         "nan"),
        (lambda kw: tc.calibrate_imu(XYZ, GYRO, rate_hz=100, **kw), {"gyro_offset": [1, 2]},
         "gyro_offset", "[1, 2]"),
        # methods/static.py
        (lambda kw: tc.tilt_rig(FACES, **kw), {"angle_deg": 90}, "angle_deg", "90"),
        (lambda kw: tc.tilt_rig(FACES, **kw), {"angle_deg": NAN}, "angle_deg", "nan"),
        (lambda kw: tc.tilt_rig(FACES, angle_deg=10, **kw), {"z_offset": NAN}, "z_offset",
         "nan"),
        (lambda kw: tc.six_position(SIX, **kw), {"gravity": 0}, "gravity", "0"),
        (lambda kw: tc.six_position(SIX, **kw), {"gravity": True}, "gravity", "True"),
        (lambda kw: tc.ferraris(FER, **kw), {"rate_hz": 0}, "rate_hz", "0"),
        (lambda kw: tc.ferraris(FER, rate_hz=100, **kw), {"gravity": NAN}, "gravity", "nan"),
        (lambda kw: tc.ferraris(FER, rate_hz=100, **kw), {"angle_deg": -360}, "angle_deg",
         "-360"),
        # methods/temperature.py
        (lambda kw: tc.fit_temperature(GYRO, TEMP, **kw), {"degree": 4}, "degree", "4"),
        (lambda kw: tc.fit_temperature(GYRO, TEMP, **kw), {"degree": 1.5}, "degree", "1.5"),
        (lambda kw: tc.fit_temperature(GYRO, TEMP, **kw), {"degree": True}, "degree", "True"),
        (lambda kw: tc.fit_temperature(GYRO, TEMP, **kw), {"reference_degC": NAN},
         "reference_degC", "nan"),
        (lambda kw: tc.fit_temperature(GYRO, TEMP, **kw), {"reference_degC": "20"},
         "reference_degC", "'20'"),
        (lambda kw: tc.fit_temperature(GYRO, TEMP, **kw), {"gain": "half"}, "gain", "'half'"),
        (lambda kw: tc.fit_temperature(GYRO, TEMP, **kw), {"min_range_degC": NAN},
         "min_range_degC", "nan"),
        (lambda kw: tc.fit_temperature(temp_degC=TEMP, **kw), {"raw": "abc"}, "raw", "<U3"),
        (lambda kw: tc.fit_temperature(temp_degC=TEMP, **kw), {"raw": GYRO + 1j}, "raw",
         "complex"),
        (lambda kw: tc.fit_temperature(GYRO, **kw), {"temp_degC": TEMP + 0j}, "temp_degC",
         "complex"),
        (lambda kw: tc.fit_temperature(GYRO, TEMP, **kw), {"matrix": np.zeros((3, 3))},
         "matrix", "singular"),
        # report.py
        (lambda kw: empty_regions(SPHERE, **kw), {"min_deg": NAN}, "min_deg", "nan"),
        (lambda kw: empty_regions(SPHERE, **kw), {"min_deg": 200}, "min_deg", "200"),
        (lambda kw: empty_regions(SPHERE, **kw), {"max_regions": 0}, "max_regions", "0"),
        (lambda kw: quality_report(SPHERE, PART, **kw), {"sensor": "baro"}, "sensor",
         "'baro'"),
        (lambda kw: quality_report(SPHERE, PART, **kw), {"rejected": [0, 99]},
         "rejected index", "99"),
        (lambda kw: quality_report(SPHERE, PART, **kw), {"rejected": [1.5]},
         "rejected index", "1.5"),
        (lambda kw: quality_report(SPHERE, PART, **kw), {"model_reason": 3}, "model_reason",
         "3"),
        (lambda kw: plot_report(SPHERE, PART, "unused.png", **kw), {"dpi": 0}, "dpi", "0"),
        (lambda kw: plot_report(SPHERE, PART, "unused.png", **kw), {"title": 5}, "title",
         "5"),
    ]
    return d


CASES = _calls()


@pytest.mark.parametrize("call, kwargs, name, shown", CASES,
                         ids=[f"{c[2]}={c[3]}" for c in CASES])
def test_bad_option_is_named(call, kwargs, name, shown, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(tc.CalibrationError) as err:
        call(kwargs)
    msg = str(err.value)
    assert name in msg, msg
    assert shown in msg, msg
    assert not (tmp_path / "unused.png").exists()


def test_good_values_pass_unchanged():
    assert opt.number(3, "x", gt=0) == 3.0 and isinstance(opt.number(3, "x"), float)
    assert opt.integer(3.0, "n", ge=1) == 3 and opt.integer(np.int64(7), "n") == 7
    assert opt.choice("full", "m", ("full", "axis")) == "full"
    assert opt.flag(np.bool_(True), "f") is True
    assert opt.intervals([(5, 9), (0, 3)], "iv", 10) == [(0, 3), (5, 9)]
    np.testing.assert_array_equal(opt.vector3(np.array([1, 2, 3], np.int16), "v"), [1, 2, 3])
    assert opt.numbers_list(np.array([2.0, 3.0]), "k") == (2.0, 3.0)


def test_messages_say_the_valid_range():
    with pytest.raises(tc.CalibrationError, match=r"k must be a finite number > 0, got nan"):
        tc.detect_still(XYZ, rate_hz=100, k=NAN)
    with pytest.raises(tc.CalibrationError,
                       match=r"max_iter must be a whole number in \[1, 10000\], got 1180"):
        tc.calibrate_imu(XYZ, GYRO, rate_hz=100, max_iter=2**70)
    with pytest.raises(tc.CalibrationError, match=r"must satisfy 0 <= start < end <= 600"):
        tc.gyro_bias(GYRO, intervals=[(0, 601)])
    with pytest.raises(tc.CalibrationError, match=r"reference_degC must be a finite number"):
        tc.fit_temperature(GYRO, TEMP, reference_degC=NAN)
