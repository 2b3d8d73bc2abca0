"""Parameter exports: ArduPilot .parm, PX4 .params, Kalibr imu.yaml, Adafruit sensor_calib.json.

Each round-trip test writes a calibration, reads the file back the way its consumer does,
stores the numbers as float32 (as the firmware does), applies the consumer's OWN equation --
written here from its source, cited in a comment -- to raw readings, and compares with
``part.apply`` (converted to the consumer's units).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import triaxcal as tc
from triaxcal.calibration import TemperatureTerms
from triaxcal.export import (
    adafruit_calib_json,
    ardupilot_params,
    ardupilot_parm,
    export,
    kalibr_imu_yaml,
    kalibr_intrinsics,
    px4_params,
    px4_params_file,
)

F32 = np.float32


def _sym(rng, scale, spread=0.03):
    a = np.eye(3) + spread * rng.normal(size=(3, 3))
    return scale * (a + a.T) / 2


def _tt(ref=25.0, rng_c=(5.0, 50.0), scale=1.0):
    return TemperatureTerms(
        temp_ref_c=ref, temp_range_c=rng_c,
        offset_poly=np.array([[0.0, 0.0, 0.0], [0.01, -0.02, 0.005], [2e-4, -1e-4, 3e-4],
                              [-3e-6, 1e-6, 2e-6]]) * scale)


@pytest.fixture
def raw_mag() -> np.ndarray:
    rng = np.random.default_rng(0)
    return rng.normal(size=(400, 3)) * 300 + [120, -300, 55]


# --------------------------------------------------------------------------------------------
# ArduPilot


def _ap_load(text: str) -> dict[str, float]:
    """The file as MAVProxy / pymavlink loads it (pymavlink/mavparm.py MAVParmDict.load)."""
    pytest.importorskip("pymavlink")
    from pymavlink.mavparm import MAVParmDict

    path = _tmp_write(text)
    d = MAVParmDict()
    assert d.load(str(path))
    return {k: float(F32(v)) for k, v in d.items()}  # ArduPilot stores AP_Float (float32)


_TMP: list = []


def _tmp_write(text: str):
    import tempfile
    from pathlib import Path

    f = tempfile.NamedTemporaryFile("w", suffix=".parm", delete=False)
    f.write(text)
    f.close()
    _TMP.append(f.name)
    return Path(f.name)


def teardown_module(module):
    import os

    for name in _TMP:
        os.unlink(name)


def _ap_compass(p: dict, raw: np.ndarray, n: str = "") -> np.ndarray:
    # ArduPilot libraries/AP_Compass/AP_Compass_Backend.cpp, AP_Compass_Backend::correct_field:
    #   mag += offsets; if (have_scale_factor(i)) mag *= scale_factor;
    #   Matrix3f mat(DIA.x, ODI.x, ODI.y, ODI.x, DIA.y, ODI.z, ODI.y, ODI.z, DIA.z); mag = mat*mag
    # have_scale_factor (AP_Compass.cpp): COMPASS_MIN_SCALE_FACTOR 0.85 .. MAX 1.4
    ofs = np.array([p[f"COMPASS_OFS{n}_{a}"] for a in "XYZ"], F32)
    dia = [p[f"COMPASS_DIA{n}_{a}"] for a in "XYZ"]
    odi = [p[f"COMPASS_ODI{n}_{a}"] for a in "XYZ"]
    mat = np.array([[dia[0], odi[0], odi[1]], [odi[0], dia[1], odi[2]],
                    [odi[1], odi[2], dia[2]]], F32)
    mag = raw.astype(F32) + ofs
    s = F32(p.get(f"COMPASS_SCALE{n}", 0.0))
    if 0.85 <= s <= 1.4:
        mag = mag * s
    return mag @ mat.T


def _ap_tcal(p: dict, kind: str, n1: str, temp: np.ndarray) -> np.ndarray:
    # ArduPilot AP_InertialSensor_tempcal.cpp: polynomial_eval(tdiff, coeff) =
    #   (c[0] + (c[1] + c[2]*tdiff)*tdiff)*tdiff*INV_SCALE_FACTOR (1e-6);
    # correct_sensor: temperature, cal_temp = constrain(.., TMIN, TMAX);
    #   v -= polynomial_eval(temperature - TEMP_REFERENCE(35)) ; v += polynomial_eval(cal_temp - 35)
    pre = f"INS_TCAL{n1}_"
    if p.get(f"{pre}ENABLE", 0) != 1:
        return np.zeros((len(temp), 3))
    c = np.array([[p[f"{pre}{kind}{k}_{a}"] for a in "XYZ"] for k in (1, 2, 3)])
    tmin, tmax = p[f"{pre}TMIN"], p[f"{pre}TMAX"]
    cal_temp = p[f"INS_{kind}{n1}_CALTEMP"]

    def ev(x):
        x = np.asarray(x, float).reshape(-1, 1)
        return (c[0] + (c[1] + c[2] * x) * x) * x * 1e-6

    t = np.clip(temp, tmin, tmax)
    tc_ = min(max(cal_temp, tmin), tmax)
    return ev(t - 35.0) - ev(np.array([tc_ - 35.0]))


def _ap_accel(p: dict, raw: np.ndarray, temp: np.ndarray, n: str = "", n1: str = "1"):
    # ArduPilot AP_InertialSensor_Backend.cpp, _rotate_and_correct_accel (sensor frame part):
    #   tcal(instance).correct_accel(T, caltemp_accel(instance), accel);
    #   accel -= _accel_offset(instance); accel.x *= accel_scale.x; ...
    v = raw - _ap_tcal(p, "ACC", n1, temp)
    v = v - np.array([p[f"INS_ACC{n}OFFS_{a}"] for a in "XYZ"])
    return v * np.array([p[f"INS_ACC{n}SCAL_{a}"] for a in "XYZ"])


def _ap_gyro(p: dict, raw: np.ndarray, temp: np.ndarray, n1: str = "1"):
    # ArduPilot AP_InertialSensor_Backend.cpp, _rotate_and_correct_gyro: gyro -= _gyro_offset
    v = raw - _ap_tcal(p, "GYR", n1, temp)
    return v - np.array([p[f"INS_GYROFFS_{a}"] for a in "XYZ"])


def test_ardupilot_compass_round_trip(raw_mag):
    rng = np.random.default_rng(1)
    for scale_mode, gain in (("auto", 1.08), (None, 1.08), ("auto", 2.0)):
        part = tc.SensorCalibration(offset=[120, -300, 55], matrix=_sym(rng, gain),
                                    raw_unit="mG", unit="mG", radius=480.0)
        cal = tc.Calibration(mag=part)
        p = _ap_load(ardupilot_parm(cal, compass_scale=scale_mode))
        got = _ap_compass(p, raw_mag)
        want = part.apply(raw_mag)
        assert np.max(np.abs(got - want)) < 2e-6 * np.abs(want).max()
        if scale_mode == "auto" and gain < 1.3:   # the gain went to COMPASS_SCALE
            assert abs(p["COMPASS_SCALE"] - gain) < 0.03
            assert abs(np.mean([p[f"COMPASS_DIA_{a}"] for a in "XYZ"]) - 1) < 0.02
        else:                                     # folded into DIA, scaling off
            assert p["COMPASS_SCALE"] == 0


def test_ardupilot_compass_from_uT_and_second_compass(raw_mag):
    rng = np.random.default_rng(2)
    part = tc.SensorCalibration(offset=[12, -30, 5.5], matrix=_sym(rng, 1.0), raw_unit="uT",
                                unit="uT", radius=48.0)
    p = _ap_load(ardupilot_parm(tc.Calibration(mag=part), compass=1))
    assert "COMPASS_OFS2_X" in p and "COMPASS_OFS_X" not in p
    raw_ut = raw_mag / 10
    got = _ap_compass(p, raw_ut * 10, n="2")              # ArduPilot works in milligauss
    assert np.allclose(got, part.apply(raw_ut) * 10, rtol=0, atol=2e-6 * 4000)


def test_ardupilot_ins_round_trip_with_temperature():
    rng = np.random.default_rng(3)
    acc = tc.SensorCalibration(offset=[0.12, -0.2, 0.31], matrix=np.diag([1.01, 0.99, 1.02]),
                               raw_unit="m/s^2", unit="m/s^2", temperature=_tt())
    gyr = tc.SensorCalibration(offset=[0.01, -0.02, 0.003], matrix=np.eye(3),
                               raw_unit="rad/s", unit="rad/s",
                               temperature=_tt(ref=30.0, rng_c=(0.0, 60.0), scale=0.1))
    cal = tc.Calibration(accel=acc, gyro=gyr)
    p = _ap_load(ardupilot_parm(cal))
    raw = rng.normal(size=(500, 3)) * 9.8
    temp = rng.uniform(0.0, 60.0, 500)    # inside the union of both ranges: ArduPilot's TMIN..TMAX
    got = _ap_accel(p, raw, temp)
    assert np.max(np.abs(got - acc.apply(raw, temperature=temp))) < 5e-6
    g = rng.normal(size=(500, 3))
    assert np.max(np.abs(_ap_gyro(p, g, temp) - gyr.apply(g, temperature=temp))) < 5e-6
    assert (p["INS_TCAL1_TMIN"], p["INS_TCAL1_TMAX"]) == (0.0, 60.0)
    # outside the range ArduPilot holds the correction, triaxcal extrapolates: they differ
    hot = np.full(500, 80.0)
    assert np.max(np.abs(_ap_accel(p, raw, hot) - acc.apply(raw, temperature=hot))) > 1e-3


def test_ardupilot_without_temperature_disables_tcal():
    acc = tc.SensorCalibration(offset=[0.1, 0, 0], matrix=np.eye(3), raw_unit="m/s^2",
                               unit="m/s^2")
    p = ardupilot_params(tc.Calibration(accel=acc), imu=2)
    assert p["INS_TCAL3_ENABLE"] == 0 and p["INS_ACC3OFFS_X"] == 0.1


def test_ardupilot_from_counts_with_driver_scale():
    # a board fitted in counts -> g: ArduPilot sees the driver's m/s^2 (16384 counts/g here)
    rng = np.random.default_rng(4)
    m = np.diag([1.02, 0.98, 1.01]) / 16384
    acc = tc.SensorCalibration(offset=[300, -120, 80], matrix=m, raw_unit="counts", unit="g")
    p = _ap_load(ardupilot_parm(tc.Calibration(accel=acc),
                                counts_per_unit={"accel": (16384, "g")}))
    counts = rng.normal(size=(200, 3)) * 16384
    got = _ap_accel(p, counts * 9.80665 / 16384, np.zeros(200))
    assert np.max(np.abs(got - acc.apply(counts) * 9.80665)) < 1e-5


@pytest.mark.parametrize("make, match", [
    (lambda: tc.Calibration(accel=tc.SensorCalibration(
        offset=[0, 0, 0], matrix=[[1, 0.01, 0], [0.01, 1, 0], [0, 0, 1]], raw_unit="m/s^2",
        unit="m/s^2")), "cross-axis"),
    (lambda: tc.Calibration(accel=tc.SensorCalibration(
        offset=[0, 0, 0], matrix=np.diag([1.3, 1, 1]), raw_unit="m/s^2", unit="m/s^2")),
     "0.8..1.2"),
    (lambda: tc.Calibration(accel=tc.SensorCalibration(
        offset=[4.0, 0, 0], matrix=np.eye(3), raw_unit="m/s^2", unit="m/s^2")), "3.5"),
    (lambda: tc.Calibration(gyro=tc.SensorCalibration(
        offset=[0, 0, 0], matrix=np.eye(3) * 1.01, raw_unit="rad/s", unit="rad/s")),
     "no gyro gains"),
    (lambda: tc.Calibration(mag=tc.SensorCalibration(
        offset=[0, 0, 0], matrix=[[1, 0.1, 0], [0, 1, 0], [0, 0, 1]], raw_unit="mG",
        unit="mG")), "not symmetric"),
    (lambda: tc.Calibration(mag=tc.SensorCalibration(
        offset=[0, 0, 0], matrix=np.diag([6.0, 1, 1]), raw_unit="mG", unit="mG")), "0.2..5"),
    (lambda: tc.Calibration(mag=tc.SensorCalibration(
        offset=[2500, 0, 0], matrix=np.eye(3), raw_unit="mG", unit="mG")), "COMPASS_OFFS_MAX"),
    (lambda: tc.Calibration(mag=tc.SensorCalibration(
        offset=[0, 0, 0], matrix=np.eye(3), raw_unit="uT", unit="uT", radius=480.0)),
     "150..950 mG"),
    (lambda: tc.Calibration(mag=tc.SensorCalibration(
        offset=[0, 0, 0], matrix=np.eye(3), raw_unit="m/s^2", unit="m/s^2")),
     "cannot be converted"),
    (lambda: tc.Calibration(accel=tc.SensorCalibration(
        offset=[0, 0, 0], matrix=np.eye(3), raw_unit="m/s^2", unit="m/s^2",
        temperature=TemperatureTerms(temp_ref_c=25, temp_range_c=(0, 50),
                                     offset_poly=[[0, 0, 0], [0.01, 0, 0]],
                                     gain_poly=[[0, 0, 0], [1e-4, 0, 0]]))), "gains"),
    (lambda: tc.Calibration(accel=tc.SensorCalibration(
        offset=[0, 0, 0], matrix=np.eye(3), raw_unit="m/s^2", unit="m/s^2",
        temperature=TemperatureTerms(temp_ref_c=25, temp_range_c=(0, 50),
                                     offset_poly=np.zeros((5, 3))))), "degree 3"),
])
def test_ardupilot_refuses_what_it_cannot_hold(make, match):
    # forced past the validity gate (which refuses several of these on its own): the format's
    # own checks must refuse them too
    with pytest.raises(tc.CalibrationError, match=match):
        ardupilot_parm(make(), force=True)


def test_ardupilot_options_validated():
    cal = tc.Calibration(mag=tc.SensorCalibration(offset=[0, 0, 0], matrix=np.eye(3),
                                                  raw_unit="mG", unit="mG"))
    with pytest.raises(tc.CalibrationError, match="0, 1 or 2"):
        ardupilot_parm(cal, compass=3)
    with pytest.raises(tc.CalibrationError, match="has no gyro part"):
        ardupilot_parm(cal, sensors=["gyro"])
    with pytest.raises(tc.CalibrationError, match="holds no temp"):
        ardupilot_parm(cal, sensors=["temp"])
    with pytest.raises(tc.CalibrationError, match="COMPASS_SCALE"):
        ardupilot_parm(cal, compass_scale=1.5)


# --------------------------------------------------------------------------------------------
# PX4


def _qgc_load(text: str) -> dict[str, float]:
    """As QGroundControl reads a parameter file (src/FactSystem/ParameterManager.cc
    readParametersFromStream): skip '#' lines, split on tabs, five fields
    vehicle-id, component-id, name, value, MAV_PARAM_TYPE; REAL32 (9) stored as float32."""
    out = {}
    for line in text.splitlines():
        if line.startswith("#") or not line:
            continue
        f = line.split("\t")
        assert len(f) == 5, line
        assert int(f[0]) == 1 and int(f[1]) == 1
        kind = int(f[4])
        assert kind in (6, 9)
        out[f[2]] = float(F32(float(f[3]))) if kind == 9 else float(int(f[3]))
    return out


def _px4_thermal(p: dict, s: str, n: int, temp: np.ndarray) -> np.ndarray:
    # PX4 src/modules/temperature_compensation/TemperatureCompensation.cpp,
    # calc_thermal_offsets_3D: delta_temp = clamp(measured, min_temp, max_temp) - ref_temp;
    #   offset[i] = x0[i] + x1[i]*dT + x2[i]*dT^2 + x3[i]*dT^3   (applied when TC_x_ENABLE == 1)
    if p.get(f"TC_{s}_ENABLE", 0) != 1:
        return np.zeros((len(temp), 3))
    dt = (np.clip(temp, p[f"TC_{s}{n}_TMIN"], p[f"TC_{s}{n}_TMAX"]) - p[f"TC_{s}{n}_TREF"])
    x = [np.array([p[f"TC_{s}{n}_X{k}_{i}"] for i in range(3)]) for k in range(4)]
    dt = dt[:, None]
    return x[0] + x[1] * dt + x[2] * dt**2 + x[3] * dt**3


def test_px4_round_trip():
    rng = np.random.default_rng(6)
    acc = tc.SensorCalibration(offset=[0.12, -0.2, 0.31], matrix=np.diag([1.01, 0.99, 1.02]),
                               raw_unit="m/s^2", unit="m/s^2", temperature=_tt())
    gyr = tc.SensorCalibration(offset=[0.01, -0.02, 0.003], matrix=np.eye(3), raw_unit="rad/s",
                               unit="rad/s")
    mag = tc.SensorCalibration(offset=[0.12, -0.3, 0.05], matrix=_sym(rng, 1.1),
                               raw_unit="gauss", unit="gauss")
    cal = tc.Calibration(accel=acc, gyro=gyr, mag=mag)
    p = _qgc_load(px4_params_file(cal, instance=1, device_ids={"accel": 2424842}))
    assert p["CAL_ACC1_ID"] == 2424842 and p["TC_A1_ID"] == 2424842
    assert p["TC_G_ENABLE"] == 0 and p["TC_M_ENABLE"] == 0
    raw = rng.normal(size=(400, 3)) * 9.8
    temp = rng.uniform(5.0, 50.0, 400)
    # PX4 src/lib/sensor_calibration/Accelerometer.hpp, Correct():
    #   _rotation * (data - _thermal_offset - _offset).emult(_scale)   (rotation left out here)
    off = np.array([p[f"CAL_ACC1_{a}OFF"] for a in "XYZ"])
    sc = np.array([p[f"CAL_ACC1_{a}SCALE"] for a in "XYZ"])
    got = (raw - _px4_thermal(p, "A", 1, temp) - off) * sc
    assert np.max(np.abs(got - acc.apply(raw, temperature=temp))) < 5e-6
    # Gyroscope.hpp, Correct(): _rotation * (data - _thermal_offset - _offset)
    g = rng.normal(size=(400, 3))
    got = g - np.array([p[f"CAL_GYRO1_{a}OFF"] for a in "XYZ"])
    assert np.max(np.abs(got - gyr.apply(g))) < 1e-8
    # Magnetometer.hpp, Correct(): _rotation * (_scale * ((data + _power*_power_compensation)
    #   - _offset)); Magnetometer.cpp set_scale -> diagonal, set_offdiagonal: (0,1)=(1,0)=X,
    #   (0,2)=(2,0)=Y, (1,2)=(2,1)=Z
    d = [p[f"CAL_MAG1_{a}SCALE"] for a in "XYZ"]
    o = [p[f"CAL_MAG1_{a}ODIAG"] for a in "XYZ"]
    s = np.array([[d[0], o[0], o[1]], [o[0], d[1], o[2]], [o[1], o[2], d[2]]])
    m = rng.normal(size=(400, 3)) * 0.5
    got = (m - np.array([p[f"CAL_MAG1_{a}OFF"] for a in "XYZ"])) @ s.T
    assert np.max(np.abs(got - mag.apply(m))) < 2e-7 * np.abs(got).max() * 10


def test_px4_refusals():
    acc_t = tc.SensorCalibration(offset=[0, 0, 0], matrix=np.eye(3), raw_unit="m/s^2",
                                 unit="m/s^2", temperature=_tt())
    with pytest.raises(tc.CalibrationError, match="TC_A0_ID"):
        px4_params(tc.Calibration(accel=acc_t))
    neg = tc.SensorCalibration(offset=[0, 0, 0], matrix=np.diag([-1.0, 1, 1]), raw_unit="gauss",
                               unit="gauss")
    with pytest.raises(tc.CalibrationError, match="positive"):
        px4_params(tc.Calibration(mag=neg), force=True)  # the gate refuses it too
    gyr = tc.SensorCalibration(offset=[0, 0, 0], matrix=np.eye(3) * 1.02, raw_unit="rad/s",
                               unit="rad/s")
    with pytest.raises(tc.CalibrationError, match="no gyro gains"):
        px4_params(tc.Calibration(gyro=gyr))
    ok = tc.Calibration(accel=tc.SensorCalibration(offset=[0, 0, 0], matrix=np.eye(3),
                                                   raw_unit="m/s^2", unit="m/s^2"))
    for bad in ({"instance": 4}, {"device_ids": {"accel": -5}}, {"device_ids": {"accel": 1.5}}):
        with pytest.raises(tc.CalibrationError):
            px4_params(ok, **bad)
    with pytest.raises(tc.CalibrationError, match="1..255"):
        px4_params_file(ok, system_id=0)


# --------------------------------------------------------------------------------------------
# Kalibr


def _imu_cal(rng):
    acc = tc.SensorCalibration(offset=[0.12, -0.2, 0.31], matrix=_sym(rng, 1.0), raw_unit="m/s^2",
                               unit="m/s^2")
    gyr = tc.SensorCalibration(offset=[0.01, -0.02, 0.003], matrix=_sym(rng, 1.0),
                               raw_unit="rad/s", unit="rad/s")
    return tc.Calibration(accel=acc, gyro=gyr)


def _kabsch(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Rotation r minimising |a - b @ r.T|."""
    u, _, vt = np.linalg.svd(a.T @ b)
    d = np.sign(np.linalg.det(u @ vt))
    return u @ np.diag([1, 1, d]) @ vt


