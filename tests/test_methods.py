"""Tilt rig, six-position min/max and the Ferraris closed form, on the seeds' and real data."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
import triaxcal as tc
from _realdata import load_ferraris_annotated, load_ferraris_session
from triaxcal.sim import SimIMU, six_face_script

# The tilt-rig seed write-up (tilt-rig-gravity-calibration.txt): its published coefficients and
# formula a = g * (s + o), its twelve real samples (raw temperature, temperature in degC,
# accelerometer x y z in g, gyro x y z) at 10 degree tilts fore down (FD), aft down (AD), left
# down (LD) and right down (RD), and the 24 norms it printed as its sanity check, as printed.
SEED_OFFSET = np.array([0.007894833, 0.009969, 0.000359667])
SEED_GAIN = np.array([1.28560825, 1.333382476, 0.936797208])
SEED_SAMPLES = """
FD
-4011, 24.732941, -0.142926, 0.012745, 1.050931, -0.053121, 0.025203, -0.000613
-4003, 24.756471, -0.142944, 0.012847, 1.050797, -0.053175, 0.025116, -0.000586
-4007, 24.744706, -0.143027, 0.012854, 1.050942, -0.053439, 0.025573, -0.000224
AD
-4269, 23.974118, 0.158685, 0.007537, 1.050188, -0.051737, 0.025540, -0.000832
-4280, 23.941765, 0.158802, 0.007494, 1.050043, -0.051684, 0.025404, -0.000848
-4269, 23.974118, 0.158779, 0.007461, 1.050281, -0.052030, 0.025653, -0.000663
LD
-4119, 24.415294, 0.005269, -0.140297, 1.050463, -0.052647, 0.025136, -0.000694
-4105, 24.456471, 0.005559, -0.139865, 1.050735, -0.052635, 0.025112, -0.000635
-4117, 24.421176, 0.005273, -0.140439, 1.050992, -0.052608, 0.025244, -0.000740
RD
-4057, 24.597647, 0.010099, 0.160093, 1.050826, -0.052801, 0.025332, -0.000706
-4046, 24.630000, 0.009812, 0.160029, 1.050554, -0.053320, 0.025580, -0.000406
-4055, 24.603529, 0.009934, 0.160293, 1.051040, -0.053330, 0.025560, -0.000511
"""
SEED_NORMS = """
1.006204657	1.007968538
1.005967585	1.007731109
1.006276408	1.008040318
1.004816622	1.006578528
1.004608175	1.006369695
1.005035531	1.006797684
1.007888677	1.009651313
1.008157198	1.009920557
1.008939806	1.010703849
1.008478641	1.010242242
1.007941093	1.009703971
1.008978921	1.010743092
"""


def _seed_samples() -> dict[str, np.ndarray]:
    """The twelve real samples of the tilt-rig seed: {FD, AD, LD, RD: (3, 8) rows}."""
    out: dict[str, list] = {}
    cur = None
    for line in SEED_SAMPLES.splitlines():
        s = line.strip()
        if s in ("FD", "AD", "LD", "RD"):
            cur = s
            out[cur] = []
        elif cur and re.match(r"^-?\d+, ", s):
            out[cur].append([float(v) for v in s.split(",")])
    return {k: np.array(v) for k, v in out.items()}


def _seed_published_norms() -> np.ndarray:
    rows = re.findall(r"^\s*(1\.0\d+)\s+(1\.0\d+)\s*$", SEED_NORMS, flags=re.MULTILINE)
    return np.array(rows, dtype=float).reshape(-1)


def test_tilt_rig_on_the_seed_samples():
    d = _seed_samples()
    assert {k: v.shape for k, v in d.items()} == {k: (3, 8) for k in ("FD", "AD", "LD", "RD")}
    acc = {k: v[:, 2:5] for k, v in d.items()}  # columns: raw temp, temp, ax ay az (g), gyro
    rig = tc.tilt_rig({"fore_down": acc["FD"], "aft_down": acc["AD"], "left_down": acc["LD"],
                       "right_down": acc["RD"]}, angle_deg=10.0)
    # same offsets as the seed (that part of its algebra is right) ...
    np.testing.assert_allclose(rig.offset[:2], SEED_OFFSET[:2], rtol=1e-6)
    # ... but gain = sin(theta) / (s - o), not / (s + o): about 11-13 % lower
    assert np.all(rig.gain[:2] < 0.9 * SEED_GAIN[:2])
    assert abs(rig.gain_z_pairs[0] - rig.gain_z_pairs[1]) < 1e-3
    everything = np.vstack(list(acc.values()))
    mine = np.abs(np.linalg.norm(rig.apply(everything), axis=1) - 1)
    seeds = np.abs(np.linalg.norm((everything + SEED_OFFSET) * SEED_GAIN, axis=1) - 1)
    published = np.abs(_seed_published_norms() - 1)
    assert published.size == 24 and published.min() > 0.004
    assert mine.max() < 1e-3
    assert mine.max() < seeds.max() and mine.mean() < seeds.mean() / 5
    assert mine.max() < published.min()
    # the data imply a tilt of about 8.2 deg, not the stated 10 (under equal gains)
    np.testing.assert_allclose(rig.implied_angle_deg, 8.15, atol=0.1)
    np.testing.assert_allclose(rig.angle_error_deg, rig.implied_angle_deg - 10.0)


def test_tilt_rig_recovers_a_known_sensor_and_angle():
    th = math.radians(12.0)
    off = np.array([0.02, -0.03, 0.0])
    gain = np.array([1.05, 0.97, 1.02])  # calibrated = (raw - off) * gain
    def raw(v):
        return np.asarray(v) / gain + off
    r = tc.tilt_rig({"fore_down": raw([-math.sin(th), 0, math.cos(th)]),
                     "aft_down": raw([math.sin(th), 0, math.cos(th)]),
                     "left_down": raw([0, -math.sin(th), math.cos(th)]),
                     "right_down": raw([0, math.sin(th), math.cos(th)])}, angle_deg=12.0)
    np.testing.assert_allclose(r.offset, off, atol=1e-12)
    np.testing.assert_allclose(r.gain, gain, rtol=1e-12)
    with pytest.raises(tc.CalibrationError, match="missing: left_down, right_down"):
        tc.tilt_rig({"fore_down": [0, 0, 1], "aft_down": [0.1, 0, 1]}, angle_deg=10)
    with pytest.raises(tc.CalibrationError, match="not tilted"):
        tc.tilt_rig({k: [0, 0, 1.0] for k in ("fore_down", "aft_down", "left_down",
                                              "right_down")}, angle_deg=10)
    with pytest.raises(tc.CalibrationError, match="angle_deg"):
        tc.tilt_rig({}, angle_deg=0)


def test_six_position_min_max_on_the_simulator():
    imu = SimIMU(7, accel={"scale": [1.02, 0.97, 1.01]})
    rec = imu.record(six_face_script(jitter_deg=0.5), rate_hz=100)
    det = tc.detect_poses(rec.accel, units_per_g=16384)
    six = tc.six_position(det.points)
    assert sorted(six.faces) == ["+x", "+y", "+z", "-x", "-y", "-z"]
    truth = imu.truth.accel
    np.testing.assert_allclose(six.offset, truth.offset, atol=0.003 * 16384)
    true_cpg = 1 / np.diag(truth.matrix)
    np.testing.assert_allclose(six.counts_per_g, true_cpg, rtol=0.005)
    np.testing.assert_allclose(np.diag(six.matrix) * six.counts_per_g, 1.0)
    g = np.linalg.norm(six.apply(det.points), axis=1)
    np.testing.assert_allclose(g, 1.0, atol=0.01)


def test_six_position_names_missing_faces():
    pts = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, -1], [0.7, 0.7, 0]])
    with pytest.raises(tc.CalibrationError, match=r"-y \(y axis pointing down\)"):
        tc.six_position(pts * 16384)
    with pytest.raises(tc.CalibrationError, match="six faces"):
        tc.six_position(pts[:3])
    with pytest.raises(tc.CalibrationError, match="NaN"):
        tc.six_position(np.full((6, 3), np.nan))


def test_ferraris_on_the_imucal_annotated_session(realdata):
    parts = load_ferraris_annotated(realdata)
    fer = tc.ferraris(parts, rate_hz=204.8, gravity=9.81)
    # a +-16 g accelerometer (2048 counts/g) and a +-2000 deg/s gyro (16.4 counts per deg/s)
    np.testing.assert_allclose(fer.accel_counts_per_g, 2048, rtol=0.04)
    np.testing.assert_allclose(fer.gyro_counts_per_dps, 16.4, rtol=0.03)
    # calibrated faces: up minus down is exactly 2 g along the axis, |g| within 2 mm/s^2
    cal = {k: fer.accel.apply(parts[k][0]).mean(axis=0) for k in parts if not k.endswith("rot")}
    for a, i in zip("xyz", range(3)):
        np.testing.assert_allclose(cal[a + "_p"] - cal[a + "_a"], 2 * 9.81 * np.eye(3)[i],
                                   atol=1e-9)
        assert abs(np.linalg.norm(cal[a + "_p"]) - 9.81) < 0.002
    # each 360 deg turn integrates to 360 deg about its own axis after calibration
    for a, i in zip("xyz", range(3)):
        acc, gyr = parts[a + "_rot"]
        w = np.degrees(fer.apply_gyro(gyr, acc)).sum(axis=0) / 204.8
        assert abs(abs(w[i]) - 360) < 1e-6 and np.all(np.abs(np.delete(w, i)) < 1e-6)
    # per-axis gains by integration agree with the closed form
    gains = []
    for a, i in zip("xyz", range(3)):
        gyr = parts[a + "_rot"][1] - fer.gyro.offset
        gains.append(abs(gyr.sum(axis=0)[i]) / 204.8 / 360)
    np.testing.assert_allclose(gains, np.abs(np.diag(np.linalg.inv(fer.gyro.matrix)))
                               * math.pi / 180, rtol=0.03)


def _imucal_ferraris(parts, rate_hz, expected_angle):
    """imucal's FerrarisCalibration on the same sections (the reference implementation)."""
    imucal = pytest.importorskip("imucal")  # in the test extra (imucal supports Python < 3.14)
    import pandas as pd

    cols = ["acc_x", "acc_y", "acc_z", "gyr_x", "gyr_y", "gyr_z"]
    frames = [pd.DataFrame(np.hstack(parts[k]), columns=cols, index=pd.Index([k] * len(parts[k][0]),
                                                                           name="part"))
              for k in parts]
    regions = imucal.ferraris_regions_from_df(pd.concat(frames))
    cal = imucal.FerrarisCalibration(grav=9.81, expected_angle=expected_angle)
    return cal.compute(regions, rate_hz, from_acc_unit="a.u.", from_gyr_unit="a.u.")


