"""``triaxcal noise`` and its library call (:mod:`triaxcal.methods.noise_file`): the at-rest
test on the demo's session, the real recordings and simulated drift, capture sessions without a
rate, units per sensor, the Kalibr workflow, valid JSON, whole files, hostile input, and the
command line's grammar (old spellings warn)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import triaxcal as tc
from triaxcal.cli import main
from triaxcal.sim import NoiseTruth, noise_chunks, simulate_noise

TRUTH = NoiseTruth(white=0.005, bias_instability=0.003, random_walk=3e-4)  # deg/s units


# ------------------------------------------------------------------------------ CLI


@pytest.fixture(scope="module")
def still_session(tmp_path_factory):
    """A session CSV at rest: accel and gyro int16 counts at 50 Hz for 40 minutes."""
    n, rate = 120_000, 50.0
    g = simulate_noise(TRUTH, n, rate, seed=3) * 131 + [50, -20, 10]
    a = simulate_noise(NoiseTruth(white=1e-4, random_walk=2e-5, unit="g"), n, rate,
                       seed=4) * 16384 + [0, 0, 16384]
    t = np.arange(n) / rate
    path = tmp_path_factory.mktemp("noise") / "still.csv"
    np.savetxt(path, np.column_stack([t, np.rint(a), np.rint(g)]), delimiter=",",
               header="t,ax,ay,az,gx,gy,gz", comments="", fmt=["%.3f"] + ["%d"] * 6)
    return path


def test_cli_prints_the_figures_and_draws_the_slopes(still_session, tmp_path, capsys):
    fig = tmp_path / "allan.png"
    args = [str(still_session), "--counts-per-unit", "gyro=131:deg/s"]
    if tc.report.have_matplotlib():
        args += ["--plot", str(fig)]
    assert main(["noise", *args]) == 0
    out = capsys.readouterr().out
    assert "gyro noise figures: 120000 samples at 50 Hz" in out
    assert "angle random walk" in out and "bias instability" in out
    line = next(ln for ln in out.splitlines() if "angle random walk" in ln)
    assert float(line.split()[3]) == pytest.approx(0.005, rel=0.05)
    if tc.report.have_matplotlib():
        assert fig.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_cli_writes_kalibr_keys_for_both_sensors(still_session, tmp_path, capsys):
    out = tmp_path / "imu_noise.yaml"
    rc = main(["noise", str(still_session), "--sensor", "both", "--unit",
               "gyro=deg/s,accel=g", "--counts-per-unit", "gyro=131,accel=16384",
               "--format", "kalibr", "-o", str(out)])
    assert rc == 0
    text = out.read_text()
    for key in ("gyroscope_noise_density", "gyroscope_random_walk",
                "accelerometer_noise_density", "accelerometer_random_walk"):
        assert text.count(f"\n{key}: ") == 1
    dens = float(text.split("gyroscope_noise_density:")[1].split()[0])
    assert dens == pytest.approx(0.005 * math.pi / 180, rel=0.05)
    assert "update_rate: 50" in text


def test_cli_refuses_what_it_cannot_do(still_session, tmp_path, capsys):
    assert main(["noise", str(still_session), "--format", "kalibr"]) == 1
    assert "cannot be converted to rad/s" in capsys.readouterr().err
    assert main(["noise", str(tmp_path / "missing.csv")]) == 1
    bad = tmp_path / "bad.csv"
    bad.write_text("t,gx,gy,gz\n0,1,2,3\n0.1,1,x,3\n")
    assert main(["noise", str(bad)]) == 1
    assert "line 3: not all numbers" in capsys.readouterr().err  # io.tables' message
    assert main(["noise", str(still_session), "--counts-per-unit", "gyro=131"]) == 1
    assert "needs --unit" in capsys.readouterr().err


def test_cli_reads_an_autopilot_log_at_rest(realdata, capsys):
    """PX4's sample_log_small.ulg: 6.3 s of sensor_combined at ~205 Hz on a bench (rad/s)."""
    pytest.importorskip("pyulog")
    log = realdata / "px4-pyulog-samples" / "sample_log_small.ulg"
    assert main(["noise", str(log), "--format", "json"]) == 0
    captured = capsys.readouterr()
    d = __import__("json").loads(captured.out)["gyro"]
    assert d["unit"] == "rad/s" and 200 < d["rate_hz"] < 210
    assert "too short to measure rate random walk" in captured.err
    # up to 1 s the deviation falls as N / sqrt(tau) (white noise), with a bump near 0.08 s (a
    # vibration of about 6 Hz on the bench): the fitted N is the typical sqrt(tau) * sigma there
    rec = tc.read_log(log)
    ad = tc.allan(np.asarray(rec.stream("gyro").data), rec.stream("gyro").rate_hz, taus="log")
    white = ad.taus <= 1.0
    for k, ax in enumerate("xyz"):
        typical = float(np.median(ad.adev[white, k] * np.sqrt(ad.taus[white])))
        assert d["axes"][ax]["white"] == pytest.approx(typical, rel=0.15)
        assert d["axes"][ax]["resolved"]["white"]


