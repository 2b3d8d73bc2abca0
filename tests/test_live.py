"""The live page without a browser: MotionCal's numbers, the spread buffer, the live state
against the offline pipeline and `triaxcal fit`, the buttons, the server, and `--live`."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.request
from pathlib import Path

import numpy as np
import pytest
from triaxcal import CalibrationError
from triaxcal.calibration import Calibration
from triaxcal.capture.run import SessionWriter, capture, channel_names
from triaxcal.cli import main
from triaxcal.detect.session import session_poses
from triaxcal.fit.select import fit_robust
from triaxcal.io.serial import Record, SerialReader
from triaxcal.live import (
    MOTIONCAL_LIMITS,
    LiveOptions,
    LiveState,
    SpreadBuffer,
    actions,
    motioncal_quality,
)
from triaxcal.live.quality import motioncal_regions
from triaxcal.live.server import LiveServer
from triaxcal.sim import SimDevice, SimIMU, globe_script

ROOT = Path(__file__).resolve().parent.parent
NAMES = channel_names("framed", 10)


def _sphere(n, seed=0):
    u = np.random.default_rng(seed).normal(size=(n, 3))
    return u / np.linalg.norm(u, axis=1, keepdims=True)


@pytest.fixture(scope="module")
def recording():
    """The globe scheme as the simulated board sends it (10 channels, counts), offline."""
    imu = SimIMU(2)
    rec = imu.record(globe_script(hold_s=1.0, seed=2), 100.0)
    return imu, rec.frames(10)


def _feed(state, frames, chunks, t0=1.7e9):
    rng = np.random.default_rng(1)
    i = 0
    while i < len(frames):
        n = int(rng.integers(1, chunks))
        state.on_records([Record(t0 + 0.01 * j, tuple(int(v) for v in row))
                          for j, row in enumerate(frames[i:i + n], start=i)])
        i += n


def _write_session(path, frames, t0=1.7e9):
    with SessionWriter(path, NAMES, mode="overwrite") as w:
        w.write(Record(t0 + 0.01 * j, tuple(int(v) for v in row)) for j, row in enumerate(frames))


# --------------------------------------------------------------------- MotionCal's numbers


def test_motioncal_regions_have_equal_area():
    counts = np.bincount(motioncal_regions(_sphere(400_000)), minlength=100)
    assert counts.size == 100
    np.testing.assert_allclose(counts / 4000, 1.0, atol=0.06)


def test_motioncal_quality_sees_each_defect():
    u = _sphere(650, 3)
    good = motioncal_quality(50 * u, 50.0)
    assert good.good and good.gaps < 2 and good.variance < 1e-9 and good.wobble < 1.5
    # an off-centre cloud (a wrong hard-iron offset): the wobble grows with the offset (about
    # three quarters of it in % of the radius: the regions are binned from the origin)
    wob = [motioncal_quality(50 * u + [d, 0, 0], 50.0).wobble for d in (2.5, 5.0, 10.0)]
    assert good.wobble < wob[0] < wob[1] < wob[2] and 3.0 < wob[1] < 5.0
    assert not motioncal_quality(50 * u + [10.0, 0, 0], 50.0).ok["wobble"]
    # an ellipsoid: the magnitudes spread
    ell = motioncal_quality(50 * u * [1.25, 1, 1], 50.0)
    assert ell.variance > MOTIONCAL_LIMITS["variance"] and not ell.good
    # half the sphere: half the regions empty
    half = motioncal_quality(50 * u[u[:, 2] > 0], 50.0)
    assert 45 < half.gaps < 55
    # noise of 1 % of the field: the fit error says 1 %
    noisy = 50 * u + np.random.default_rng(4).normal(0, 0.5, size=u.shape)
    assert 0.8 < motioncal_quality(noisy, 50.0).fit_error < 1.2


# ----------------------------------------------------------------------- the spread buffer


def test_spread_buffer_stays_bounded_and_spread_over_a_long_lopsided_stream():
    rng = np.random.default_rng(5)
    buf = SpreadBuffer(650)
    nbytes = buf._d.nbytes + buf._p.nbytes
    offset = np.array([300.0, -200.0, 100.0])
    # 100 s at 1000 records/s: 90 % of the time the board sits still near one direction,
    # then it tumbles; the buffer must keep the tumble, not the pile at one spot
    still = offset + 480 * np.array([0.0, 0.0, 1.0]) + rng.normal(0, 2, size=(90_000, 3))
    tumble = offset + 480 * _sphere(10_000, 6) + rng.normal(0, 2, size=(10_000, 3))
    stream = np.vstack([still[:45_000], tumble, still[45_000:]])
    for i in range(0, len(stream), 50):
        buf.add(stream[i:i + 50])
    pts = buf.points
    assert 600 <= len(buf) <= 650 and buf._d.nbytes + buf._p.nbytes == nbytes
    regions = motioncal_regions(pts - offset)
    assert len(np.unique(regions)) >= 95  # nearly all of MotionCal's 100 regions
    near_pole = np.mean((pts - offset)[:, 2] / 480 > 0.99)
    assert near_pole < 0.05  # the 90 000 still samples did not flood it
    # the last 650 samples, for comparison, all sit at the still spot
    assert np.all((stream[-650:] - offset)[:, 2] / 480 > 0.97)


def test_spread_buffer_drops_outliers_once_the_fit_is_good():
    rng = np.random.default_rng(8)
    buf = SpreadBuffer(200)
    buf.add(1000 * _sphere(400, 1))
    bad = 1600 * _sphere(5, 2)  # five readings next to a magnet
    buf.add(bad)
    assert any(np.linalg.norm(p) > 1500 for p in buf.points)
    buf.set_fit(np.zeros(3), np.eye(3), 1000.0, gaps=1.0)
    for _ in range(400):
        buf.add(1000 * _sphere(20, int(rng.integers(1 << 30))))
    assert all(np.linalg.norm(p) < 1100 for p in buf.points)


def test_spread_buffer_rejects_bad_capacity():
    with pytest.raises(CalibrationError, match="capacity"):
        SpreadBuffer(3)


# ------------------------------------------------------------------------ the live state


def test_live_poses_are_those_of_triaxcal_fit_poses(recording, tmp_path):
    _, frames = recording
    st = LiveState(tmp_path / "s.csv", NAMES)
    _feed(st, frames, chunks=97)
    st.finish_poses()  # the end of the stream decides on the pose in progress
    doc = st.refresh()
    det, _ = session_poses(NAMES, frames)
    assert doc["sensors"]["accel"]["poses"] == len(det.poses) >= 80
    live = np.array(st._poses)[:, :3]
    np.testing.assert_allclose(live, det.points, rtol=0, atol=1e-9)
    # the live accelerometer fit is fit_robust on those poses with fit's options
    ref = fit_robust(det.points, model="auto", radius=1.0, max_rounds=10)  # fit's default rule
    fit = doc["sensors"]["accel"]["fit"]
    np.testing.assert_allclose(fit["offset"], ref.fit.offset, rtol=1e-9)
    np.testing.assert_allclose(fit["matrix"], ref.fit.matrix, rtol=1e-9)
    assert fit["model"] == ref.fit.model and fit["rejected"] == len(ref.rejected)


def test_live_fit_converges_to_the_truth(recording, tmp_path):
    imu, frames = recording
    st = LiveState(tmp_path / "s.csv", NAMES, options=LiveOptions(mag_radius="50uT"))
    _feed(st, frames, chunks=60)
    doc = st.refresh()
    for sensor, truth in (("accel", imu.truth.accel), ("mag", imu.truth.mag)):
        fit = doc["sensors"][sensor]["fit"]
        se = fit["stderr"]
        for i, a in enumerate("xyz"):
            assert abs(fit["offset"][i] - truth.offset[i]) <= 4 * se[f"offset_{a}"], (sensor, a)
        for i, j, name in ((0, 0, "diag_x"), (1, 1, "diag_y"), (2, 2, "diag_z"),
                           (0, 1, "offdiag_xy"), (0, 2, "offdiag_xz"), (1, 2, "offdiag_yz")):
            if name in se:
                assert abs(fit["matrix"][i][j] - truth.matrix[i, j]) <= 4 * se[name], (sensor,
                                                                                      name)
    assert doc["sensors"]["accel"]["ready"]
    assert doc["sensors"]["mag"]["samples"] <= 650


def test_memory_and_document_stay_flat_however_long_the_capture(recording, tmp_path):
    _, frames = recording
    st = LiveState(tmp_path / "s.csv", NAMES)
    sizes = []
    for _ in range(6):  # ~75 000 records: the globe six times over
        _feed(st, frames, chunks=200)
        st.refresh()
        pts = st.points()
        sizes.append((len(pts["mag"]["raw"]), len(pts["trail"]["t"]), len(json.dumps(pts))))
    assert st.rows == 6 * len(frames)
    assert all(s[0] <= 650 and s[1] <= 250 for s in sizes)
    # the page's data does not grow with the capture (the poses repeat, so no new ones)
    assert sizes[-1][2] < 1.3 * sizes[1][2]
    assert len(st._poses) <= 90  # 84 orientations: one pose each, however often revisited


def test_finish_shows_what_triaxcal_fit_gives(recording, tmp_path):
    _, frames = recording
    session = tmp_path / "session.csv"
    _write_session(session, frames)
    st = LiveState(session, NAMES, options=LiveOptions(mag_radius="50uT"))
    _feed(st, frames, chunks=80)
    st.refresh()
    st.finish()
    doc = st.document()
    assert doc["status"] == "finished"
    cmds = doc["fit_commands"]
    out = tmp_path / "cli.json"
    for cmd in cmds:
        argv = cmd.split()[1:]
        argv[argv.index("-o") + 1] = str(out)
        assert main(argv) == 0
    cal = Calibration.load(out)
    for sensor in ("accel", "mag"):
        fit = doc["sensors"][sensor]["fit"]
        part = cal.part(sensor)
        assert fit["source"] == "session"
        assert fit["offset"] == part.offset.tolist()
        assert fit["matrix"] == part.matrix.tolist()
        assert fit["rms"] == part.stats["rms"] and fit["n"] == part.stats["n"]
        assert fit["stderr"] == part.stats["stderr"]


@pytest.mark.slow
def test_save_and_reset_do_what_the_cli_does(recording, tmp_path, capsys):
    _, frames = recording
    session = tmp_path / "session.csv"
    _write_session(session, frames)
    st = LiveState(session, NAMES, options=LiveOptions(out_dir=tmp_path / "out"))
    _feed(st, frames, chunks=80)
    res = actions.save(st)
    assert res["ok"], res
    saved = Calibration.load(tmp_path / "out" / "calibration.json")
    ref = tmp_path / "ref.json"
    assert main(["fit", str(session), "--sensor", "accel", "--poses", "-o", str(ref)]) == 0
    assert main(["fit", str(session), "--sensor", "mag", "-o", str(ref)]) == 0
    cli = Calibration.load(ref)
    for sensor in ("accel", "mag"):
        assert saved.part(sensor).to_dict() == cli.part(sensor).to_dict()
    # export: the same header `triaxcal export --format c` writes
    res = actions.export_header(st, "c")
    assert res["ok"], res
    assert main(["export", str(tmp_path / "out" / "calibration.json"), "--format", "c",
                 "-o", str(tmp_path / "ref.h")]) == 0
    assert (tmp_path / "out" / "triaxcal_calibration.h").read_text() == (
        tmp_path / "ref.h").read_text()
    assert not actions.export_header(st, "rust")["ok"]
    # reset: the live view starts again, and Save fits only the rows since
    n_before = st.rows
    assert actions.reset(st)["ok"]
    assert st.refresh()["sensors"]["accel"]["poses"] == 0
    with SessionWriter(session, NAMES, mode="append") as w:
        w.write(Record(1.8e9 + 0.01 * j, tuple(int(v) for v in row))
                for j, row in enumerate(frames))
    _feed(st, frames, chunks=80)
    res = actions.save(st)
    assert res["ok"], res
    tail = tmp_path / "session.after-reset-1.csv"
    assert tail.exists() and len(tail.read_text().splitlines()) == len(frames) + 1
    assert st.rows == 2 * n_before
    ref2 = tmp_path / "ref2.json"
    assert main(["fit", str(tail), "--sensor", "accel", "--poses", "-o", str(ref2)]) == 0
    live = Calibration.load(tmp_path / "out" / "calibration.json").accel.to_dict()
    # like the command, Save kept the calibration it replaced (fitted before the reset)
    assert live.pop("previous")[0]["offset"] == saved.accel.offset.tolist()
    assert live == Calibration.load(ref2).accel.to_dict()


def test_reader_events_become_banners(tmp_path):
    st = LiveState(tmp_path / "s.csv", NAMES)
    st.on_event("disconnected", "/dev/ttyUSB0 disconnected (gone)")
    assert st.refresh()["stream"]["banner"]["kind"] == "disconnected"
    st.on_event("reconnected", "/dev/ttyUSB0 is back after 2.0 s; capturing")
    doc = st.refresh()
    assert doc["stream"]["banner"]["kind"] == "reconnected"
    assert [e["kind"] for e in doc["stream"]["events"]] == ["disconnected", "reconnected"]


@pytest.mark.parametrize("kw, word", [
    ({"model": "cubic"}, "model"), ({"accel_radius": "1 parsec"}, "radius"),
    ({"prefix": "9lives"}, "identifier"), ({"refresh_hz": 1000}, "refresh_hz"),
    ({"mag_buffer": 5}, "mag_buffer"), ({"sigma": -1}, "sigma"),
])
def test_bad_options_say_what_is_wrong(kw, word):
    with pytest.raises(CalibrationError, match=word):
        LiveOptions(**kw)


def test_missing_extra_names_it(monkeypatch, tmp_path, capsys):
    import importlib.util

    from triaxcal.live import server

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == "uvicorn" else real(name, *a))
    with pytest.raises(CalibrationError, match=r"pip install 'triaxcal\[live\]'"):
        server.LiveServer(LiveState(tmp_path / "s.csv", NAMES), port=0)
    assert main(["capture", "--port", "/nonexistent", "--protocol", "framed", "-o",
                 str(tmp_path / "x.csv"), "--live"]) == 1
    monkeypatch.undo()
    # one board per page: several ports with --live are refused before anything opens
    assert main(["capture", "--port", "/nonexistent0", "--port", "/nonexistent1", "--protocol",
                 "framed", "--out-dir", str(tmp_path / "many"), "--live"]) == 1
    assert "--live shows one board" in capsys.readouterr().err
    assert not (tmp_path / "many").exists()


# ------------------------------------------------------------------------------ the server


def _get(url, headers=None, data=None):
    req = urllib.request.Request(url, headers=headers or {}, data=data,
                                 method="POST" if data is not None else "GET")
    try:
        with urllib.request.urlopen(req, timeout=30) as r:
            return r.status, r.headers, r.read()
    except urllib.error.HTTPError as e:
        return e.code, e.headers, e.read()


def test_server_routes_and_guards(recording, tmp_path):
    _, frames = recording
    st = LiveState(tmp_path / "s.csv", NAMES)
    _feed(st, frames[:3000], chunks=50)
    with LiveServer(st.start(), port=0) as srv:
        try:
            code, _, body = _get(srv.url)
            page = body.decode()
            assert code == 200 and "Save calibration" in page
            # every script and style the page loads comes from this server
            refs = re.findall(r'(?:src|href)="([^"]+)"', page)
            assert refs and all(not r.startswith(("http:", "https:", "//")) for r in refs)
            code, hdr, body = _get(srv.url + "static/plotly.min.js",
                                   {"Accept-Encoding": "gzip"})
            assert code == 200 and hdr.get("Content-Encoding") == "gzip" and len(body) < 2.5e6
            assert _get(srv.url + "static/../server.py")[0] == 404
            assert _get(srv.url + "static/secrets.txt")[0] == 404
            code, _, body = _get(srv.url + "api/state")
            doc = json.loads(body)
            assert doc["samples"] == 3000 and set(doc["sensors"]) == {"accel", "gyro", "mag"}
            both = json.loads(_get(srv.url + "api/state?points=1")[2])
            assert set(both["points"]) == {"accel", "mag", "trail"}
            # another site's page cannot press the buttons, nor reach the API by DNS rebinding
            assert _get(srv.url + "api/save", data=b"")[0] == 403
            assert _get(srv.url + "api/state", {"Host": "evil.example:80"})[0] == 400
            assert not (tmp_path / "calibration.json").exists()
            # the event stream: the document, then only the point sets that changed
            with urllib.request.urlopen(srv.url + "api/events", timeout=30) as r:
                msgs = []
                while len(msgs) < 2:
                    line = r.readline().decode()
                    if line.startswith("data: "):
                        msgs.append(json.loads(line[6:]))
            assert msgs[0]["state"]["samples"] == 3000
            assert set(msgs[0]["points"]) == {"accel", "mag", "trail"}
            assert msgs[1]["state"]["version"] > msgs[0]["state"]["version"]
            assert msgs[1]["points"] == {}  # nothing new arrived
        finally:
            st.stop()


def test_port_taken_moves_to_the_next_and_other_hosts_are_flagged(tmp_path):
    import socket

    st = LiveState(tmp_path / "s.csv", NAMES)
    first = LiveServer(st, port=0)
    try:
        taken = first.port
        nxt = LiveServer(st, port=taken)  # taken: the next free one
        try:
            assert nxt.port != taken and taken < nxt.port <= taken + 20
            assert not nxt.public and nxt.url == f"http://127.0.0.1:{nxt.port}/"
        finally:
            nxt.stop()
    finally:
        first.stop()
    anywhere = LiveServer(st, host="0.0.0.0", port=0)
    try:
        assert anywhere.public and socket.gethostname() in anywhere.url
    finally:
        anywhere.stop()
    with pytest.raises(CalibrationError, match="http-port"):
        LiveServer(st, port=70000)


@pytest.mark.slow
def test_send_goes_over_the_open_port_with_the_echo_check(tmp_path):
    imu = SimIMU(4)
    with SimDevice(imu, globe_script(hold_s=0.6, seed=4), speed=30, loop=True, seed=4) as dev:
        reader = SerialReader(dev.port, protocol="framed", channels=10)
        from triaxcal.sim import SIM_COUNTS_PER_UNIT

        # the packet is in m/s^2 and uT: the board driver's scale is given (none is assumed)
        st = LiveState(tmp_path / "s.csv", NAMES, port=dev.port,
                       options=LiveOptions(out_dir=tmp_path, send_timeout_s=15.0,
                                           counts_per_unit=SIM_COUNTS_PER_UNIT))
        st.attach(reader)
        stop = threading.Event()
        th = threading.Thread(target=capture, args=(reader, tmp_path / "s.csv"), kwargs={
            "stop": stop, "on_records": st.on_records, "progress": None,
            "handle_sigint": False})
        th.start()
        try:
            deadline = time.monotonic() + 120
            # poses on four latitudes of the globe: enough for `fit` to write a calibration
            while st.refresh()["sensors"]["accel"]["poses"] < 45:
                assert time.monotonic() < deadline and th.is_alive()
                time.sleep(0.3)
            # as `triaxcal send`: the packet cannot carry the accelerometer's gains, so it is
            # refused until the loss is accepted (--offsets-only)
            res = actions.send(st)
            assert not res["ok"] and res["needs_offsets_only"], res
            assert "cannot carry" in res["message"] and dev.motioncal is None
            res = actions.send(st, offsets_only=True)
            assert res["ok"], res
            assert "the board confirmed it" in res["message"] and "not in the packet" in res[
                "message"]
            saved = Calibration.load(tmp_path / "calibration.json")
            from triaxcal.export import decode_motioncal, motioncal_packet

            assert dev.motioncal == decode_motioncal(motioncal_packet(
                saved, offsets_only=True, counts_per_unit=SIM_COUNTS_PER_UNIT))
        finally:
            stop.set()
            dev.silence(10.0)  # a streaming capture stops once the line goes quiet
            th.join(30)
        assert not th.is_alive()
    st.status = "finished"
    assert "capture has ended" in actions.send(st)["message"]


# ----------------------------------------------------------------------------- --live CLI


def _spawn(args, cwd):
    env = dict(os.environ, PYTHONPATH=str(ROOT / "python"))
    # Ctrl-C as at a terminal: a test run started in the background of a non-interactive
    # shell has SIGINT ignored, and a child inherits that (Python then raises no
    # KeyboardInterrupt, and a command waiting for Ctrl-C waits for ever)
    code = ("import signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); "
            "from triaxcal.cli import main; sys.exit(main())")
    return subprocess.Popen([sys.executable, "-c", code, *args], cwd=cwd, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)


def _url_from(proc, timeout=120):
    deadline = time.monotonic() + timeout
    seen = ""
    while time.monotonic() < deadline:
        line = proc.stderr.readline()
        seen += line
        m = re.search(r"live page at (http://\S+/)", line)
        if m:
            return m.group(1)
        if proc.poll() is not None:
            break
    raise AssertionError(f"no live page address printed: {seen!r}")


def _drain(stream, sink):
    for line in stream:
        sink.append(line)


@pytest.mark.slow
def test_capture_live_cli_serves_and_ctrl_c_saves_and_exits(tmp_path):
    with SimDevice(SimIMU(5), globe_script(hold_s=0.8, seed=5), speed=10, loop=True,
                   seed=5) as dev:
        proc = _spawn(["capture", "--port", dev.port, "--protocol", "framed", "--live",
                       "--no-browser", "--http-port", "0", "-o", "s.csv", "--no-bell"],
                      tmp_path)
        try:
            url = _url_from(proc)
            err: list[str] = []
            drain = threading.Thread(target=_drain, args=(proc.stderr, err), daemon=True)
            drain.start()
            deadline = time.monotonic() + 120
            while True:
                doc = json.loads(_get(url + "api/state")[2])
                if doc["sensors"]["accel"]["poses"] >= 3:
                    break
                assert time.monotonic() < deadline, doc["next"]
                time.sleep(0.5)
            assert doc["status"] == "capturing" and doc["stream"]["dropped"] == 0
            proc.send_signal(signal.SIGINT)
            proc.wait(timeout=60)
            drain.join(30)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
            proc.stderr.close()
    assert proc.returncode == 0, "".join(err)
    assert "stopped by Ctrl-C" in "".join(err)
    rows = len((tmp_path / "s.csv").read_text().splitlines()) - 1
    assert rows >= doc["samples"]
    with pytest.raises(OSError):
        urllib.request.urlopen(url + "api/state", timeout=5)


def _session_summary(out: Path) -> str:
    """Rows, poses and first rows of a demo's session, for a failure message."""
    path = out / "session.csv"
    if not path.exists():
        return " (no session.csv)"
    try:
        from triaxcal.capture.run import read_session

        cols, data = read_session(path)
        det, how = session_poses(cols, data)
        return (f"\nsession: {len(data)} rows, {len(det.poses)} poses, counts_per_g "
                f"{how.counts_per_g:.1f}, rejected {len(det.rejected)}; first rows:\n"
                + "\n".join(path.read_text().splitlines()[:4]))
    except Exception as exc:  # noqa: BLE001 - a summary for a failure message
        return f" (session.csv unreadable: {exc})"


