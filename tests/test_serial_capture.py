"""Capture through real pseudo-terminals: the simulated board (SimDevice) on one end, the
SerialReader / capture / CLI on the other. The device logs every frame it sent, and the
session CSV is checked row by row against that log."""

from __future__ import annotations

import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import serial
from triaxcal import sim
from triaxcal.capture.run import (
    SessionWriter,
    capture,
    channel_names,
    read_session,
)
from triaxcal.cli import main
from triaxcal.errors import CalibrationError
from triaxcal.io.motioncal import encode_motioncal, parse_motioncal_echo
from triaxcal.io.serial import (
    CaptureError,
    GarbageError,
    PortNotFoundError,
    Record,
    SerialReader,
    SilentDeviceError,
    parse_request_byte,
)
from triaxcal.quality.coverage import coverage, suggest_turn

ROOT = Path(__file__).resolve().parent.parent

# gyro offsets 10 = 0A 00, 2570 = 0A 0A, -246 = 0A FF: while the board is still, every binary
# frame carries 0x0A ('\n') bytes inside its data
NEWLINE_GYRO = {"offset": (10, 2570, -246), "noise": 0.0}


def newline_imu(seed: int = 3) -> sim.SimIMU:
    return sim.SimIMU(seed, gyro=NEWLINE_GYRO)


def device(protocol: str | None = None, *, speed: float = 10.0, faults=None, seed: int = 3,
           **kw) -> sim.SimDevice:
    script = sim.globe_script(hold_s=1.0, latitudes=3, turns=4, seed=seed)
    return sim.SimDevice(newline_imu(seed), script, speed=speed, faults=faults, seed=seed, **kw)


def session_rows(path: Path) -> list[tuple[int, ...]]:
    """The value columns of a session CSV, checking every row is complete."""
    lines = path.read_text().splitlines()
    header = lines[0].split(",")
    assert header[0] == "t"
    rows = []
    for line in lines[1:]:
        parts = line.split(",")
        assert len(parts) == len(header), f"incomplete row {line!r}"
        float(parts[0])
        rows.append(tuple(int(v) for v in parts[1:]))
    return rows


def align(rows, sent):
    """Match each row to a sent frame at increasing positions; return (positions, wrong)."""
    vals = [f.values for f in sent]
    positions, wrong = [], []
    j = 0
    for r in rows:
        try:
            k = vals.index(r, j)
        except ValueError:
            wrong.append(r)
            continue
        positions.append(k)
        j = k + 1
    return positions, wrong


def on_time(sent, poll_timeout_s: float = 0.1) -> list[bool]:
    """For each frame sent: a streamed frame, or a polled reply that the board sent within the
    reader's poll timeout (``SerialReader``'s default: 0.1 s), not back to back with another
    reply, and after a reply that was on time too (a late reply can reach the host while it
    waits for the next one, which then cannot be told from it)."""
    out, before = [], True
    for f in sent:
        if f.reply_s is None:
            out.append(True)
            continue
        now = f.reply_s < poll_timeout_s
        out.append(now and before)
        before = now
    return out


def check_exact(rows, sent, poll_timeout_s: float = 0.1):
    """No wrong row; every intact frame between the first and last row was captured (for a
    polled reply: every intact reply sent on time, see ``on_time``)."""
    assert rows, "nothing captured"
    positions, wrong = align(rows, sent)
    assert not wrong, f"{len(wrong)} rows that the device never sent, e.g. {wrong[:2]}"
    # the intact frames in that span are a subsequence of the rows (exact even when a polled
    # board repeats a sample, so that values alone cannot say which reply a row came from)
    timely = on_time(sent, poll_timeout_s)
    intact = [k for k in range(positions[0], positions[-1] + 1) if sent[k].intact and timely[k]]
    it = iter(rows)
    missing = [k for k in intact if not any(sent[k].values == r for r in it)]
    assert not missing, (f"{len(missing)} intact frames not captured, the first: "
                         f"{sent[missing[0]] if missing else None}")
    return positions


