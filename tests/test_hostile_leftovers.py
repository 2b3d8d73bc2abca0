"""The outside audit's numeric findings, one test each: values near the edge of a double, negative
seeds, a file name or a dict where readings belong, degenerate Ferraris sections, a heading of
an axis along the vertical, the bootstrap's bound. Each ended in a traceback (OverflowError,
ValueError, LinAlgError), a NaN result, or a finite but meaningless calibration; each must
now be a CalibrationError that names what was wrong and what to give instead."""

from __future__ import annotations

import time

import numpy as np
import pytest
import triaxcal as tc
from _hostile_api import _ferraris_sections
from _hostile_cli import run
from triaxcal import sim


@pytest.fixture(scope="module")
def sections():
    return _ferraris_sections()


def test_ferraris_refuses_sections_without_their_turns(sections):
    """A gyroscope that reads nothing in the _rot sections, or the same turn in all three,
    gave a finite gain matrix of nonsense (entries of 155 where 0.001 was right)."""
    good = tc.ferraris(sections, rate_hz=100.0)
    np.testing.assert_allclose(np.diag(good.gyro.matrix), 0.00106, atol=1e-5)
    still = {k: (a, np.zeros_like(g)) if k.endswith("_rot") else (a, g)
             for k, (a, g) in sections.items()}
    with pytest.raises(tc.CalibrationError, match=r"x_rot \(\d+ deg off its axis\).*own axis"):
        tc.ferraris(still, rate_hz=100.0)
    same = {k: (a, sections["x_rot"][1]) if k.endswith("_rot") else (a, g)
            for k, (a, g) in sections.items()}
    with pytest.raises(tc.CalibrationError, match=r"y_rot \(90 deg off its axis\), z_rot"):
        tc.ferraris(same, rate_hz=100.0)


@pytest.mark.parametrize("scale", [0.0, 1e-300])
def test_ferraris_refuses_degenerate_poses(sections, scale):
    """Poses that do not span three axes (all zero, or lost below a double's resolution) made
    numpy's inverse raise LinAlgError."""
    flat = {k: (a * scale, g * scale) for k, (a, g) in sections.items()}
    with pytest.raises(tc.CalibrationError, match="do not span three axes"):
        tc.ferraris(flat, rate_hz=100.0)


@pytest.mark.parametrize("make", [
    lambda: sim.SimIMU(-1),
    lambda: tc.bootstrap(np.eye(3).repeat(10, 0) + 0.01 * np.arange(30)[:, None] % 0.07,
                         model="sphere", n_boot=20, seed=-1),
], ids=["SimIMU", "bootstrap"])
def test_negative_seeds_are_refused_by_name(make):
    """numpy raised ValueError ('expected non-negative integer') from deep inside."""
    with pytest.raises(tc.CalibrationError, match=r"seed must be a whole number in \[0, "):
        make()


@pytest.mark.parametrize("given", ["session.csv", {"ax": [1.0, 2.0]}, b"\x00" * 30])
def test_autocalibrate_given_a_file_name_or_a_dict(given):
    """autocalibrate iterated the characters of a path (or the keys of a dict) as chunks."""
    with pytest.raises(tc.CalibrationError, match="read a file first"):
        tc.autocalibrate(given, 10.0)


def test_axis_heading_of_a_vertical_axis_is_refused_not_nan():
    up = np.tile([0.0, 0.0, 1.0], (4, 1))
    field = np.tile([20.0, 0.0, -40.0], (4, 1))
    np.testing.assert_allclose(tc.axis_heading(up, field, axis=0), 0.0, atol=1e-9)
    with pytest.raises(tc.CalibrationError, match="straight up or down in reading 0"):
        tc.axis_heading(up, field, axis=2)
    with pytest.raises(tc.CalibrationError, match="axis must be 3 finite"):
        tc.axis_heading(up, field, axis=[np.nan, 0.0, 0.0])


