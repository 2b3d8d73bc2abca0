"""Files that cannot be read or written give messages, never tracebacks: folders, missing
folders, full disks (/dev/full, a file size limit), /proc, truncated captures, junk lines."""

from __future__ import annotations

import os
import stat
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import triaxcal as tc
from triaxcal import sim
from triaxcal.capture.run import SessionWriteError, SessionWriter, read_session
from triaxcal.cli import main
from triaxcal.io.serial import Record
from triaxcal.io.tables import read_table

ROOT = Path(__file__).resolve().parent.parent
HAVE_DEV_FULL = os.path.exists("/dev/full") and stat.S_ISCHR(os.stat("/dev/full").st_mode)


def _session(tmp_path: Path, name: str = "session.csv", n_poses: int = 26) -> Path:
    """A capture-style session of still poses over the sphere (accelerometer counts)."""
    rng = np.random.default_rng(0)
    k = np.arange(n_poses) + 0.5
    z = 1 - 2 * k / n_poses
    phi = k * np.pi * (3 - np.sqrt(5))
    dirs = np.column_stack([np.sqrt(1 - z * z) * np.cos(phi), np.sqrt(1 - z * z) * np.sin(phi),
                            z])
    rows, t = [], 0.0
    for u in dirs:
        for _ in range(60):
            a = [300, -200, 150] + u * 16384 + rng.normal(scale=15, size=3)
            rows.append(f"{t:.3f}," + ",".join(str(round(v)) for v in a) + ",1,2,3")
            t += 0.01
    p = tmp_path / name
    p.write_text("t,ax,ay,az,gx,gy,gz\n" + "\n".join(rows) + "\n")
    return p


def _no_traceback(err: str) -> None:
    assert "Traceback" not in err, err


# ----------------------------------------------------------------------- fit, export, report


def test_fit_a_directory(tmp_path, capsys):
    _session(tmp_path)
    assert main(["fit", str(tmp_path), "-o", str(tmp_path / "c.json")]) == 1
    err = capsys.readouterr().err
    _no_traceback(err)
    assert "is a folder" in err and "session.csv" in err


def test_fit_into_a_missing_folder_fails_before_fitting(tmp_path, capsys):
    sess = _session(tmp_path)
    out = tmp_path / "missing_dir" / "x.json"
    assert main(["fit", str(sess), "--poses", "-o", str(out)]) == 1
    err = capsys.readouterr().err
    assert "folder" in err and "does not exist" in err and "mkdir -p" in err
    assert not out.parent.exists()
    assert main(["fit", str(sess), "--poses", "-o", str(tmp_path)]) == 1
    assert "is a folder" in capsys.readouterr().err


@pytest.mark.skipif(not HAVE_DEV_FULL, reason="needs /dev/full")
def test_fit_and_export_to_a_full_device(tmp_path, capsys):
    sess = _session(tmp_path)
    assert main(["fit", str(sess), "--poses", "-o", "/dev/full"]) == 1
    err = capsys.readouterr().err
    _no_traceback(err)
    assert "no space left" in err
    assert stat.S_ISCHR(os.stat("/dev/full").st_mode)  # never renamed over a device
    cal = tmp_path / "c.json"
    assert main(["fit", str(sess), "--poses", "-o", str(cal)]) == 0
    for fmt in ("c", "c-fixed", "json", "motioncal"):
        scale = ["--counts-per-unit", "accel=16384:g", "--offsets-only"] \
            if fmt == "motioncal" else []
        assert main(["export", str(cal), "--format", fmt, "-o", "/dev/full", *scale]) == 1
        assert "no space left" in capsys.readouterr().err
    assert stat.S_ISCHR(os.stat("/dev/full").st_mode)


def test_export_and_report_paths(tmp_path, capsys):
    sess = _session(tmp_path)
    cal = tmp_path / "c.json"
    assert main(["fit", str(sess), "--poses", "-o", str(cal)]) == 0
    capsys.readouterr()
    cases = [
        (["export", str(cal), "--format", "c", "-o", str(tmp_path / "no" / "x.h")],
         "does not exist"),
        (["export", str(tmp_path), "--format", "c", "-o", str(tmp_path / "x.h")],
         "is a folder"),
        (["report", str(tmp_path)], "is a folder"),
        (["report", str(cal), "-o", str(tmp_path / "no" / "r.json")], "does not exist"),
        (["report", str(cal), "--plot", str(tmp_path / "no" / "r.png")], "does not exist"),
    ]
    for argv, words in cases:
        assert main(argv) == 1, argv
        err = capsys.readouterr().err
        _no_traceback(err)
        assert words in err, (argv, err)


def test_fit_reports_the_right_line_and_skips_bad_lines_on_request(tmp_path, capsys):
    sess = _session(tmp_path)
    text = sess.read_text().splitlines()
    text.insert(0, "garbage the serial monitor printed")
    text.insert(500, "ERROR: I2C timeout")
    bad = tmp_path / "bad.csv"
    bad.write_text("\n".join(text) + "\n")
    assert main(["fit", str(bad), "--poses", "-o", str(tmp_path / "c.json")]) == 1
    err = capsys.readouterr().err
    assert "line 1:" in err and "--skip-bad-lines" in err  # not "line 2" as before
    assert main(["fit", str(bad), "--poses", "--skip-bad-lines",
                 "-o", str(tmp_path / "c.json")]) == 0
    err = capsys.readouterr().err
    assert "skipped 2 bad lines (first: line 1" in err
    assert tc.Calibration.load(tmp_path / "c.json").accel.stats["lines_skipped"] == 2


