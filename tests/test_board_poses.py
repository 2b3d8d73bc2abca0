"""The still-pose mode's host side (triaxcal.io.board_poses): frames in, one record per pose out.

Pure decoder properties with hypothesis (round trips in any chunking, garbage, truncation, no
wrong record, never an exception), the settings packet, and ``triaxcal capture --board-poses``
through a real pseudo-terminal against a small fake board that answers the mode byte ``S`` as
the firmware does (the firmware itself runs in QEMU in test_firmware.py).
"""

from __future__ import annotations

import os
import select
import threading
import time
import tty

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from triaxcal import CalibrationError
from triaxcal.capture.run import read_session
from triaxcal.cli import main
from triaxcal.detect.session import POSE_N_COLUMN
from triaxcal.io.board_poses import (
    MODE_BYTE,
    BoardPoseDecoder,
    BoardPoseSettings,
    BoardStatus,
    encode_pose_frame,
    encode_settings_frame,
    encode_status_frame,
)
from triaxcal.io.protocol import FramedDecoder, crc16_ccitt, encode_framed

K = 7


@st.composite
def poses(draw, k: int = K):
    """(sums, n): sums of n int16 samples, as the board makes them."""
    n = draw(st.integers(1, 62500))
    means = draw(st.lists(st.integers(-32768, 32767), min_size=k, max_size=k))
    jitter = draw(st.lists(st.integers(-1000, 1000), min_size=k, max_size=k))
    sums = [int(np.clip(m * n + j, -32768 * n, 32767 * n)) for m, j in zip(means, jitter)]
    return sums, n


statuses = st.builds(
    BoardStatus,
    flags=st.integers(0, 15), run=st.integers(0, 255), poses=st.integers(0, 65535),
    accel=st.tuples(*[st.integers(-32768, 32767)] * 3),
    rate=st.tuples(*[st.integers(-32768, 32767)] * 3),
)


def stream(items, spans=None) -> tuple[bytes, list[tuple]]:
    """Frames of ``items`` (pose (sums, n) or a BoardStatus), and the records they give;
    ``spans`` gets the (start, end) of each pose frame in the bytes."""
    data, want, index = b"", [], 0
    for seq, item in enumerate(items):
        if isinstance(item, BoardStatus):
            data += encode_status_frame(item, seq=seq)
        else:
            sums, n = item
            frame = encode_pose_frame(sums, n, index=index, seq=seq)
            if spans is not None:
                spans.append((len(data), len(data) + len(frame)))
            data += frame
            want.append((*(s / n for s in sums), n))
            index += 1
    return data, want


items = st.lists(st.one_of(poses(), statuses), max_size=12)


@given(items, st.lists(st.integers(0, 2000), max_size=8))
def test_round_trip_any_chunking(its, cuts):
    data, want = stream(its)
    dec = BoardPoseDecoder(K)
    got = []
    for a, b in zip([0, *sorted(cuts)], [*sorted(cuts), len(data)]):
        got += dec.feed(data[a:b])
    assert got == want and dec.buffered == 0
    assert dec.stats.dropped_frames == 0 and dec.stats.lost_frames == 0
    assert dec.poses_lost == 0
    assert dec.heartbeats == sum(isinstance(i, BoardStatus) for i in its)
    last = [i for i in its if isinstance(i, BoardStatus)]
    assert dec.status == (last[-1] if last else None)


@given(items, st.binary(max_size=300), st.integers(0, 10_000), st.integers(0, 10_000))
def test_garbage_and_truncation_never_give_a_wrong_record(its, garbage, at, cut):
    """Garbage inserted anywhere and a stream cut anywhere: the decoder never raises, keeps a
    bounded buffer, and every record it returns is one that was sent, in order."""
    spans: list[tuple[int, int]] = []
    data, want = stream(its, spans)
    at %= len(data) + 1
    whole = data[:at] + garbage + data[at:]
    cut %= len(whole) + 1
    damaged = whole[:cut]
    dec = BoardPoseDecoder(K)
    got = dec.feed(damaged) + dec.flush()
    assert dec.buffered == 0
    it = iter(want)
    assert all(any(g == w for w in it) for g in got)  # a subsequence of what was sent
    # every pose frame that neither the garbage nor the cut touched comes through
    untouched = sum(
        1 for a, b in spans
        if (b <= at and b <= cut) or (a >= at and b + len(garbage) <= cut)
    )
    assert len(got) >= untouched


@given(st.binary(max_size=500))
@settings(max_examples=300)
def test_any_bytes(data):
    dec = BoardPoseDecoder(None)
    for rec in dec.feed(data) + dec.flush():
        n = rec[-1]
        assert 1 <= n <= 65535 and all(abs(m) <= 32768 for m in rec[:-1])
    assert dec.buffered <= 2 * 300


def test_flipped_bit_is_dropped_and_counted():
    sums, n = [100 * 7] * K, 7
    frame = bytearray(encode_pose_frame(sums, n, index=0, seq=0))
    good = bytes(frame)
    frame[5] ^= 0x04
    dec = BoardPoseDecoder(K)
    assert dec.feed(bytes(frame)) == []
    assert dec.stats.dropped_frames == 1
    assert dec.feed(good) == [(100.0,) * K + (7,)]


