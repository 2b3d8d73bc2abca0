"""The command line: fit, export, report, send (against a pseudo-terminal echo board)."""

from __future__ import annotations

import os
import struct
import threading
import tty
from pathlib import Path

import numpy as np
import pytest
import triaxcal as tc
from triaxcal.calibration.request import parse_radius
from triaxcal.cli import main
from triaxcal.export import crc16_modbus, decode_motioncal, motioncal_packet
from triaxcal.io.tables import pick_columns, read_table
from triaxcal.sim import SIM_COUNTS_PER_UNIT

#: The simulated board's driver scale, which send needs for parts in counts (none is assumed).
SCALE = ["--counts-per-unit", "accel=16384:g,gyro=131:deg/s,mag=10:uT"]

ICM = "icm20948-magneto"

# The published Magneto 1.4 results for the same files (jremington/ICM_20948-AHRS,
# example_calibration_data/cal_acc_1.lis and cal_mag_1.lis, also in Mahony_AHRS/
# ICM_20948_Mahony.ino as A_B/A_Ainv and M_B/M_Ainv): Hcalc = Ainv (H - B), after rejecting
# readings whose raw length is more than 2 standard deviations from the mean length.
MAGNETO = {
    "acc": {
        "B": [79.60, -18.56, 383.31],
        "Ainv": [[1.00847, 0.00470, -0.00428], [0.00470, 1.00846, -0.00328],
              [-0.00428, -0.00328, 0.99559]],
        "rejected": [20, 67, 78, 79, 107, 153, 166, 195, 222, 242, 259],
    },
    "mag": {
        "B": [-156.70, -52.79, -141.07],
        "Ainv": [[1.12823, -0.01142, 0.00980], [-0.01142, 1.09539, 0.00927],
              [0.00980, 0.00927, 1.10625]],
        "rejected": [73, 74, 100, 101, 102, 238, 239, 240, 241, 242],
    },
}


def _uniformity(cal_points: np.ndarray) -> float:
    n = np.linalg.norm(cal_points, axis=1)
    return float(np.std(n, ddof=1) / np.mean(n))


@pytest.mark.parametrize("kind,sensor", [("acc", "accel"), ("mag", "mag")])
def test_beats_published_magneto_on_same_data(realdata, tmp_path, capsys, kind, sensor):
    src = realdata / ICM / f"icm_20948_cal_{kind}.csv"
    cal_path = tmp_path / "cal.json"
    # Magneto's procedure (one pass of the 2-sigma rule on raw lengths), a full ellipsoid
    assert main([
        "fit", str(src), "--sensor", sensor, "--columns", "0,1,2", "--model", "full",
        "--outliers", "magneto", "-o", str(cal_path),
    ]) == 0
    assert main(["report", str(cal_path), "--plot", str(tmp_path / "fig.png")]) == 0
    out = capsys.readouterr().out
    assert "std/mean" in out and (tmp_path / "fig.png").stat().st_size > 10_000
    cal = tc.Calibration.load(cal_path)
    part = cal.part(sensor)
    m = MAGNETO[kind]
    assert part.stats["rejected"] == m["rejected"]  # the same readings as Magneto rejected
    raw = np.loadtxt(src, delimiter=",")
    keep = np.ones(len(raw), dtype=bool)
    keep[m["rejected"]] = False
    ours = _uniformity(cal.apply(raw[keep], sensor=sensor))
    theirs = _uniformity((raw[keep] - m["B"]) @ np.array(m["Ainv"]).T)
    assert ours <= theirs, (ours, theirs)
    # and the default pipeline (iterated rejection) is at least as uniform on what it keeps
    assert main(["fit", str(src), "--sensor", sensor, "--model", "full", "-o",
                 str(tmp_path / "cal2.json")]) == 0
    part2 = tc.Calibration.load(tmp_path / "cal2.json").part(sensor)
    k2 = np.ones(len(raw), dtype=bool)
    k2[part2.stats["rejected"]] = False
    assert _uniformity(part2.apply(raw[k2])) <= _uniformity(
        (raw[k2] - m["B"]) @ np.array(m["Ainv"]).T)