def test_kalibr_round_trip():
    yaml = pytest.importorskip("yaml")
    rng = np.random.default_rng(7)
    cal = _imu_cal(rng)
    noise = {"accelerometer_noise_density": 1.86e-3, "accelerometer_random_walk": 4.33e-4,
             "gyroscope_noise_density": 1.87e-4, "gyroscope_random_walk": 2.66e-5}
    doc = yaml.safe_load(kalibr_imu_yaml(cal, topic="/imu/data_raw", rate_hz=200.0,
                                         noise=noise))
    # kalibr_common/ConfigReader.py ImuParameters: rostopic (str), update_rate > 0, four noise
    # keys > 0
    assert doc["rostopic"] == "/imu/data_raw" and doc["update_rate"] == 200.0
    assert all(doc[k] == v for k, v in noise.items())
    ma = np.array(doc["accelerometers"]["M"])
    mg = np.array(doc["gyroscopes"]["M"])
    c = np.array(doc["gyroscopes"]["C_gyro_i"])
    a_ = np.array(doc["gyroscopes"]["A"])
    # Kalibr's parametrisation (IccSensors.py IccScaledMisalignedImu.addDesignVariables):
    # M_accel, M_gyro lower triangular (mask [[1,0,0],[1,1,0],[1,1,1]]); C_gyro_i a rotation
    assert np.all(np.triu(ma, 1) == 0) and np.all(np.triu(mg, 1) == 0)
    assert np.allclose(c @ c.T, np.eye(3), atol=1e-12) and np.linalg.det(c) > 0
    # The measurement model (IccScaledMisalignedImu.addAccelerometerErrorTerms /
    # addGyroscopeErrorTerms): alpha = M*a_i + b;  omega = M*(C_gyro_i*w_i) + Ma*a_i + b.
    # Solve it for the true values from raw readings, with the biases b = triaxcal's offsets.
    raw_a = rng.normal(size=(300, 3)) * 9.8
    raw_g = rng.normal(size=(300, 3))
    a_i = (raw_a - cal.accel.offset) @ np.linalg.inv(ma).T
    w_i = ((raw_g - cal.gyro.offset - a_i @ a_.T) @ np.linalg.inv(mg).T) @ c  # C^-1 = C^T
    a_ours, w_ours = cal.apply(raw_a, sensor="accel"), cal.apply(raw_g, sensor="gyro")
    # Kalibr's IMU frame is triaxcal's turned by one rotation, the same for both sensors
    r = _kabsch(a_i, a_ours)
    assert np.max(np.abs(a_i - a_ours @ r.T)) < 1e-10
    assert np.max(np.abs(w_i - w_ours @ r.T)) < 1e-10
    assert np.allclose(r, kalibr_intrinsics(cal)["R_i"], atol=1e-12)