@pytest.mark.slow
def test_demo_live_ends_on_the_session_fit_and_lingers_until_ctrl_c(tmp_path):
    # 10x real time: 1,000 frames a second, which a loaded test machine's reader keeps up with
    proc = _spawn(["demo", "--live", "--no-browser", "--http-port", "0", "--speed", "10",
                   "--no-plot", "--quiet", "--out-dir", "d"], tmp_path)
    try:
        url = _url_from(proc)
        err: list[str] = []
        drain = threading.Thread(target=_drain, args=(proc.stderr, err), daemon=True)
        drain.start()
        deadline = time.monotonic() + 300
        while True:
            # the demo ended early: say why, with what the session holds
            assert proc.poll() is None, "".join(err) + _session_summary(tmp_path / "d")
            doc = json.loads(_get(url + "api/state")[2])
            if doc["status"] == "finished" and (tmp_path / "d" / "results.json").exists():
                break
            assert time.monotonic() < deadline, doc["next"]
            time.sleep(0.5)
        # the page shows the session's fit, and every check is green at the end of the demo
        for sensor in ("accel", "mag"):
            s = doc["sensors"][sensor]
            failed = [(c["key"], c["value"], c.get("limit")) for c in s["quality"] if not c["ok"]]
            assert s["fit"]["source"] == "session" and s["ready"], (sensor, failed)
        code, _, body = _get(url + "api/save", {"X-Triaxcal": "1"}, data=b"")
        assert code == 200, body
        assert (tmp_path / "d" / "live" / "calibration.json").exists()
        time.sleep(1.0)
        assert proc.poll() is None  # still serving
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=60)
        drain.join(30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        proc.stderr.close()
    assert proc.returncode == 0
