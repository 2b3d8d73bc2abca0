"""The methods from the command line on the real recordings: ``triaxcal ferraris`` (imucal's two
sessions), ``imu`` (imu_tk's Xsens recording), ``turntable`` (freeIMUCal's record player) and
``gyro-gains --turns whole --axes X --bias REST`` (sunsided's two 360 deg turns per axis). Each
command writes what the API computes on the same recording, to float precision, through the
validity gate."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import triaxcal as tc
from _realdata import (
    load_ferraris_annotated,
    load_ferraris_session,
    load_gearvr,
    load_imutk_xsens,
    load_sunsided,
)
from triaxcal.calibration.parts import part_from_ferraris
from triaxcal.cli import main

RTOL = 1e-12  # float precision: the same numbers through a file and back


def _run(capsys, *argv) -> tuple[int, str, str]:
    rc = main([str(a) for a in argv])
    got = capsys.readouterr()
    return rc, got.out, got.err


def _same(part: tc.SensorCalibration, offset, matrix) -> None:
    np.testing.assert_allclose(part.offset, offset, rtol=RTOL, atol=0)
    np.testing.assert_allclose(part.matrix, matrix, rtol=RTOL,
                               atol=RTOL * float(np.abs(matrix).max()))


# --- ferraris ---------------------------------------------------------------------------------


def test_ferraris_on_the_annotated_session(realdata, tmp_path, capsys):
    out = tmp_path / "cal.json"
    rc, text, _ = _run(capsys, "ferraris", realdata / "imucal-ferraris" / "annotated_session.csv",
                       "--rate-hz", "204.8", "-o", out)
    assert rc == 0, text
    fer = tc.ferraris(load_ferraris_annotated(realdata), rate_hz=204.8, gravity=9.81)
    cal = tc.Calibration.load(out)
    _same(cal.accel, fer.accel.offset, fer.accel.matrix)
    _same(cal.gyro, fer.gyro.offset, fer.gyro.matrix)
    assert (cal.accel.unit, cal.accel.radius, cal.gyro.unit) == ("m/s^2", 9.81, "rad/s")
    assert cal.accel.valid and cal.gyro.valid and cal.gyro.model == "ferraris"
    np.testing.assert_allclose(cal.gyro.stats["g_sensitivity"], fer.g_sensitivity, rtol=RTOL)
    np.testing.assert_allclose(cal.accel.stats["accel_counts_per_g"], fer.accel_counts_per_g,
                               rtol=RTOL)
    # the coefficients are printed as the table of the calibration file
    for sensor in ("accel", "gyro"):
        table = tc.report.text.coefficient_table(cal.part(sensor), sensor)
        assert "\n".join("  " + r for r in table) in text
    # a +-16 g accelerometer (2048 counts per g) and a +-2000 deg/s gyro (16.4 per deg/s)
    assert "accel x 2045.83  y 2040.49  z 2107.04 counts per g" in text


def test_ferraris_on_the_continuous_session_and_its_section_list(realdata, tmp_path, capsys):
    d = realdata / "imucal-ferraris"
    out = tmp_path / "cal.json"
    rc, text, _ = _run(capsys, "ferraris", d / "example_ferraris_session.csv", "--sections",
                       d / "example_ferraris_session_list.json", "--rate-hz", "102.4",
                       "--accel-raw-unit", "m/s^2", "--gyro-raw-unit", "deg/s", "-o", out)
    assert rc == 0, text
    acc, gyr, sec = load_ferraris_session(realdata)
    fer = tc.ferraris({k: (acc[a:b], gyr[a:b]) for k, (a, b) in sec.items()}, rate_hz=102.4,
                      gravity=9.81)
    cal = tc.Calibration.load(out)
    _same(cal.accel, fer.accel.offset, fer.accel.matrix)
    _same(cal.gyro, fer.gyro.offset, fer.gyro.matrix)
    # readings already in m/s^2 and deg/s: the gate checked the gains lie near 1
    assert (cal.accel.raw_unit, cal.gyro.raw_unit) == ("m/s^2", "deg/s")
    assert cal.accel.valid and cal.gyro.valid
    assert "turned x clockwise, y clockwise, z clockwise" in text


def test_ferraris_refusals(realdata, tmp_path, capsys):
    d = realdata / "imucal-ferraris"
    out = tmp_path / "cal.json"
    # counts declared as m/s^2: gains of 0.005 where 1 is expected; the gate writes nothing
    rc, _, err = _run(capsys, "ferraris", d / "annotated_session.csv", "--rate-hz", "204.8",
                      "--accel-raw-unit", "m/s^2", "-o", out)
    assert rc == 2 and "not written" in err and "gains should lie near 1" in err
    assert not out.exists()
    # --force writes both, marked not valid
    rc, _, _ = _run(capsys, "ferraris", d / "annotated_session.csv", "--rate-hz", "204.8",
                    "--accel-raw-unit", "m/s^2", "--force", "-o", out)
    cal = tc.Calibration.load(out)
    assert rc == 0 and cal.accel.valid is False and cal.gyro.valid is True
    # a continuous recording without its list of sections
    rc, _, err = _run(capsys, "ferraris", d / "example_ferraris_session.csv", "--rate-hz",
                      "102.4", "-o", tmp_path / "x.json")
    assert rc == 1 and "--sections" in err
    # a section list that misses a section, or runs past the recording
    bad = tmp_path / "list.json"
    bad.write_text('{"x_p": {"start": 0, "end": 10}}')
    rc, _, err = _run(capsys, "ferraris", d / "example_ferraris_session.csv", "--sections", bad,
                      "--rate-hz", "102.4", "-o", tmp_path / "x.json")
    assert rc == 1 and "no section x_a" in err
    sec = (d / "example_ferraris_session_list.json").read_text().replace('"end":9512',
                                                                          '"end":99999')
    assert "99999" in sec
    bad.write_text(sec)
    rc, _, err = _run(capsys, "ferraris", d / "example_ferraris_session.csv", "--sections", bad,
                      "--rate-hz", "102.4", "-o", tmp_path / "x.json")
    assert rc == 1 and "outside the recording" in err
    # no rate and no time column
    rc, _, err = _run(capsys, "ferraris", d / "annotated_session.csv", "-o", tmp_path / "x.json")
    assert rc == 1 and "--rate-hz" in err


def test_part_from_ferraris_judges_both_before_returning_either(realdata):
    fer = tc.ferraris(load_ferraris_annotated(realdata), rate_hz=204.8, gravity=9.81)
    with pytest.raises(tc.calibration.gate.InvalidCalibrationError, match="this gyro fit"):
        part_from_ferraris(fer, gravity=9.81, unit="m/s^2", gyro_raw_unit="rad/s")
    parts = part_from_ferraris(fer, gravity=9.81, unit="m/s^2")
    assert set(parts) == {"accel", "gyro"} and all(p.valid for p in parts.values())


# --- imu (Tedaldi) ----------------------------------------------------------------------------


def test_imu_on_the_imutk_xsens_recording(realdata, tmp_path, capsys):
    d = realdata / "imutk-xsens"
    out = tmp_path / "cal.json"
    rc, text, _ = _run(capsys, "imu", d / "xsens_acc.mat", d / "xsens_gyro.mat",
                       "--time-column", "0", "--accel-columns", "1,2,3", "--gyro-columns",
                       "1,2,3", "--rate-hz", "100", "--gravity", "9.81744", "-o", out)
    assert rc == 0, text
    t, acc, gyr = load_imutk_xsens(realdata)
    res = tc.calibrate_imu(acc, gyr, rate_hz=100, gravity=9.81744, t=t)
    cal = tc.Calibration.load(out)
    _same(cal.accel, res.accel.offset, res.accel.matrix)
    _same(cal.gyro, res.gyro.offset, res.gyro.matrix)
    np.testing.assert_allclose(cal.gyro.stats["g_sensitivity"], res.gyro_g_sensitivity,
                               rtol=RTOL)
    assert cal.accel.model == "imu" and cal.accel.valid and cal.gyro.valid
    assert cal.gyro.stats["gyro_source"]["path"].endswith("xsens_gyro.mat")
    # the maker's certificate (test_imu.py): gains within 0.25 %
    inv = np.linalg.norm(np.linalg.inv(cal.gyro.matrix), axis=1)
    np.testing.assert_allclose(inv, [4778.0, 4758.0, 4766.0], rtol=2.5e-3)
    assert "40 still poses and 37 turns" in text and "model full" in text


def test_imu_refuses_sensors_not_sampled_together(realdata, tmp_path, capsys):
    d = realdata / "imutk-xsens"
    short = tmp_path / "gyro.txt"
    short.write_text("\n".join((d / "xsens_gyro.mat").read_text().splitlines()[:1000]) + "\n")
    rc, _, err = _run(capsys, "imu", d / "xsens_acc.mat", short, "--time-column", "0",
                      "--accel-columns", "1,2,3", "--gyro-columns", "1,2,3", "-o",
                      tmp_path / "c.json")
    assert rc == 1 and "row for row" in err
    rc, _, err = _run(capsys, "imu", d / "xsens_acc.mat", "--accel-columns", "1,2,3",
                      "-o", tmp_path / "c.json")
    assert rc == 1 and "--gyro-columns" in err


# --- turntable --------------------------------------------------------------------------------


def test_turntable_on_the_gearvr_recordings(realdata, tmp_path, capsys):
    d = realdata / "freeimucal-gearvr"
    out = tmp_path / "cal.json"
    rc, text, _ = _run(capsys, "turntable", d / "33RPMgyr.txt", d / "45RPMgyr.txt", "--rpm",
                       "100/3", "--rpm", "45", "--bias", d / "0RPMgyr.txt", "--rate-hz", "100",
                       "--rest", "10", "--raw-unit", "rad/s", "-o", out)
    assert rc == 0, text
    bias = tc.gyro_bias(load_gearvr(realdata, "0RPMgyr.txt"), rate_hz=100, rest_s=10.0)
    rates = [2 * math.pi * (100 / 3) / 60, 2 * math.pi * 45 / 60]
    fit = tc.fit_turntable([load_gearvr(realdata, "33RPMgyr.txt"),
                            load_gearvr(realdata, "45RPMgyr.txt")], rates, offset=bias.offset)
    cal = tc.Calibration.load(out)
    _same(cal.gyro, fit.offset, fit.matrix)
    assert cal.gyro.model == "turntable" and cal.gyro.unit == "rad/s" and cal.gyro.valid
    assert cal.gyro.stats["n_plateaus"] == list(fit.n_plateaus)
    # both speeds within 0.2 % of the table's after calibration (test_gyro.py)
    assert np.all(np.abs(fit.rel_error) < 2e-3)
    assert "24 plateaus" in text and "40 plateaus" in text
    # in deg/s, from one speed given for every file
    given = "--bias=" + ",".join(repr(float(v)) for v in bias.offset)  # a negative first
    rc, _, _ = _run(capsys, "turntable", d / "45RPMgyr.txt", "--rpm", "45", given, "--unit",
                    "deg/s", "--raw-unit", "rad/s", "-o", tmp_path / "deg.json")
    deg = tc.Calibration.load(tmp_path / "deg.json").gyro
    one = tc.fit_turntable([load_gearvr(realdata, "45RPMgyr.txt")], [rates[1]],
                           offset=bias.offset)  # found in rad/s, the readings' unit
    assert rc == 0 and deg.unit == "deg/s"
    _same(deg, one.offset, one.matrix * 180 / math.pi)
    # counts need the datasheet's scale to find the plateaus in them
    rc, _, err = _run(capsys, "turntable", d / "45RPMgyr.txt", "--rpm", "45", "--bias", "0,0,0",
                      "-o", tmp_path / "c.json")
    assert rc == 1 and "--counts-per-unit" in err


def test_turntable_refusals(realdata, tmp_path, capsys):
    d = realdata / "freeimucal-gearvr"
    rc, _, err = _run(capsys, "turntable", d / "33RPMgyr.txt", d / "45RPMgyr.txt", "--rpm", "45",
                      "--rpm", "33", "--rpm", "78", "--bias", "0,0,0", "-o", tmp_path / "c.json")
    assert rc == 1 and "2 files and 3 --rpm" in err
    with pytest.raises(SystemExit):
        main(["turntable", str(d / "33RPMgyr.txt"), "--rpm", "45", "-o", str(tmp_path / "c.json")])
    assert "--bias" in capsys.readouterr().err
    rc, _, err = _run(capsys, "turntable", d / "33RPMgyr.txt", "--rpm", "100", "--bias", "0,0,0",
                      "--raw-unit", "rad/s", "-o", tmp_path / "c.json")
    assert rc == 1 and "no constant-rate plateau" in err
    assert not (tmp_path / "c.json").exists()


# --- gyro-gains: whole turns about one axis, the bias from a recording at rest ----------------


SUNSIDED_TURNS = (("x", "rotate-360ccw-around-x-pointing-forward"),
                  ("y", "rotate-360ccw-around-y-pointing-left"),
                  ("z", "rotate-360ccw-around-z-pointing-up"))


def _sunsided_csv(realdata: Path, folder: str, path: Path) -> Path:
    """A sunsided gyro buffer (HDF5 .mat) as the table the command reads, digits kept."""
    np.savetxt(path, load_sunsided(realdata, folder, "gyroscope"), delimiter=",",
               header="t,gx,gy,gz", comments="", fmt="%.17g")
    return path


def test_gyro_gains_whole_turns_about_one_axis_with_an_external_bias(realdata, tmp_path, capsys):
    rest = _sunsided_csv(realdata, "unmoved-x-pointing-forward", tmp_path / "rest.csv")
    out = tmp_path / "cal.json"
    rest_g = load_sunsided(realdata, "unmoved-x-pointing-forward", "gyroscope")
    bias = tc.gyro_bias(rest_g[:, 1:], rate_hz=tc.methods.gyro.sample_rate(rest_g[:, 0]),
                        rest_s=3.0).offset
    gains = {}
    for axis, folder in SUNSIDED_TURNS:
        data = _sunsided_csv(realdata, folder, tmp_path / f"turns_{axis}.csv")
        # the recording never rests: without the bias from the rest it is refused
        rc, _, err = _run(capsys, "gyro-gains", data, "--angle", "720", "--turns", "whole",
                          "--axes", axis, "-o", tmp_path / "no.json")
        assert rc == 1 and not (tmp_path / "no.json").exists()
        if axis == "x":  # one still period found: the message says what to pass
            assert "--turns whole" in err and "--bias" in err, err
        rc, text, _ = _run(capsys, "gyro-gains", data, "--angle", "720", "--turns", "whole",
                           "--axes", axis, "--bias", rest, "--counts-per-unit", "1",
                           "--raw-unit", "deg/s", "-o", out)
        assert rc == 0, text
        g = load_sunsided(realdata, folder, "gyroscope")
        res = tc.gyro_gains(g[:, 1:], angle_deg=720, t=g[:, 0], offset=bias, turns="whole",
                            axes=axis, nominal_counts_per_dps=1.0)
        k = "xyz".index(axis)
        part = tc.Calibration.load(out).gyro
        np.testing.assert_allclose(part.offset, res.offset, rtol=RTOL)
        assert part.matrix[k, k] == pytest.approx(1 / res.gain_counts_per_dps[k], rel=RTOL)
        assert part.stats["gain_from"][k] == "turns" and part.valid
        (rot,) = res.rotations
        assert (rot.start, rot.end) == (0, len(g))  # the whole recording is the turn
        gains[axis] = (rot.direction, res.gain_counts_per_dps[k])
        assert "  " + tc.report.text.coefficient_table(part, "gyro")[0] in text
    # the author's flipped x axis reads its ccw turns as cw; gains within 0.3 % of 1 deg/s per
    # deg/s: 1.0009, 1.0024, 1.0023 (test_gyro.py)
    assert {a: d for a, (d, _) in gains.items()} == {"x": "cw", "y": "ccw", "z": "ccw"}
    np.testing.assert_allclose([v for _, v in gains.values()], 1.0, atol=3e-3)
    # the file holds all three: each run kept the axes turned before
    part = tc.Calibration.load(out).gyro
    np.testing.assert_allclose(np.diag(part.matrix), [1 / v for _, v in gains.values()],
                               rtol=RTOL)
    assert part.stats["gain_from"] == ["existing part", "existing part", "turns"]  # z last


def test_gyro_gains_one_axis_needs_the_others_from_somewhere(realdata, tmp_path, capsys):
    rest = _sunsided_csv(realdata, "unmoved-x-pointing-forward", tmp_path / "rest.csv")
    data = _sunsided_csv(realdata, SUNSIDED_TURNS[2][1], tmp_path / "z.csv")
    rc, _, err = _run(capsys, "gyro-gains", data, "--angle", "720", "--turns", "whole", "--axes",
                      "z", "--bias", rest, "--raw-unit", "deg/s", "-o", tmp_path / "c.json")
    assert rc == 1 and "no gain for x, y" in err and "--counts-per-unit" in err
    assert not (tmp_path / "c.json").exists()


def test_the_gate_judges_an_unsigned_adcs_offset_from_its_mid_scale():
    """The Xsens MTi of imu_tk reads 0 g near 32768 counts (an unsigned 16-bit ADC): its
    offset is judged from there; a signed register's offset from 0."""
    from triaxcal.calibration.gate import check_part as check

    xsens = tc.SensorCalibration(offset=[33123.0, 33276.0, 32360.0], matrix=np.eye(3) / 415.0,
                                 unit="m/s^2", radius=9.81744, model="imu")
    assert check(xsens, "accel").valid
    for offset in ([33123.0 - 6000, 33276.0, 32360.0],  # 14 m/s^2 from mid-scale
                   [5000.0, 0.0, 0.0]):  # 12 m/s^2 from 0, far from any mid-scale
        v = check(xsens.replace(offset=np.array(offset)), "accel")
        assert not v.valid and "its offset reaches" in v.reasons[0]
    # readings in m/s^2 are never taken for ADC codes
    assert not check(xsens.replace(raw_unit="m/s^2", matrix=np.eye(3)), "accel").valid