def has_newline_bytes(sent, protocol):
    from triaxcal.io.protocol import encode_binary
    return sum(b"\n" in encode_binary(f.values)[:-1] for f in sent)


# ----------------------------------------------------------------------- clean streams


@pytest.mark.parametrize(
    "protocol,stream",
    [("binary", False), ("binary", True), ("framed", False), ("text", False), ("raw", False)],
)
def test_every_protocol_captures_exactly_what_was_sent(tmp_path, protocol, stream):
    out = tmp_path / "s.csv"
    with device(speed=10.0) as dev:
        reader = SerialReader(dev.port, protocol=protocol,
                              channels=None if protocol == "raw" else 10, stream=stream)
        res = capture(reader, out, samples=400, progress=None, handle_sigint=False)
        sent = list(dev.sent)
    rows = session_rows(out)
    assert len(rows) == res.samples == 400
    positions = check_exact(rows, sent)
    if protocol != "binary" or stream:
        # streaming: a contiguous run of frames, none lost
        assert positions == list(range(positions[0], positions[0] + 400))
    else:
        # a request fails only when the board answered it late (a stalled simulator thread
        # on a loaded machine): no fault is injected here
        late = sum(f.polled and not ok for f, ok in zip(sent, on_time(sent)))
        assert reader.stats.polls >= 400 and reader.stats.poll_failures <= late
    header = out.read_text().splitlines()[0]
    assert header == "t," + ",".join(channel_names(protocol, 9 if protocol == "raw" else 10))
    if protocol == "binary":
        assert has_newline_bytes(sent[positions[0]:positions[-1] + 1], protocol) > 100


def test_seven_channel_board(tmp_path):
    out = tmp_path / "s7.csv"
    with device(channels=7) as dev:
        res = capture(SerialReader(dev.port, protocol="binary", channels=7), out, samples=50,
                      progress=None, handle_sigint=False)
        sent = list(dev.sent)
    assert out.read_text().splitlines()[0] == "t,ax,ay,az,gx,gy,gz,temp"
    check_exact(session_rows(out), sent)
    assert res.samples == 50


def test_cli_polled_capture_at_a_fixed_rate(tmp_path, capsys):
    out = tmp_path / "p.csv"
    with device(speed=1.0) as dev:
        t0 = time.monotonic()
        rc = main(["capture", "--port", dev.port, "--protocol", "binary", "--rate-hz", "100",
                   "--samples", "50", "-o", str(out), "--quiet", "--no-bell"])
        elapsed = time.monotonic() - t0
        sent = list(dev.sent)
    assert rc == 0
    assert 0.45 < elapsed < 3.0  # 50 requests at 100 per second
    rows = session_rows(out)
    check_exact(rows, sent)
    assert len(set(rows)) >= 45  # one request per sample: (almost) no repeats
    assert "sample count reached: 50 rows" in capsys.readouterr().err


# ----------------------------------------------------------------------- injected faults


@pytest.mark.parametrize(
    "protocol,faults",
    [
        ("binary", sim.Faults(garbage_prob=0.05, drop_prob=0.05, seed=1)),  # polled
        ("framed", sim.Faults(garbage_prob=0.05, drop_prob=0.05, flip_prob=0.05, seed=2)),
        ("text", sim.Faults(garbage_prob=0.05, drop_prob=0.05, drop_where="structure", seed=3)),
        ("raw", sim.Faults(garbage_prob=0.05, drop_prob=0.05, drop_where="structure", seed=4)),
    ],
)
def test_faults_lose_only_damaged_frames_and_never_write_a_wrong_row(tmp_path, protocol, faults):
    out = tmp_path / "f.csv"
    with device(speed=10.0, faults=faults) as dev:
        reader = SerialReader(dev.port, protocol=protocol,
                              channels=None if protocol == "raw" else 10, poll_timeout_s=0.05)
        capture(reader, out, samples=500, progress=None, handle_sigint=False)
        sent = list(dev.sent)
    rows = session_rows(out)
    positions = check_exact(rows, sent, poll_timeout_s=0.05)
    span = sent[positions[0]:positions[-1] + 1]
    damaged = sum(not f.intact for f in span)
    assert damaged >= 20, "the test needs faults to mean anything"
    st = reader.stats
    if protocol == "binary":
        assert st.poll_failures >= damaged // 2
    elif protocol == "framed":
        assert st.decoder.dropped_frames > 0 and st.decoder.lost_frames >= damaged // 2
    else:
        assert st.decoder.lines_skipped > 0


