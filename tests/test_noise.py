"""Allan deviation (against allantools, streamed, bounded memory) and noise figures (against
the simulator's truth), the Kalibr keys (``triaxcal noise`` itself: test_noise_cli.py)."""

from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest
import triaxcal as tc
from triaxcal.methods.noise import kalibr_yaml
from triaxcal.sim import NoiseTruth, noise_chunks, simulate_noise

allantools = pytest.importorskip("allantools")

RATE = 100.0


def _data(n=60_000, seed=0, axes=3):
    """Rate readings with a large bias, white noise and a random walk (deg/s)."""
    rng = np.random.default_rng(seed)
    y = 250.0 + rng.normal(0, 0.05, (n, axes)) + np.cumsum(rng.normal(0, 2e-4, (n, axes)), 0)
    return y


def _allantools(y, taus="octave", rate=RATE):
    t, ad, _, ns = allantools.oadev(y, rate=rate, data_type="freq", taus=taus)
    return t, ad, ns


# ------------------------------------------------------------------------------ allantools


def test_equal_to_allantools_oadev_on_every_axis_and_octave_tau():
    y = _data()
    ad = tc.allan(y, RATE, unit="deg/s")
    assert ad.adev.shape == (len(ad.taus), 3) and ad.unit == "deg/s" and ad.n == len(y)
    worst = 0.0
    for k in range(3):
        t, ref, ns = _allantools(y[:, k])
        np.testing.assert_array_equal(ad.taus, t)
        np.testing.assert_array_equal(ad.terms, ns)
        worst = max(worst, float(np.max(np.abs(ad.adev[:, k] / ref - 1))))
    assert worst < 1e-9, worst
    assert (ad.stride == 1).all()


def test_equal_to_allantools_for_taus_in_seconds_and_log_spacing():
    y = _data(n=30_000, seed=1, axes=1)[:, 0]
    taus = [0.01, 0.05, 0.37, 2.0, 11.11, 99.0]
    ad = tc.allan(y, RATE, taus=taus)
    t, ref, ns = _allantools(y, taus=np.array(taus))
    np.testing.assert_allclose(ad.taus, t, rtol=0, atol=1e-12)
    np.testing.assert_allclose(ad.adev[:, 0], ref, rtol=1e-9, atol=0)
    ad = tc.allan(y, RATE, taus="log")
    t, ref, ns = _allantools(y, taus=ad.taus)
    np.testing.assert_allclose(ad.adev[:, 0], ref, rtol=1e-9, atol=0)
    assert len(ad.taus) > 30  # about 10 per decade over four decades


def test_stream_in_ragged_chunks_equals_the_array_and_allantools():
    y = _data(n=50_000, seed=2)
    whole = tc.allan(y, RATE)
    rng = np.random.default_rng(5)
    cuts = np.sort(rng.choice(np.arange(1, len(y)), 40, replace=False))
    chunks = (c for c in np.split(y, cuts))
    streamed = tc.allan(chunks, RATE)
    # a stream does not know its length: it reports the taus that got at least 2 terms
    np.testing.assert_array_equal(streamed.taus, whole.taus)
    np.testing.assert_allclose(streamed.adev, whole.adev, rtol=1e-12)


def test_long_clusters_are_strided_and_equal_to_allantools_with_that_stride():
    y = _data(n=400_000, seed=3, axes=1)[:, 0]
    ad = tc.allan(y, RATE, exact_up_to=4096)
    from allantools.allantools import calc_adev_phase, frequency2phase

    phase = frequency2phase(y, RATE)
    strided = ad.stride > 1
    assert strided.any() and (ad.m[strided] / ad.stride[strided] >= 2048).all()
    for m, d, val, n in zip(ad.m, ad.stride, ad.adev[:, 0], ad.terms):
        ref, _, ns = calc_adev_phase(phase, RATE, int(m), int(d))
        assert n == ns and abs(val / ref - 1) < 1e-9
    # and statistically the same as the fully overlapping estimate (a few % at most)
    full = tc.allan(y, RATE, exact_up_to=None)
    ok = full.terms > 20 * full.m  # enough clusters for the comparison to mean something
    np.testing.assert_allclose(ad.adev[ok], full.adev[ok], rtol=0.03)