def test_cli_writes_the_json_that_export_takes(still_session, tmp_path, capsys):
    out = tmp_path / "noise.json"
    assert main(["noise", str(still_session), "--sensor", "both", "--unit",
                 "gyro=deg/s,accel=g", "--counts-per-unit", "gyro=131,accel=16384",
                 "--format", "kalibr", "-o", str(out)]) == 0
    noise = __import__("json").loads(out.read_text())
    from triaxcal.export.kalibr import kalibr_imu_yaml

    text = kalibr_imu_yaml(None, topic="/imu0", rate_hz=50.0, model="calibrated", noise=noise)
    line = next(ln for ln in text.splitlines() if ln.startswith("gyroscope_noise_density:"))
    assert float(line.split(":")[1].split("#")[0]) == noise["gyroscope_noise_density"]


def test_docs_noise_example_runs(capsys):
    import re

    from conftest import doc_page

    code = re.findall(r"```python\n(.*?)```", doc_page("guide/noise.md"), re.S)[0]
    ns: dict = {}
    exec(compile(code, "docs noise example", "exec"), ns)
    out = capsys.readouterr().out
    assert "angle random walk" in out and "gyroscope_noise_density" in out
    assert ns["acc"].n == 1_000_000
    for a in ns["nf"].axes:
        assert abs(a.white / 0.005 - 1) < 0.05


def test_cli_reads_a_table_in_chunks_without_changing_the_result(still_session, monkeypatch,
                                                                  capsys):
    import json as _json

    from triaxcal.io.tables import iter_table
    from triaxcal.methods.noise_file import NoiseRequest, noise_from_file

    args = ["noise", str(still_session), "--format", "json", "--taus", "octave", "--rate-hz", "50"]
    assert main(args) == 0
    whole = _json.loads(capsys.readouterr().out)
    sizes = [len(b.data) for b in iter_table(still_session, rows=7_777)]
    assert len(sizes) == 16 and sum(sizes) == 120_000  # 16 blocks with a ragged tail
    chunked = noise_from_file(NoiseRequest(still_session, rate_hz=50.0, taus="octave",
                                           chunk_rows=7_777)).to_dict()
    assert chunked == whole
    data = np.loadtxt(still_session, delimiter=",", skiprows=1)
    ad = tc.allan(data[:, 4:7], 50.0, taus="octave", exact_up_to=65536)
    fig = tc.noise_figures(ad, sensor="gyro")
    assert whole["gyro"]["axes"]["x"]["white"] == pytest.approx(fig.axes[0].white, rel=1e-12)


# ------------------------------------------------------------------------------ at rest


@pytest.fixture(scope="module")
def demo_dir(tmp_path_factory):
    """`triaxcal demo`: a moving capture session (the board tumbled through 84 poses) and its
    calibration (accelerometer in g, gyroscope in deg/s)."""
    out = tmp_path_factory.mktemp("demo") / "demo"
    assert main(["demo", "--no-plot", "--quiet", "--out-dir", str(out)]) == 0
    return out