def test_a_board_that_stalls_loses_only_its_late_replies(tmp_path):
    """A board that stops reading for longer than the poll timeout (busy, or a simulator
    thread starved on a loaded machine) answers the waiting requests late and back to back.
    The reader gives up on them (a reply that comes too late, or glued to another, cannot be
    told from garbage) and never writes a wrong row; every reply sent on time is captured."""
    out = tmp_path / "s.csv"
    with device(speed=10.0) as dev:
        rows_stalls = [0, 0]

        def stall_now_and_then(recs) -> None:  # 0.12 s after every 40 rows, six times
            rows_stalls[0] += len(recs)
            if rows_stalls[1] < 6 and rows_stalls[0] >= 40 * (rows_stalls[1] + 1):
                rows_stalls[1] += 1
                dev.stall(0.12)

        reader = SerialReader(dev.port, protocol="binary", channels=10, poll_timeout_s=0.05)
        capture(reader, out, samples=300, progress=None, handle_sigint=False,
                on_records=stall_now_and_then)
        sent = list(dev.sent)
    assert rows_stalls[1] == 6
    rows = session_rows(out)
    check_exact(rows, sent, poll_timeout_s=0.05)
    timely = on_time(sent, 0.05)
    late = [f for f, ok in zip(sent, timely) if not ok]
    assert len(late) >= 6 and reader.stats.poll_failures >= 6
    assert any(f.reply_s == float("inf") for f in late)  # requests answered back to back
    assert sum(timely) >= 250


def test_text_lost_digits_are_the_limit_of_a_format_without_checksum(tmp_path):
    """Any byte lost from a text line: a lost digit makes another number that no decoder
    can see, so wrong rows appear, but only for damaged lines; intact lines all arrive."""
    out = tmp_path / "t.csv"
    with device(speed=10.0, faults=sim.Faults(drop_prob=0.05, seed=3)) as dev:
        capture(SerialReader(dev.port, protocol="text", channels=10), out, samples=500,
                progress=None, handle_sigint=False)
        sent = list(dev.sent)
    rows = session_rows(out)
    positions, wrong = align(rows, sent)
    span = sent[positions[0]:positions[-1] + 1]
    damaged = sum(not f.intact for f in span)
    assert 0 < len(wrong) <= damaged
    got = set(positions)
    lost = [k for k in range(positions[0], positions[-1] + 1) if sent[k].intact and k not in got]
    assert not lost


