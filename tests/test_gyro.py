"""Gyro calibration: bias, gains from integrated rotations, turntable fits (sim + real data)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import triaxcal as tc
from _realdata import load_ferraris_session, load_gearvr, load_sunsided
from triaxcal.methods import gyro as tg
from triaxcal.sim import Script, SimIMU, rotation_script

RPM33 = 2 * math.pi * (100 / 3) / 60  # rad/s
RPM45 = 2 * math.pi * 45 / 60


def _sim_rotations(seed=3, angle=360.0, axes="xyz", rate=200.0):
    imu = SimIMU(seed)
    rec = imu.record(rotation_script(axes, angle, hold_s=1.5, settle_s=3.0), rate_hz=rate)
    return imu, rec


def test_gains_per_axis_and_direction_recover_the_simulator():
    imu, rec = _sim_rotations()
    res = tc.gyro_gains(rec.gyro, angle_deg=360, t=rec.t, rest_s=3.0)
    inv = np.linalg.inv(imu.truth.gyro.matrix)  # counts per rad/s
    true_gain = np.diag(inv) * math.pi / 180  # counts per deg/s
    np.testing.assert_allclose(res.gain_counts_per_dps, true_gain, rtol=2e-3)
    np.testing.assert_allclose(res.gain_ccw_counts_per_dps, true_gain, rtol=3e-3)
    np.testing.assert_allclose(res.gain_cw_counts_per_dps, true_gain, rtol=3e-3)
    np.testing.assert_allclose(res.scale_dps_per_count, 1 / res.gain_counts_per_dps)
    assert res.missing == ()
    assert sorted(r.label for r in res.rotations) == sorted(
        f"{a} {d}" for a in "xyz" for d in ("ccw", "cw"))
    np.testing.assert_allclose(res.offset, imu.truth.gyro.offset, atol=1.0)
    # calibrated rates in deg/s: the integral of each turn is 360 deg
    dps = res.apply(rec.gyro)
    cum = tg.integrate_rate(dps, rec.t)
    for r in res.rotations:
        assert abs(abs(cum[r.end - 1, r.axis] - cum[r.start, r.axis]) - 360) < 1.0


def test_missing_axis_and_direction_are_named():
    _, rec = _sim_rotations(axes="xy", angle=90.0)
    with pytest.raises(tc.CalibrationError, match="about z"):
        tc.gyro_gains(rec.gyro, angle_deg=90, rate_hz=rec.rate_hz)
    imu = SimIMU(4)
    one_way = imu.record(rotation_script("xyz", 90.0).__class__.from_moves(
        np.eye(3), np.array([[math.pi / 2, 0, 0], [0, math.pi / 2, 0], [0, 0, math.pi / 2]]),
        hold_s=np.array([4.0, 1.5, 1.5, 1.5])), rate_hz=100)
    res = tc.gyro_gains(one_way.gyro, angle_deg=90, rate_hz=100)
    assert res.missing == ("x cw", "y cw", "z cw")
    assert np.isnan(res.gain_cw_counts_per_dps).all() and np.isfinite(res.gain_counts_per_dps).all()
    with pytest.raises(tc.CalibrationError, match="rotations missing: x cw, y cw, z cw"):
        tc.gyro_gains(one_way.gyro, angle_deg=90, rate_hz=100, require_both_directions=True)


def test_unusable_input_is_rejected():
    rng = np.random.default_rng(0)
    still = rng.normal(0, 3, (3000, 3))
    with pytest.raises(tc.CalibrationError, match="still period"):
        tc.gyro_gains(still, angle_deg=90, rate_hz=100)
    with pytest.raises(tc.CalibrationError, match="NaN"):
        tc.gyro_gains(np.full((10, 3), np.nan), angle_deg=90, rate_hz=100)
    with pytest.raises(tc.CalibrationError, match="shape"):
        tc.gyro_bias(np.zeros((10, 2)))
    with pytest.raises(tc.CalibrationError, match="rate_hz"):
        tc.find_rotations(still)
    with pytest.raises(tc.CalibrationError, match="angle_deg"):
        tc.gyro_gains(still, angle_deg=0, rate_hz=100)
    # tiny wiggles between rests: too small for a 90 deg calibration
    x = rng.normal(0, 3, (6000, 3))
    for k, a in enumerate(range(1000, 6000, 1000)):
        x[a:a + 50, k % 3] += 300 * (1 + k) * np.sin(np.linspace(0, np.pi, 50))  # 10-50 deg
    with pytest.raises(tc.CalibrationError, match="rotations are missing.*rotation too small"):
        tc.gyro_gains(x, angle_deg=90, rate_hz=100, nominal_counts_per_dps=131.0)
    ok = tc.gyro_gains(x, angle_deg=90, rate_hz=100)  # without a nominal gain: judged relatively
    assert len(ok.rotations) >= 3


def test_ferraris_session_rotations(realdata):
    """imucal's session (gyro already in deg/s): three 360 deg turns, gains near 1."""
    _, gyr, sec = load_ferraris_session(realdata)
    res = tc.gyro_gains(gyr, angle_deg=360, rate_hz=102.4)
    labels = {r.label for r in res.rotations}
    assert labels == {"x cw", "y cw", "z cw"}
    for r in res.rotations:  # each found turn lies on the annotated section
        name = "xyz"[r.axis] + "_rot"
        a, b = sec[name]
        assert r.start <= a + 30 and r.end >= b - 30
    np.testing.assert_allclose(res.gain_counts_per_dps, 1.0, atol=0.04)
    # the face changes (90 and 180 deg turns) were seen and rejected with reasons
    assert {r.reason for r in res.rejected} >= {tg.TOO_SMALL}