def test_non_overlapping_core_equals_allantools_adev_in_any_chunking():
    """The core's non-overlapping mode (terms m samples apart) is allantools' ``adev``."""
    from triaxcal import _core

    y = _data(n=70_000, seed=6)
    ms = [1, 2, 3, 8, 100, 1024, 10_000]
    for chunk in (len(y), 9_999, 777):
        acc = _core.AllanStream(RATE, 3, ms, exact_up_to=None, overlapping=False)
        for i in range(0, len(y), chunk):
            acc.push(np.ascontiguousarray(y[i:i + chunk]))
        d = acc.result()
        np.testing.assert_array_equal(d["stride"], d["m"])
        for k in range(3):
            t, ref, _, ns = allantools.adev(y[:, k], rate=RATE, data_type="freq",
                                            taus=np.array(ms) / RATE)
            np.testing.assert_array_equal(d["terms"], ns)
            np.testing.assert_allclose(d["adev"][:, k], ref, rtol=1e-11)


def test_real_recording_at_rest_equals_allantools(realdata):
    """The first 45 s of the imu_tk Xsens recording are at rest (raw ADC counts, 100 Hz)."""
    from _realdata import load_imutk_xsens

    t, _, gyro = load_imutk_xsens(realdata)
    rate = 1.0 / float(np.median(np.diff(t)))
    rest = gyro[t < t[0] + 45.0]
    ad = tc.allan(rest, rate)
    for k in range(3):
        _, ref, _ = _allantools(rest[:, k], taus=ad.taus, rate=rate)
        np.testing.assert_allclose(ad.adev[:, k], ref, rtol=1e-9)
    nf = tc.noise_figures(ad, sensor="gyro")
    # white noise dominates the short taus of this log: its per-sample sigma agrees with the
    # rms difference of consecutive readings / sqrt(2), an estimate that needs no fit
    for k, a in enumerate(nf.axes):
        direct = float(np.std(np.diff(rest[:, k]))) / math.sqrt(2.0)
        assert a.resolved["white"], a
        assert nf.per_sample("white", k) == pytest.approx(direct, rel=0.1)


# ------------------------------------------------------------------------------ streaming


@pytest.mark.slow
def test_a_1e8_sample_stream_runs_in_fixed_memory():
    def rss() -> int:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmRSS"):
                    return int(line.split()[1]) * 1024
        raise AssertionError("no VmRSS")

    acc = tc.AllanAccumulator(1000.0, axes=1, unit="deg/s")
    assert acc.memory_bytes < 8e6
    truth = NoiseTruth(white=0.005, random_walk=1e-4)
    before = None
    for i, c in enumerate(noise_chunks(truth, 100_000_000, 1000.0, axes=1, chunk=1 << 21)):
        acc.add(c)
        if i == 1:
            before = rss()
    assert acc.n == 100_000_000 and before is not None
    grew = rss() - before
    assert grew < 16e6, f"RSS grew by {grew / 1e6:.1f} MB over 1e8 samples"
    r = acc.result()
    # 1e8 samples at 1 kHz: taus up to 2^25 samples (33554 s)
    assert r.taus[-1] == 2**25 / 1000.0
    white = r.adev[r.taus == 0.064, 0][0] * math.sqrt(0.064)
    assert abs(white / 0.005 - 1) < 0.01


def test_memory_is_fixed_when_the_accumulator_is_made():
    acc = tc.AllanAccumulator(1000.0, axes=3)
    before = acc.memory_bytes
    rng = np.random.default_rng(0)
    for _ in range(5):
        acc.add(rng.normal(size=(50_000, 3)))
    assert acc.memory_bytes == before < 16e6
    assert acc.n == 250_000


def test_threads_release_the_gil_and_do_not_interfere():
    ys = [_data(n=200_000, seed=s) for s in range(4)]
    serial = [tc.allan(y, RATE, exact_up_to=4096).adev for y in ys]
    with ThreadPoolExecutor(4) as pool:
        par = list(pool.map(lambda y: tc.allan(y, RATE, exact_up_to=4096).adev, ys))
    for a, b in zip(serial, par):
        np.testing.assert_array_equal(a, b)