def test_legacy_stream_corruption_costs_only_neighbouring_frames(tmp_path):
    faults = sim.Faults(garbage_prob=0.03, drop_prob=0.03, seed=5)
    out = tmp_path / "b.csv"
    with device(speed=10.0, faults=faults) as dev:
        reader = SerialReader(dev.port, protocol="binary", channels=10, stream=True)
        capture(reader, out, samples=800, progress=None, handle_sigint=False)
        sent = list(dev.sent)
    rows = session_rows(out)
    positions, wrong = align(rows, sent)
    bad = [k for k, f in enumerate(sent) if not f.intact]
    assert len(bad) >= 20
    # wrong rows are possible without a checksum, but must stay rare
    assert len(wrong) <= max(1, len(bad) // 10), wrong
    got = set(positions)
    lo, hi = positions[0], positions[-1]
    far = [k for k in range(lo, hi + 1)
           if sent[k].intact and min(abs(k - b) for b in bad) > 3]
    lost_far = [k for k in far if k not in got]
    assert not lost_far, f"intact frames far from any damage were lost: {lost_far[:5]}"
    near_lost = [k for k in range(lo, hi + 1) if sent[k].intact and k not in got]
    assert len(near_lost) <= 3 * len(bad)
    assert has_newline_bytes(sent[lo:hi + 1], "binary") > 200


# ----------------------------------------------------------------------- stopping


def test_ctrl_c_stops_cleanly_with_everything_saved(tmp_path):
    out = tmp_path / "c.csv"
    with device(speed=5.0) as dev:
        proc = subprocess.Popen(
            [sys.executable, "-c",
             "import sys; from triaxcal.cli import main; sys.exit(main(sys.argv[1:]))",
             "capture", "--port", dev.port, "--protocol", "framed", "-o", str(out)],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )
        deadline = time.monotonic() + 15
        while time.monotonic() < deadline and (
            not out.exists() or out.read_text().count("\n") < 200
        ):
            time.sleep(0.05)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=10)
        sent = list(dev.sent)
    assert proc.returncode == 0, err
    assert "stopped by Ctrl-C" in err
    rows = session_rows(out)  # every row complete
    assert len(rows) >= 200
    check_exact(rows, sent)
    assert f"{len(rows)} rows" in err


def test_stop_event_and_poses_limit(tmp_path):
    with device(speed=40.0, loop=False) as dev:
        res = capture(SerialReader(dev.port, protocol="framed", channels=10), tmp_path / "a.csv",
                      stop=dev.finished, progress=None, handle_sigint=False)
        sent = list(dev.sent)
    assert res.stopped_by == "stop"
    positions = check_exact(session_rows(tmp_path / "a.csv"), sent)
    assert positions[-1] == len(sent) - 1  # drained to the last frame
    assert len(res.poses) >= 6 and res.coverage > 0.2
    with device(speed=20.0) as dev:
        res = capture(SerialReader(dev.port, protocol="framed", channels=10), tmp_path / "p.csv",
                      poses=3, progress=None, handle_sigint=False, bell=False)
    assert res.stopped_by == "poses" and len(res.poses) == 3


@pytest.mark.parametrize("request_byte", [b"F", b"!"])
def test_the_script_starts_when_the_host_first_asks_for_data(request_byte):
    # a host slow to open the port (`demo --live` starts its page first, on a loaded machine
    # for longer than the first still pose lasts at 10x) must not miss the start of the script
    with device(speed=10.0, loop=False) as dev:
        time.sleep(0.5)  # 5 s of simulated time go by with nobody listening
        assert dev.sim_time_s == 0.0 and not dev.sent
        with serial.Serial(dev.port, 115200, timeout=1) as port:
            port.write(request_byte)
            assert port.read(21)
            port.write(b"P")
        sent = list(dev.sent)
        assert dev.sim_time_s > 0.0
    assert sent and sent[0].index == 0  # the first sample of the script, not the 500th
    streamed = [f.index for f in sent if not f.polled]
    assert streamed == list(range(len(streamed)))


def test_progress_line_bell_and_suggestion(tmp_path):
    import io

    buf = io.StringIO()
    with device(speed=20.0) as dev:
        capture(SerialReader(dev.port, protocol="framed", channels=10), tmp_path / "a.csv",
                poses=3, progress=buf, bell=True, handle_sigint=False)
    text = buf.getvalue()
    assert text.count("\a") == 3
    assert "3/3 poses" in text and "coverage" in text and "next: " in text


# ----------------------------------------------------------------------- pulled cable