def test_kalibr_models_and_validation():
    yaml = pytest.importorskip("yaml")
    rng = np.random.default_rng(8)
    cal = _imu_cal(rng)
    doc = yaml.safe_load(kalibr_imu_yaml(cal, rate_hz=100, model="calibrated"))
    assert doc["model"] == "calibrated" and "accelerometers" not in doc
    assert "accelerometer_noise_density" not in doc
    for kw, match in (({"topic": "imu; rm -rf"}, "ROS topic"),
                      ({"rate_hz": 0}, r"rate_hz must be a finite number in \[0.001"),
                      ({"noise": {"accelerometer_noise_density": 1.0}}, "missing"),
                      ({"noise": {**dict.fromkeys(
                          ("accelerometer_noise_density", "accelerometer_random_walk",
                           "gyroscope_noise_density", "gyroscope_random_walk"), 1.0),
                          "extra": 2.0}}, "unknown"),
                      ({"noise": dict.fromkeys(
                          ("accelerometer_noise_density", "accelerometer_random_walk",
                           "gyroscope_noise_density", "gyroscope_random_walk"), -1.0)}, "> 0"),
                      ({"model": "scale-misalignment-size-effect"}, "unknown Kalibr")):
        args = {"rate_hz": 100, **kw}
        with pytest.raises(tc.CalibrationError, match=match):
            kalibr_imu_yaml(cal, **args)
    with pytest.raises(tc.CalibrationError, match="accelerometer and gyroscope"):
        kalibr_imu_yaml(tc.Calibration(accel=cal.accel), rate_hz=100)


