"""Free-living auto-calibration (van Hees et al. 2014) on simulated recordings with known
offsets, gains and temperature drift."""

from __future__ import annotations

import tracemalloc
import warnings

import numpy as np
import pytest
import triaxcal as tc
from triaxcal.errors import CalibrationError
from triaxcal.methods.autocal import StillWindows, fit_still_windows
from triaxcal.sim import FreeLivingSim


def errors(cal, sim):
    tr = sim.truth
    off = cal.offset - tr.offset_at(cal.temp_ref_c)
    return off, cal.gain / tr.gain - 1.0, cal.temp_coef - tr.temp_coef


@pytest.mark.slow
def test_week_at_100hz_in_chunks_recovers_offsets_gains_and_drift_with_bounded_memory():
    sim = FreeLivingSim(seed=11, days=7.0, rate_hz=100.0)
    assert sim.n_samples == 60_480_000  # 1.45 GB as float64 (N, 3): never held at once
    tracemalloc.start()
    try:
        cal = tc.autocalibrate(sim.chunks(chunk_s=3600.0), 100.0)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    off, gain, drift = errors(cal, sim)
    print(f"\n{cal}\noffset error mg {np.round(1000 * off, 4)}, gain error % "
          f"{np.round(100 * gain, 5)}, drift error mg/degC {np.round(1000 * drift, 5)}, "
          f"peak memory {peak / 1e6:.0f} MB")
    assert cal.accepted and cal.status == "recalibration done, no problems detected"
    assert cal.hours == pytest.approx(168.0)
    assert np.all(np.abs(off) < 0.002)  # the must-show: 2 mg
    assert np.all(np.abs(gain) < 0.002)  # and 0.2 %
    assert np.all(np.abs(off) < 0.0002) and np.all(np.abs(gain) < 0.0002)  # what it reaches
    assert np.all(np.abs(drift) < 2e-5)  # 0.02 mg/degC
    assert cal.error_before_g > 0.01 > 0.0005 > cal.error_after_g
    assert peak < 150e6  # a 1 h chunk and its temporaries, not the recording


def test_chunking_does_not_change_the_result(tmp_path):
    sim = FreeLivingSim(seed=2, days=1.0, rate_hz=25.0)
    acc = np.concatenate([a for a, _ in sim.chunks()])
    temp = np.concatenate([t for _, t in sim.chunks()])
    whole = tc.autocalibrate(acc, 25.0, temp, min_hours=0, chunk_s=1e9)
    k = 19_441  # chunks that cut windows anywhere
    odd = tc.autocalibrate(((acc[i:i + k], temp[i:i + k]) for i in range(0, len(acc), k)),
                           25.0, min_hours=0)
    mm = np.lib.format.open_memmap(tmp_path / "acc.npy", mode="w+", dtype=np.float64,
                                   shape=acc.shape)
    mm[:] = acc
    mm.flush()
    mapped = tc.autocalibrate(np.load(tmp_path / "acc.npy", mmap_mode="r"), 25.0, temp,
                              min_hours=0, chunk_s=3000.0)
    for other in (odd, mapped):
        assert np.array_equal(whole.offset, other.offset)
        assert np.array_equal(whole.gain, other.gain)
        assert np.array_equal(whole.temp_coef, other.temp_coef)
        assert whole.n_still == other.n_still and whole.n_windows == other.n_windows
    off, gain, _ = errors(whole, sim)
    assert np.all(np.abs(off) < 2e-4) and np.all(np.abs(gain) < 2e-4)
    assert whole.accepted  # min_hours=0: judged on the error and the sphere alone


def test_published_acceptance_rule():
    sim = FreeLivingSim(seed=3, days=1.0, rate_hz=20.0)
    day = tc.autocalibrate(sim.chunks(), 20.0)  # default min_hours = 72, as GGIR
    assert not day.accepted and "24.0 h of data, fewer than 72 h" in day.status
    assert day.error_after_g < 0.01  # the estimate itself is fine
    # one orientation only: the sphere is not populated, nothing is fitted
    rng = np.random.default_rng(0)
    flat = np.array([0.02, -0.01, 1.01]) + rng.normal(0, 0.004, (20 * 3600, 3))
    one = tc.autocalibrate(flat, 20.0, min_hours=0)
    assert not one.accepted and not one.sphere_populated
    assert "not enough points on all sides of the sphere" in one.status
    assert np.array_equal(one.gain, np.ones(3))
    # all movement: no still window
    moving = rng.normal(0, 0.3, (20 * 600, 3))
    none = tc.autocalibrate(moving, 20.0, min_hours=0)
    assert not none.accepted and none.n_still == 0 and "0 still" in none.status
    # windows above 13 mg are not still; a lower threshold drops them all
    quiet = tc.autocalibrate(sim.chunks(), 20.0, min_hours=0, sd_threshold_g=0.002)
    assert quiet.n_still == 0