class AfterRecords:
    """``on_records`` for capture: calls ``action`` once ``first`` records have arrived; once
    ``then`` more arrived after ``resume()`` holds, silences the device and sets ``stop`` (a
    test of what happens mid-capture that does not depend on how fast a loaded machine starts
    the capture)."""

    def __init__(self, dev, first: int, action, then: int, resume=lambda: True) -> None:
        self.dev, self.first, self.action, self.then, self.resume = dev, first, action, then, resume
        self.n = 0
        self.after: int | None = None
        self.stop = threading.Event()
        self.thread: threading.Thread | None = None

    def __call__(self, recs) -> None:
        self.n += len(recs)
        if self.thread is None and self.n >= self.first:
            self.at_action = self.n
            self.thread = threading.Thread(target=self.action)  # unplug waits for the device
            self.thread.start()
        elif self.thread is not None and not self.thread.is_alive() and self.resume():
            self.after = self.n if self.after is None else self.after
            if self.n - self.after >= self.then and not self.stop.is_set():
                self.dev.silence(60.0)  # the capture ends once the line is quiet
                self.stop.set()


@pytest.mark.parametrize("protocol", ["framed", "binary"])
def test_unplug_and_return_resumes(tmp_path, protocol):
    out = tmp_path / "u.csv"
    with device(speed=5.0) as dev:
        reader = SerialReader(dev.port, protocol=protocol, channels=10, poll_interval_s=0.002)
        # pull the cable for 0.6 s after 100 records; stop 150 records after it came back
        after = AfterRecords(dev, 100, lambda: dev.unplug(0.6), 150,
                             resume=lambda: reader.stats.reconnects > 0)
        res = capture(reader, out, stop=after.stop, duration_s=60.0, progress=None,
                      handle_sigint=False, on_records=after)
        sent = list(dev.sent)
    assert res.stopped_by == "stop"
    kinds = [k for k, _ in res.events]
    assert "disconnected" in kinds and "reconnected" in kinds
    assert res.stats.disconnects == 1 and res.stats.reconnects == 1
    rows = session_rows(out)
    positions, wrong = align(rows, sent)
    assert not wrong
    # frames were captured both before and after the gap; the gap is in the sample index
    idx = np.array([sent[k].index for k in positions])
    assert len(rows) == res.samples == after.n
    # the rows before the cable was pulled and those after it came back (100 and 150 at
    # least), with the time the board was away between them
    assert after.at_action >= 100 and after.n - after.after >= 150
    assert idx[after.after] - idx[after.at_action - 1] >= 0.5 * 5.0 * 100  # ~0.6 s at 5x, 100 Hz
    # after the reconnect the board (rebooted to polled mode) was switched to framed again
    if protocol == "framed":
        assert dev.received.count(b"F") >= 2


def test_device_going_quiet_mid_capture_is_a_warning_not_an_error(tmp_path):
    with device(speed=5.0) as dev:
        reader = SerialReader(dev.port, protocol="framed", channels=10, silent_s=0.4)
        # quiet for 0.8 s after 150 records; stop 150 records after the data came back
        after = AfterRecords(dev, 150, lambda: dev.silence(0.8), 150,
                             resume=lambda: any(k == "resumed" for k, _ in reader_events))
        reader_events: list = []
        reader.on_event = lambda kind, msg: reader_events.append((kind, msg))
        res = capture(reader, tmp_path / "q.csv", stop=after.stop, duration_s=60.0,
                      progress=None, handle_sigint=False, on_records=after)
    kinds = [k for k, _ in reader_events]
    assert "silent" in kinds and "resumed" in kinds
    assert res.stopped_by == "stop" and res.samples >= 300


def test_reader_gives_up_when_port_does_not_return():
    from triaxcal.io.serial import DisconnectedError

    with device(speed=5.0, mode="F") as dev:
        reader = SerialReader(dev.port, protocol="framed", channels=10, reconnect_timeout_s=0.5)
        reader.open()
        got = reader.read()
        dev.unplug(30.0)
        t0 = time.monotonic()
        with pytest.raises(DisconnectedError, match="did not come back"):
            while True:
                got += reader.read()
        assert time.monotonic() - t0 < 3.0
        reader.close()


# ----------------------------------------------------------------------- clear errors


