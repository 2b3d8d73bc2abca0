"""The simulated IMU: the true calibration recovers physical values; scripts do what they say."""

from __future__ import annotations

import math

import numpy as np
import pytest
import triaxcal as tc
from hypothesis import given, settings
from hypothesis import strategies as st
from triaxcal import sim


@pytest.fixture(scope="module")
def globe():
    imu = sim.SimIMU(seed=7)
    return imu, imu.record(sim.globe_script(hold_s=0.5), rate_hz=100)


def test_globe_has_84_poses_and_covers_the_sphere(globe):
    _, rec = globe
    assert len(rec.script) == 84
    assert set(np.unique(rec.pose[rec.pose >= 0])) == set(range(84))
    up = np.array([r.T @ [0, 0, 1] for r in rec.script.poses])  # 'up' in the body frame
    # every octant of the body sphere is visited
    octants = {tuple(np.sign(u + 1e-9).astype(int)) for u in up}
    assert len(octants) == 8
    # both poles, 12 twists each (same gravity, different heading)
    assert (up[:, 2] > 0.99).sum() == 12 and (up[:, 2] < -0.99).sum() == 12


@pytest.mark.parametrize("sensor,magnitude", [("accel", 1.0), ("mag", None)])
def test_true_calibration_gives_constant_magnitude(globe, sensor, magnitude):
    imu, rec = globe
    truth = imu.truth.sensor(sensor)
    expected = magnitude if magnitude is not None else imu.truth.field_ut
    values = truth.apply(getattr(rec, sensor)[rec.still])
    norm = np.linalg.norm(values, axis=1)
    noise = truth.noise * np.abs(truth.matrix).max() * 1.2  # one axis' noise in units
    assert abs(norm.mean() - expected) < 0.2 * noise
    assert norm.std() < 2.5 * noise
    # and the recovered vectors are the true body-frame vectors, sample by sample
    true = getattr(rec, f"{sensor}_g" if sensor == "accel" else "mag_ut")[rec.still]
    assert np.sqrt(((values - true) ** 2).mean()) < 1.5 * noise


def test_gyro_still_reads_offset_and_moving_reads_rate(globe):
    imu, rec = globe
    g = imu.truth.gyro
    still = rec.gyro[rec.still]
    tol = 4 * g.noise / math.sqrt(len(still)) + 0.05
    np.testing.assert_allclose(still.mean(axis=0), g.offset, atol=tol)
    rate = g.apply(rec.gyro)
    err = rate - rec.gyro_rad_s
    assert np.sqrt((err**2).mean()) < 1.5 * g.noise * np.abs(g.matrix).max()


def test_integrating_true_gyro_rate_gives_each_move():
    s = sim.globe_script(hold_s=0.2, latitudes=3, turns=4)
    rec = sim.SimIMU(seed=1).record(s, rate_hz=400)
    dt = 1 / rec.rate_hz
    for j in range(1, len(s)):
        sel = np.arange(len(rec))
        start = np.where(rec.pose == j - 1)[0][-1]
        end = np.where(rec.pose == j)[0][0]
        rot = np.eye(3)
        for w in rec.gyro_rad_s[(sel > start) & (sel <= end)]:
            rot = rot @ sim.rotvec_to_matrix(w * dt)
        want = s.poses[j - 1].T @ s.poses[j]
        err = np.degrees(np.linalg.norm(sim.matrix_to_rotvec(rot.T @ want)))
        assert err < 0.05, (j, err)


def test_rotation_script_turns_both_ways_about_each_axis():
    s = sim.rotation_script("xyz", 360.0)
    rec = sim.SimIMU(seed=2).record(s, rate_hz=200)
    dt = 1 / rec.rate_hz
    # 6 turns: +x, -x, +y, -y, +z, -z; the integrated true rate is +-360 deg on one axis
    turns = []
    for j in range(1, len(s)):
        sel = (np.arange(len(rec)) > np.where(rec.pose == j - 1)[0][-1]) & (
            np.arange(len(rec)) <= np.where(rec.pose == j)[0][0]
        )
        turns.append(np.degrees(rec.gyro_rad_s[sel].sum(axis=0) * dt))
    turns = np.array(turns)
    want = np.array(
        [[360, 0, 0], [-360, 0, 0], [0, 360, 0], [0, -360, 0], [0, 0, 360], [0, 0, -360]]
    )
    np.testing.assert_allclose(turns, want, atol=0.5)
    # peak rate stays inside the +-250 deg/s range and counts inside int16
    assert np.degrees(np.abs(rec.gyro_rad_s)).max() < 250
    assert np.abs(rec.gyro).max() < 32767


def test_six_faces_point_each_axis_up_and_down():
    s = sim.six_face_script(jitter_deg=0.0)
    up = np.array([r.T @ [0, 0, 1] for r in s.poses])
    np.testing.assert_allclose(np.abs(up).max(axis=1), 1.0, atol=1e-9)
    np.testing.assert_allclose(up.sum(axis=0), 0.0, atol=1e-9)