# --------------------------------------------------------------------------------------------
# Adafruit_Sensor_Calibration


def _ada_load(text: str) -> dict:
    # Adafruit_Sensor_Calibration_SDFat.cpp loadCalibration: each value `calibJSON[key][i] | def`
    # (a missing key gives the default: 0, identity soft iron) into float members
    d = json.loads(text)
    soft_def = [1.0 if i in (0, 4, 8) else 0.0 for i in range(9)]
    return {
        "mag_hardiron": np.array(d.get("mag_hardiron", [0.0] * 3), F32),
        "mag_softiron": np.array(d.get("mag_softiron", soft_def), F32),
        "mag_field": F32(d.get("mag_field", 0.0)),
        "gyro_zerorate": np.array(d.get("gyro_zerorate", [0.0] * 3), F32),
        "accel_zerog": np.array(d.get("accel_zerog", [0.0] * 3), F32),
    }


def _ada_calibrate(c: dict, sensor: str, v: np.ndarray) -> np.ndarray:
    # Adafruit_Sensor_Calibration.cpp calibrate(): mag: mx = x - hardiron[0] ...;
    #   x = mx*soft[0] + my*soft[1] + mz*soft[2]; y = ...soft[3..5]; z = ...soft[6..8]
    #   gyro: x -= gyro_zerorate[0] ...; accel: x -= accel_zerog[0] ...
    v = v.astype(F32)
    if sensor == "mag":
        return (v - c["mag_hardiron"]) @ c["mag_softiron"].reshape(3, 3).T
    return v - c["gyro_zerorate" if sensor == "gyro" else "accel_zerog"]