def test_parse_radius_units():
    assert parse_radius("1g", "accel") == (1.0, "g")
    assert parse_radius("9.80665", "accel") == (9.80665, "m/s^2")
    assert parse_radius("16384", "accel") == (16384.0, "counts")
    assert parse_radius("48uT", "mag") == (48.0, "uT")
    assert parse_radius("48 uT", "mag") == (48.0, "uT")
    assert parse_radius("250dps", "gyro") == (250.0, "deg/s")
    for bad in ("abc", "-1g", "0", "5 furlongs"):
        with pytest.raises(tc.CalibrationError):
            parse_radius(bad, "accel")


def test_read_table_detects_header_and_delimiter(tmp_path):
    (tmp_path / "a.csv").write_text("t,ax,ay,az\n0.0,1,2,3\n0.1,4,5,6\n")
    (tmp_path / "b.txt").write_text("# comment\n1 2 3 4\n5 6 7 8\n\n")
    (tmp_path / "c.csv").write_text("x;y;z\n1;2;3\n")
    a, b, c = (read_table(tmp_path / n) for n in ("a.csv", "b.txt", "c.csv"))
    assert a.names == ("t", "ax", "ay", "az") and a.data.shape == (2, 4)
    assert b.names is None and b.data.shape == (2, 4)
    assert c.names == ("x", "y", "z")
    assert pick_columns(a, None, "accel") == [1, 2, 3]
    assert pick_columns(a, "az,ay,ax", "accel") == [3, 2, 1]
    assert pick_columns(b, "1,2,3", "accel") == [1, 2, 3]
    assert pick_columns(c, None, "mag") == [0, 1, 2]
    with pytest.raises(tc.CalibrationError, match="pass columns with"):
        pick_columns(b, None, "accel")  # the API's name; a command names its flag
    from triaxcal._checks.spelling import command_line

    with command_line(), pytest.raises(tc.CalibrationError, match="pass --gyro-columns with"):
        pick_columns(b, None, "gyro", option="gyro_columns")
    with pytest.raises(tc.CalibrationError, match="out of range"):
        pick_columns(b, "0,1,9", "accel")
    with pytest.raises(tc.CalibrationError, match="no column 'mx'"):
        pick_columns(a, "mx,my,mz", "mag")
    (tmp_path / "bad.csv").write_text("1,2,3\n4,5\n")
    with pytest.raises(tc.CalibrationError, match="line 2"):
        read_table(tmp_path / "bad.csv")


def _session(tmp_path: Path, seed: int = 0) -> Path:
    """A capture-style session: 30 still poses of 60 samples each, gravity in counts."""
    rng = np.random.default_rng(seed)
    offset = np.array([300.0, -200.0, 150.0])
    gains = np.array([16000.0, 16500.0, 16300.0])
    rows, t = [], 0.0
    k = np.arange(30) + 0.5
    z = 1 - 2 * k / 30
    phi = k * np.pi * (3 - np.sqrt(5))
    dirs = np.column_stack([np.sqrt(1 - z * z) * np.cos(phi), np.sqrt(1 - z * z) * np.sin(phi), z])
    for u in dirs:
        for _ in range(100):
            a = offset + u * gains + rng.normal(scale=20, size=3)
            rows.append(f"{t:.3f}," + ",".join(str(round(v)) for v in a) + ",0,0,0")
            t += 0.01
        for _ in range(40):  # moving between poses
            a = offset + rng.normal(size=3) * 9000
            rows.append(f"{t:.3f}," + ",".join(str(round(v)) for v in a) + ",0,0,0")
            t += 0.01
    p = tmp_path / "session.csv"
    p.write_text("t,ax,ay,az,gx,gy,gz\n" + "\n".join(rows) + "\n")
    return p