def test_the_demo_session_is_refused_as_moving(demo_dir, capsys):
    """Before: 'the t column does not increase'; with --rate 100, confident random walks."""
    session = str(demo_dir / "session.csv")
    capsys.readouterr()
    assert main(["noise", session]) == 2  # a refusal, as the validity gate's
    err = capsys.readouterr().err
    assert "the gyroscope turns at up to" in err and "record the board lying still" in err
    assert "--force" in err and "Traceback" not in err
    assert main(["noise", session, "--sensor", "accel"]) == 2
    assert "the accelerometer moves" in capsys.readouterr().err
    # the rate given by hand changes nothing: the readings moved
    assert main(["noise", session, "--rate", "100"]) == 2
    err = capsys.readouterr().err
    assert "--rate is now --rate-hz" in err and "the gyroscope turns at up to" in err


def test_force_computes_moving_figures_marked(demo_dir, tmp_path, capsys):
    session = str(demo_dir / "session.csv")
    cal = str(demo_dir / "calibration.json")
    assert main(["noise", session, "--force"]) == 0
    assert "NOT AT REST" in capsys.readouterr().out
    assert main(["noise", session, "--force", "--format", "json"]) == 0
    d = json.loads(capsys.readouterr().out)["gyro"]
    assert d["at_rest"] is False and d["rest"]["at_rest"] is False
    assert "turns at up to" in d["motion"] and "--force" in d["warnings"][0]
    yaml_out = tmp_path / "imu_noise.yaml"
    assert main(["noise", session, "--sensor", "both", "--cal", cal, "--force", "--format",
                 "kalibr", "-o", str(yaml_out)]) == 0
    assert "# NOT AT REST: the accelerometer" in yaml_out.read_text()
    assert "# NOT AT REST: the gyroscope" in yaml_out.read_text()
    # Kalibr's noise JSON (what export --noise takes) has no place for the mark: refused
    json_out = tmp_path / "noise.json"
    assert main(["noise", session, "--sensor", "both", "--cal", cal, "--force", "--format",
                 "kalibr", "-o", str(json_out)]) == 1
    assert "no place to say so" in capsys.readouterr().err and not json_out.exists()


def test_a_bag_whose_gyroscope_turns_is_refused(realdata, capsys):
    """The Phidgets bag: the gyroscope's z rate moves by 0.24 rad/s (standard deviation).
    Before: noise figures with exit 0 and no word that the data are not at rest."""
    pytest.importorskip("rosbags")
    bag = realdata / "ros1-imu-tools-madgwick" / "phidgets_imu_upside_down.bag"
    assert main(["noise", str(bag)]) == 2
    err = capsys.readouterr().err
    assert "the gyroscope turns at up to 0.89 rad/s" in err
    assert "at rest it changes by less than 0.01 rad/s" in err


def _sunsided(root, motion):
    from _realdata import load_sunsided

    g = load_sunsided(root, motion, "gyroscope")
    a = load_sunsided(root, motion, "accelerometer")
    n = min(len(g), len(a))
    t = g[:, 0]
    rate = (len(t) - 1) / (t[-1] - t[0])  # batch-stamped: rows over the span (~100 Hz)
    return rate, g[:n, 1:], "deg/s", a[:n, 1:], "g"


def _log(root, rel):
    rec = tc.read_log(root / rel)
    g, a = rec.stream("gyro"), rec.stream("accel")
    return g.rate_hz, np.asarray(g.data), g.unit, np.asarray(a.data), a.unit


def _imutk(root, seconds):
    from _realdata import load_imutk_xsens

    t, acc, gyr = load_imutk_xsens(root)
    keep = t < t[0] + seconds
    return 1.0 / float(np.median(np.diff(t))), gyr[keep], "counts", acc[keep], "counts"


def _ferraris(root):
    from _realdata import load_ferraris_session

    acc, gyr, _ = load_ferraris_session(root)
    return 102.4, gyr, "deg/s", acc, "m/s^2"


def _ferraris_counts(root):
    from _realdata import load_ferraris_annotated

    parts = load_ferraris_annotated(root).values()
    return (204.8, np.vstack([g for _, g in parts]), "counts", np.vstack([a for a, _ in parts]),
            "counts")


