"""The firmware's still-pose detector and frame code, compiled for the host and driven sample by
sample through ctypes.

``still.c``, ``protocol.c``, ``cobs.c`` and ``crc16.c`` are hardware-free, so the same source
that runs on the ATmega328P runs here on streams the QEMU globe does not make: a board left
still, a turn during the hold-off, a missing sensor, a gyro bias taken while turning, the
largest sums. The frames it writes are read back with the host's
:class:`~triaxcal.io.board_poses.BoardPoseDecoder` (the wire format checked from both ends).
The integer types are fixed-width (``int32_t`` sums, ``uint16_t`` counts), so the host build
computes what the AVR build computes.
"""

from __future__ import annotations

import ctypes
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from _synth import twist_first
from triaxcal import sim
from triaxcal.detect import detect_poses
from triaxcal.io.board_poses import BoardPoseDecoder, BoardPoseSettings

ROOT = Path(__file__).resolve().parent.parent
SRC = ROOT / "firmware" / "src"
#: The portable library the firmware's detector and CRC live in.
LIB = ROOT / "firmware" / "lib" / "triaxcal" / "src"
CC = shutil.which("cc") or shutil.which("gcc")

pytestmark = pytest.mark.skipif(CC is None, reason="no C compiler for the host (cc)")


class Settings(ctypes.Structure):
    _fields_ = [("period_ms", ctypes.c_uint8), ("window", ctypes.c_uint8),
                ("hold_windows", ctypes.c_uint8), ("holdoff_ms", ctypes.c_uint16),
                ("accel_threshold", ctypes.c_uint16), ("gyro_threshold", ctypes.c_uint16),
                ("beep_ms", ctypes.c_uint8)]


class Status(ctypes.Structure):
    _fields_ = [("flags", ctypes.c_uint8), ("run", ctypes.c_uint8), ("poses", ctypes.c_uint16),
                ("accel", ctypes.c_int16 * 3), ("rate", ctypes.c_int16 * 3)]


class PoseC(ctypes.Structure):
    _fields_ = [("index", ctypes.c_uint16), ("n", ctypes.c_uint16),
                ("sum", ctypes.c_int32 * 7)]


WRITER = ctypes.CFUNCTYPE(None, ctypes.c_uint8)