# --- the documentation page, as written --------------------------------------------------------


def test_method_commands_page_runs_on_the_real_recordings(realdata, tmp_path, monkeypatch,
                                                          capsys):
    """The blocks of docs/guide/method-commands.md marked ``realdata``, in order, in a folder
    laid out as the data registry lays out the recordings: each command prints what the page
    shows."""
    import shlex

    from test_seed_commands import PAGE, console, page_blocks

    for folder in realdata.iterdir():
        (tmp_path / folder.name).symlink_to(folder, target_is_directory=True)
    monkeypatch.chdir(tmp_path)
    blocks = page_blocks(realdata=True)
    ran = []
    for info, body in blocks:
        if info.split()[0] == "python":
            exec(compile(body, str(PAGE), "exec"), {})
        elif info.split()[0] == "console":
            for cmd, want in console(body):
                argv = shlex.split(cmd)
                assert argv[0] == "triaxcal"
                capsys.readouterr()
                rc = main(argv[1:])
                got = [ln.rstrip() for ln in capsys.readouterr().out.splitlines()]
                assert rc == 0, cmd
                assert got == want, f"{cmd}\n--- page\n" + "\n".join(want) + "\n--- now\n" + \
                    "\n".join(got)
                ran.append(argv[1])
    assert {"ferraris", "imu", "turntable", "gyro-gains"} <= set(ran)
    cal = tc.Calibration.load(tmp_path / "whole.json")
    assert cal.gyro.stats["gain_from"] == ["existing part", "existing part", "turns"]