_SUNSIDED_MOVING = [f"{k}-{d}" for k, d in (
    ("pan", "x-pointing-forward"), ("pan", "y-pointing-left"), ("pan", "z-pointing-up"),
    ("rotate-360ccw-around", "x-pointing-forward"), ("rotate-360ccw-around", "y-pointing-left"),
    ("rotate-360ccw-around", "z-pointing-up"), ("tilt-around", "x-pointing-forward"),
    ("tilt-around", "x-pointing-up"), ("tilt-around", "y-pointing-left"),
    ("tilt-around", "y-pointing-up"), ("tilt-around", "z-pointing-up"))] + ["tilt-sphere"]
#: Every real recording with a gyroscope that triaxcal reads as numbers, and whether it lay
#: still (from its README): (loader, at rest, module it needs).
RECORDINGS = {
    "sample_log_small.ulg": (lambda r: _log(r, "px4-pyulog-samples/sample_log_small.ulg"),
                             True, "pyulog"),
    "sample.ulg": (lambda r: _log(r, "px4-pyulog-samples/sample.ulg"), False, "pyulog"),
    "Erle-Brain3.BIN": (lambda r: _log(r, "ardupilot-erle-logs/Erle-Brain3.BIN"), False,
                        "pymavlink"),
    "PXFv2.0b+Rpi.BIN": (lambda r: _log(r, "ardupilot-erle-logs/PXFv2.0b+Rpi.BIN"), False,
                         "pymavlink"),
    **{b: ((lambda r, b=b: _log(r, f"ros1-imu-tools-madgwick/{b}")), False, "rosbags")
       for b in ("ardrone_imu.bag", "phidgets_imu_upside_down.bag", "sparkfun_razor.bag")},
    **{f"sunsided/{m}": ((lambda r, m=m: _sunsided(r, m)), m.startswith("unmoved"), "h5py")
       for m in ("unmoved-x-pointing-forward", "unmoved-x-pointing-up",
                 "unmoved-z-pointing-left", *_SUNSIDED_MOVING)},
    "imutk-xsens, first 45 s": (lambda r: _imutk(r, 45.0), True, None),
    "imutk-xsens, whole": (lambda r: _imutk(r, 1e9), False, None),
    "ferraris session": (_ferraris, False, None),
    "ferraris annotated": (_ferraris_counts, False, None),
}


@pytest.mark.parametrize("name", list(RECORDINGS))
def test_at_rest_decision_on_every_real_recording_with_a_gyroscope(name, realdata):
    """Still recordings pass (their largest change: 2.5 to 5.4 times their noise), moving
    ones are refused by the gyroscope (49 or more times) and, except where the board turned
    about the vertical, by the accelerometer too (34 or more times)."""
    from triaxcal.methods.rest import check_rest

    load, still, module = RECORDINGS[name]
    if module:
        pytest.importorskip(module)
    rate, gyro, gu, accel, au = load(realdata)
    g = check_rest(gyro, rate, sensor="gyro", unit=gu)
    a = check_rest(accel, rate, sensor="accel", unit=au)
    assert g.at_rest is still, g.message
    if still:
        assert a.at_rest and g.change < 6 * g.noise and a.change < 6 * a.noise
        assert "was at rest" in g.message
    else:
        assert g.change > 45 * g.noise and "turns at up to" in g.message
        if name != "phidgets_imu_upside_down.bag":  # it turns about the vertical
            assert a.at_rest is False and a.change > 30 * a.noise, a.message


def test_the_rest_test_is_the_same_in_chunks_and_allows_drift():
    """A simulated 6 hours at rest with a strong random walk (the bias wanders by 0.1 deg/s)
    is at rest; the verdict does not depend on how the readings are chunked."""
    from triaxcal.methods.rest import RestMonitor, check_rest

    truth = NoiseTruth(white=0.005, random_walk=2e-3)
    y = np.concatenate(list(noise_chunks(truth, 2_160_000, 100.0, seed=9)))
    assert np.ptp(y[::6000], axis=0).max() > 0.1  # the bias wandered
    whole = check_rest(y, 100.0, sensor="gyro", unit="deg/s")
    assert whole.at_rest and whole.change < 6 * whole.noise
    mon = RestMonitor(100.0, sensor="gyro", unit="deg/s")
    for c in np.array_split(y, 37):
        mon.add(c)
    assert mon.result() == whole
    turned = y.copy()
    turned[1_000_000:1_000_300, 0] += 3.0  # a 3 s turn at 3 deg/s
    r = check_rest(turned, 100.0, sensor="gyro", unit="deg/s")
    assert r.at_rest is False and r.change == pytest.approx(3.0, rel=0.05)
    assert r.at_s == pytest.approx(10_000, abs=10)