def test_temperature_ramp_drifts_offsets_as_the_truth_says():
    imu = sim.SimIMU(seed=4, gyro={"tempco": (5.0, -3.0, 2.0), "noise": 2.0})
    s = sim.six_face_script(hold_s=20.0)
    rec = imu.record(s, rate_hz=50, temp_c=(10.0, 50.0))
    assert rec.temp_c[0] == pytest.approx(10.0) and rec.temp_c[-1] == pytest.approx(50.0)
    np.testing.assert_allclose(sim.temp_c_from_raw(rec.temp_raw), rec.temp_c, atol=0.1)
    still = rec.still
    slope = np.polyfit(rec.temp_c[still], rec.gyro[still], 1)[0]
    np.testing.assert_allclose(slope, [5.0, -3.0, 2.0], atol=0.1)
    # the temperature-aware true calibration removes the drift
    rate = imu.truth.gyro.apply(rec.gyro[still], rec.temp_c[still])
    assert np.abs(rate.mean(axis=0)).max() < 1e-4  # rad/s


def test_gain_tempco_and_overrides():
    imu = sim.SimIMU(
        seed=5, accel={"offset": (10, 10, 2570), "scale": (1.0, 1.0, 1.0), "noise": 0,
                       "gain_tempco": 1e-3}
    )
    a = imu.truth.accel
    np.testing.assert_array_equal(a.offset, [10, 10, 2570])
    np.testing.assert_allclose(a.matrix, np.eye(3) / 16384)
    rec = imu.record(sim.six_face_script(jitter_deg=0.0), rate_hz=20, temp_c=(25.0, 45.0))
    g = a.apply(rec.accel[rec.still], rec.temp_c[rec.still])
    np.testing.assert_allclose(np.linalg.norm(g, axis=1), 1.0, atol=2e-4)
    # matrix_at / offset_at
    np.testing.assert_allclose(a.matrix_at(35.0), a.matrix * 1.01)


def test_fit_recovers_truth_from_pose_means(globe):
    imu, rec = globe
    fit = tc.fit_ellipsoid(rec.pose_means("accel"), model="full", radius=1.0)
    a = imu.truth.accel
    err = np.abs(fit.offset - a.offset)
    assert (err < 5 * fit.stderr[:3] + 1.0).all(), (fit.offset, a.offset, fit.stderr[:3])
    np.testing.assert_allclose(fit.matrix, a.matrix, atol=5e-4 / 16384 * 5)


def test_frames_channel_order_and_bad_options():
    rec = sim.SimIMU(seed=0).record(sim.six_face_script(hold_s=0.2, settle_s=0.0), rate_hz=20)
    f = rec.frames(10)
    assert f.shape == (len(rec), 10)
    np.testing.assert_array_equal(f[:, 3:6], rec.gyro)
    np.testing.assert_array_equal(f[:, 9], rec.temp_raw)
    np.testing.assert_array_equal(rec.frames(7)[:, 6], rec.temp_raw)
    with pytest.raises(tc.CalibrationError, match="channels"):
        rec.frames(5)
    with pytest.raises(tc.CalibrationError, match="symmetric"):
        sim.SimIMU(mag={"matrix": [[1, 0.1, 0], [0, 1, 0], [0, 0, 1]]})
    with pytest.raises(tc.CalibrationError, match="unknown"):
        sim.SimIMU(gyro={"bias": 3})


def test_same_seed_same_data():
    a = sim.SimIMU(seed=9).record(sim.six_face_script(hold_s=0.3), rate_hz=50)
    b = sim.SimIMU(seed=9).record(sim.six_face_script(hold_s=0.3), rate_hz=50)
    np.testing.assert_array_equal(a.frames(), b.frames())


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    offset=st.tuples(*[st.floats(-3000, 3000)] * 3),
    diag=st.tuples(*[st.floats(0.9, 1.1)] * 3),
    off=st.tuples(*[st.floats(-0.03, 0.03)] * 3),
)
def test_true_calibration_inverts_any_truth(seed, offset, diag, off):
    scale = np.array([[diag[0], off[0], off[1]], [off[0], diag[1], off[2]],
                      [off[1], off[2], diag[2]]])
    imu = sim.SimIMU(seed, accel={"offset": offset, "scale": scale, "noise": 20.0})
    rec = imu.record(sim.six_face_script(hold_s=0.3, settle_s=0.0, seed=seed), rate_hz=100)
    g = imu.truth.accel.apply(rec.accel[rec.still])
    # per sample: the true specific force back, within the noise (20 counts ~ 1.2 mg per axis)
    err = np.abs(g - rec.accel_g[rec.still]).max()
    assert err < 6 * 20 / 16384 * 1.2
    assert abs(np.linalg.norm(g, axis=1).mean() - 1.0) < 1e-3