def test_sunsided_ccw_turns_show_the_flipped_x_axis(realdata):
    """Two hand-made 360 deg ccw turns about each axis; the author says X is sign-flipped.

    The turn recordings have no rest, so the bias comes from the 'unmoved' recording.
    """
    rest = tc.gyro_bias(load_sunsided(realdata, "unmoved-x-pointing-forward", "gyroscope")[:, 1:])
    assert rest.n > 6000 and np.all(rest.std < 0.2)  # deg/s
    dirs = {}
    for axis, folder in (("x", "rotate-360ccw-around-x-pointing-forward"),
                         ("y", "rotate-360ccw-around-y-pointing-left"),
                         ("z", "rotate-360ccw-around-z-pointing-up")):
        g = load_sunsided(realdata, folder, "gyroscope")
        t, w = g[:, 0], g[:, 1:]
        cum = tg.integrate_rate(w - rest.offset, t)
        k = "xyz".index(axis)
        total = cum[-1]
        assert abs(total[k]) / np.linalg.norm(total) > 0.98
        dirs[axis] = "ccw" if total[k] > 0 else "cw"
        # two turns by hand: 720 deg (the gyro is in deg/s: nominal gain 1 count per deg/s)
        assert abs(abs(total[k]) / 720 - 1) < 0.005
    assert dirs == {"x": "cw", "y": "ccw", "z": "ccw"}


SUNSIDED_TURNS = (("x", "rotate-360ccw-around-x-pointing-forward"),
                  ("y", "rotate-360ccw-around-y-pointing-left"),
                  ("z", "rotate-360ccw-around-z-pointing-up"))


def test_sunsided_two_turns_give_gains_through_gyro_gains(realdata):
    """Two 360 deg turns in a row, no rest at either end: integrate the whole recording.

    The recorder already scaled the MPU-6050 to deg/s (the folder's README), so the nominal
    gain is 1 count per deg/s; the bias comes from the 'unmoved' recording of the same board.
    """
    rest = tc.gyro_bias(load_sunsided(realdata, "unmoved-x-pointing-forward", "gyroscope")[:, 1:])
    gains = {}
    for axis, folder in SUNSIDED_TURNS:
        g = load_sunsided(realdata, folder, "gyroscope")
        t, w = g[:, 0], g[:, 1:]
        # the detector finds no real pause between (or around) the turns: refused
        with pytest.raises(tc.CalibrationError, match="still period|no rotation of about 720"):
            tc.gyro_gains(w, angle_deg=720, t=t, axes=axis)
        res = tc.gyro_gains(w, angle_deg=720, t=t, offset=rest.offset, turns=[(0, len(w))],
                            axes=axis)
        k = "xyz".index(axis)
        (rot,) = res.rotations
        assert (rot.start, rot.end, rot.axis) == (0, len(w), k) and rot.purity > 0.98
        assert np.isnan(np.delete(res.gain_counts_per_dps, k)).all()
        gains[axis] = (rot.direction, res.gain_counts_per_dps[k])
    # x is sign-flipped on this board (the author's caveat): the ccw turns read as cw
    assert {a: d for a, (d, _) in gains.items()} == {"x": "cw", "y": "ccw", "z": "ccw"}
    # 1.0009, 1.0024, 1.0023 counts per deg/s: within 0.3 % of the nominal 1
    g = np.array([v for _, v in gains.values()])
    np.testing.assert_allclose(g, 1.0, atol=3e-3)