def test_fit_accepts_a_capture_cut_by_a_full_disk(tmp_path, capsys):
    sess = _session(tmp_path)
    data = sess.read_bytes()
    cut = tmp_path / "cut.csv"
    cut.write_bytes(data[: len(data) - 7])  # the last row half written
    assert main(["fit", str(cut), "--poses", "-o", str(tmp_path / "c.json")]) == 0
    err = capsys.readouterr().err
    assert "is cut short and was skipped" in err
    cols, rows = read_session(cut)
    assert len(rows) == data.count(b"\n") - 2


# ----------------------------------------------------------------------- capture


def _device(speed: float = 20.0) -> sim.SimDevice:
    return sim.SimDevice(sim.SimIMU(3), sim.globe_script(hold_s=0.5, latitudes=3, turns=4),
                         speed=speed, seed=3)


@pytest.mark.skipif(not HAVE_DEV_FULL, reason="needs /dev/full")
def test_capture_to_dev_full(capsys):
    with _device() as dev:
        rc = main(["capture", "--port", dev.port, "--protocol", "framed", "--samples", "50",
                   "-o", "/dev/full", "--quiet", "--no-bell"])
    err = capsys.readouterr().err
    _no_traceback(err)
    assert rc == 1 and "no space left" in err and "nothing was captured" in err
    assert stat.S_ISCHR(os.stat("/dev/full").st_mode)  # not removed, not replaced


@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="needs /proc")
def test_capture_into_proc(capsys):
    with _device() as dev:
        rc = main(["capture", "--port", dev.port, "--protocol", "framed", "--samples", "50",
                   "-o", "/proc/x.csv", "--quiet", "--no-bell"])
    err = capsys.readouterr().err
    _no_traceback(err)
    assert rc == 1 and "cannot write /proc/x.csv" in err


# A capture in a child process whose files may not grow past LIMIT bytes: the disk "fills"
# in the middle of a batch of rows, exactly like a full disk (write() stores part of the data
# and then fails).
CHILD = textwrap.dedent("""
    import resource, signal, sys
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    limit = int(sys.argv[3])
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    from triaxcal.cli import main
    sys.exit(main(["capture", "--port", sys.argv[1], "--protocol", "framed", "--samples",
                   "100000", "-o", sys.argv[2], "--no-bell", "--quiet"]))
""")


@pytest.mark.skipif(sys.platform != "linux", reason="RLIMIT_FSIZE semantics of Linux")
def test_capture_on_a_full_disk_keeps_whole_rows_and_says_how_many(tmp_path):
    out = tmp_path / "s.csv"
    limit = 40_000
    env = {**os.environ, "PYTHONPATH": str(ROOT / "python")}
    with _device(speed=40.0) as dev:
        res = subprocess.run([sys.executable, "-c", CHILD, dev.port, str(out), str(limit)],
                             capture_output=True, text=True, timeout=120, env=env)
    _no_traceback(res.stderr)
    assert res.returncode == 1, res.stderr
    import re

    m = re.search(r"the first (\d+) rows are safe in", res.stderr)
    assert m, res.stderr
    rows = int(m.group(1))
    data = out.read_bytes()
    assert 0 < len(data) <= limit and data.endswith(b"\n")  # cut back to a whole row
    assert data.count(b"\n") == rows + 1
    t = read_table(out)
    assert t.data.shape == (rows, 11) and t.skipped == 0


def test_session_writer_cuts_back_to_the_last_whole_row(tmp_path, monkeypatch):
    """In-process: the file object fails half-way through a batch."""
    p = tmp_path / "s.csv"
    w = SessionWriter(p, ("ax", "ay", "az"))
    w.write([Record(1.0, (1, 2, 3))] * 5)
    real = w._f

    class HalfFull:
        def write(self, data):
            real.write(data[: len(data) // 2])
            real.flush()
            raise OSError(28, "No space left on device")

        def __getattr__(self, name):
            return getattr(real, name)

    w._f = HalfFull()
    with pytest.raises(SessionWriteError, match="the first 5 rows are safe") as exc:
        w.write([Record(2.0, (4, 5, 6))] * 5)
    assert exc.value.rows == 5 and "no space left" in str(exc.value)
    assert p.read_text().count("\n") == 6 and p.read_text().endswith("\n")
    w.close()  # idempotent after a failure


def test_append_removes_a_row_cut_by_a_crash(tmp_path):
    p = tmp_path / "s.csv"
    with SessionWriter(p, ("ax", "ay", "az")) as w:
        w.write([Record(1.0, (1, 2, 3))])
    with open(p, "a") as f:
        f.write("2.0,4,5")  # cut by a power cut
    with SessionWriter(p, ("ax", "ay", "az"), mode="append") as w:
        w.write([Record(3.0, (7, 8, 9))])
    assert p.read_text() == "t,ax,ay,az\n1.000000,1,2,3\n3.000000,7,8,9\n"
    t = read_table(p)
    assert t.skipped == 0 and t.data.shape == (2, 4)