def test_adafruit_round_trip_from_counts():
    rng = np.random.default_rng(9)
    # a board fitted in counts (10 counts/uT, 131 counts/(deg/s)): the driver gives uT, rad/s
    mag = tc.SensorCalibration(offset=[300, -120, 80], matrix=_sym(rng, 0.1), raw_unit="counts",
                               unit="uT", radius=48.0)
    gyr = tc.SensorCalibration(offset=[40, -12, 7], matrix=np.eye(3) / 131, raw_unit="counts",
                               unit="deg/s")
    cal = tc.Calibration(mag=mag, gyro=gyr)
    text = adafruit_calib_json(cal, counts_per_unit={"mag": (10, "uT"), "gyro": (131, "deg/s")})
    d = json.loads(text)
    # only the parts written (no accel part: accel_zerog is left out, and the board reads it as
    # 0 -- which triaxcal export says); nothing else: the board parses into 512 bytes
    assert list(d) == ["mag_hardiron", "mag_softiron", "mag_field", "gyro_zerorate"]
    assert len(text) < 400
    c = _ada_load(text)
    counts = rng.normal(size=(300, 3)) * 500
    got = _ada_calibrate(c, "mag", counts / 10.0)
    assert np.max(np.abs(got - mag.apply(counts))) < 1e-4
    assert c["mag_field"] == F32(48.0)
    gc = rng.normal(size=(300, 3)) * 1000
    got = _ada_calibrate(c, "gyro", gc / 131 * np.pi / 180)
    assert np.max(np.abs(got - gyr.apply(gc) * np.pi / 180)) < 1e-6
    assert np.all(c["accel_zerog"] == 0)