# ------------------------------------------------------------------------------ sessions


def _capture_session(path, rate=100.0, n=60_000, seed=3):
    """A still board captured as `triaxcal capture` writes it (the same writer): int16 counts
    (accel 16384 per g, gyro 131 per deg/s), and each batch of rows read from the port stamped
    with one host time (the time it arrived)."""
    from triaxcal.capture.run import SessionWriter

    g = simulate_noise(TRUTH, n, rate, seed=seed) * 131 + [50, -20, 10]
    a = simulate_noise(NoiseTruth(white=1e-4, random_walk=2e-5, unit="g"), n, rate,
                       seed=seed + 1) * 16384 + [0, 0, 16384]
    rows = np.rint(np.column_stack([a, g, np.tile([300, -100, 200, -3900], (n, 1))]))
    rng = np.random.default_rng(seed)
    t0 = 1.7e9
    names = ("ax", "ay", "az", "gx", "gy", "gz", "mx", "my", "mz", "temp")
    with SessionWriter(path, names) as w:
        i = 0
        while i < n:
            j = min(n, i + int(rng.integers(1, 40)))
            stamp = t0 + j / rate + rng.uniform(0.0, 0.004)  # the host's read time
            w.write([(stamp, tuple(int(v) for v in rows[k])) for k in range(i, j)])
            i = j
    return path


@pytest.fixture(scope="module")
def capture_session(tmp_path_factory):
    return _capture_session(tmp_path_factory.mktemp("capture") / "still.csv")


def test_a_capture_session_needs_no_rate(capture_session, capsys):
    """Before: 'the t column does not increase: pass --rate HZ'."""
    t = np.loadtxt(capture_session, delimiter=",", skiprows=1, usecols=0)
    assert np.median(np.diff(t)) == 0  # batches share a stamp
    assert main(["noise", str(capture_session), "--counts-per-unit", "gyro=131:deg/s",
                 "--format", "json"]) == 0
    out, err = capsys.readouterr()
    d = json.loads(out)["gyro"]
    assert d["rate_hz"] == pytest.approx(100.0, rel=2e-4)
    assert "from the t column" in err and "rows over the span" in err
    assert d["rest"]["at_rest"] is True
    for ax in "xyz":
        assert d["axes"][ax]["white"] == pytest.approx(TRUTH.white, rel=0.05)


def test_gaps_and_clock_steps_in_the_t_column(tmp_path, capsys):
    from triaxcal.methods.noise_file import TimeBase

    tb = TimeBase("s.csv")
    t = np.arange(10_000) / 100.0
    t[5000:] += 20.0  # 20 s without rows
    for c in np.array_split(t, 7):
        tb.add(c)
    rate = tb.rate_hz()
    assert any("jumps by 20" in n and "rows missing" in n for n in tb.notes(rate))
    back = tmp_path / "back.csv"
    tt = np.arange(3000) / 100.0
    tt[2000:] -= 5.0
    np.savetxt(back, np.column_stack([tt, np.ones((3000, 3))]), delimiter=",",
               header="t,gx,gy,gz", comments="")
    assert main(["noise", str(back)]) == 1
    assert "goes back by 4.99 s" in capsys.readouterr().err


# ------------------------------------------------------------------------------ Kalibr


def _floats_only(node, where="imu.yaml"):
    """Every number in a parsed YAML document is a float (yaml.safe_load reads '2e-05' as a
    string: Kalibr's config reader, which uses it, would fail on it)."""
    if isinstance(node, dict):
        for k, v in node.items():
            _floats_only(v, f"{where}:{k}")
    elif isinstance(node, list):
        for i, v in enumerate(node):
            _floats_only(v, f"{where}[{i}]")
    elif isinstance(node, str):
        try:
            float(node)
        except ValueError:
            return
        raise AssertionError(f"{where} = {node!r} is a number read as a string")
    else:
        assert isinstance(node, float), f"{where} = {node!r} is not a float"


