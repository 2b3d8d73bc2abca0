"""The magnetometer alignment in every export that can hold it, through the consumer's own
equation; the formats that cannot hold it refuse or warn."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
import triaxcal as tc
from test_export import CFLAGS, GCC, _build_and_run  # noqa: F401
from test_export_params import F32, _ada_calibrate, _ada_load, _ap_compass, _ap_load, _qgc_load
from triaxcal.conventions.rotations import mounting

ROLL90 = mounting("ROTATION_ROLL_90").matrix
TILTED = ROLL90 @ tc.sim.rotvec_to_matrix(np.radians([1.5, 0.8, -1.1]))  # 2 deg off ROLL_90


def _mag(rot: np.ndarray, mount: str | None, raw_unit: str = "mG") -> tc.SensorCalibration:
    m = np.array([[1.04, 0.02, -0.01], [0.02, 0.97, 0.015], [-0.01, 0.015, 1.01]])
    return tc.SensorCalibration(
        offset=[120.0, -300.0, 55.0], matrix=m, raw_unit=raw_unit, unit=raw_unit,
        radius=480.0, alignment=tc.Alignment(rotation=rot, mounting=mount))


@pytest.fixture
def raw() -> np.ndarray:
    return np.random.default_rng(0).normal(size=(300, 3)) * 300 + [120, -300, 55]


def _ap_rotate(p: dict, raw: np.ndarray, n: str = "") -> np.ndarray:
    # AP_Compass_Backend::rotate_field: for an external compass mag.rotate(orientation), before
    # correct_field; Vector3::rotate(ROTATION_ROLL_90): tmp = z; z = y; y = -tmp
    assert p[f"COMPASS_ORIENT{n}"] == 16
    x, y, z = raw.T
    return np.column_stack([x, -z, y])


def test_ardupilot_compass_orient(raw):
    part = _mag(ROLL90, "ROTATION_ROLL_90")
    p = _ap_load(tc.ardupilot_parm(tc.Calibration(mag=part)))
    got = _ap_compass(p, _ap_rotate(p, raw))
    want = part.apply_aligned(raw)
    assert np.max(np.abs(got - want)) < 2e-6 * np.abs(want).max()
    # compass 2 writes COMPASS_ORIENT2
    p2 = _ap_load(tc.ardupilot_parm(tc.Calibration(mag=part), compass=1))
    assert p2["COMPASS_ORIENT2"] == 16 and "COMPASS_ORIENT" not in p2


def test_ardupilot_and_px4_warn_about_what_they_leave_out(raw):
    part = _mag(TILTED, "ROTATION_ROLL_90")
    cal = tc.Calibration(mag=part)
    with pytest.warns(tc.AlignmentWarning, match=r"2\.\d+ deg"):
        p = _ap_load(tc.ardupilot_parm(cal))
    got = _ap_compass(p, _ap_rotate(p, raw))
    want = part.replace(alignment=tc.Alignment(rotation=ROLL90)).apply_aligned(raw)
    assert np.max(np.abs(got - want)) < 2e-6 * np.abs(want).max()  # the mounting, exactly
    with pytest.warns(tc.AlignmentWarning, match="CAL_MAG0_ROT"):
        tc.px4_params_file(cal)
    # within 1 deg: no warning
    small = _mag(ROLL90 @ tc.sim.rotvec_to_matrix(np.radians([0.3, 0, 0])), "ROTATION_ROLL_90")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        tc.ardupilot_parm(tc.Calibration(mag=small))


def test_non_right_angle_alignment_refused_by_autopilots():
    part = _mag(tc.sim.rotvec_to_matrix(np.radians([0, 0, 45.0])), None)
    cal = tc.Calibration(mag=part)
    for fn, name in ((tc.ardupilot_parm, "COMPASS_ORIENT"), (tc.px4_params_file, "CAL_MAG0_ROT")):
        with pytest.raises(tc.CalibrationError, match=f"{name}.*right-angle.*45.0 deg"):
            fn(cal)


def test_px4_cal_mag_rot(raw):
    part = _mag(ROLL90, "ROTATION_ROLL_90", raw_unit="gauss")
    # forced: the fixture's hard iron (in gauss here) is far beyond any compass's, which the
    # validity gate refuses; this test is about the rotation's convention
    p = _qgc_load(tc.px4_params_file(tc.Calibration(mag=part), instance=2, force=True))
    assert p["CAL_MAG2_ROT"] == 16
    # PX4 Magnetometer::Correct: _rotation * (_scale * (data - _offset)), rotation from
    # get_rot_matrix(ROTATION_ROLL_90) = Dcmf(Eulerf(90 deg, 0, 0))
    off = np.array([p[f"CAL_MAG2_{a}OFF"] for a in "XYZ"])
    d = [p[f"CAL_MAG2_{a}SCALE"] for a in "XYZ"]
    o = [p[f"CAL_MAG2_{a}ODIAG"] for a in "XYZ"]
    s = np.array([[d[0], o[0], o[1]], [o[0], d[1], o[2]], [o[1], o[2], d[2]]])
    rot = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]])
    got = (raw / 1000 - off) @ s.T @ rot.T
    want = part.apply_aligned(raw / 1000)
    assert np.max(np.abs(got - want)) < 1e-6 * np.abs(want).max()


def test_adafruit_soft_iron_holds_any_rotation(raw):
    part = _mag(TILTED, "ROTATION_ROLL_90", raw_unit="uT")
    c = _ada_load(tc.adafruit_calib_json(tc.Calibration(mag=part), force=True))  # as above
    got = _ada_calibrate(c, "mag", raw / 10)
    want = part.apply_aligned(raw / 10)
    assert np.max(np.abs(got - want)) < 2e-6 * np.abs(want).max()
    assert got.dtype == F32


def test_kalibr_says_the_magnetometer_is_not_written():
    rng = np.random.default_rng(1)
    acc = tc.SensorCalibration(offset=rng.normal(size=3) * 0.1, matrix=np.eye(3) * 1.01,
                               raw_unit="m/s^2", unit="m/s^2")
    gyr = tc.SensorCalibration(offset=[0.01, 0, 0], matrix=np.eye(3), raw_unit="rad/s",
                               unit="rad/s")
    text = tc.kalibr_imu_yaml(tc.Calibration(accel=acc, gyro=gyr, mag=_mag(ROLL90, None)),
                              rate_hz=200)
    assert "not written: the magnetometer part and its alignment" in text


def test_motioncal_refuses_and_no_alignment_exports(tmp_path, raw):
    cal = tc.Calibration(mag=_mag(ROLL90, "ROTATION_ROLL_90", raw_unit="uT"))
    with pytest.raises(tc.CalibrationError, match="no rotation"):
        tc.motioncal_packet(cal, force=True)  # forced past the gate (300 uT of hard iron)
    path = tmp_path / "cal.json"
    cal.save(path)
    from triaxcal.cli import main

    assert main(["export", str(path), "--format", "motioncal", "--force", "-o",
                 str(tmp_path / "m.bin")]) == 1
    assert main(["export", str(path), "--format", "motioncal", "--no-alignment", "--force",
                 "-o", str(tmp_path / "m.bin")]) == 0
    assert (tmp_path / "m.bin").stat().st_size == 68


MAIN = r"""
#include <stdio.h>
#include "cal.h"
int main(void) {
    float raw[3], out[3];
    while (scanf("%f %f %f", &raw[0], &raw[1], &raw[2]) == 3) {
        imu_mag_aligned_apply(raw, out);
        printf("%.9g %.9g %.9g\n", out[0], out[1], out[2]);
    }
    return 0;
}
"""


@pytest.mark.skipif(GCC is None, reason="gcc not installed")
def test_c_header_aligned_block(tmp_path, raw):
    part = _mag(TILTED, "ROTATION_ROLL_90", raw_unit="counts")
    header = tc.c_header(tc.Calibration(mag=part), prefix="imu")
    assert "mag_aligned: the mag calibration followed by its alignment" in header
    out = _build_and_run(tmp_path, header, MAIN, [" ".join(f"{v:.9g}" for v in r) for r in raw])
    got = np.array(out, float)
    want = part.apply_aligned(raw)
    assert np.max(np.abs(got - want)) < 1e-5 * np.abs(want).max()


def test_c_fixed_header_has_the_aligned_block():
    part = _mag(TILTED, "ROTATION_ROLL_90", raw_unit="counts")
    header = tc.c_fixed_header(tc.Calibration(mag=part), prefix="imu")
    assert "imu_mag_aligned_apply_q" in header and "imu_mag_apply_q" in header
    json.dumps(header)  # plain text
