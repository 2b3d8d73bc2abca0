"""The host side of the board's own calibration (triaxcal.io.board_store, triaxcal board): the
stored record and its frames, pure; ``triaxcal board read`` / ``write`` through a real
pseudo-terminal against a small fake board that keeps a record as the firmware does (the
firmware itself runs in QEMU in test_firmware_lib.py)."""

from __future__ import annotations

import os
import select
import struct
import threading
import tty

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from triaxcal import Calibration, CalibrationError, SensorCalibration
from triaxcal.calibration.board import calibration_to_record, record_to_calibration
from triaxcal.cli import main
from triaxcal.io.board_poses import BoardPoseDecoder, encode_pose_frame
from triaxcal.io.board_store import (
    BoardQuality,
    BoardRecord,
    BoardStoreDecoder,
    RecordReport,
    crc16,
    decode_record,
    encode_quality_frame,
    encode_record_frame,
    write_packet,
)
from triaxcal.io.framing import crc16_ccitt
from triaxcal.io.protocol import encode_framed

REC = BoardRecord(offset=(180.0625, -239.875, 350.5),
                  matrix=((0.98520, 0.0, 0.0), (0.0, 1.01639, 0.0), (0.0, 0.0, 0.99600)),
                  radius=16384.0, model="axis", origin="board", n=60, warnings=0x40,
                  rms=0.29, spread=0.29)
QUALITY = BoardQuality(code=0, descent_code=0, warnings=0, n=60, iterations=3,
                       descent_iterations=15, center=(180.0, -240.0, 350.0), rms=0.25,
                       spread=0.28125, faces=(9, 9, 9, 9, 12, 12), stack_free=82)


def test_one_crc_definition():
    data = bytes(range(200))
    assert crc16(data) == crc16_ccitt(data) and crc16(b"123456789") == 0x29B1


def test_record_round_trip_and_layout():
    b = REC.to_bytes()
    assert len(b) == 72 and b[:3] == b"TC\x01" and b[3:6] == bytes([1, 6, 1])
    assert struct.unpack_from("<HH", b, 6) == (60, 0x40)
    assert struct.unpack_from("<4f", b, 10) == (16384.0, 180.0625, -239.875, 350.5)
    assert struct.unpack_from("<H", b, 70)[0] == crc16(b[:70])
    assert decode_record(b) == REC
    # values are float32 from the start: what comes back equals what was made
    r = BoardRecord(offset=(0.1, 0.2, 0.3), matrix=((1.0000001, 0, 0), (0, 1, 0), (0, 0, 1)),
                    radius=16384)
    assert decode_record(r.to_bytes()) == r and r.offset[0] == np.float32(0.1)