def test_sums_that_no_samples_give_are_refused():
    """A frame with a good CRC whose sums could not come from n int16 samples, or n = 0."""
    dec = BoardPoseDecoder(2)
    assert dec.feed(encode_pose_frame([32768 * 3 + 1, 0], 3, index=0, seq=0)) == []
    assert dec.stats.dropped_frames == 1
    with pytest.raises(CalibrationError, match="n"):
        encode_pose_frame([0, 0], 0, index=0, seq=0)


def test_int16_frames_and_pose_frames_are_not_confused():
    """Pose, status and settings frames have an odd byte count between seq and CRC, frames of K
    int16 an even one: each decoder drops the other's frames, whatever K."""
    pose = encode_pose_frame([1] * K, 1, index=0, seq=0)
    status = encode_status_frame(BoardStatus(0, 0, 0, (0, 0, 0), (0, 0, 0)), seq=1)
    conf = encode_settings_frame(BoardPoseSettings(), seq=2)
    plain = FramedDecoder(None)
    assert plain.feed(pose + status + conf) == []
    assert plain.stats.dropped_frames == 3
    boardd = BoardPoseDecoder(None)
    for k in range(1, 20):
        assert boardd.feed(encode_framed(list(range(k)), seq=k)) == []
    assert boardd.stats.dropped_frames == 19 and boardd.channels is None


def test_pose_index_counts_lost_poses_and_restarts():
    dec = BoardPoseDecoder(1)
    for i, idx in enumerate((0, 1, 4, 5, 0, 1)):
        dec.feed(encode_pose_frame([10], 1, index=idx, seq=i))
    assert dec.poses_lost == 2 and dec.restarts == 1 and dec.last_index == 1


def test_settings_packet_and_validation():
    s = BoardPoseSettings()
    assert s.to_dict() == {"period_ms": 10, "window": 25, "hold_windows": 4,
                           "holdoff_ms": 2000, "accel_threshold": 1147,
                           "gyro_threshold": 393, "beep_ms": 100}
    p = s.packet()
    assert p[:2] == b"s1" and len(p) == 14
    assert int.from_bytes(p[-2:], "little") == crc16_ccitt(p[:-2])
    # little-endian fields in the firmware's order (still_pack)
    assert p[2:12] == bytes([10, 25, 4]) + (2000).to_bytes(2, "little") + \
        (1147).to_bytes(2, "little") + (393).to_bytes(2, "little") + bytes([100])
    assert s.holdoff_samples == 200
    for bad in ({"window": 0}, {"period_ms": 251}, {"holdoff_ms": 60001},
                {"accel_threshold": 0}, {"gyro_threshold": -1}, {"beep_ms": 1.5},
                {"hold_windows": True}):
        with pytest.raises(CalibrationError, match=next(iter(bad))):
            BoardPoseSettings(**bad)
    # a settings frame with values out of range is a bad frame, not a crash
    body = bytes([0, 0x43, 1, 1]) + bytes([0, 25, 4, 0, 0, 1, 0, 0, 0, 0])
    from triaxcal.io.protocol import cobs_encode

    frame = cobs_encode(body + crc16_ccitt(body).to_bytes(2, "little")) + b"\0"
    dec = BoardPoseDecoder(K)
    assert dec.feed(frame) == [] and dec.stats.dropped_frames == 1 and dec.settings is None


# ------------------------------------------------------------------- the CLI, a fake board

class FakeBoard:
    """A pseudo-terminal that answers the settings packet and ``S`` as the firmware does: a
    ``C`` frame, then status frames and the given poses, one every few milliseconds."""

    def __init__(self, poses_to_send, *, refuse: bool = False) -> None:
        self.master, slave = os.openpty()
        tty.setraw(slave)
        self.port = os.ttyname(slave)
        self._slave = slave
        self.poses = list(poses_to_send)
        self.refuse = refuse
        self.received = bytearray()
        self.settings: BoardPoseSettings | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        seq, sent, started = 0, 0, False
        while not self._stop.is_set():
            ready, _, _ = select.select([self.master], [], [], 0.005)
            if ready:
                try:
                    self.received += os.read(self.master, 4096)
                except OSError:
                    return
                i = self.received.find(b"s1")
                if i >= 0 and len(self.received) >= i + 14 and self.settings is None:
                    self.settings = BoardPoseSettings.from_bytes(
                        bytes(self.received[i + 2:i + 12]))
                if not started and MODE_BYTE in self.received[i + 14 if i >= 0 else 0:]:
                    started = True
                    use = BoardPoseSettings() if self.refuse else self.settings
                    os.write(self.master, encode_settings_frame(use, seq=seq))
                    seq += 1
            if started and sent < len(self.poses):
                sums, n = self.poses[sent]
                out = encode_status_frame(BoardStatus(8, 4, sent, (0, 0, 16384), (0, 0, 0)),
                                          seq=seq)
                out += encode_pose_frame(sums, n, index=sent, seq=seq + 1)
                os.write(self.master, out)
                seq, sent = seq + 2, sent + 1
                time.sleep(0.005)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
        os.close(self.master)
        os.close(self._slave)