def test_adafruit_refuses_accel_gains():
    acc = tc.SensorCalibration(offset=[0.1, 0, 0], matrix=np.diag([1.02, 1, 1]),
                               raw_unit="m/s^2", unit="m/s^2")
    with pytest.raises(tc.CalibrationError, match="offsets only"):
        adafruit_calib_json(tc.Calibration(accel=acc))
    ok = tc.SensorCalibration(offset=[0.1, 0, 0], matrix=np.eye(3), raw_unit="m/s^2",
                              unit="m/s^2")
    c = _ada_load(adafruit_calib_json(tc.Calibration(accel=ok)))
    assert np.allclose(c["accel_zerog"], [0.1, 0, 0])


# --------------------------------------------------------------------------------------------
# export() and the simulator: the consumer's equation gives the simulated truth


def test_export_dispatch(tmp_path):
    part = tc.SensorCalibration(offset=[120, -40, 15], matrix=np.eye(3) * 1.02, raw_unit="mG",
                                unit="mG")
    cal = tc.Calibration(mag=part)
    for fmt in ("ardupilot", "px4", "adafruit"):
        extra = {"mag_field": "48uT"} if fmt == "adafruit" else {}
        out = export(cal, fmt, tmp_path / f"x.{fmt}", **extra)
        assert out.stat().st_size > 0
    with pytest.raises(tc.CalibrationError, match="apply to the parameter formats"):
        export(cal, "c", tmp_path / "x.h", instance=1)