def test_bootstrap_has_an_upper_bound():
    """10^7 to 10^8 refits ran for hours; the bound answers at once."""
    pts = np.random.default_rng(0).normal(size=(50, 3))
    t0 = time.monotonic()
    with pytest.raises(tc.CalibrationError, match=r"n_boot must be a whole number in \[20, "
                                                  r"10000\]"):
        tc.bootstrap(pts, model="sphere", n_boot=10**8)
    assert time.monotonic() - t0 < 1.0


@pytest.mark.parametrize("kw", [{"rest_s": 1e308}, {"window_s": 1e308},
                                {"min_duration_s": 1e308}, {"rate_hz": 1e300},
                                {"rate_hz": 1e-300}])
def test_durations_and_rates_near_the_edge_of_a_double(kw):
    """rest_s=1e308 overflowed converting seconds to samples (OverflowError)."""
    x = np.random.default_rng(1).normal(size=(400, 3))
    args = {"rate_hz": 100.0, "rest_s": 1.0, "window_s": 0.5, **kw}
    with pytest.raises(tc.CalibrationError, match=next(iter(kw))):
        tc.detect_still(x, **args)


@pytest.mark.parametrize("rate", ["1e-300", "1e300"])
def test_noise_rate_near_the_edge_of_a_double(tmp_path, rate):
    """noise --rate-hz 1e-300 / 1e300 ended in LinAlgError."""
    data = tmp_path / "rest.csv"
    g = np.random.default_rng(2).normal(0, 1, (500, 3))
    np.savetxt(data, g, delimiter=",", header="gx,gy,gz", comments="", fmt="%.6f")
    wrong, code, _, err = run(["noise", str(data), "--sensor", "gyro", "--rate-hz", rate])
    assert wrong is None and code == 1, (wrong, code, err)
    assert "--rate-hz" in err and "Hz" in err, err


@pytest.mark.parametrize("speed", ["5e-324", "1e308"])
def test_demo_speed_at_the_edges(tmp_path, speed):
    """demo --speed 1e308 overflowed the simulated board's sample counter in its thread (a
    traceback on the terminal) and 5e-324 blamed the board for sending nothing."""
    wrong, code, _, err = run(["demo", "--speed", speed, "--out-dir", str(tmp_path),
                               "--no-plot", "--quiet"], limit_s=30.0)
    assert wrong is None and code == 1, (wrong, code, err)
    assert "--speed" in err and "frames a second" in err, err
    with pytest.raises(tc.CalibrationError, match="speed"):
        sim.SimDevice(speed=float(speed))


class _NoPool:
    """Stands in for ProcessPoolExecutor: records how many workers were asked for and starts
    none (a regression must not fork a hundred thousand interpreters on the test machine)."""

    asked: list[int] = []

    def __init__(self, max_workers: int) -> None:
        _NoPool.asked.append(max_workers)
        raise RuntimeError("no pool in this test")


def test_batch_jobs_are_bounded_and_never_more_than_the_boards(tmp_path, monkeypatch):
    """batch --jobs 100000 started a worker process per job (5,000 interpreters before it was
    stopped, the machine's memory gone); jobs past MAX_JOBS are refused by name, and a pool
    never has more workers than boards."""
    from triaxcal.fleet import batch as fleet_batch

    monkeypatch.setattr(fleet_batch, "ProcessPoolExecutor", _NoPool)
    _NoPool.asked.clear()
    data = tmp_path / "b.csv"
    data.write_text("ax,ay,az\n1,0,0\n")
    for jobs in (10**5, 0, -1, 2.5, "4"):
        with pytest.raises(tc.CalibrationError, match="jobs must be a whole number in"):
            fleet_batch.batch_fit([("a", data), ("b", data)], jobs=jobs)
    with pytest.raises(RuntimeError, match="no pool"):
        fleet_batch.batch_fit([("a", data), ("b", data)], jobs=fleet_batch.MAX_JOBS)
    assert _NoPool.asked == [2]
    wrong, code, _, err = run(["batch", str(data), "--jobs", "100000", "--out-dir",
                               str(tmp_path / "out")])
    assert wrong is None and code == 1 and "--jobs" in err, (wrong, code, err)
    assert _NoPool.asked == [2]