def test_every_flipped_bit_is_caught():
    b = REC.to_bytes()
    for i in range(len(b) * 8):
        bad = bytearray(b)
        bad[i // 8] ^= 1 << (i % 8)
        with pytest.raises(CalibrationError, match="damaged"):
            decode_record(bytes(bad))


@pytest.mark.parametrize("data, match", [
    (b"\xff" * 72, "holds no calibration"),
    (b"\x00" * 72, "holds no calibration"),
    (b"\x01" * 71, "72 bytes"),
    (b"XX" + b"\x00" * 70, "damaged"),
])
def test_absent_and_damaged_records(data, match):
    with pytest.raises(CalibrationError, match=match):
        decode_record(data)


def _resealed(b: bytes) -> bytes:
    return b[:70] + struct.pack("<H", crc16(b[:70]))


def test_intact_records_that_cannot_be_used():
    b = bytearray(REC.to_bytes())
    b[2] = 2  # a newer version
    with pytest.raises(CalibrationError, match="version 2"):
        decode_record(_resealed(bytes(b)))
    b = bytearray(REC.to_bytes())
    b[14:18] = struct.pack("<f", float("nan"))
    with pytest.raises(CalibrationError, match="not finite"):
        decode_record(_resealed(bytes(b)))
    b = bytearray(REC.to_bytes())
    b[26:62] = struct.pack("<9f", *[0.0] * 9)  # a singular matrix
    with pytest.raises(CalibrationError, match="singular"):
        decode_record(_resealed(bytes(b)))
    for bad in ({"radius": 0}, {"radius": float("inf")}, {"n": 70000}, {"model": "magic"},
                {"offset": (1, 2)}, {"rms": 1e39}):
        with pytest.raises(CalibrationError):
            BoardRecord(**{**REC.__dict__, **bad})


@given(st.lists(st.one_of(st.just("K"), st.just("Q"), st.just("P"), st.just("F"),
                          st.binary(max_size=40)), max_size=10),
       st.lists(st.integers(0, 3000), max_size=6))
@settings(max_examples=150)
def test_decoder_any_chunking_and_garbage(items, cuts):
    """K and Q frames come through in order whatever is around them and however the bytes
    arrive; pose and sample frames are passed over; garbage is dropped; nothing raises."""
    data, want = b"", []
    for seq, it in enumerate(items):
        if it == "K":
            data += encode_record_frame(REC.to_bytes(), flags=0x11, seq=seq)
            want.append("K")
        elif it == "Q":
            data += encode_quality_frame(QUALITY, seq=seq)
            want.append("Q")
        elif it == "P":
            data += encode_pose_frame([1] * 7, 1, index=0, seq=seq)
        elif it == "F":
            data += encode_framed([1, 2, 3], seq=seq)
        else:
            data += it.replace(b"\x00", b"") + b"\x00"  # a garbage frame
    dec, got = BoardStoreDecoder(), []
    for a, b in zip([0, *sorted(cuts)], [*sorted(cuts), len(data)]):
        got += dec.feed(data[a:b])
    assert ["K" if isinstance(g, RecordReport) else "Q" for g in got] == want
    for g in got:
        if isinstance(g, RecordReport):
            assert g.record() == REC and g.reason == "fitted" and g.applied
        else:
            assert g == QUALITY and g.why == "fitted and stored"
    assert dec.other_frames == sum(it in ("P", "F") for it in items)
    assert dec.buffered <= 400


@given(st.binary(max_size=600))
def test_decoder_never_raises(data):
    dec = BoardStoreDecoder()
    dec.feed(data)
    dec.flush()
    assert dec.buffered == 0


def test_pose_decoder_passes_over_the_calibration_frames():
    """After the 84th pose the board sends its fit and its record in the pose stream: the
    still-pose decoder keeps them out of the poses without counting them as damage."""
    dec = BoardPoseDecoder(7)
    data = encode_pose_frame([16384 * 4] * 7, 4, index=0, seq=0)
    data += encode_quality_frame(QUALITY, seq=1) + encode_record_frame(REC.to_bytes(), seq=2)
    data += encode_pose_frame([0] * 7, 4, index=1, seq=3)
    assert len(dec.feed(data)) == 2
    assert dec.stats.dropped_frames == 0 and dec.stats.lost_frames == 0 and dec.heartbeats == 2


def test_reports_say_why():
    rep = RecordReport(status=2, reason="report", applied=False, raw=b"\x12" * 72)
    with pytest.raises(CalibrationError, match="damaged"):
        rep.record()
    rep = RecordReport(status=4, reason="write refused", applied=False, raw=REC.to_bytes())
    with pytest.raises(CalibrationError, match="refused the record: a record whose values"):
        rep.record()
    assert write_packet(REC) == b"w1" + REC.to_bytes()


# ------------------------------------------------------------ calibration file <-> record

def host_calibration(**part) -> Calibration:
    kw = {"offset": [100.5, -20.25, 3.0], "matrix": np.diag([1 / 16500, 1 / 16300, 1 / 16400]),
          "raw_unit": "counts", "unit": "g", "radius": 1.0, "model": "axis",
          "stats": {"rms": 1e-4, "n": 26}}
    kw.update(part)
    return Calibration(accel=SensorCalibration(**kw))


def test_record_and_calibration_file():
    cal = host_calibration()
    rec = calibration_to_record(cal,
                              counts_per_g=16384)
    assert rec.radius == 16384 and rec.origin == "host" and rec.model == "axis" and rec.n == 26
    assert rec.matrix[0][0] == pytest.approx(16384 / 16500, rel=1e-7)
    assert rec.rms == pytest.approx(1e-4 * 16384, rel=1e-6)
    back = record_to_calibration(decode_record(rec.to_bytes())).accel
    np.testing.assert_allclose(back.matrix, cal.accel.matrix, rtol=1e-7)
    np.testing.assert_allclose(back.offset, cal.accel.offset, rtol=1e-7)
    assert back.unit == "g" and back.radius == 1.0 and back.stats["origin"] == "host"
    # m/s^2 converts; other units, raw units and temperature terms cannot go to a board
    ms2 = host_calibration(unit="m/s^2", matrix=np.eye(3) * 9.80665 / 16384, radius=9.80665)
    assert calibration_to_record(ms2,
                              counts_per_g=16384).matrix[1][1] == pytest.approx(1.0, rel=1e-7)
    with pytest.raises(CalibrationError, match="cannot convert"):
        calibration_to_record(host_calibration(unit="uT"),
                              counts_per_g=16384)
    with pytest.raises(CalibrationError, match="raw unit"):
        calibration_to_record(host_calibration(raw_unit="g", unit="g"),
                              counts_per_g=16384)
    gyro_only = Calibration(gyro=SensorCalibration(offset=[0, 0, 0], matrix=np.eye(3)))
    with pytest.raises(CalibrationError, match="no accel part"):
        calibration_to_record(gyro_only,
                              counts_per_g=16384)


# ------------------------------------------------------------- the CLI, a fake board

class FakeStore:
    """A pseudo-terminal that keeps a record as the firmware does: 'K' reports it, a write
    packet stores it (or refuses it), 'A' / 'a' switch applying; other frames around."""

    def __init__(self, stored: bytes = b"\xff" * 72, *, refuse: bool = False,
                 mute: bool = False) -> None:
        self.master, slave = os.openpty()
        tty.setraw(slave)
        self.port = os.ttyname(slave)
        self._slave = slave
        self.stored, self.refuse, self.mute = stored, refuse, mute
        self.applied = False
        self.seq = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _status(self) -> int:
        try:
            decode_record(self.stored)
            return 0
        except CalibrationError as exc:
            return 1 if "no calibration" in str(exc) else 2

    def _send(self, data: bytes) -> None:
        os.write(self.master, data)

    def _report(self, flags: int, status: int | None = None) -> None:
        st = self._status() if status is None else status
        self._send(encode_framed([1, 2, 3, 4, 5, 6, 7], seq=self.seq))  # a stream around it
        self._send(encode_record_frame(self.stored, status=st,
                                       flags=flags | int(self.applied), seq=self.seq + 1))
        self.seq += 2

    def _run(self) -> None:
        buf = bytearray()
        while not self._stop.is_set():
            ready, _, _ = select.select([self.master], [], [], 0.01)
            if not ready:
                continue
            try:
                buf += os.read(self.master, 4096)
            except OSError:
                return
            while buf and not self.mute:
                if buf[:2] == b"w1":
                    if len(buf) < 74:
                        break
                    rec, buf = bytes(buf[2:74]), buf[74:]
                    if self.refuse:
                        self._report(0x30, status=4)
                    else:
                        self.stored = rec
                        self._report(0x20)
                    continue
                c, buf = buf[:1], buf[1:]
                if c in (b"A", b"a"):
                    self.applied = c == b"A" and self._status() == 0
                if c in (b"K", b"A", b"a"):
                    self._report(0x00)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
        os.close(self.master)
        os.close(self._slave)


@pytest.fixture
def fake():
    boards = []

    def make(*args, **kw):
        boards.append(FakeStore(*args, **kw))
        return boards[-1]

    yield make
    for b in boards:
        b.close()


def test_board_read_writes_a_calibration_file(fake, tmp_path, capsys):
    board = fake(REC.to_bytes())
    out = tmp_path / "board.json"
    assert main(["board", "read", "--port", board.port, "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "fitted on the board, 60 poses" in text and "180.062" in text
    assert "only a band" in text  # the record's warning, in words
    part = Calibration.load(out).accel
    np.testing.assert_allclose(part.offset, REC.offset)
    np.testing.assert_allclose(part.matrix, np.asarray(REC.matrix) / 16384)
    assert part.unit == "g" and part.raw_unit == "counts" and part.model == "axis"
    assert part.stats["n_poses"] == 60 and part.stats["origin"] == "board"


@pytest.mark.parametrize("stored, match", [
    (b"\xff" * 72, "holds no calibration"),
    (REC.to_bytes()[:30] + b"\x55" + REC.to_bytes()[31:], "damaged"),
])
def test_board_read_reports_absent_and_damaged_records(fake, tmp_path, capsys, stored, match):
    board = fake(stored)
    out = tmp_path / "board.json"
    assert main(["board", "read", "--port", board.port, "-o", str(out)]) == 1
    assert match in capsys.readouterr().err
    assert not out.exists()


def test_board_write_stores_a_host_calibration(fake, tmp_path, capsys):
    board = fake()
    cal = tmp_path / "host.json"
    host_calibration().save(cal)
    assert main(["board", "write", "--counts-per-g", "16384",
                 str(cal), "--port", board.port, "--apply"]) == 0
    assert "calibrated now" in capsys.readouterr().out
    assert board.applied and decode_record(board.stored) == calibration_to_record(
        Calibration.load(cal),
                              counts_per_g=16384)
    assert main(["board", "read", "--port", board.port, "-o", str(tmp_path / "b.json")]) == 0
    back = Calibration.load(tmp_path / "b.json").accel
    np.testing.assert_allclose(back.matrix, Calibration.load(cal).accel.matrix, rtol=1e-7)


def test_board_write_refused_and_silent_boards(fake, tmp_path, capsys):
    cal = tmp_path / "host.json"
    host_calibration().save(cal)
    board = fake(refuse=True)
    assert main(["board", "write", "--counts-per-g", "16384",
                 str(cal), "--port", board.port]) == 1
    assert "refused the record" in capsys.readouterr().err
    board = fake(mute=True)
    assert main(["board", "read", "--port", board.port, "--timeout", "0.5"]) == 1
    assert "no answer from" in capsys.readouterr().err
    assert main(["board", "read", "--port", str(tmp_path / "nope")]) == 1
    assert "cannot open" in capsys.readouterr().err


def test_board_write_refuses_what_a_board_cannot_apply(tmp_path, capsys):
    from triaxcal.calibration import TemperatureTerms

    cal = tmp_path / "t.json"
    terms = TemperatureTerms(temp_ref_c=25.0, temp_range_c=(10.0, 40.0),
                             offset_poly=np.zeros((2, 3)))
    host_calibration(temperature=terms).save(cal)
    assert main(["board", "write", "--counts-per-g", "16384",
                 str(cal), "--port", str(tmp_path / "nope")]) == 1
    assert "temperature terms" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["board", "read", "--port", "x", "--counts-per-g", "0"])
    assert "--counts-per-g" in capsys.readouterr().err


def test_board_read_and_write_pass_the_validity_gate(fake, tmp_path, capsys):
    """Gains 1 : 3.7 between axes (the gate's bound is 3): not written, not stored, unless
    --force, and then marked as not valid."""
    bad = BoardRecord(offset=(0, 0, 0), matrix=((1, 0, 0), (0, 1, 0), (0, 0, 0.27)),
                      radius=16384, model="axis", origin="board", n=60)
    board = fake(bad.to_bytes())
    out = tmp_path / "board.json"
    assert main(["board", "read", "--port", board.port, "-o", str(out)]) == 2  # not written
    assert "factor of" in capsys.readouterr().err and not out.exists()
    assert main(["board", "read", "--port", board.port, "-o", str(out), "--force"]) == 0
    assert Calibration.load(out).accel.valid is False
    cal = tmp_path / "host.json"
    host_calibration(matrix=np.diag([1 / 16384, 1 / 16384, 1 / 60000])).save(cal)
    board = fake()
    assert main(["board", "write", "--counts-per-g", "16384",
                 str(cal), "--port", board.port]) == 2
    assert "refused to store on the board" in capsys.readouterr().err
    assert board.stored == b"\xff" * 72
    assert main(["board", "write", "--counts-per-g", "16384",
                 str(cal), "--port", board.port, "--force"]) == 0
    assert decode_record(board.stored).matrix[2][2] == pytest.approx(16384 / 60000, rel=1e-6)