def _ferraris_sessions(realdata):
    acc, gyr, sec = load_ferraris_session(realdata)
    cont = {k: (acc[a:b], gyr[a:b]) for k, (a, b) in sec.items()}
    return {"annotated": (load_ferraris_annotated(realdata), 204.8), "continuous": (cont, 102.4)}


@pytest.mark.parametrize("session", ["annotated", "continuous"])
def test_ferraris_equals_imucal(realdata, session):
    parts, rate = _ferraris_sessions(realdata)[session]
    fer = tc.ferraris(parts, rate_hz=rate, gravity=9.81)
    # imucal takes the turning sense as the sign of expected_angle; ours reads it from the data
    assert len(set(fer.rotation_sign.tolist())) == 1
    ref = _imucal_ferraris(parts, rate, expected_angle=360.0 * fer.rotation_sign[0])
    # offsets and matrices, with the name mapping of triaxcal.methods.static's notes
    np.testing.assert_allclose(fer.accel.offset, ref.b_a, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(fer.accel.matrix, np.linalg.inv(ref.R_a) @ np.linalg.inv(ref.K_a),
                               rtol=1e-10)
    np.testing.assert_allclose(np.linalg.inv(fer.accel.matrix), ref.K_a @ ref.R_a, rtol=1e-10)
    np.testing.assert_allclose(fer.accel_counts_per_g / 9.81, np.diag(ref.K_a), rtol=1e-12)
    np.testing.assert_allclose(fer.gyro.offset, ref.b_g, rtol=1e-12)
    np.testing.assert_allclose(fer.g_sensitivity, ref.K_ga, rtol=1e-12)
    np.testing.assert_allclose(fer.gyro.matrix * 180 / math.pi,
                               np.linalg.inv(ref.R_g) @ np.linalg.inv(ref.K_g), rtol=1e-10)
    np.testing.assert_allclose(fer.gyro_counts_per_dps, np.diag(ref.K_g), rtol=1e-10)
    # the first calibrated rows of every section: imucal's acc in m/s^2, gyro in deg/s
    for acc, gyr in parts.values():
        a_ref, g_ref = ref.calibrate(acc[:50], gyr[:50], acc_unit="a.u.", gyr_unit="a.u.")
        np.testing.assert_allclose(fer.accel.apply(acc[:50]), a_ref, rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(np.degrees(fer.apply_gyro(gyr[:50], acc[:50])), g_ref,
                                   rtol=1e-9, atol=1e-9)
    # the six static poses calibrated with it have |g| = 9.81 within 2 mm/s^2 (they missed by
    # up to 37 mm/s^2 with the old offset, the mean of all six poses)
    for k in ("x_p", "x_a", "y_p", "y_a", "z_p", "z_a"):
        assert abs(np.linalg.norm(fer.accel.apply(parts[k][0]).mean(axis=0)) - 9.81) < 0.002


def test_ferraris_names_missing_sections(realdata):
    parts = load_ferraris_annotated(realdata)
    part = {k: v for k, v in parts.items() if k not in ("y_a", "z_rot")}
    msg = "static poses missing: y_a; rotations missing: z_rot"
    with pytest.raises(tc.CalibrationError, match=msg):
        tc.ferraris(part, rate_hz=204.8)
    small = dict(parts)
    small["y_rot"] = (parts["y_rot"][0][:40], parts["y_rot"][1][:40])
    with pytest.raises(tc.CalibrationError, match="rotations too small in y_rot"):
        tc.ferraris(small, rate_hz=204.8)


def test_six_position_agrees_with_ferraris_on_real_faces(realdata):
    parts = load_ferraris_annotated(realdata)
    faces = np.array([parts[k][0].mean(axis=0) for k in ("x_p", "x_a", "y_p", "y_a", "z_p",
                                                          "z_a")])
    six = tc.six_position(faces, gravity=9.81)
    fer = tc.ferraris(parts, rate_hz=204.8, gravity=9.81)
    assert six.faces == {"+x": 0, "-x": 1, "+y": 2, "-y": 3, "+z": 4, "-z": 5}
    # min/max sees the diagonal of Ferraris' sensitivity; cross-axis terms are a few per mille
    a_mat = np.linalg.inv(fer.accel.matrix) * 9.81  # counts per g
    np.testing.assert_allclose(six.counts_per_g, np.diag(a_mat), rtol=1e-9)
    np.testing.assert_allclose(six.counts_per_g, fer.accel_counts_per_g, rtol=0.005)
    # offsets: both are the per-axis midpoint of the two faces with that axis vertical
    np.testing.assert_allclose(six.offset, fer.accel.offset, atol=1e-9)


def test_docstrings_run():
    import doctest

    import triaxcal.methods.static as mod

    assert doctest.testmod(mod, raise_on_error=True).attempted > 0