def test_whole_turn_between_a_rest_at_each_end():
    """Two 360 deg turns about z with a pause between them: per gap or as one 720 deg turn."""
    imu = SimIMU(3)
    script = Script.from_moves(np.eye(3), [[0, 0, 2 * math.pi], [0, 0, 2 * math.pi]],
                               hold_s=[4.0, 1.5, 2.0])
    rec = imu.record(script, rate_hz=200)
    true_z = np.linalg.inv(imu.truth.gyro.matrix)[2, 2] * math.pi / 180  # counts per deg/s
    each = tc.gyro_gains(rec.gyro, angle_deg=360, t=rec.t, axes="z")
    assert [r.label for r in each.rotations] == ["z ccw", "z ccw"]
    whole = tc.gyro_gains(rec.gyro, angle_deg=720, t=rec.t, axes="z", turns="whole")
    (rot,) = whole.rotations
    assert rot.start < each.rotations[0].start + 5 and rot.end > each.rotations[1].end - 5
    assert abs(whole.gain_counts_per_dps[2] / true_z - 1) < 1e-3
    assert abs(each.gain_counts_per_dps[2] / true_z - 1) < 1e-3
    # the same turn given as an explicit interval, with the offset from the detected rests
    expl = tc.gyro_gains(rec.gyro, angle_deg=720, t=rec.t, axes="z",
                         turns=[(rot.start, rot.end)])
    assert expl.gain_counts_per_dps[2] == pytest.approx(whole.gain_counts_per_dps[2], rel=1e-9)


def test_time_stamps_in_bursts():
    """A logger that stamps samples as it drains a FIFO: the detector uses the mean rate."""
    _, rec = _sim_rotations(rate=200.0)
    i = np.arange(len(rec.t))
    bursty = (i // 10) * 0.05 + (i % 10) * 1e-4  # 10 samples per 50 ms read, 0.1 ms apart
    labels = sorted(r.label for r in tc.find_rotations(rec.gyro, t=bursty))
    assert labels == sorted(f"{a} {d}" for a in "xyz" for d in ("ccw", "cw"))


def _plateau_rates(g, rate, fit):
    means, _ = tg.turntable_plateaus(g - fit.offset, min_rate=0.9 * rate)
    return np.linalg.norm(means @ fit.matrix.T, axis=1), np.linalg.norm(means, axis=1)


def test_turntable_true_rate_within_0p2_percent(realdata):
    g0 = load_gearvr(realdata, "0RPMgyr.txt")
    g33 = load_gearvr(realdata, "33RPMgyr.txt")
    g45 = load_gearvr(realdata, "45RPMgyr.txt")
    bias = tc.gyro_bias(g0, rate_hz=100, rest_s=10.0)  # the end of the file is handled
    assert bias.intervals[0][0] == 0 and bias.n > 3000
    # calibrate on 45 rpm, check on 33 1/3 rpm (held out), and the other way round
    for train, rtrain, test, rtest in ((g45, RPM45, g33, RPM33), (g33, RPM33, g45, RPM45)):
        fit = tc.fit_turntable([train], [rtrain], offset=bias.offset)
        assert abs(fit.rel_error[0]) < 2e-3
        cal, raw = _plateau_rates(test, rtest, fit)
        assert len(cal) >= 20
        assert abs(cal.mean() / rtest - 1) < 2e-3
        assert np.max(np.abs(cal / rtest - 1)) < 4e-3
        # uncalibrated plateaus scatter by more than 1 % (orientation-dependent gains)
        assert np.ptp(raw / rtest) > 0.02
    both = tc.fit_turntable([g33, g45], [RPM33, RPM45], offset=bias.offset)
    assert np.all(np.abs(both.rel_error) < 2e-3) and both.n_plateaus[0] >= 20


def test_turntable_rejects_unusable_input(realdata):
    g33 = load_gearvr(realdata, "33RPMgyr.txt")
    with pytest.raises(tc.CalibrationError, match="plateau"):
        tc.fit_turntable([g33], [RPM33 * 3], offset=np.zeros(3))
    with pytest.raises(tc.CalibrationError, match="at least 6"):
        tc.fit_turntable([g33[:1500]], [RPM33], offset=np.zeros(3))
    with pytest.raises(tc.CalibrationError, match="one rate per recording"):
        tc.fit_turntable([g33], [], offset=np.zeros(3))


def test_docstrings_run():
    import doctest

    import triaxcal.methods.gyro as mod

    assert doctest.testmod(mod, raise_on_error=True).attempted > 0