def test_noise_then_export_to_kalibr_in_one_go(demo_dir, capture_session, tmp_path, capsys):
    """`noise SESSION --sensor both --cal CAL.json --format kalibr -o noise.json` then `export
    CAL.json --format kalibr --noise noise.json`: Kalibr's imu.yaml with every number a
    float, also when the random walks are replaced by datasheet values typed as 2e-05."""
    yaml = pytest.importorskip("yaml")
    cal = str(demo_dir / "calibration.json")
    noise = tmp_path / "noise.json"
    assert main(["noise", str(capture_session), "--sensor", "both", "--cal", cal,
                 "--format", "kalibr", "-o", str(noise)]) == 0
    keys = json.loads(noise.read_text())
    assert keys["gyroscope_noise_density"] == pytest.approx(
        TRUTH.white * math.pi / 180, rel=0.05)
    assert keys["accelerometer_noise_density"] == pytest.approx(1e-4 * 9.80665, rel=0.05)
    imu = tmp_path / "imu.yaml"
    export = ["export", cal, "--format", "kalibr", "--noise", str(noise), "--rate-hz", "100",
              "--sensor-model", "MPU-6050:2g,250dps", "-o", str(imu)]  # the demo board
    assert main(export) == 0, capsys.readouterr().err
    doc = yaml.safe_load(imu.read_text())
    for k, v in keys.items():
        assert doc[k] == pytest.approx(v, rel=1e-12)
    _floats_only(doc)
    # the log cannot resolve the random walks: the datasheet's, typed as a person types them
    noise.write_text(json.dumps(keys | {"gyroscope_random_walk": 2e-05,
                                        "accelerometer_random_walk": 4e-06}))
    assert "2e-05" in noise.read_text()
    assert main(export) == 0, capsys.readouterr().err
    doc = yaml.safe_load(imu.read_text())
    _floats_only(doc)
    assert doc["gyroscope_random_walk"] == 2e-05 and doc["accelerometer_random_walk"] == 4e-06
    # noise's own Kalibr block reads as floats too (update_rate included)
    block = tmp_path / "block.yaml"
    assert main(["noise", str(capture_session), "--sensor", "both", "--cal", cal,
                 "--format", "kalibr", "--ros-topic", "/imu1", "-o", str(block)]) == 0
    doc = yaml.safe_load(block.read_text())
    _floats_only(doc)
    assert doc["rostopic"] == "/imu1" and doc["update_rate"] == pytest.approx(100, rel=2e-4)


def test_both_sensors_of_a_table_already_in_si_units(tmp_path, capsys):
    """Before: one --unit for both sensors, so a table in m/s^2 and rad/s could not give both
    of Kalibr's noise blocks in one call."""
    n, rate = 60_000, 100.0
    g = simulate_noise(NoiseTruth(white=2e-4, unit="rad/s"), n, rate, seed=5)
    a = simulate_noise(NoiseTruth(white=2e-3, unit="m/s^2"), n, rate, seed=6) + [0, 0, 9.81]
    path = tmp_path / "si.csv"
    np.savetxt(path, np.column_stack([np.arange(n) / rate, a, g]), delimiter=",",
               header="t,ax,ay,az,gx,gy,gz", comments="")
    out = tmp_path / "noise.json"
    assert main(["noise", str(path), "--sensor", "both", "--unit", "accel=m/s^2",
                 "--unit", "gyro=rad/s", "--format", "kalibr", "-o", str(out)]) == 0
    keys = json.loads(out.read_text())
    assert keys["gyroscope_noise_density"] == pytest.approx(2e-4, rel=0.05)
    assert keys["accelerometer_noise_density"] == pytest.approx(2e-3, rel=0.05)
    # bare units go to the sensor they measure
    assert main(["noise", str(path), "--sensor", "both", "--unit", "m/s^2", "--unit", "rad/s",
                 "--format", "kalibr", "-o", str(out)]) == 0
    assert json.loads(out.read_text()) == keys
    # one sensor's columns cannot give both sensors' figures
    gyro_only = tmp_path / "gyro.csv"
    np.savetxt(gyro_only, np.column_stack([np.arange(n) / rate, g]), delimiter=",",
               header="t,x,y,z", comments="")
    assert main(["noise", str(gyro_only), "--sensor", "both"]) == 1
    assert "the columns of one sensor only" in capsys.readouterr().err
    # a unit of the wrong quantity is refused, naming the flag
    assert main(["noise", str(path), "--unit", "gyro=m/s^2"]) == 1
    assert "--unit: 'm/s^2' is not a unit of the gyroscope" in capsys.readouterr().err