def test_fit_poses_export_formats(tmp_path, capsys):
    sess = _session(tmp_path)
    cal_path = tmp_path / "cal.json"
    assert main(["fit", str(sess), "--sensor", "accel", "--poses", "--model", "axis",
                 "--radius", "1g", "--sensor-id", "bench-7", "-o", str(cal_path)]) == 0
    cal = tc.Calibration.load(cal_path)
    assert cal.sensor_id == "bench-7" and cal.accel.unit == "g"
    assert cal.accel.stats["poses"] is True and cal.accel.stats["n_input"] == 30
    capsys.readouterr()
    assert main(["report", str(cal_path)]) == 0  # re-detects the poses of the session
    assert "readings        30 (" in capsys.readouterr().out
    np.testing.assert_allclose(cal.accel.offset, [300, -200, 150], atol=15)
    np.testing.assert_allclose(np.diag(cal.accel.matrix), 1 / np.array([16000, 16500, 16300]),
                               rtol=2e-3)
    for fmt, name in (("c", "a.h"), ("c-fixed", "b.h"), ("json", "c.json"),
                      ("motioncal", "d.bin")):
        # the packet has no gains; it is in m/s^2, so the board driver's scale must be given
        extra = ["--offsets-only", "--counts-per-unit", "accel=16384:g"] if fmt == "motioncal" \
            else []
        assert main(["export", str(cal_path), "--format", fmt, "--prefix", "imu", "-o",
                     str(tmp_path / name), *extra]) == 0
    assert "imu_accel_apply(" in (tmp_path / "a.h").read_text()
    assert "imu_accel_apply_q(" in (tmp_path / "b.h").read_text()
    assert tc.Calibration.load(tmp_path / "c.json") == cal
    pkt = decode_motioncal((tmp_path / "d.bin").read_bytes())
    np.testing.assert_allclose(pkt.accel_offset, cal.accel.offset / 16384 * 9.80665, rtol=1e-6)
    # a second sensor is added to the same file
    mag = tmp_path / "mag.txt"
    rng = np.random.default_rng(3)
    u = rng.normal(size=(200, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    np.savetxt(mag, u * 480 + [100, 20, -50], fmt="%.1f")
    assert main(["fit", str(mag), "--sensor", "mag", "--columns", "0,1,2", "--radius", "48uT",
                 "-o", str(cal_path)]) == 0
    cal2 = tc.Calibration.load(cal_path)
    assert cal2.sensors == ("accel", "mag") and cal2.accel == cal.accel
    assert "updated" in capsys.readouterr().out


def test_cli_errors_are_clear(tmp_path, capsys):
    (tmp_path / "x.csv").write_text("1,2,3\n")
    assert main(["fit", str(tmp_path / "missing.csv"), "-o", str(tmp_path / "c.json")]) == 1
    assert "not found" in capsys.readouterr().err
    assert main(["fit", str(tmp_path / "x.csv"), "--radius", "1 parsec",
                 "-o", str(tmp_path / "c.json")]) == 1
    assert "unknown unit" in capsys.readouterr().err
    (tmp_path / "new.json").write_text('{"schema": "triaxcal.calibration/9", "parts": {}}')
    assert main(["export", str(tmp_path / "new.json"), "--format", "c", "-o",
                 str(tmp_path / "h.h")]) == 1
    assert "newer" in capsys.readouterr().err


def test_report_on_session_and_json(realdata, tmp_path, capsys):
    src = realdata / ICM / "mag3_raw.csv"
    assert main(["report", str(src), "--sensor", "mag", "--radius", "48uT", "-o",
                 str(tmp_path / "r.json")]) == 0
    out = capsys.readouterr().out
    for words in ("residual RMS", "coverage", "standard errors", "offdiag_xy", "outliers"):
        assert words in out
    import json

    d = json.loads((tmp_path / "r.json").read_text())["mag"]
    assert d["unit"] == "uT" and 0 < d["rms_pct"] < 5 and d["coverage_pct"] > 50
    # a calibration finds its data (checked by SHA-256); without it, stored statistics only
    data = tmp_path / "m.csv"
    data.write_bytes(src.read_bytes())
    cal = tmp_path / "c.json"
    assert main(["fit", str(data), "--sensor", "mag", "-o", str(cal)]) == 0
    capsys.readouterr()
    assert main(["report", str(cal)]) == 0
    n_rej = len(tc.Calibration.load(cal).mag.stats["rejected"])
    assert f"{n_rej} rejected" in capsys.readouterr().out
    data.write_text(data.read_text() + "1,2,3\n")
    assert main(["report", str(cal)]) == 1
    assert "has changed" in capsys.readouterr().err
    data.unlink()
    assert main(["report", str(cal)]) == 0
    assert "stored at fit time" in capsys.readouterr().out
    assert main(["report", str(cal), "--data", str(src)]) == 0
    assert "calibration report" in capsys.readouterr().out


# ---- send -----------------------------------------------------------------------------------


class EchoBoard:
    """A pseudo-terminal that answers a MotionCal packet like the PJRC/Adafruit sketches:
    ``Cal1:``/``Cal2:`` lines with 4 decimals, after some streaming noise."""

    def __init__(self, garble: bool = False, silent: bool = False) -> None:
        self.master, slave = os.openpty()
        tty.setraw(slave)
        self.port = os.ttyname(slave)
        self._slave = slave
        self.garble, self.silent = garble, silent
        self.received = bytearray()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        import select

        buf = bytearray()
        while not self._stop.is_set():
            r, _, _ = select.select([self.master], [], [], 0.02)
            if not r:
                continue
            try:
                data = os.read(self.master, 1024)
            except OSError:
                return
            buf += data
            self.received += data
            i = buf.find(bytes([117, 84]))
            if i < 0 or len(buf) < i + 68:
                continue
            pkt = bytes(buf[i:i + 68])
            del buf[: i + 68]
            if struct.unpack("<H", pkt[66:])[0] != crc16_modbus(pkt[:66]) or self.silent:
                continue
            v = list(struct.unpack("<16f", pkt[2:66]))
            if self.garble:
                v[6] += 1.0
            xx, yy, zz, xy, xz, yz = v[10:]
            s = [xx, xy, xz, xy, yy, yz, xz, yz, zz]
            reply = (b"\x01\x02\xff\n" + b"Cal1:" + ",".join(f"{x:.4f}" for x in v[:10]).encode()
                     + b"\r\nCal2:" + ",".join(f"{x:.4f}" for x in s).encode() + b"\r\n")
            os.write(self.master, reply)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(1)
        os.close(self.master)
        os.close(self._slave)


@pytest.fixture
def cal_file(tmp_path) -> Path:
    mag = tc.SensorCalibration(
        offset=[120.0, -40.0, 75.0],
        matrix=[[0.105, 0.002, -0.001], [0.002, 0.098, 0.0005], [-0.001, 0.0005, 0.101]],
        unit="uT", radius=48.5,
    )
    acc = tc.SensorCalibration(offset=[100.0, -50.0, 30.0], matrix=np.eye(3) / 16384, unit="g")
    p = tmp_path / "cal.json"
    tc.Calibration(accel=acc, mag=mag).save(p)
    return p


def test_send_confirms_echo(cal_file, capsys):
    board = EchoBoard()
    try:
        assert main(["send", str(cal_file), "--port", board.port, "--timeout", "3", *SCALE]) == 0
    finally:
        board.close()
    out = capsys.readouterr().out
    assert "confirmed" in out and "Cal2:" in out
    assert bytes(board.received) == motioncal_packet(tc.Calibration.load(cal_file),
                                                       counts_per_unit=SIM_COUNTS_PER_UNIT)


@pytest.mark.parametrize("garble,silent,msg", [(True, False, "echoed different values"),
                                               (False, True, "no Cal1:/Cal2: echo")])
def test_send_reports_bad_or_missing_echo(cal_file, capsys, garble, silent, msg):
    board = EchoBoard(garble=garble, silent=silent)
    try:
        assert main(["send", str(cal_file), "--port", board.port, "--timeout", "0.5", *SCALE]) == 1
    finally:
        board.close()
    assert msg in capsys.readouterr().err


def test_send_unopenable_port(cal_file, capsys):
    assert main(["send", str(cal_file), "--port", "/dev/does-not-exist", "--timeout", "0.2",
                 *SCALE]) == 1
    assert "cannot open" in capsys.readouterr().err


def test_send_to_simulated_device(cal_file, capsys):
    sim = pytest.importorskip("triaxcal.sim")
    if not hasattr(sim, "SimDevice"):
        pytest.skip("triaxcal.sim.SimDevice not available")
    with sim.SimDevice(speed=10) as dev:
        assert main(["send", str(cal_file), "--port", dev.port, "--timeout", "3", *SCALE]) == 0
        assert dev.motioncal is not None
    assert "confirmed" in capsys.readouterr().out


@pytest.mark.parametrize("command", ["fit", "export", "report", "send"])
def test_help_renders(command, capsys):
    with pytest.raises(SystemExit) as exc:
        main([command, "--help"])
    assert exc.value.code == 0
    assert f"triaxcal {command}" in capsys.readouterr().out