def test_ggir_stopping_rule_stops_early_and_the_default_does_not():
    sim = FreeLivingSim(seed=4, days=1.0, rate_hz=20.0)
    sw = StillWindows(20.0)
    for a, t in sim.chunks():
        sw.update(a, t)
    st = sw.result()
    ours = fit_still_windows(st, min_hours=0)
    ggir = fit_still_windows(st, min_hours=0, stop="ggir")
    e_ours, e_ggir = np.abs(errors(ours, sim)[0]).max(), np.abs(errors(ggir, sim)[0]).max()
    assert ggir.iterations < ours.iterations
    assert e_ours < 5e-5 and e_ggir > 4 * e_ours


def test_conventions_ggir_and_calibration_file():
    sim = FreeLivingSim(seed=6, days=1.0, rate_hz=20.0)
    acc, temp = next(sim.chunks(chunk_s=86400.0))
    cal = tc.autocalibrate(acc, 20.0, temp, min_hours=0)
    y, t = acc[:1000], temp[:1000]
    g = cal.ggir
    ggir_form = (y + g["offset"]) * g["scale"] + (t[:, None] - g["meantemp"]) * g["tempoffset"]
    assert np.allclose(cal.apply(y, t), ggir_form, atol=1e-12)
    part = tc.calibration.parts.part_from_autocal(cal)
    assert np.allclose(part.apply(y, temperature=t), cal.apply(y, t), atol=1e-12)
    assert part.raw_unit == part.unit == "g" and part.model == "autocal-vanhees"
    back = tc.Calibration.from_json(tc.Calibration(accel=part).to_json()).accel
    assert back == part
    # corrected still readings have length 1 g, to well under a milligram
    true = sim.truth.apply(y, t)
    assert np.abs(cal.apply(y, t) - true).max() < 5e-4
    with pytest.raises(CalibrationError, match="temperature terms"):
        cal.apply(y)


def test_hostile_inputs():
    with pytest.raises(CalibrationError, match=r"\(N, 3\)"):
        tc.autocalibrate(np.zeros((100, 2)), 10.0)
    with pytest.raises(CalibrationError, match="rate_hz"):
        tc.autocalibrate(np.zeros((100, 3)), 0.0)
    with pytest.raises(CalibrationError, match="temperatures for"):
        tc.autocalibrate(np.zeros((100, 3)), 10.0, np.zeros(99))
    with pytest.raises(CalibrationError, match="empty"):
        tc.autocalibrate(np.zeros((0, 3)), 10.0)
    with pytest.raises(CalibrationError, match="stop"):
        fit_still_windows(StillWindows(10.0).result(), stop="never")
    # NaN samples spoil only their own windows
    rng = np.random.default_rng(1)
    u = rng.normal(size=(300, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    raw = np.repeat(u, 100, axis=0) + rng.normal(0, 0.003, (30000, 3))
    raw[150:160] = np.nan
    cal = tc.autocalibrate(raw, 10.0, min_hours=0)
    assert cal.n_still == 299 and cal.accepted


@pytest.mark.slow
def test_side_by_side_with_scikit_digital_health():
    skdh = pytest.importorskip("skdh.preprocessing")
    days, rate = 4.0, 25.0
    sim = FreeLivingSim(seed=5, days=days, rate_hz=rate)
    acc = np.concatenate([a for a, _ in sim.chunks()])
    temp = np.concatenate([t for _, t in sim.chunks()])
    ours = tc.autocalibrate(acc, rate, temp)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = skdh.CalibrateAccelerometer().predict(
            time=1.7e9 + np.arange(len(acc)) / rate, accel=acc, fs=rate, temperature=temp,
            apply=False)
    s, d = r["scale"], r["offset"]
    tr = sim.truth
    # skdh's offset in triaxcal's terms at the same reference temperature (the mean over the
    # still windows, which both select alike)
    skdh_off = -d - tr.offset_at(ours.temp_ref_c)
    ours_off = ours.offset - tr.offset_at(ours.temp_ref_c)
    print(f"\noffset error mg: ours {np.round(1000 * ours_off, 4)}, skdh "
          f"{np.round(1000 * skdh_off, 4)}; gain error %: ours "
          f"{np.round(100 * (ours.gain / tr.gain - 1), 4)}, skdh "
          f"{np.round(100 * (s / tr.gain - 1), 4)}")
    assert ours.accepted
    assert np.abs(ours_off).max() <= np.abs(skdh_off).max()
    assert np.abs(ours.gain / tr.gain - 1).max() <= np.abs(s / tr.gain - 1).max()