def test_json_output_is_valid_json(still_session, capsys):
    """Before: `Infinity` for the uncertainty of a term the fit left at zero, which `export
    --noise` (and any strict JSON reader) refuses."""
    assert main(["noise", str(still_session), "--sensor", "both", "--format", "json",
                 "--counts-per-unit", "gyro=131:deg/s", "--counts-per-unit",
                 "accel=16384:g"]) == 0
    out = capsys.readouterr().out

    def refuse(name):
        raise AssertionError(f"{name} in the JSON")

    d = json.loads(out, parse_constant=refuse)
    nulls = [(s, ax, t) for s in d for ax, v in d[s]["axes"].items()
             for t, e in v["rel_err"].items() if e is None]
    assert nulls, "expected a term left at zero in this log (its uncertainty is null)"
    assert all("rel_err" in d[s]["null"] for s in d)


# ------------------------------------------------------------------------------ hostile input


def test_a_long_line_is_refused_in_bounded_memory(tmp_path):
    """Before: noise had its own line reader with no line-length limit (a 512 MiB file
    without a line break peaked at 2.6 GB); a sparse file (zeros) gave a MemoryError. Now
    io.tables reads it: at most 1 MiB per line, in blocks."""
    import subprocess
    import sys

    sparse = tmp_path / "sparse.csv"
    with open(sparse, "wb") as f:
        f.write(b"t,gx,gy,gz\n0,1,2,3\n")
        f.truncate(512 << 20)  # 512 MiB: a hole, no disk used, no line break
    code = (  # VmHWM: the peak RSS of this process image (ru_maxrss would include pytest's)
        "import sys\n"
        "from triaxcal.cli import main\n"
        "rc = main(['noise', sys.argv[1]])\n"
        "hwm = next(ln for ln in open('/proc/self/status') if ln.startswith('VmHWM'))\n"
        "print(rc, hwm.split()[1])\n"
    )
    res = subprocess.run([sys.executable, "-c", code, str(sparse)], capture_output=True,
                         text=True, timeout=120)
    rc, kib = res.stdout.split()
    assert rc == "1", res.stderr
    assert "more than 1048576 bytes without a line break" in res.stderr
    assert "Traceback" not in res.stderr and "MemoryError" not in res.stderr
    assert int(kib) < 200_000, f"peak RSS {int(kib) / 1024:.0f} MB"


def test_output_is_written_whole_or_not_at_all(still_session, tmp_path, monkeypatch, capsys):
    """Before: on a full disk `noise -o` replaced an existing file with a truncated one."""
    import errno
    import os

    out = tmp_path / "figures.txt"
    out.write_text("figures of yesterday\n")

    def full(fd):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "fsync", full)
    assert main(["noise", str(still_session), "--rate-hz", "50", "-o", str(out)]) == 1
    assert "no space left" in capsys.readouterr().err
    assert out.read_text() == "figures of yesterday\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["figures.txt"]  # no temp left


@pytest.mark.parametrize("rate", ["1e-300", "1e300", "0", "-5", "nan", "inf"])
def test_rates_at_the_edge_of_a_double_are_refused(still_session, rate, capsys):
    """Before: `--rate 1e-300` and `1e300` raised numpy's LinAlgError."""
    assert main(["noise", str(still_session), "--rate-hz", rate]) == 1
    err = capsys.readouterr().err
    assert "--rate-hz must be a finite number in [0.001, 1e+06]" in err
    assert "Traceback" not in err