def test_sim_truth_through_ardupilot_equation():
    from triaxcal.sim import SimIMU, globe_script

    imu = SimIMU(seed=3)
    rec = imu.record(globe_script(hold_s=0.2), rate_hz=50)
    fit = tc.fit_ellipsoid(rec.mag, model="full", radius=50.0)
    part = tc.SensorCalibration.from_fit(fit, unit="uT")
    from triaxcal.sim import SIM_COUNTS_PER_UNIT

    p = _ap_load(ardupilot_parm(tc.Calibration(mag=part), counts_per_unit=SIM_COUNTS_PER_UNIT))
    # the simulator's driver: 10 counts/uT -> ArduPilot milligauss = counts
    got = _ap_compass(p, rec.mag.astype(float))
    err = np.linalg.norm(got / 10 - rec.mag_ut, axis=1)
    assert np.median(err) < 0.5     # uT, against the simulator's true field (noise 3 counts)


# --------------------------------------------------------------------------------------------
# Interference (a compass calibrated from a flight: triaxcal.methods.attitude)


def _flight_part(unit: str, per: str, vector, rng) -> tc.SensorCalibration:
    """A flight calibration: ``(raw - offset) @ M.T + vector * x`` with ``x`` the battery
    current (A) or the throttle (0..1), ``vector`` in ``unit`` per A / per unit of throttle."""
    k = {"mG": 1.0, "gauss": 1e-3}[unit]
    return tc.SensorCalibration(
        offset=np.array([140.0, -95.0, 60.0]) * k, matrix=_sym(rng, 1.02), raw_unit=unit,
        unit=unit, radius=480.0 * k, model="attitude",
        stats={"interference": {"per": per, "vector": list(np.asarray(vector) * k),
                                "unit": unit, "source": "BAT.Curr"}})


