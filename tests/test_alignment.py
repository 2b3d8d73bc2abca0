"""Magnetometer-to-accelerometer alignment: the 24 mountings, recovery on simulated data with a
known rotation, the heading error on held-out poses, the calibration file, and the sunsided
recordings (MPU6050 + HMC5883L)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import triaxcal as tc
from triaxcal.conventions.rotations import MOUNTINGS, mounting, nearest_mounting, rotation_angle_deg

# --------------------------------------------------------------------------------------------
# the 24 right-angle rotations


def test_mountings_are_the_24_right_angle_rotations():
    mats = [m.matrix for m in MOUNTINGS]
    assert len(mats) == 24
    for r in mats:
        assert set(np.unique(r)) <= {-1.0, 0.0, 1.0}
        assert np.allclose(r @ r.T, np.eye(3)) and np.isclose(np.linalg.det(r), 1.0)
    keys = {tuple(r.ravel()) for r in mats}
    assert len(keys) == 24  # distinct: every proper right-angle rotation once
    for a in mats:  # a group: closed under composition
        for b in mats:
            assert tuple((a @ b).ravel()) in keys


# ArduPilot's Vector3<T>::rotate (libraries/AP_Math/vector3.cpp) swaps components; a few of its
# cases written out, applied to (x, y, z):
AP_ROTATE = {
    "ROTATION_YAW_90": lambda x, y, z: (-y, x, z),
    "ROTATION_YAW_270": lambda x, y, z: (y, -x, z),
    "ROTATION_ROLL_180_YAW_90": lambda x, y, z: (y, x, -z),
    "ROTATION_PITCH_180": lambda x, y, z: (-x, y, -z),
    "ROTATION_ROLL_90": lambda x, y, z: (x, -z, y),
    "ROTATION_ROLL_270": lambda x, y, z: (x, z, -y),
    "ROTATION_PITCH_90": lambda x, y, z: (z, y, -x),
    "ROTATION_PITCH_270": lambda x, y, z: (-z, y, x),
    # roll 90 (y' = -z, z' = y) then pitch 90 (x' = z, z' = -x)
    "ROTATION_ROLL_90_PITCH_90": lambda x, y, z: (y, -z, -x),
    # roll 90 then yaw 270 (x' = y, y' = -x)
    "ROTATION_ROLL_90_YAW_270": lambda x, y, z: (-z, -x, y),
}


@pytest.mark.parametrize("name", sorted(AP_ROTATE))
def test_mounting_matrices_follow_ardupilot(name):
    v = np.array([0.3, -1.7, 2.9])
    assert np.allclose(mounting(name).matrix @ v, AP_ROTATE[name](*v))


def test_mounting_numbers_and_lookup():
    assert mounting("ROTATION_ROLL_90").number == 16
    assert mounting("yaw_270").number == 6
    assert mounting(37).name == "ROTATION_ROLL_90_YAW_270"
    for bad in ("ROTATION_YAW_45", "sideways", 1, 99, True):
        with pytest.raises(tc.CalibrationError):
            mounting(bad)
    m, ang = nearest_mounting(mounting(29).matrix @ tc.sim.rotvec_to_matrix([0.05, 0, 0]))
    assert m.number == 29 and ang == pytest.approx(math.degrees(0.05))


# --------------------------------------------------------------------------------------------
# simulation with a known rotation


def _sim(rot_mag_to_accel: np.ndarray, seed: int = 4):
    """Readings of a simulated IMU whose magnetometer frame is turned: v_accel = R v_mag."""
    imu = tc.sim.SimIMU(seed=seed)
    rec = imu.record(tc.sim.globe_script(hold_s=1.0, seed=seed), rate_hz=100)
    tr = imu.truth
    rng = np.random.default_rng(seed)
    field_mag_frame = rec.mag_ut @ rot_mag_to_accel  # R^T m per row
    raw_mag = np.rint(field_mag_frame @ np.linalg.inv(tr.mag.matrix).T + tr.mag.offset
                      + rng.normal(0, tr.mag.noise, field_mag_frame.shape))
    mag_fit = tc.fit_ellipsoid(raw_mag[rec.still][::4], model="full", radius=tr.field_ut)
    acc_fit = tc.fit_ellipsoid(rec.pose_means("accel"), model="full", radius=1.0)
    return rec, raw_mag, mag_fit, acc_fit


ARBITRARY = tc.sim.rotvec_to_matrix(np.radians([23.0, -41.0, 67.0]))
MOUNTED = mounting("ROTATION_ROLL_180_YAW_90").matrix @ tc.sim.rotvec_to_matrix(
    np.radians([0.8, -0.6, 0.9]))


@pytest.mark.parametrize("truth, mount", [(ARBITRARY, None),
                                          (MOUNTED, "ROTATION_ROLL_180_YAW_90")])
def test_alignment_recovered_on_simulated_data(truth, mount):
    rec, raw_mag, mag_fit, acc_fit = _sim(truth)
    al = tc.align_mag_accel(raw_mag, rec.accel, mag_cal=mag_fit, accel_cal=acc_fit,
                            expected_inclination_deg=rec.truth.inclination_deg)
    err = rotation_angle_deg(al.rotation, truth)
    assert err < 0.2, al.text()
    assert al.n_poses >= 70 and len(al.heldout_index) >= 15
    if mount is None:
        assert al.mounting is None and al.mounting_residual_deg > MAX_DEG_ARB
    else:
        assert al.mounting is not None and al.mounting.name == mount
        assert al.mounting_residual_deg == pytest.approx(rotation_angle_deg(truth, mounting(
            mount).matrix), abs=0.2)
    assert al.dip_deg == pytest.approx(rec.truth.inclination_deg, abs=0.2)
    assert al.dip_std_before_deg > 10 and al.dip_std_after_deg < 0.1
    assert al.dip_std_heldout_after_deg < 0.1
    assert np.all(al.stderr_deg < 0.1)
    # the heading error on the held-out poses, against the simulator's true attitude
    mid = [(lo + hi) // 2 for lo, hi in al.spans]
    truth_att = rec.orientation[mid][al.heldout_index]
    ho = al.heldout_index
    before = tc.heading_errors(al.accel[ho], al.mag[ho], truth_att)
    after = tc.heading_errors(al.accel[ho], al.mag[ho], truth_att, rotation=al.rotation)
    rms = lambda e: float(np.sqrt(np.mean(e**2)))  # noqa: E731
    assert rms(before) > 30 and rms(after) < 0.3 and np.abs(after).max() < 0.8
    assert 0.3 * rms(after) < al.heading_rms_est_deg < 3 * rms(after) + 0.05


MAX_DEG_ARB = 20.0


def test_turns_about_one_axis_leave_that_rotation_undetermined():
    rng = np.random.default_rng(2)
    yaw = rng.uniform(0, 2 * np.pi, 30)
    att = [tc.sim.rotvec_to_matrix([0, 0, y]) for y in yaw]  # level, turned about up only
    f = np.array([20.0, 0.0, -40.0])
    accel = np.array([a.T @ [0, 0, 1.0] for a in att]) + rng.normal(0, 1e-4, (30, 3))
    mag = np.array([a.T @ f for a in att]) + rng.normal(0, 0.02, (30, 3))
    al = tc.align_mag_accel(mag, accel, detect=False, holdout=0)
    assert al.stderr_deg[2] > 2 and any("about the accelerometer's z axis" in w
                                        for w in al.warnings)


def test_gravity_instead_of_specific_force_is_caught():
    rng = np.random.default_rng(5)
    att = [tc.sim.rotvec_to_matrix(v) for v in rng.normal(size=(20, 3))]
    f = np.array([20.0, 0.0, -40.0])
    accel = np.array([a.T @ [0, 0, 1.0] for a in att])
    mag = np.array([a.T @ f for a in att])
    ok = tc.align_mag_accel(mag, accel, detect=False, expected_inclination_deg=63.4)
    assert ok.dip_deg == pytest.approx(63.43, abs=0.01)
    with pytest.raises(tc.CalibrationError, match="gravity"):
        tc.align_mag_accel(mag, -accel, detect=False, expected_inclination_deg=63.4)


@pytest.mark.parametrize("mag, accel, kw, match", [
    (np.ones((10, 3)), np.ones((9, 3)), {}, "same instants"),
    (np.full((10, 3), np.nan), np.ones((10, 3)), {}, "finite"),
    (np.random.default_rng(0).normal(size=(5, 3)), np.random.default_rng(1).normal(size=(5, 3)),
     {"detect": False}, "at least 6"),
    (np.ones((10, 3)), np.ones((10, 3)), {"detect": False, "holdout": 0.9}, "holdout"),
    (np.zeros((10, 3)), np.ones((10, 3)), {"detect": False}, "zero length"),
])
def test_bad_alignment_inputs(mag, accel, kw, match):
    with pytest.raises(tc.CalibrationError, match=match):
        tc.align_mag_accel(mag, accel, **kw)


def test_axis_heading_conventions():
    up = np.array([[0, 0, 1.0]] * 4)
    # field north and down; body x pointing north, east, south, west
    yaws = np.radians([0, -90, 180, 90])  # counter-clockwise about up (world x north, y west)
    f_world = np.array([20.0, 0.0, -40.0])
    mag = np.array([tc.sim.rotvec_to_matrix([0, 0, y]).T @ f_world for y in yaws])
    np.testing.assert_allclose(tc.axis_heading(up, mag, axis=0), [0, 90, 180, 270], atol=1e-9)
    with pytest.raises(tc.CalibrationError, match="vertical"):
        tc.axis_heading(up[:1], [[0, 0, -40.0]])


# --------------------------------------------------------------------------------------------
# in the calibration file


def _part_with_alignment(rot: np.ndarray, mount: str | None) -> tc.SensorCalibration:
    al = tc.Alignment(rotation=rot, mounting=mount, stats={"dip_deg": 60.0})
    return tc.SensorCalibration(offset=[1, 2, 3], matrix=np.eye(3) * 0.1, unit="uT",
                                alignment=al)


def test_alignment_round_trips_and_applies():
    part = _part_with_alignment(MOUNTED, "ROTATION_ROLL_180_YAW_90")
    cal = tc.Calibration(mag=part)
    back = tc.Calibration.from_json(cal.to_json())
    assert back == cal and back.mag.alignment.mounting == "ROTATION_ROLL_180_YAW_90"
    assert back.mag.alignment.mounting_residual_deg == pytest.approx(
        rotation_angle_deg(MOUNTED, mounting(10).matrix))
    raw = np.array([[11.0, 2.0, 3.0]])
    np.testing.assert_allclose(back.mag.apply_aligned(raw), part.apply(raw) @ MOUNTED.T)
    with pytest.raises(tc.CalibrationError, match="no alignment"):
        back.mag.replace(alignment=None).apply_aligned(raw)


@pytest.mark.parametrize("change, match", [
    ({"rotation": [[1, 0, 0], [0, 1, 0], [0, 0, -1]]}, "proper rotation"),
    ({"rotation": [[1, 0.01, 0], [0, 1, 0], [0, 0, 1]]}, "proper rotation"),
    ({"rotation": [[1, 0], [0, 1]]}, "shape"),
    ({"mounting": "ROTATION_YAW_90"}, "disagree"),
    ({"mounting": "ROTATION_SIDEWAYS"}, "unknown mounting"),
    ({"mounting": 2}, "mounting must be text"),
    ({"to": "compass"}, "alignment.to"),
    ({"to": "mag"}, "to itself"),
    ({"colour": "red"}, "unknown field"),
    ({"stats": [1, 2]}, "JSON object"),
])
def test_alignment_in_the_file_is_validated(change, match):
    d = json.loads(tc.Calibration(mag=_part_with_alignment(np.eye(3), "ROTATION_NONE")).to_json())
    d["parts"]["mag"]["alignment"].update(change)
    with pytest.raises(tc.CalibrationError, match=match):
        tc.Calibration.from_dict(d)


# --------------------------------------------------------------------------------------------
# real recordings: MPU6050 + HMC5883L (sunsided/sensor-fusion, data set 1)

#: recordings turned about one horizontal body axis, which should keep its heading
HEADING_CHECKS = {"rotate-360ccw-around-x-pointing-forward": 0,
                  "rotate-360ccw-around-y-pointing-left": 1,
                  "tilt-around-x-pointing-forward": 0, "tilt-around-y-pointing-left": 1}


def _circstd_deg(h: np.ndarray) -> float:
    r = abs(np.mean(np.exp(1j * np.radians(h))))
    return float(np.degrees(np.sqrt(-2 * np.log(r))))


@pytest.fixture(scope="module")
def sunsided(realdata):
    from _realdata import load_sunsided

    def load(motion):
        a = load_sunsided(realdata, motion, "accelerometer")
        m = load_sunsided(realdata, motion, "compass")
        g = load_sunsided(realdata, motion, "gyroscope")
        acc = a[:, 1:].copy()
        acc[:, 0] *= -1  # the README: the MPU6050's x axis sign is flipped

        def onto(x):  # the compass (75 Hz) and gyro onto the accelerometer's times
            x = x[np.argsort(x[:, 0])]
            return np.column_stack([np.interp(a[:, 0], x[:, 0], x[:, k]) for k in (1, 2, 3)])

        gyr = onto(g)
        gyr[:, 0] *= -1
        keep = (a[:, 0] >= m[:, 0].min()) & (a[:, 0] <= m[:, 0].max())
        return acc[keep], onto(m)[keep], gyr[keep], m[:, 1:]

    motions = sorted(p.name for p in (realdata / "sunsided-mpu6050-hmc5883l").iterdir()
                     if p.is_dir())
    data = {mo: load(mo) for mo in motions}
    # accelerometer: still poses of every recording (1 g); magnetometer: the sphere tumble
    poses = np.array([p.mean for mo in motions for p in tc.detect_poses(
        data[mo][0], window=10, threshold=0.02, min_separation=0.0).poses])
    acc_fit = tc.fit_robust(poses, model="full", radius=1.0).fit
    mag_fit = tc.fit_robust(data["tilt-sphere"][3], model="full").fit
    # alignment: paired still poses of every recording not used for the heading check
    from triaxcal.methods.alignment import paired_still_poses

    pm, pa = [], []
    for mo in motions:
        if mo in HEADING_CHECKS:
            continue
        try:
            m, a, _ = paired_still_poses(mag_fit.apply(data[mo][1]), acc_fit.apply(data[mo][0]),
                                         window=10)
        except tc.CalibrationError:
            continue
        pm.append(m)
        pa.append(a)
    pm, pa = np.vstack(pm), np.vstack(pa)
    # poses in a disturbed field (|B| more than 5 % off) say nothing about the frames
    clean = np.abs(np.linalg.norm(pm, axis=1) / mag_fit.radius - 1) < 0.05
    al = tc.align_mag_accel(pm[clean], pa[clean], detect=False)
    return data, acc_fit, mag_fit, al


def test_sunsided_alignment_finds_the_mounting(sunsided):
    _, _, _, al = sunsided
    # the HMC5883L's frame is the MPU6050's rolled by 90 deg (y -> z), within a few degrees
    assert al.mounting is not None and al.mounting.name == "ROTATION_ROLL_90"
    assert al.mounting_residual_deg < 4
    assert al.dip_std_before_deg > 25 and al.dip_std_after_deg < 3
    assert al.dip_std_heldout_after_deg < 3
    # Germany 2013: inclination about 66-68 deg (the fit sees the local, disturbed field)
    assert 60 < al.dip_deg < 70


def test_sunsided_heading_before_and_after(sunsided):
    data, acc_fit, mag_fit, al = sunsided
    spread = {}
    for mo, axis in HEADING_CHECKS.items():
        acc, mag, gyr, _ = data[mo]
        ca, cm = acc_fit.apply(acc), mag_fit.apply(mag)
        # quasi-static samples: |a| within 3 % of 1 g, turning slower than 30 deg/s
        q = (np.abs(np.linalg.norm(ca, axis=1) - 1) < 0.03) & (np.linalg.norm(gyr, axis=1) < 30)
        assert q.sum() > 200
        spread[mo] = (
            _circstd_deg(tc.axis_heading(acc[q], mag[q], axis=axis)),
            _circstd_deg(tc.axis_heading(ca[q], cm[q], axis=axis)),
            _circstd_deg(tc.axis_heading(ca[q], cm[q], axis=axis, rotation=al.rotation)),
        )
    for mo in ("rotate-360ccw-around-y-pointing-left", "tilt-around-y-pointing-left"):
        raw, cal, aligned = spread[mo]
        assert raw > 30 and cal > 30 and aligned < 0.35 * raw and aligned < 12, spread
    for mo in ("rotate-360ccw-around-x-pointing-forward", "tilt-around-x-pointing-forward"):
        # a roll about x keeps x where the ROLL_90 mounting leaves it: small either way
        assert max(spread[mo]) < 8, spread