@pytest.fixture(scope="module")
def lib(tmp_path_factory):
    out = tmp_path_factory.mktemp("still") / "libstill.so"
    srcs = [str(LIB / "still.c"), str(SRC / "protocol.c"), str(SRC / "cobs.c"),
            str(LIB / "crc16.c")]
    proc = subprocess.run([CC, "-shared", "-fPIC", "-O1", "-std=gnu99", "-Wall", "-Wextra",
                           "-Werror", f"-I{SRC}", f"-I{LIB}", *srcs, "-o", str(out)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    so = ctypes.CDLL(str(out))
    so.still_feed.restype = ctypes.c_uint8
    so.still_status.restype = ctypes.POINTER(Status)
    so.still_pose.restype = ctypes.POINTER(PoseC)
    so.still_valid.restype = ctypes.c_uint8
    so.proto_pose_settings.restype = ctypes.POINTER(Settings)
    so.proto_feed.restype = ctypes.c_int
    return so


class Detector:
    """still.c fed from Python; every frame main.c would send goes to a BoardPoseDecoder."""

    def __init__(self, lib, settings: BoardPoseSettings) -> None:
        self.lib = lib
        self.settings = settings
        self.out = bytearray()
        self._writer = WRITER(self.out.append)  # kept alive while the library holds it
        lib.proto_set_writer(self._writer)
        s = Settings(**settings.to_dict())
        lib.still_start(ctypes.byref(s))
        self.poses: list[tuple[int, int, tuple[int, ...]]] = []  # (sample, n, sums)
        self.samples = 0

    def feed(self, rows) -> None:
        for row in np.asarray(rows, dtype=np.int64):
            v = (ctypes.c_int16 * 7)(*(int(x) for x in row))
            ev = self.lib.still_feed(v)
            self.samples += 1
            if ev & 2:
                p = self.lib.still_pose().contents
                self.poses.append((self.samples, p.n, tuple(p.sum)))
                self.lib.proto_send_pose(self.lib.still_pose(), 7)
            if ev & 1:
                self.lib.proto_send_status(self.lib.still_status())

    def breaks(self) -> None:
        self.lib.still_break()

    @property
    def status(self) -> Status:
        return self.lib.still_status().contents


BIAS = np.array([42, -17, 9])


def still(n, accel=(0, 0, 16384), bias=BIAS, temp=-1500, noise=3, seed=0):
    rng = np.random.default_rng(seed)
    rows = np.zeros((n, 7), dtype=np.int64)
    rows[:, 0:3] = accel
    rows[:, 3:6] = bias
    rows[:, 6] = temp
    rows += rng.integers(-noise, noise + 1, size=rows.shape)
    return rows


def turn(n, accel=(0, 0, 16384), rate=(0, 0, 5240)):
    rows = still(n, accel, noise=0)
    rows[:, 3:6] += np.asarray(rate)
    return rows


S = BoardPoseSettings(holdoff_ms=200)  # 20 samples at 10 ms: short enough for these streams


def test_a_board_left_still_gives_one_pose_at_the_expected_sample(lib):
    d = Detector(lib, S)
    data = still(5000)
    d.feed(data)
    w, h = S.window, S.hold_windows
    # window 0 has nothing to compare with, window 1 sets the bias and is skipped (it may end
    # a move), windows 2..h+1 are averaged; the seed would register a point per window
    assert [p[0] for p in d.poses] == [(h + 2) * w]
    sample, n, sums = d.poses[0]
    assert n == h * w
    assert sums == tuple(int(x) for x in data[2 * w:(h + 2) * w].sum(axis=0))
    assert d.status.poses == 1 and d.status.flags & 4  # waiting for a move


def test_frames_from_the_c_code_decode_on_the_host(lib):
    d = Detector(lib, S)
    data = np.vstack([still(300), turn(50), still(300, accel=(16384, 0, 0))])
    d.feed(data)
    dec = BoardPoseDecoder(7)
    recs = dec.feed(bytes(d.out))
    assert dec.stats.dropped_frames == 0 and dec.stats.lost_frames == 0
    assert [(r[-1], tuple(round(m * r[-1]) for m in r[:-1])) for r in recs] == \
        [(n, sums) for _, n, sums in d.poses]
    assert len(recs) == 2 and dec.status.poses == 2


def test_a_twist_seen_only_by_the_gyro_ends_the_pose(lib):
    for gyro, expect in ((393, 2), (0, 1)):
        d = Detector(lib, BoardPoseSettings(holdoff_ms=200, gyro_threshold=gyro))
        d.feed(np.vstack([still(400), turn(75), still(400, seed=1)]))
        assert len(d.poses) == expect


def test_a_slow_turn_below_the_threshold_is_not_motion(lib):
    d = Detector(lib, S)
    d.feed(np.vstack([still(400), turn(200, rate=(0, 0, 300)), still(400, seed=1)]))
    assert len(d.poses) == 1


def test_a_move_during_the_holdoff_counts(lib):
    """The seed waits 2 s after its beep for the hand to let go: a move inside the hold-off
    still arms the next pose, which is registered once the hold-off is over."""
    s = BoardPoseSettings(holdoff_ms=2000)  # 200 samples
    d = Detector(lib, s)
    d.feed(still(150))
    assert len(d.poses) == 1
    d.feed(turn(50))  # entirely inside the hold-off
    d.feed(still(1000, seed=2))
    assert len(d.poses) == 2
    first, second = d.poses
    assert second[0] - first[0] >= s.holdoff_samples
    # nothing from inside the hold-off is averaged
    assert second[0] - second[1] >= first[0] + s.holdoff_samples


def test_a_missing_sample_is_never_averaged(lib):
    d = Detector(lib, S)
    d.feed(still(110))
    d.breaks()  # the sensor did not answer
    assert d.status.flags & 1 and d.status.run == 0
    d.feed(still(500, seed=3))
    assert len(d.poses) == 1
    sample, n, _ = d.poses[0]
    assert sample - n >= 110  # after the gap


def test_a_bias_taken_while_turning_is_given_up(lib):
    """The board turned at a constant rate when the mode started: the first windows' gyro mean
    is not the bias. When the gyro then stays off it but unchanging for 8 steady windows, that
    becomes the bias and poses are found."""
    d = Detector(lib, S)
    d.feed(turn(100, rate=(0, 0, 2000)))
    d.feed(still(2000))
    assert len(d.poses) == 1
    sample, n, sums = d.poses[0]
    assert abs(sums[5] / n - BIAS[2]) < 1


def test_a_gyro_bias_that_drifts_is_followed(lib):
    """Warming up moves an MPU-6050's bias by a deg/s or more. Here it drifts by 600 counts
    (4.6 deg/s: more than the 393-count threshold, less than 16 of them) over 20 windows while
    the board lies still after a pose: once the rate is off the bias it is not averaged, but it
    is no move either (a pose after it would be the same pose again); after 8 unchanging
    windows it is the bias, and the next pose comes after a real move."""
    d = Detector(lib, S)
    d.feed(still(400))
    assert len(d.poses) == 1
    ramp = still(20 * S.window, seed=4)
    ramp[:, 4] += np.linspace(0, 600, len(ramp)).astype(np.int64)
    drifted = BIAS + (0, 600, 0)
    d.feed(ramp)
    d.feed(still(20 * S.window, bias=drifted, seed=5))
    assert len(d.poses) == 1 and d.status.flags & 4  # waiting for a move
    assert d.status.flags & 1 == 0  # the drift is the bias now: steady
    d.feed(turn(50, accel=(16384, 0, 0)))
    d.feed(still(400, accel=(16384, 0, 0), bias=drifted, seed=6))
    assert len(d.poses) == 2
    _, n, sums = d.poses[1]
    assert abs(sums[4] / n - drifted[1]) < 1
    # a jump of the rate by more than the threshold from one window to the next is a move
    d.feed(still(400, accel=(16384, 0, 0), bias=drifted + (0, 600, 0), seed=7))
    assert len(d.poses) == 3


def test_a_fast_steady_turn_is_never_taken_for_the_bias(lib):
    """A turn faster than 16 thresholds stays motion however steady it is: no pose while the
    board turns at the pole, one when it stops."""
    d = Detector(lib, S)
    d.feed(still(400))
    d.feed(turn(40 * S.window, rate=(0, 0, 7000)))
    assert len(d.poses) == 1
    d.feed(still(400, seed=6))
    assert len(d.poses) == 2


def _twist_first(seed: int):
    """The pose detectors' twist-first stream (``_synth.twist_first``) rounded to counts, with
    a temperature channel. Returns the rows and the samples at rest."""
    x, rest = twist_first(np.random.default_rng(seed))
    rows = np.zeros((len(x), 7), dtype=np.int64)
    rows[:, :6] = np.round(x)
    rows[:, 6] = -1500
    return rows, rest


#: 1 s rests (4 windows): a moving window, a skipped one and 2 averaged fit in them
QUICK = BoardPoseSettings(hold_windows=2, holdoff_ms=0)


@pytest.mark.parametrize("seed", [0, 5])
def test_a_twist_at_the_start_does_not_capture_the_gyro_bias(lib, seed):
    """A twist about the vertical from the first sample is steady to the accelerometer and to
    the gyro, so its rate was taken for the bias; every rest after it was a turn (1310 counts
    off), and 4-window rests never gave the 8 windows in a row that follow a drift: 1 pose.
    The first bias is provisional now, as in the host's detector: 8 steady windows off it at
    one rate, after different moves, replace it. The board then finds the poses the host's
    detector finds -- the same rests, inside the host's spans -- except the rest in which the
    bias is replaced (the host registers its last window; the board needs a skipped window and
    2 averaged ones)."""
    rows, rest = _twist_first(seed)
    d = Detector(lib, QUICK)
    d.feed(rows)
    host = detect_poses(rows[:, :6].astype(float), units_per_g=16384, gyro_columns=(3, 4, 5),
                        min_separation=0, max_windows=4).poses
    spans = [(p.start, p.end) for p in host]
    assert len(host) >= 1 + 12 - 3
    assert len(d.poses) >= len(host) - 1, (d.poses, spans)
    # every board pose is one of the host's poses: its samples inside that pose's span
    match = []
    for end, n, _ in d.poses:
        inside = [k for k, (a, b) in enumerate(spans) if a <= end - n and end <= b]
        assert len(inside) == 1, (end - n, end, spans)
        match += inside
    assert match[0] == 0 and d.poses[0][0] <= 300  # the twist itself is a pose to both
    # from the first rest the board registers, it registers every pose the host does
    assert match[1:] == list(range(match[1], len(host))), (match, spans)
    for end, n, sums in d.poses[1:]:
        assert rest[end - n:end].all()  # no turning sample in a pose
        np.testing.assert_allclose(np.array(sums[3:6]) / n, [60.0, -40.0, 25.0], atol=2.0)


def test_the_demo_cut_in_a_twist_finds_the_poses_of_a_start_at_rest(lib):
    """The demo's board (the globe, then a tumble) recorded from sample 274: the first
    windows lie in a twist about the vertical at 59 deg/s (7700 counts, more than 16
    thresholds), which was taken for the bias -- every rest after it read as a fast turn and
    the board found no pose in 20,000 samples. Cut 25 samples earlier, in the same windows,
    the recording starts at rest. Once the provisional bias is replaced, the board finds the
    same poses at the same samples with the same sums as from that start."""
    script = sim.globe_script(hold_s=1.0, seed=1) + sim.tumble_script(30, seed=1)
    x = sim.SimIMU(1).record(script, rate_hz=100).frames(7)
    found = {}
    for start in (249, 274):
        d = Detector(lib, QUICK)
        d.feed(x[start:])
        found[start] = [(start + end, n, sums) for end, n, sums in d.poses]
    at_rest, twist = found[249], found[274]
    assert len(at_rest) >= 80
    assert twist and twist == at_rest[-len(twist):]
    assert len(twist) >= len(at_rest) - 3  # the poses of the first 6 s are lost, no more


def test_the_largest_sums_do_not_overflow(lib):
    s = BoardPoseSettings(window=250, hold_windows=250, holdoff_ms=0)
    d = Detector(lib, s)
    d.feed(still(252 * 250, accel=(-32768, 32767, -32768), bias=(-32768, 32767, 0), noise=0))
    assert len(d.poses) == 1
    _, n, sums = d.poses[0]
    assert n == 62500
    assert sums[:5] == (-32768 * n, 32767 * n, -32768 * n, -32768 * n, 32767 * n)


def test_settings_wire_form_and_ranges_agree_with_the_host(lib):
    for s in (BoardPoseSettings(), BoardPoseSettings(1, 250, 250, 60000, 32767, 32767, 250),
              BoardPoseSettings(250, 1, 1, 0, 1, 0, 0)):
        c = Settings(**s.to_dict())
        assert lib.still_valid(ctypes.byref(c)) == 1
        buf = (ctypes.c_uint8 * 10)()
        lib.still_pack(ctypes.byref(c), buf)
        assert bytes(buf) == s.to_bytes()
    for field, bad in (("window", 0), ("period_ms", 0), ("hold_windows", 0),
                       ("holdoff_ms", 60001), ("accel_threshold", 0),
                       ("accel_threshold", 32768), ("gyro_threshold", 40000), ("beep_ms", 251)):
        c = Settings(**{**BoardPoseSettings().to_dict(), field: bad})
        assert lib.still_valid(ctypes.byref(c)) == 0, field


def test_the_settings_packet_is_parsed_by_the_command_parser(lib):
    out = bytearray()
    writer = WRITER(out.append)
    lib.proto_set_writer(writer)
    want = BoardPoseSettings(period_ms=2, window=10, hold_windows=3, holdoff_ms=700,
                             accel_threshold=900, gyro_threshold=100, beep_ms=50)
    events = [lib.proto_feed(b, 0) for b in want.packet()]
    assert events[-1] == 4 and not any(events[:-1])  # PROTO_EV_SETTINGS; no command inside
    got = lib.proto_pose_settings().contents
    assert {f: getattr(got, f) for f, _ in Settings._fields_} == want.to_dict()
    dec = BoardPoseDecoder(7)
    dec.feed(bytes(out))
    assert dec.settings == want and dec.settings_accepted
    # a damaged packet changes nothing and gets no answer; bytes after it are commands again
    out.clear()
    bad = bytearray(BoardPoseSettings().packet())
    bad[4] ^= 1
    assert [lib.proto_feed(b, 10) for b in bytes(bad) + b"S"][-1] == 2  # PROTO_EV_MODE
    assert not out and lib.proto_pose_settings().contents.window == 10
    lib.proto_feed(ord("P"), 20)