def sphere_poses(offset, per_g, n=100):
    """Pose sums of a board with these offsets and counts per g, at 26 directions."""
    dirs = [(x, y, z) for x in (-1, 0, 1) for y in (-1, 0, 1) for z in (-1, 0, 1)
            if (x, y, z) != (0, 0, 0)]
    out = []
    for d in dirs:
        u = np.array(d, dtype=float) / np.linalg.norm(d)
        acc = np.asarray(offset) + u * np.asarray(per_g)
        sums = [int(round(v * n)) for v in acc] + [40 * n, -17 * n, 9 * n, -1500 * n]
        out.append((sums, n))
    return out


def test_capture_board_poses_then_fit(tmp_path, capsys):
    offset, per_g = np.array([180.0, -240.0, 350.0]), np.array([16630.0, 16120.0, 16450.0])
    board = FakeBoard(sphere_poses(offset, per_g))
    out = tmp_path / "globe.csv"
    try:
        rc = main(["capture", "--port", board.port, "--protocol", "framed", "--board-poses",
                   "--holdoff", "2", "--gyro-threshold", "off", "--poses", "26",
                   "--seconds", "30", "-o", str(out), "--quiet"])
    finally:
        board.close()
    assert rc == 0, capsys.readouterr().err
    # the options went to the board in its units; 7 channels by default
    assert board.settings == BoardPoseSettings(holdoff_ms=2000, gyro_threshold=0)
    cols, data = read_session(out)
    assert cols == ("t", "ax", "ay", "az", "gx", "gy", "gz", "temp", POSE_N_COLUMN)
    assert data.shape == (26, 9) and (data[:, 8] == 100).all()
    err = capsys.readouterr().err
    assert "26 rows, 26 poses" in err and "pose settings" not in err
    # fit takes the rows as the poses they are, with or without --poses
    for extra in ([], ["--poses"]):
        cal = tmp_path / f"cal{len(extra)}.json"
        assert main(["fit", str(out), "--model", "axis", "-o", str(cal), *extra]) == 0
        from triaxcal import Calibration

        part = Calibration.load(cal).accel
        np.testing.assert_allclose(part.offset, offset, atol=0.05)
        np.testing.assert_allclose(1 / np.diag(part.matrix), per_g, rtol=1e-5)
        assert part.stats["pose_source"] == "board" and part.stats["n_poses"] == 26
    assert main(["report", str(tmp_path / "cal0.json")]) == 0


def test_several_boards_find_their_poses(tmp_path, capsys):
    boards = [FakeBoard(sphere_poses([10 * i, 0, 0], [16384] * 3)[:5]) for i in range(2)]
    try:
        rc = main(["capture", *[a for b in boards for a in ("--port", b.port)], "--protocol",
                   "framed", "--board-poses", "--poses", "5", "--seconds", "30", "--no-id",
                   "--out-dir", str(tmp_path / "sessions"), "--quiet"])
    finally:
        for b in boards:
            b.close()
    assert rc == 0, capsys.readouterr().err
    files = sorted((tmp_path / "sessions").glob("*.csv"))
    assert len(files) == 2
    for b in boards:
        assert b.settings == BoardPoseSettings(holdoff_ms=0)
    for f in files:
        cols, data = read_session(f)
        assert cols[-1] == POSE_N_COLUMN and data.shape == (5, 9)
    assert sorted(read_session(f)[1][0, 1] for f in files) == \
        pytest.approx([-16384 / 3 ** 0.5, 10 - 16384 / 3 ** 0.5], abs=0.01)


def test_capture_warns_when_the_board_keeps_other_settings(tmp_path, capsys):
    board = FakeBoard(sphere_poses([0, 0, 0], [16384] * 3)[:3], refuse=True)
    try:
        rc = main(["capture", "--port", board.port, "--protocol", "framed", "--board-poses",
                   "--window", "10", "--poses", "3", "--seconds", "30",
                   "-o", str(tmp_path / "s.csv")])
    finally:
        board.close()
    assert rc == 0
    err = capsys.readouterr().err
    assert "the board uses other pose settings than sent" in err
    assert "'window': 25" in err and "'window': 10" in err


@pytest.mark.parametrize("argv, match", [
    (["--protocol", "binary", "--board-poses"], "framed"),
    (["--protocol", "framed", "--board-poses", "--hold", "off"], "--hold"),
    (["--protocol", "framed", "--board-poses", "--rate-hz", "300"], "--rate-hz"),
    (["--protocol", "framed", "--board-poses", "--mag-threshold", "5"], "magnetometer"),
    (["--protocol", "framed", "--board-poses", "--beep-ms", "300"], "beep_ms"),
    (["--protocol", "framed", "--board-poses", "--window", "251"], "window"),
])
def test_board_poses_options_are_checked(argv, match, tmp_path, capsys):
    rc = main(["capture", "--port", str(tmp_path / "nope"), *argv,
               "-o", str(tmp_path / "s.csv")])
    assert rc != 0
    assert match in capsys.readouterr().err
    assert not (tmp_path / "s.csv").exists()