def test_the_library_refuses_rates_the_noise_model_cannot_hold():
    with pytest.raises(tc.CalibrationError, match="rate_hz"):
        ad = tc.allan(np.random.default_rng(0).normal(size=(5000, 3)), 1e300)
        tc.noise_figures(ad, sensor="gyro")


# ------------------------------------------------------------------------------ the command


def test_the_command_is_a_typed_request_and_one_library_call(still_session, capsys):
    import triaxcal.cli.noise as cli_noise
    from triaxcal.methods.noise_file import NoiseRequest, noise_from_file

    for name in ("figures_from_file", "read_chunks", "_rate_from_t", "_header", "_scale"):
        assert not hasattr(cli_noise, name), f"cli.noise still holds {name}"
    res = noise_from_file(NoiseRequest(still_session, counts_per_unit={"gyro": (131, "deg/s")}))
    assert main(["noise", str(still_session), "--counts-per-unit", "gyro=131:deg/s",
                 "--format", "json"]) == 0
    assert json.loads(capsys.readouterr().out) == json.loads(res.to_json())
    # the library names Python's options, the command line its flags
    with pytest.raises(tc.CalibrationError, match=r"^rate_hz must be"):
        NoiseRequest(still_session, rate_hz=1e300)
    with pytest.raises(tc.CalibrationError, match=r"^counts_per_unit gyro=131 needs unit"):
        NoiseRequest(still_session, counts_per_unit={"gyro": 131})
    with pytest.raises(tc.CalibrationError, match="needs one value per sensor with sensor='both'"):
        NoiseRequest(still_session, sensor="both", counts_per_unit=131)
    # (nothing below cli/ imports argparse: tests/test_layout.py)


def test_old_spellings_warn_and_do_what_the_new_ones_do(still_session, tmp_path, capsys):
    new = ["noise", str(still_session), "--format", "kalibr", "--rate-hz", "50",
           "--counts-per-unit", "gyro=131:deg/s", "--ros-topic", "/imu3"]
    assert main(new) == 0
    want, err = capsys.readouterr()
    assert "is now" not in err and "rostopic: /imu3" in want
    old = ["noise", str(still_session), "--format", "kalibr", "--rate", "50",
           "--unit", "deg/s", "--counts-per-unit", "131", "--rostopic", "/imu3"]
    assert main(old) == 0
    got, err = capsys.readouterr()
    assert got == want
    assert "--rate is now --rate-hz" in err and "--rostopic is now --ros-topic" in err
    assert "--counts-per-unit 131 is now --counts-per-unit gyro=131:UNIT" in err
    # a bare number cannot say whose counts it scales when both sensors are read
    assert main(["noise", str(still_session), "--sensor", "both", "--counts-per-unit",
                 "131"]) == 1
    assert "say whose counts" in capsys.readouterr().err


_T = "t,gx,gy,gz\n"


@pytest.mark.parametrize("content, message", [
    (_T + "".join(f"{i / 100},1,2,3\n" for i in range(5)), "too short for noise figures"),
    (_T + "".join(f"{i / 100},{'nan' if i == 700 else 1},2,3\n" for i in range(3000)),
     "is NaN or inf"),
    (_T + "".join(f"{i / 100},{(-1) ** i * 1e300},2e300,3\n" for i in range(3000)),
     "overflows a double"),
    (_T + "".join(f"{'nan' if i == 9 else i / 100},1,2,3\n" for i in range(3000)),
     "t column is not a number at data row 10"),
    (_T + "".join(f"{i / 100},5,5,5\n" for i in range(3000)), "zero Allan deviation"),
    (_T + "".join(f"{1e308 * (i % 2) - 1e308 * (1 - i % 2)},1,2,3\n" for i in range(3000)),
     "goes back"),
    (_T, "only a header"),
    ("", "holds no rows of numbers"),
    ("\x00\xff\x1b[2J garbage\n" * 10, "not all numbers"),
])
def test_hostile_tables_get_a_message_not_a_traceback(tmp_path, content, message, capsys):
    import warnings

    path = tmp_path / "hostile.csv"
    path.write_bytes(content.encode("utf-8", "surrogateescape"))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no RuntimeWarning from numpy either
        assert main(["noise", str(path)]) == 1
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