def test_nonexistent_port_is_reported_quickly(tmp_path, capsys):
    t0 = time.monotonic()
    with pytest.raises(PortNotFoundError, match="does not exist"):
        SerialReader(str(tmp_path / "ttyNOPE"), protocol="framed").open()
    assert time.monotonic() - t0 < 4.0
    out = tmp_path / "x.csv"
    rc = main(["capture", "--port", str(tmp_path / "ttyNOPE"), "--protocol", "text",
               "-o", str(out)])
    assert rc == 1
    assert "does not exist" in capsys.readouterr().err
    assert not out.exists()


def test_silent_device_is_reported_quickly(tmp_path):
    with device() as dev:
        dev.silence(60.0)
        t0 = time.monotonic()
        with pytest.raises(SilentDeviceError, match="did not answer the request byte"):
            capture(SerialReader(dev.port, protocol="binary", channels=10), tmp_path / "s.csv",
                    progress=None, handle_sigint=False)
        assert time.monotonic() - t0 < 5.0
    # no empty session is left behind to block running the command again
    assert not (tmp_path / "s.csv").exists()


def test_garbage_only_stream_is_reported_quickly(tmp_path):
    with device(mode="T", wrong_baud=True) as dev:
        t0 = time.monotonic()
        with pytest.raises(GarbageError, match="baud rate is probably wrong"):
            capture(SerialReader(dev.port, protocol="text", channels=10, baud=9600),
                    tmp_path / "g.csv", progress=None, handle_sigint=False)
        assert time.monotonic() - t0 < 5.0
    assert issubclass(GarbageError, CaptureError) and issubclass(CaptureError, ValueError)


# ----------------------------------------------------------------------- device commands


def test_motioncal_packet_is_echoed_and_mode_bytes_switch():
    with device(speed=10.0) as dev, serial.Serial(dev.port, 115200, timeout=1) as port:
        soft = [[1.01, 0.01, -0.02], [0.01, 0.99, 0.03], [-0.02, 0.03, 1.02]]
        pkt = encode_motioncal(accel_offset=[0.1, -0.2, 0.3], gyro_offset=[1, 2, 3],
                               mag_offset=[10, -20, 30], field=48.5, soft_iron=soft)
        port.write(pkt)
        time.sleep(0.2)
        cal = parse_motioncal_echo(port.read(port.in_waiting))
        assert cal is not None
        assert cal[0] == pytest.approx((0.1, -0.2, 0.3, 1, 2, 3, 10, -20, 30, 48.5), abs=1e-4)
        assert cal[1] == pytest.approx(
            (1.01, 0.01, -0.02, 0.01, 0.99, 0.03, -0.02, 0.03, 1.02), abs=1e-4)
        # a packet with a bad CRC is ignored
        port.write(pkt[:-1] + bytes([pkt[-1] ^ 1]))
        time.sleep(0.2)
        assert port.in_waiting == 0
        port.write(b"T")
        time.sleep(0.2)
        assert port.in_waiting > 100
        port.write(b"P")
        time.sleep(0.1)
        port.reset_input_buffer()
        time.sleep(0.2)
        assert port.in_waiting == 0
        assert dev.motioncal is not None


# ----------------------------------------------------------------------- pieces


def test_session_writer_modes(tmp_path):
    p = tmp_path / "w.csv"
    with SessionWriter(p, ("ax", "ay", "az")) as w:
        w.write([Record(1.5, (1, 2, 3)), Record(2.0, (4, 5, 6.5))])
    with pytest.raises(CalibrationError, match="exists already"):
        SessionWriter(p, ("ax", "ay", "az"))
    with pytest.raises(CalibrationError, match="header"):
        SessionWriter(p, ("ax", "ay"), mode="append")
    with open(p, "a") as f:
        f.write("3.0,7,8")  # a row cut by a power cut
    with SessionWriter(p, ("ax", "ay", "az"), mode="append") as w:
        w.write([Record(4.0, (9, 10, 11))])
    cols, data = read_session(p)
    assert cols == ("t", "ax", "ay", "az")
    np.testing.assert_array_equal(data[:, 1:], [[1, 2, 3], [4, 5, 6.5], [9, 10, 11]])
    assert p.read_text().splitlines()[1] == "1.500000,1,2,3"