def _ap_compass_mot(p: dict, raw: np.ndarray, x: np.ndarray, n: str = "") -> np.ndarray:
    # ArduPilot libraries/AP_Compass/AP_Compass_Backend.cpp, correct_field, after the elliptical
    # correction:  const Vector3f &mot = state.motor_compensation.get();
    #   if (_compass._motor_comp_type == AP_COMPASS_MOT_COMP_THROTTLE)   motor_offset = mot * _thr;
    #   else if (... == AP_COMPASS_MOT_COMP_CURRENT) motor_offset = mot * battery.current_amps();
    #   mag += state.motor_offset;     (AP_Compass.h: MOT_COMP_THROTTLE 1, MOT_COMP_CURRENT 2)
    mot = np.array([p[f"COMPASS_MOT{n}_{a}"] for a in "XYZ"], F32)
    assert p["COMPASS_MOTCT"] in (1.0, 2.0)
    return _ap_compass(p, raw, n) + x.astype(F32)[:, None] * mot


@pytest.mark.parametrize("per, compass", [("A", 0), ("throttle", 0), ("A", 1)])
def test_ardupilot_interference_round_trip(raw_mag, per, compass):
    rng = np.random.default_rng(11)
    part = _flight_part("mG", per, [3.5, -2.0, 5.0] if per == "A" else [120.0, -60.0, 200.0], rng)
    p = _ap_load(ardupilot_parm(tc.Calibration(mag=part), compass=compass))
    n = "" if compass == 0 else str(compass + 1)
    assert p["COMPASS_MOTCT"] == (2.0 if per == "A" else 1.0)
    x = rng.uniform(0, 40, len(raw_mag)) if per == "A" else rng.uniform(0, 1, len(raw_mag))
    want = part.apply(raw_mag) + x[:, None] * np.asarray(part.stats["interference"]["vector"])
    got = _ap_compass_mot(p, raw_mag, x, n)
    assert np.max(np.abs(got - want)) < 2e-6 * np.abs(want).max() * 10


def _px4_mag_comp(p: dict, raw: np.ndarray, x: np.ndarray, n: int) -> np.ndarray:
    # PX4 src/lib/sensor_calibration/Magnetometer.hpp, Correct():
    #   return _rotation * (_scale * ((data + _power * _power_compensation) - _offset));
    # Magnetometer.cpp ParametersUpdate: _power_compensation = CAL_MAGn_{X,Y,Z}COMP.
    # src/modules/sensors/vehicle_magnetometer/VehicleMagnetometer.cpp Run(), when armed:
    #   CAL_MAG_COMP_TYP 1 (Throttle): UpdatePower(actuator_controls_0.control[INDEX_THROTTLE])
    #   2 / 3 (Current_inst0 / 1): UpdatePower(bat_stat.current_a * 0.001f)   // [kA]
    typ = p["CAL_MAG_COMP_TYP"]
    power = (x * 0.001 if typ in (2.0, 3.0) else x).astype(F32)
    d = [p[f"CAL_MAG{n}_{a}SCALE"] for a in "XYZ"]
    o = [p[f"CAL_MAG{n}_{a}ODIAG"] for a in "XYZ"]
    s = np.array([[d[0], o[0], o[1]], [o[0], d[1], o[2]], [o[1], o[2], d[2]]], F32)
    comp = np.array([p[f"CAL_MAG{n}_{a}COMP"] for a in "XYZ"], F32)
    off = np.array([p[f"CAL_MAG{n}_{a}OFF"] for a in "XYZ"], F32)
    return ((raw.astype(F32) + power[:, None] * comp) - off) @ s.T


@pytest.mark.parametrize("per, slot", [("A", 0), ("throttle", 2)])
def test_px4_power_compensation_round_trip(per, slot):
    rng = np.random.default_rng(12)
    part = _flight_part("gauss", per, [3.5, -2.0, 5.0] if per == "A" else [120.0, -60.0, 200.0],
                        rng)
    p = _qgc_load(px4_params_file(tc.Calibration(mag=part), instance=slot))
    assert p["CAL_MAG_COMP_TYP"] == (2.0 if per == "A" else 1.0)
    raw = rng.normal(size=(400, 3)) * 0.3 + [0.14, -0.095, 0.06]
    x = rng.uniform(0, 40, 400) if per == "A" else rng.uniform(0, 1, 400)
    want = part.apply(raw) + x[:, None] * np.asarray(part.stats["interference"]["vector"])
    got = _px4_mag_comp(p, raw, x, slot)
    assert np.max(np.abs(got - want)) < 2e-6 * np.abs(want).max() * 10
