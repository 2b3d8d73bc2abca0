"""The methods from the command line: every command of the documentation page
docs/guide/method-commands.md, run as written, prints what the page shows and writes a part that
export and report take."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import numpy as np
import pytest
import triaxcal as tc
from triaxcal.cli import main

ROOT = Path(__file__).resolve().parent.parent
PAGE = ROOT / "docs" / "guide" / "method-commands.md"


def page_blocks(realdata: bool = False) -> list[tuple[str, str]]:
    """(info string, body) of every fenced block of the page, in order: those that run on the
    simulator, or (``realdata``) those marked ``realdata``, which run on the published
    recordings (tests/test_method_commands.py)."""
    blocks = re.findall(r"```([^\n]*)\n(.*?)```", PAGE.read_text(), re.S)
    return [(info, body) for info, body in blocks if ("realdata" in info.split()) == realdata]


def console(body: str) -> list[tuple[str, list[str]]]:
    """(command, expected output lines) of a console block."""
    out: list[tuple[str, list[str]]] = []
    for line in body.splitlines():
        if line.startswith("$ "):
            out.append((line[2:], []))
        elif out:
            out[-1][1].append(line.rstrip())
    return out


def run_section(tmp_path: Path, monkeypatch, capsys) -> list[tuple[str, list[str], list[str]]]:
    """Run the section in ``tmp_path``: (command, the page.s output, actual output)."""
    monkeypatch.chdir(tmp_path)
    done = []
    for info, body in page_blocks():
        words = info.split()
        if words and words[0] == "python":
            exec(compile(body, str(PAGE), "exec"), {})
            capsys.readouterr()
        elif any(w.startswith("file=") for w in words):
            name = next(w for w in words if w.startswith("file="))[5:]
            (tmp_path / name).write_text(body)
        elif words and words[0] == "console":
            for cmd, want in console(body):
                argv = shlex.split(cmd)
                assert argv[0] == "triaxcal"
                rc = main(argv[1:])
                got = [ln.rstrip() for ln in capsys.readouterr().out.splitlines()]
                assert rc == 0, (cmd, got)
                done.append((cmd, want, got))
    return done


def test_page_runs_and_prints_what_it_shows(tmp_path, monkeypatch, capsys):
    done = run_section(tmp_path, monkeypatch, capsys)
    assert len(done) >= 6
    for cmd, want, got in done:
        assert got == want, f"{cmd}\n--- page\n" + "\n".join(want) + "\n--- now\n" + \
            "\n".join(got)


@pytest.fixture(scope="module")
def section(tmp_path_factory):
    """The page.s files and calibration files, made once."""
    import contextlib
    import io
    import os

    d = tmp_path_factory.mktemp("seeds")
    old = os.getcwd()
    os.chdir(d)
    try:
        for info, body in page_blocks():
            words = info.split()
            if words and words[0] == "python":
                with contextlib.redirect_stdout(io.StringIO()):
                    exec(compile(body, str(PAGE), "exec"), {})
            elif any(w.startswith("file=") for w in words):
                name = next(w for w in words if w.startswith("file="))[5:]
                (d / name).write_text(body)
            elif words and words[0] == "console":
                for cmd, _ in console(body):
                    with contextlib.redirect_stdout(io.StringIO()):
                        assert main(shlex.split(cmd)[1:]) == 0
    finally:
        os.chdir(old)
    return d


def _run(capsys, *argv: str) -> str:
    capsys.readouterr()
    assert main([str(a) for a in argv]) == 0
    return capsys.readouterr().out


def _fails(capsys, *argv: str) -> str:
    capsys.readouterr()
    assert main([str(a) for a in argv]) == 1
    return capsys.readouterr().err


# --- sphere-center ----------------------------------------------------------------------------

GLOBE_OFFSET = tc.sim.SimIMU(1).truth.accel.offset  # the page.s board (its scale is forced)


def test_sphere_center_finds_the_seed_offset(section, tmp_path, capsys):
    cal = tc.Calibration.load(section / "cal.json")
    # the page ran descent, then grid, into cal.json: the grid's part is the one kept
    assert cal.accel.stats["method"] == "grid" and cal.accel.model == "sphere"
    np.testing.assert_allclose(cal.accel.offset, GLOBE_OFFSET, atol=3.0)  # counts (0.2 mg)
    np.testing.assert_allclose(cal.accel.matrix, np.eye(3) / 16384)
    assert cal.accel.unit == "g" and cal.accel.radius == 1.0
    for method in ("descent", "grid"):
        out = tmp_path / f"{method}.json"
        _run(capsys, "sphere-center", section / "globe.csv", "--radius", "16384", "--method",
             method, "-o", out)
        part = tc.Calibration.load(out).accel
        np.testing.assert_allclose(part.offset, GLOBE_OFFSET, atol=3.0)
        # the mean of the readings, which the seed warns about, is far worse
        mean = np.loadtxt(section / "globe.csv", delimiter=",", skiprows=1).mean(axis=0)
        assert np.abs(mean - GLOBE_OFFSET).max() > 10 * np.abs(part.offset - GLOBE_OFFSET).max()
        # the part is the seed's: a 1 g reading along z calibrates to 1 g
        raw = GLOBE_OFFSET + [0, 0, 16384.0]
        np.testing.assert_allclose(part.apply(raw), [0, 0, 1], atol=3e-4)


def test_sphere_center_on_a_wedge(tmp_path, capsys):
    # the seed: "if you know the radius exactly, you can calculate the center only by its
    # wedge" -- 60 readings within 60 deg of +Z
    rng = np.random.default_rng(5)
    u = rng.normal(size=(4000, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    u = u[u[:, 2] > 0.5][:60]
    off = np.array([856.0, -249.0, 642.0])
    pts = u * 16384 + off + rng.normal(0, 4.0, u.shape)
    f = tmp_path / "cap.csv"
    np.savetxt(f, pts, delimiter=",", header="ax,ay,az", comments="")
    out = _run(capsys, "sphere-center", f, "--radius", "16384", "-o", tmp_path / "c.json")
    part = tc.Calibration.load(tmp_path / "c.json").accel
    assert np.abs(part.offset - off).max() < 5.0
    assert "plain mean of the readings would say" in out
    assert np.abs(pts.mean(axis=0) - off).max() > 5000  # the mean is useless on a wedge


def test_sphere_center_fit_method(section, tmp_path, capsys):
    argv = ("sphere-center", section / "globe.csv", "--radius", "16384", "--method", "fit",
            "-o", tmp_path / "f.json")
    _run(capsys, *argv)
    part = tc.Calibration.load(tmp_path / "f.json").accel
    np.testing.assert_allclose(part.offset, GLOBE_OFFSET, atol=3.0)
    assert part.stats["method"] == "fit"
    assert set(part.stats["stderr"]) == {"offset_x", "offset_y", "offset_z"}
    assert all(0 < v < 3 for v in part.stats["stderr"].values())


def test_sphere_center_scales_and_units(section, tmp_path, capsys):
    out = tmp_path / "m.json"
    _run(capsys, "sphere-center", section / "globe.csv", "--radius", "16384", "--scale-to",
         "none", "-o", out)
    part = tc.Calibration.load(out).accel
    assert part.unit == "counts" and part.model == "offset"
    np.testing.assert_array_equal(part.matrix, np.eye(3))
    _run(capsys, "sphere-center", section / "globe.csv", "--radius", "16384", "--columns",
         "0,1,2", "--sensor", "mag", "--scale-to", "48uT", "-o", out)
    mag = tc.Calibration.load(out).mag
    assert mag.unit == "uT" and mag.matrix[0, 0] == pytest.approx(48 / 16384)
    assert tc.Calibration.load(out).accel is not None  # the other sensor kept
    for bad, why in ((["--radius", "1g"], "raw units"), (["--radius", "-3"], "radius"),
                     (["--radius", "16384", "--start", "1,2"], "--start"),
                     (["--radius", "16384", "--scale-to", "3"], "unit")):
        assert why in _fails(capsys, "sphere-center", section / "globe.csv", *bad, "-o", out)
    with pytest.raises(SystemExit):  # refused as it is parsed
        main(["sphere-center", str(section / "globe.csv"), "--radius", "16384", "--method",
              "grid", "--half-width", "0", "-o", str(out)])
    assert "--half-width: expected a number > 0" in capsys.readouterr().err
    few = tmp_path / "few.csv"
    few.write_text("ax,ay,az\n1,2,3\n4,5,6\n")
    assert "at least 4" in _fails(capsys, "sphere-center", few, "--radius", "10", "-o", out)


def test_sphere_center_reads_a_session_with_poses(tmp_path, capsys):
    rec = tc.sim.SimIMU(1, accel={"scale": [1.0, 1.0, 1.0]}).record(tc.sim.globe_script(),
                                                                     rate_hz=100)
    f = tmp_path / "session.csv"
    np.savetxt(f, np.column_stack([rec.t, rec.frames(10)]), delimiter=",", comments="",
               header="t,ax,ay,az,gx,gy,gz,mx,my,mz,temp", fmt="%.6g")
    _run(capsys, "sphere-center", f, "--poses", "--radius", "16384", "-o", tmp_path / "p.json")
    part = tc.Calibration.load(tmp_path / "p.json").accel
    assert part.stats["n_poses"] == 84 and part.stats["n"] == 84
    np.testing.assert_allclose(part.offset, GLOBE_OFFSET, atol=4.0)  # 0.25 mg


# --- tilt-rig --------------------------------------------------------------------------------


def test_tilt_rig_reproduces_the_seed(section, capsys):
    part = tc.Calibration.load(section / "tilt.json").accel
    # the seed's offsets, the corrected gains, the z offset it cannot measure left at 0
    np.testing.assert_allclose(part.offset, [0.007894833, 0.009969, 0.0], rtol=1e-6, atol=1e-9)
    want = tc.tilt_rig(_seed_tilts(section), angle_deg=10)
    np.testing.assert_allclose(np.diag(part.matrix), want.gain, rtol=1e-12)
    assert part.raw_unit == "g" and part.unit == "g" and part.stats["method"] == "tilt-rig"
    # the gains the implied angle (8.15 deg) gives are recorded with the warning
    alt = tc.tilt_rig(_seed_tilts(section), angle_deg=float(np.mean(want.implied_angle_deg)))
    np.testing.assert_allclose(part.stats["gain_at_implied_angle"], alt.gain, rtol=1e-12)
    # at the implied angle there is nothing to warn about
    out = _run(capsys, "tilt-rig", section / "tilt.txt", "--angle", "8.15", "--columns",
               "2,3,4", "--raw-unit", "g", "-o", section / "tilt815.json")
    assert "warning" not in out


def _seed_tilts(section: Path) -> dict[str, np.ndarray]:
    from triaxcal.io.sections import read_tilts

    return {k: v[:, 2:5] for k, v in read_tilts(section / "tilt.txt").groups.items()}


def test_tilt_rig_layouts_and_errors(section, tmp_path, capsys):
    groups = _seed_tilts(section)
    labelled = tmp_path / "labelled.csv"
    lines = ["label,ax,ay,az"] + [f"{k.upper()},{','.join(map(str, r))}" for k, rows in
                                  groups.items() for r in rows]
    labelled.write_text("\n".join(lines).replace("FORE_DOWN", "FD").replace("AFT_DOWN", "AD")
                        .replace("LEFT_DOWN", "LD").replace("RIGHT_DOWN", "RD") + "\n")
    _run(capsys, "tilt-rig", labelled, "--angle", "10", "--raw-unit", "g", "-o",
         tmp_path / "l.json")
    seed = tc.Calibration.load(section / "tilt.json").accel
    assert tc.Calibration.load(tmp_path / "l.json").accel.offset.tolist() == pytest.approx(
        seed.offset.tolist())
    bad = tmp_path / "bad.txt"
    bad.write_text("FD\n0.1,0,1\nAD\n-0.1,0,1\n")
    assert "left_down, right_down" in _fails(capsys, "tilt-rig", bad, "--angle", "10", "-o",
                                             tmp_path / "b.json")
    bad.write_text("0.1,0,1\n")
    assert "before any tilt label" in _fails(capsys, "tilt-rig", bad, "--angle", "10", "-o",
                                             tmp_path / "b.json")
    bad.write_text("FD\n0.1,0,1\nAD\n-0.1,x,1\n")
    assert "line 4" in _fails(capsys, "tilt-rig", bad, "--angle", "10", "-o", tmp_path / "b.json")
    assert "--columns" in _fails(capsys, "tilt-rig", section / "tilt.txt", "--angle", "10", "-o",
                                 tmp_path / "b.json")
    assert "in (0, 90), got 95" in _fails(capsys, "tilt-rig", section / "tilt.txt", "--angle",
                                        "95", "--columns", "2,3,4", "-o", tmp_path / "b.json")


# --- gyro-gains ------------------------------------------------------------------------------


def test_gyro_gains_recover_the_simulated_gyro(section):
    truth = tc.sim.SimIMU(1, gyro={"scale": [131 / 16.4 * k for k in (1.01, 0.985, 1.0)]}
                          ).truth.gyro
    counts_per_dps = np.pi / 180 / np.diag(truth.matrix)
    part = tc.Calibration.load(section / "cal.json").gyro
    gains = np.array(part.stats["gain_counts_per_dps"])
    np.testing.assert_allclose(gains, counts_per_dps, rtol=1e-3)
    # the part's matrix holds the inverse of the dividing gain: raw counts -> deg/s
    raw = part.offset + [10 * counts_per_dps[0], 0, 0]
    got = part.apply([raw], temperature=part.temperature.temp_ref_c)[0]
    np.testing.assert_allclose(got, [10, 0, 0], atol=0.02)


def test_gyro_gains_name_the_axis_whose_directions_differ(section, capsys):
    out = _run(capsys, "gyro-gains", section / "turns_short.csv", "--angle", "90", "-o",
               section / "short2.json")
    warns = [ln for ln in out.splitlines() if ln.startswith("warning:")]
    assert len(warns) == 1 and warns[0].startswith("warning: x: clockwise")
    assert "not the same angle both ways" in warns[0] and "82" not in warns[0][:40]
    stats = tc.Calibration.load(section / "short2.json").gyro.stats
    assert abs(stats["asymmetry"][0]) > 0.08 and max(abs(a) for a in stats["asymmetry"][1:]) < 0.01


def test_gyro_gains_name_saturation(tmp_path, capsys):
    imu = tc.sim.SimIMU(1, gyro={"scale": [131 / 16.4] * 3})  # +-2000 deg/s range
    d = np.radians
    moves = [[d(90), 0, 0], [-d(90), 0, 0], [0, d(90), 0], [0, -d(90), 0], [0, 0, d(90)],
             [0, 0, -d(90)]]
    # the last (clockwise) turn about z peaks at 3000 deg/s: past the range
    script = tc.sim.Script.from_moves(np.eye(3), moves, hold_s=[4, 1, 1, 1, 1, 1, 1],
                                      move_s=[0.5, 0.5, 0.5, 0.5, 0.5, 0.056])
    rec = imu.record(script, rate_hz=1000)
    f = tmp_path / "fast.csv"
    np.savetxt(f, np.column_stack([rec.t, rec.frames(10)]), delimiter=",", comments="",
               header="t,ax,ay,az,gx,gy,gz,mx,my,mz,temp", fmt="%.6g")
    assert np.abs(rec.gyro[:, 2]).max() >= 32767
    out = _run(capsys, "gyro-gains", f, "--angle", "90", "-o", tmp_path / "g.json")
    warns = [ln for ln in out.splitlines() if ln.startswith("warning:")]
    assert len(warns) == 1 and warns[0].startswith("warning: z: clockwise")
    assert "the clockwise turn saturated the gyro" in warns[0]


# --- temperature -----------------------------------------------------------------------------


def test_temperature_adds_the_seed_tempcomp_to_the_gains(section):
    cal = tc.Calibration.load(section / "cal.json")
    g = cal.gyro
    assert g.temperature is not None and g.stats["method"] == "temperature"
    np.testing.assert_allclose(g.temperature.offset_poly[1], [3.0, -2.0, 1.5], atol=0.02)
    np.testing.assert_allclose(np.array(g.stats["gain_counts_per_dps"]),
                               1 / np.diag(g.matrix), rtol=1e-12)  # gyro-gains' gains kept
    imu = tc.sim.SimIMU(1, gyro={"scale": [131 / 16.4 * k for k in (1.01, 0.985, 1.0)],
                                 "tempco": [3.0, -2.0, 1.5]})
    for temp in (12.0, 20.0, 28.0):
        rest = imu.truth.gyro.offset_at(np.array([temp]))[0]
        np.testing.assert_allclose(g.apply([rest], temperature=temp)[0], 0, atol=0.01)  # deg/s


def test_temperature_alone_and_errors(section, tmp_path, capsys):
    out = tmp_path / "t.json"
    _run(capsys, "temperature", section / "warmup.csv", "--degree", "2", "-o", out)
    part = tc.Calibration.load(out).gyro
    assert part.unit == "counts" and part.temperature.offset_poly.shape == (3, 3)
    np.testing.assert_allclose(part.temperature.offset_poly[1], [3.0, -2.0, 1.5], atol=0.05)
    notemp = tmp_path / "n.csv"
    notemp.write_text("t,gx,gy,gz\n0,1,2,3\n1,1,2,3\n")
    assert "temperature column" in _fails(capsys, "temperature", notemp, "-o", out)
    assert "no such column" in _fails(capsys, "temperature", section / "warmup.csv",
                                      "--temp-column", "T", "-o", out)


# --- export and report take every part ---------------------------------------------------------


def test_export_and_report_take_the_parts(section, tmp_path, capsys):
    cal = section / "cal.json"
    _run(capsys, "export", cal, "--format", "c", "-o", tmp_path / "cal.h")
    header = (tmp_path / "cal.h").read_text()
    assert "accel_apply" in header and "gyro_apply_t" in header
    text = _run(capsys, "report", cal)
    assert "accel calibration report" in text and "coverage        100 %" in text
    assert "gyro calibration (counts -> deg/s, temperature)" in text and "drift" in text
    text = _run(capsys, "report", section / "tilt.json")
    assert "readings        12" in text and "residual RMS" in text
    text = _run(capsys, "report", section / "short.json")
    assert "warnings" in text and "x: clockwise" in text