def test_coverage_and_suggestions():
    rec = sim.SimIMU(1).record(sim.globe_script(hold_s=0.5), rate_hz=50)
    assert coverage(rec.pose_means("accel")).fraction == 1.0
    six = sim.SimIMU(1).record(sim.six_face_script(hold_s=0.5), rate_hz=50)
    assert coverage(six.pose_means("accel")).fraction == pytest.approx(6 / 24)
    assert "every direction covered" in suggest_turn(rec.pose_means("accel"))
    assert suggest_turn([[0, 0, 1.0]]).startswith("turn it upside down")
    s = suggest_turn([[0, 0, 1.0], [0, 0, -1.0]], [0, 0, 1.0])
    assert s.startswith("tilt the ") and "side" in s


def test_request_byte_forms():
    assert parse_request_byte("0x21") == b"!" == parse_request_byte("!")
    assert parse_request_byte(33) == b"!" == parse_request_byte(b"!")
    with pytest.raises(CaptureError):
        parse_request_byte("0x1FF")


def test_capture_page_names_the_command():
    from conftest import doc_page

    section = doc_page("guide/capture.md")
    assert "triaxcal capture --port" in section and "triaxcal demo" in section


@pytest.fixture(autouse=True)
def _no_leftover_threads():
    before = {t.ident for t in threading.enumerate()}
    yield
    deadline = time.monotonic() + 2
    while time.monotonic() < deadline:
        extra = [t for t in threading.enumerate()
                 if t.ident not in before and t.name == "SimDevice" and t.is_alive()]
        if not extra:
            break
        time.sleep(0.05)
    assert not extra





# ----------------------------------------------------------------------- emulated firmware

QEMU_TOOLS = [t for t in ("avr-gcc", "qemu-system-avr", "make") if shutil.which(t) is None]


@pytest.mark.slow
@pytest.mark.qemu
@pytest.mark.skipif(bool(QEMU_TOOLS), reason=f"{QEMU_TOOLS} not found: run `make deps`")
def test_capture_from_the_emulated_avr_firmware(tmp_path, capsys):
    """`triaxcal capture` against the project's firmware in QEMU's Arduino Uno, as a board."""
    import re

    build = tmp_path / "build"
    subprocess.run(["make", "-s", "-C", str(ROOT / "firmware"), f"BUILD={build}", "sim"],
                   check=True, capture_output=True, timeout=180)
    truth = dict(re.findall(r"#define\s+(SIM_\w+)\s+(-?\d+)",
                            (ROOT / "firmware" / "src" / "sim_truth.h").read_text()))
    gyro = np.array([int(truth[f"SIM_GYRO_OFFSET_{a}"]) for a in "XYZ"])
    proc = subprocess.Popen(
        ["qemu-system-avr", "-machine", "arduino-uno", "-bios", str(build / "triaxcal-sim.elf"),
         "-nographic", "-serial", "pty", "-monitor", "none"],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )
    try:
        line = proc.stdout.readline()
        port = re.search(r"(/dev/pts/\d+)", line).group(1)
        for protocol in ("binary", "framed", "text"):
            out = tmp_path / f"{protocol}.csv"
            rc = main(["capture", "--port", port, "--protocol", protocol, "--channels", "7",
                       "--samples", "60", "-o", str(out), "--quiet"])
            assert rc == 0, capsys.readouterr().err
            cols, data = read_session(out)
            assert cols == ("t", *sim.CHANNELS_7) and len(data) == 60
            # a still-ish board: the gyro columns sit on the firmware's true offsets
            np.testing.assert_allclose(np.median(data[:, 4:7], axis=0), gyro, atol=6)
            assert abs(np.median(data[:, 7]) - int(truth["SIM_TEMP_RAW"])) <= 6
    finally:
        proc.terminate()
        proc.wait(timeout=10)
        proc.stdout.close()