# ------------------------------------------------------------------------------ bad input


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"rate_hz": 0.0}, "rate_hz"),
        ({"rate_hz": float("nan")}, "rate_hz"),
        ({"taus": "weekly"}, "taus"),
        ({"taus": [0.001]}, "shorter than one sample"),
        ({"taus": [1e9]}, "too long"),
        ({"taus": [-1.0]}, "taus"),
        ({"exact_up_to": 0}, "exact_up_to"),
    ],
)
def test_bad_options_say_what_to_do(kwargs, match):
    args = {"rate_hz": RATE, **kwargs}
    with pytest.raises(tc.CalibrationError, match=match):
        tc.allan(_data(n=1000), args.pop("rate_hz"), **args)


def test_bad_readings_are_refused_and_named():
    y = _data(n=1000)
    y[617, 1] = np.nan
    with pytest.raises(tc.NonFiniteError, match="row 617"):
        tc.allan(y, RATE)
    with pytest.raises(tc.CalibrationError, match="at least 3"):
        tc.allan(np.zeros((2, 3)), RATE)
    with pytest.raises(tc.CalibrationError, match="real numbers"):
        tc.allan(np.array([["a", "b"]] * 10), RATE)
    with pytest.raises(tc.CalibrationError, match="empty"):
        tc.allan(iter([]), RATE)
    acc = tc.AllanAccumulator(RATE, axes=3)
    acc.add(np.zeros((10, 3)))
    with pytest.raises(tc.CalibrationError, match=r"shape \(rows, 3\)"):
        acc.add(np.zeros((10, 2)))
    bad = np.zeros((5, 3))
    bad[3, 0] = np.inf
    with pytest.raises(tc.NonFiniteError, match="row 13 of the stream"):
        acc.add(bad)
    assert acc.n == 10  # the bad chunk was refused whole
    short = tc.AllanAccumulator(RATE, axes=3)
    short.add(np.zeros((2, 3)))
    with pytest.raises(tc.CalibrationError, match="too few samples"):
        short.result()
    with pytest.raises(tc.CalibrationError, match="zero Allan deviation"):
        tc.noise_figures(np.ones((5000, 3)), RATE)


@pytest.mark.parametrize("taus", [None, "log"])  # octaves: window sums; log: the phases
def test_readings_at_the_edge_of_a_double(taus):
    # a level near the largest double is no problem: the deviation of a constant is 0
    flat = tc.allan(np.full((64, 3), 1.7e308), RATE, taus=taus)
    assert np.all(flat.adev == 0.0)
    # a spike whose square overflows is refused, not returned as inf or NaN
    spike = _data(n=1000)
    spike[500, 2] = 1e300
    with pytest.raises(tc.CalibrationError, match="overflows a double"):
        tc.allan(spike, RATE, taus=taus)
    # the largest readings of both signs: their differences overflow
    with pytest.raises(tc.CalibrationError, match="rescale"):
        tc.allan(np.array([1.7e308, -1.7e308] * 32), RATE, taus=taus)


# ------------------------------------------------------------------------------ figures

TRUTH = NoiseTruth(white=0.005, bias_instability=0.003, random_walk=3e-4)  # deg/s units


@pytest.mark.slow
def test_noise_figures_are_within_10_percent_of_the_truth_for_a_long_log():
    # 4e6 samples at 10 Hz: 111 hours at rest, three independent axes
    y = simulate_noise(TRUTH, 4_000_000, 10.0, seed=11)
    nf = tc.noise_figures(y, 10.0, unit="deg/s")
    assert nf.warnings == ()
    for a in nf.axes:
        assert all(a.resolved[t] for t in ("white", "bias_instability", "random_walk")), a
        assert abs(a.white / TRUTH.white - 1) < 0.10, a
        assert abs(a.bias_instability / TRUTH.bias_instability - 1) < 0.10, a
        assert abs(a.random_walk / TRUTH.random_walk - 1) < 0.10, a
        # the floor shows where white noise and random walk meet the flicker floor
        assert 5.0 < a.bias_tau_s < 200.0
    # both conventions: per-sample sigma = N sqrt(f); bias step = K / sqrt(f)
    assert nf.per_sample("white", "x") == pytest.approx(nf.axes[0].white * math.sqrt(10.0))
    assert nf.per_sample("random_walk", 2) == pytest.approx(nf.axes[2].random_walk / math.sqrt(10))


def test_a_short_log_warns_about_the_figures_it_cannot_show():
    y = simulate_noise(TRUTH, 20_000, 10.0, seed=0)  # 33 minutes
    nf = tc.noise_figures(y, 10.0, unit="deg/s")
    assert any("too short to measure rate random walk" in w for w in nf.warnings)
    for a in nf.axes:
        assert a.resolved["white"] and abs(a.white / TRUTH.white - 1) < 0.05
        assert not a.resolved["random_walk"]
        assert a.upper["random_walk"] > TRUTH.random_walk  # a true upper bound
    text = nf.text()
    assert "angle random walk" in text and "deg/s/sqrt(Hz)" in text and "deg/sqrt(h)" in text
    assert "per sample at 10 Hz" in text and "not resolved" in text


def test_accelerometer_names_and_units():
    y = simulate_noise(NoiseTruth(white=1e-4, random_walk=1e-6, unit="g"), 100_000, 100.0)
    nf = tc.noise_figures(y, 100.0, sensor="accel", unit="g")
    text = nf.text()
    assert "velocity random walk" in text and "acceleration random walk" in text
    assert "ug/sqrt(Hz)" in text and "m/s/sqrt(h)" in text
    assert nf.axes[0].white == pytest.approx(1e-4, rel=0.03)


def test_kalibr_keys_in_si_units_from_the_worst_axis():
    g = tc.noise_figures(simulate_noise(TRUTH, 400_000, 50.0, seed=4), 50.0, unit="deg/s")
    a = tc.noise_figures(
        simulate_noise(NoiseTruth(white=2e-4, random_walk=4e-5, unit="g"), 400_000, 50.0),
        50.0, sensor="accel", unit="g")
    keys = tc.kalibr_noise(g, a)
    assert set(keys) == {"gyroscope_noise_density", "gyroscope_random_walk",
                         "accelerometer_noise_density", "accelerometer_random_walk"}
    assert keys["gyroscope_noise_density"] == pytest.approx(
        g.worst("white") * math.pi / 180, rel=1e-12)
    assert keys["gyroscope_noise_density"] == pytest.approx(0.005 * math.pi / 180, rel=0.03)
    assert keys["accelerometer_noise_density"] == pytest.approx(2e-4 * 9.80665, rel=0.03)
    assert keys["accelerometer_random_walk"] == pytest.approx(4e-5 * 9.80665, rel=0.25)
    assert all(v > 0 for v in keys.values())  # Kalibr refuses values <= 0
    text = kalibr_yaml(g, a, ros_topic="/imu0")
    parsed = {ln.split(":")[0]: float(ln.split(":")[1].split("#")[0])
              for ln in text.splitlines() if ln and not ln.startswith("#")
              and not ln.startswith("rostopic")}
    assert parsed["update_rate"] == 50.0
    for k, v in keys.items():
        assert parsed[k] == pytest.approx(v, rel=1e-6)
    assert "rad/s^2/sqrt(Hz)" in text and "m/s^3/sqrt(Hz)" in text
    with pytest.raises(tc.CalibrationError, match="ros_topic"):
        kalibr_yaml(g, ros_topic="/imu0\nevil: 1")
    with pytest.warns(DeprecationWarning, match="ros_topic"):  # the old name, one release
        assert kalibr_yaml(g, a, rostopic="/imu0") == text
    counts = tc.noise_figures(simulate_noise(TRUTH, 50_000, 50.0), 50.0)  # unit "counts"
    with pytest.raises(tc.CalibrationError, match="cannot be converted to rad/s"):
        tc.kalibr_noise(counts)
