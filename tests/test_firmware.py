"""The AVR firmware, built with avr-gcc and run in QEMU's Arduino Uno, captured like a board.

Builds ``firmware/`` with ``SIMULATED=1`` (QEMU's AVR machine has no TWI/I2C device), starts
``qemu-system-avr -machine arduino-uno ... -serial pty``, opens the pseudo-terminal it prints
with pyserial and talks to it as to a real board: polled legacy frames, the framed, text, Raw:
and legacy binary streams, a MotionCal calibration packet, and the still-pose mode (the board
finds the 84 poses of the globe scheme itself and beeps the buzzer pin on each; QEMU logs the
pin's writes with ``-d unimp``). The values are checked against
``firmware/src/sim_truth.h``. QEMU runs the CPU faster or slower than real time, so every wait
is "until enough has arrived or a generous deadline", never a fixed sleep that must be right.

Skipped only when avr-gcc or qemu-system-avr is missing (``make deps`` installs both; CI does).
"""

from __future__ import annotations

import contextlib
import os
import re
import select
import shutil
import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import serial
import triaxcal
from triaxcal.capture.run import capture, read_session
from triaxcal.cli import main
from triaxcal.detect.session import POSE_N_COLUMN
from triaxcal.io.board_poses import BoardPoseDecoder, BoardPoseSettings
from triaxcal.io.motioncal import encode_motioncal, parse_motioncal_echo
from triaxcal.io.protocol import (
    BinaryDecoder,
    FramedDecoder,
    RawDecoder,
    TextDecoder,
)
from triaxcal.io.serial import SerialReader

pytestmark = pytest.mark.qemu

ROOT = Path(__file__).resolve().parent.parent
FIRMWARE = ROOT / "firmware"
K = 7
MISSING = [tool for tool in ("avr-gcc", "qemu-system-avr", "make") if shutil.which(tool) is None]


def truth() -> dict[str, int]:
    text = (FIRMWARE / "src" / "sim_truth.h").read_text()
    found = dict(re.findall(r"^#define\s+(SIM_\w+)\s+(-?\d+)\s*$", text, flags=re.M))
    return {k: int(v) for k, v in found.items()}


TRUTH = truth()
OFFSET = np.array([TRUTH[f"SIM_ACCEL_OFFSET_{a}"] for a in "XYZ"], dtype=float)
PER_G = np.array([TRUTH[f"SIM_ACCEL_COUNTS_PER_G_{a}"] for a in "XYZ"], dtype=float)
GYRO = np.array([TRUTH[f"SIM_GYRO_OFFSET_{a}"] for a in "XYZ"], dtype=float)
NOISE = TRUTH["SIM_NOISE_COUNTS"]
POSES = TRUTH["SIM_LATITUDES"] * TRUTH["SIM_TURNS"]
SAMPLES = POSES * TRUTH["SIM_SAMPLES_PER_POSE"]


@pytest.fixture(scope="module")
def firmware_elf(tmp_path_factory) -> Path:
    if MISSING:
        pytest.skip(
            f"{', '.join(MISSING)} not found: run `make deps` (Debian packages gcc-avr, "
            "avr-libc, qemu-system-misc) to build and emulate the firmware"
        )
    build = tmp_path_factory.mktemp("avr-build")
    proc = subprocess.run(
        ["make", "-C", str(FIRMWARE), f"BUILD={build}", "sim"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, f"firmware build failed:\n{proc.stdout}\n{proc.stderr}"
    elf = build / "triaxcal-sim.elf"
    assert elf.is_file()
    return elf


class Board:
    """The emulated board behind a pyserial port, with deadline-bounded helpers."""

    def __init__(self, port) -> None:
        self.port = port

    def quiet(self, mode: bytes = b"P") -> None:
        """Switch mode and wait until the line is quiet, then empty the input buffer."""
        self.port.write(mode)
        self.port.flush()
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline:
            time.sleep(0.05)
            if not self.port.in_waiting:
                time.sleep(0.05)
                if not self.port.in_waiting:
                    break
            self.port.reset_input_buffer()
        self.port.reset_input_buffer()

    def poll(self, decoder: BinaryDecoder, request: bytes = b"!"):
        decoder.reset()
        self.port.reset_input_buffer()
        self.port.write(request)
        return decoder.feed(self.port.read(decoder.frame_len))

    def stream(self, mode: bytes, decoder, records: int, timeout_s: float = 15.0):
        """Switch to a streaming mode and decode until ``records`` records (or the deadline)."""
        self.quiet()
        self.port.write(mode)
        out: list[tuple] = []
        deadline = time.monotonic() + timeout_s
        while len(out) < records and time.monotonic() < deadline:
            data = self.port.read(self.port.in_waiting or 1)
            out += decoder.feed(data)
        self.quiet()
        return out

    def read_until(self, marker: bytes, timeout_s: float = 5.0) -> bytes:
        got = b""
        deadline = time.monotonic() + timeout_s
        while marker not in got and time.monotonic() < deadline:
            got += self.port.read(self.port.in_waiting or 1)
        return got


@contextlib.contextmanager
def qemu(elf: Path, unimp_log: Path | None = None):
    """Run the firmware in QEMU's Arduino Uno; yield the pseudo-terminal of its USART0."""
    cmd = ["qemu-system-avr", "-machine", "arduino-uno", "-bios", str(elf), "-nographic",
           "-serial", "pty", "-monitor", "none"]
    if unimp_log is not None:  # every access to a device QEMU does not model: the GPIO ports
        cmd += ["-d", "unimp", "-D", str(unimp_log)]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            stdin=subprocess.DEVNULL)
    try:
        banner = b""
        pty = re.compile(rb"char device redirected to (/dev/pts/\d+)\D")
        deadline = time.monotonic() + 15
        while not pty.search(banner) and time.monotonic() < deadline:
            ready, _, _ = select.select([proc.stdout], [], [], 0.2)
            if ready:
                chunk = os.read(proc.stdout.fileno(), 4096)
                if not chunk:
                    break  # qemu exited
                banner += chunk
        m = pty.search(banner)
        assert m, f"qemu-system-avr did not report its pseudo-terminal: {banner!r}"
        yield m.group(1).decode()
    finally:
        proc.kill()
        proc.wait(timeout=10)
        proc.stdout.close()


@pytest.fixture(scope="module")
def board(firmware_elf):
    with qemu(firmware_elf) as pty:
        port = serial.Serial(pty, 115200, timeout=1.0, write_timeout=2.0)
        try:
            b = Board(port)
            b.quiet()
            yield b
        finally:
            port.close()


def accel_g(rows) -> np.ndarray:
    """Accelerometer counts -> unit gravity vectors using the truth header."""
    a = np.asarray(rows, dtype=float)[:, :3]
    return (a - OFFSET) / PER_G


def check_consistent(rows) -> None:
    rows = np.asarray(rows, dtype=float)
    assert rows.shape[1] == K
    norm = np.linalg.norm(accel_g(rows), axis=1)
    # noise +-3 counts and rounding: |u| is 1 to within a few 1e-4
    assert np.abs(norm - 1).max() < 0.002, norm
    assert np.abs(rows[:, 3:6] - GYRO).max() <= NOISE
    assert np.abs(rows[:, 6] - TRUTH["SIM_TEMP_RAW"]).max() <= NOISE


def test_polled_frames_recover_the_truth(board):
    dec = BinaryDecoder(K, polled=True)
    rows = []
    n = 2 * SAMPLES  # twice round the globe, wherever the sample counter stands
    for _ in range(n):
        rows += board.poll(dec)
    assert len(rows) == n, dec.stats
    assert dec.stats.dropped_frames == 0 and dec.stats.dropped_bytes == 0
    check_consistent(rows)
    acc = np.asarray(rows, dtype=float)[:, :3]
    # the scripted globe: every one of the poses was visited
    u = accel_g(rows)
    poses = {tuple(np.round(v, 1)) for v in u}
    assert len(poses) >= POSES - 2 * (TRUTH["SIM_TURNS"] - 1)  # 12 turns at a pole coincide
    fit = triaxcal.fit_ellipsoid(acc, model="axis", radius=16384)
    assert np.abs(fit.offset - OFFSET).max() < 1.5, fit.offset
    counts_per_g = 16384 / np.diag(fit.matrix)  # the matrix multiplies
    assert np.abs(counts_per_g / PER_G - 1).max() < 2e-4, counts_per_g


def test_framed_stream(board):
    dec = FramedDecoder(K)
    rows = board.stream(b"F", dec, 150)
    assert len(rows) >= 150, dec.stats
    assert dec.stats.lost_frames == 0  # consecutive sequence numbers
    assert dec.stats.dropped_frames <= 1  # at most a frame cut by the mode switch
    check_consistent(rows)


def test_legacy_binary_stream(board):
    dec = BinaryDecoder(K)
    rows = board.stream(b"B", dec, 150)
    rows += dec.flush()
    assert len(rows) >= 150, dec.stats
    assert dec.stats.dropped_frames <= 1
    check_consistent(rows)


def test_text_stream(board):
    dec = TextDecoder(K)
    rows = board.stream(b"T", dec, 100)
    assert len(rows) >= 100, dec.stats
    assert dec.stats.lines_skipped <= 1
    assert all(isinstance(v, int) for r in rows for v in r)
    check_consistent(rows)


def test_raw_stream(board):
    dec = RawDecoder()
    rows = np.asarray(board.stream(b"R", dec, 100), dtype=float)
    assert len(rows) >= 100, dec.stats
    assert dec.stats.lines_skipped <= 1
    # accel at 8192 counts/g (MPU counts / 2), gyro at 16 counts/(deg/s), no magnetometer
    u = (rows[:, :3] * 2 - OFFSET) / PER_G
    assert np.abs(np.linalg.norm(u, axis=1) - 1).max() < 0.003
    # C integer division truncates: within the noise, scaled, plus one count
    assert np.abs(rows[:, 3:6] - GYRO * 16 / 131).max() <= NOISE * 16 / 131 + 1
    assert (rows[:, 6:9] == 0).all()


def test_motioncal_packet_is_echoed(board):
    board.quiet()
    accel, gyro, mag = [0.125, -0.25, 0.5], [1.5, -2.0, 3.25], [10.5, -20.25, 30.0]
    field, soft = 48.5, [1.01, 0.99, 1.02, 0.01, -0.02, 0.03]
    xx, yy, zz, xy, xz, yz = soft
    si = [[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]]
    packet = encode_motioncal(accel_offset=accel, gyro_offset=gyro, mag_offset=mag, field=field,
                              soft_iron=si)
    assert len(packet) == 68
    board.port.write(packet)
    reply = board.read_until(b"Cal2:", timeout_s=5) + board.read_until(b"\r\n", timeout_s=2)
    echo = parse_motioncal_echo(reply)
    assert echo is not None, reply
    assert echo[0] == pytest.approx([*accel, *gyro, *mag, field], abs=1e-4)
    assert echo[1] == pytest.approx([xx, xy, xz, xy, yy, yz, xz, yz, zz], abs=1e-4)
    assert re.search(rb"Cal1:(-?\d+\.\d{4},){9}-?\d+\.\d{4}\r\n", reply), reply

    # a packet with a bad CRC gets no answer, and the device still answers requests
    bad = bytearray(packet)
    bad[20] ^= 0x55
    board.port.write(bytes(bad))
    time.sleep(0.3)
    assert b"Cal1" not in board.port.read(board.port.in_waiting)
    dec = BinaryDecoder(K, polled=True)
    rows = board.poll(dec)
    assert len(rows) == 1
    check_consistent(rows)


def test_truth_header_is_parsed():
    # the test reads the same numbers the firmware compiles in
    assert set(TRUTH) >= {
        "SIM_ACCEL_OFFSET_X", "SIM_ACCEL_COUNTS_PER_G_Z", "SIM_GYRO_OFFSET_Y", "SIM_TEMP_RAW",
        "SIM_NOISE_COUNTS", "SIM_LATITUDES", "SIM_TURNS", "SIM_SAMPLES_PER_POSE",
    }
    assert len(TRUTH) == len(re.findall(r"^#define\s+SIM_", (FIRMWARE / "src" / "sim_truth.h")
                                        .read_text(), flags=re.M))


# ------------------------------------------------------------------ still poses on the board

def globe_truth() -> tuple[np.ndarray, np.ndarray]:
    """Accelerometer readings (counts, before the firmware rounds them and adds noise) and unit
    vectors of the 84 poses, in the order the globe with moves visits them (snake order,
    sim_truth.h)."""
    lats, turns = TRUTH["SIM_LATITUDES"], TRUTH["SIM_TURNS"]
    u = []
    for q in range(lats * turns):
        lat_i, j = divmod(q, turns)
        turn = turns - 1 - j if lat_i % 2 else j
        lat = np.radians(np.float32(-90.0 + 180.0 * lat_i / (lats - 1)))
        lon = np.radians(np.float32(360.0 / turns * turn))
        u.append([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)])
    u = np.array(u)
    return OFFSET + u * PER_G, u


def rounding_error(means: np.ndarray, exact: np.ndarray) -> np.ndarray:
    """``means`` minus the whole counts the firmware rounds ``exact`` to. Its single-precision
    sums can put a value that is a half in exact arithmetic (-12292.5) on either side, so
    near a half both neighbours are allowed."""
    lo, hi = np.floor(exact), np.floor(exact) + 1
    near_half = np.abs(exact - lo - 0.5) < 1e-3
    nearest = np.where(exact - lo < 0.5, lo, hi)
    err = means - nearest
    either = np.where(np.abs(means - lo) < np.abs(means - hi), means - lo, means - hi)
    return np.where(near_half, either, err)


def test_globe_truth_has_twelve_twists_per_pole():
    exact, u = globe_truth()
    counts = np.round(exact)
    assert len(counts) == POSES == 84
    # the accelerometer cannot tell the twists at a pole apart: the gyro has to
    turns = TRUTH["SIM_TURNS"]
    assert len({tuple(c) for c in counts[:turns]}) == 1
    assert len({tuple(c) for c in counts[-turns:]}) == 1
    assert len({tuple(c) for c in counts}) == POSES - 2 * (turns - 1)
    # every move is one 30-degree step
    steps = np.degrees(np.arccos(np.clip(np.sum(u[1:] * u[:-1], axis=1), -1, 1)))
    assert steps.max() == pytest.approx(30.0, abs=1e-4)


#: The firmware's defaults (the seed's 0.07 g and 2 s hold-off, 25-sample windows, 4 averaged)
#: with the sample period cut from 10 ms to 1 ms: the simulated globe is scripted in samples,
#: so the board sees the same samples as at 100 Hz, ten times faster.
FAST = BoardPoseSettings(period_ms=1, holdoff_ms=200)


@pytest.mark.slow
def test_board_finds_the_84_poses_of_the_globe(firmware_elf, tmp_path):
    assert FAST.holdoff_samples == BoardPoseSettings().holdoff_samples == 200
    log = tmp_path / "unimp.log"
    out = tmp_path / "globe.csv"
    with qemu(firmware_elf, unimp_log=log) as pty:
        reader = SerialReader(pty, protocol="framed", channels=K, board_poses=FAST,
                              silent_s=10, garbage_s=10)
        dec = reader.decoder
        assert isinstance(dec, BoardPoseDecoder)
        stop = threading.Event()

        def after_the_last_pose() -> None:
            # keep listening for 3 s of status frames after the 84th pose: no 85th may come
            seen = None
            while not stop.wait(0.05):
                st = dec.status
                if st is not None and st.poses >= POSES and seen is None:
                    seen = time.monotonic()
                if seen is not None and time.monotonic() - seen > 3.0:
                    stop.set()

        watcher = threading.Thread(target=after_the_last_pose, daemon=True)
        watcher.start()
        try:
            result = capture(reader, out, stop=stop, duration_s=240, progress=None,
                             handle_sigint=False)
        finally:
            stop.set()
            watcher.join(timeout=5)
    # the board reported the settings it was sent, and nothing was lost or damaged
    assert result.board_settings == FAST
    assert dec.settings_accepted is True
    assert dec.stats.dropped_frames == 0 and dec.stats.lost_frames == 0
    assert dec.poses_lost == 0 and dec.restarts == 0
    assert dec.status.poses == POSES and dec.status.waiting  # still on the last pose, no 85th
    assert result.stopped_by == "stop" and len(result.poses) == POSES

    cols, data = read_session(out)
    assert cols == ("t", "ax", "ay", "az", "gx", "gy", "gz", "temp", POSE_N_COLUMN)
    assert data.shape == (POSES, 9)
    n = data[:, 8]
    assert (n == FAST.window * FAST.hold_windows).all()
    # every pose in the order the script visits them, the means on the truth within the noise:
    # uniform +-3 counts has sigma 2, so a mean of 100 samples has sigma 0.2 counts
    exact, _ = globe_truth()
    err = rounding_error(data[:, 1:4], exact)
    assert np.abs(err).max() < 1.0, np.abs(err).max(axis=0)  # 5 sigma
    assert np.abs(data[:, 4:7] - GYRO).max() < 1.0
    assert np.abs(data[:, 7] - TRUTH["SIM_TEMP_RAW"]).max() < 1.0
    print(f"\nboard poses: {len(data)}; accel mean error max {np.abs(err).max():.3f} "
          f"rms {np.sqrt(np.mean(err ** 2)):.3f} counts")

    # the buzzer: 100 toggles of PB0 (PINB0 written with 1) per pose, a 500 Hz beep of 100 ms
    writes = re.findall(r"atmega-gpio-b: unimplemented device write \(size 1, "
                        r"offset (0x[0-9a-f]+), value (0x[0-9a-f]+)\)", log.read_text())
    toggles = sum(1 for off, v in writes if off == "0x0" and int(v, 16) & 1)
    assert toggles == POSES * FAST.beep_ms
    assert ("0x1", "0x01") in writes  # DDRB: PB0 is an output

    # an accelerometer fit of the 84 means recovers the header's offsets and gains
    cal = tmp_path / "cal.json"
    assert main(["fit", str(out), "-o", str(cal)]) == 0
    part = triaxcal.Calibration.load(cal).accel
    offset = np.asarray(part.offset)
    counts_per_g = 1.0 / np.diag(part.matrix)  # counts -> g: the matrix multiplies
    assert part.stats["poses"] and part.stats["pose_source"] == "board"
    assert part.stats["n_poses"] == POSES
    assert np.abs(offset - OFFSET).max() < 0.5, offset
    assert np.abs(counts_per_g / PER_G - 1).max() < 5e-5, counts_per_g
    print(f"fit: offset error {offset - OFFSET} counts, gain error "
          f"{counts_per_g / PER_G - 1}")
    # --poses takes the rows as the poses they are: the same fit
    cal2 = tmp_path / "cal2.json"
    assert main(["fit", str(out), "--poses", "-o", str(cal2)]) == 0
    again = triaxcal.Calibration.load(cal2).accel
    np.testing.assert_array_equal(again.offset, part.offset)
    np.testing.assert_array_equal(again.matrix, part.matrix)


def read_poses(board: Board, dec: BoardPoseDecoder, until, timeout_s: float = 60.0) -> list:
    """Decode the pose mode's frames until ``until(poses)`` holds (or the deadline)."""
    poses: list = []
    deadline = time.monotonic() + timeout_s
    while not until(poses) and time.monotonic() < deadline:
        poses += dec.feed(board.port.read(board.port.in_waiting or 1))
    return poses


@pytest.mark.slow
def test_without_the_gyro_the_twists_at_the_pole_merge(board):
    """The 12 twists at the south pole look alike to the accelerometer: with the gyro taking no
    part (threshold 0) the board registers them as one pose, and the next pose it registers is
    already the first of latitude -60; with the gyro, it is the 13th."""
    counts, _ = globe_truth()
    pole = np.round(counts[0])
    first_off_pole = np.round(counts[TRUTH["SIM_TURNS"]])

    def off_pole(poses) -> bool:
        return any(np.abs(np.array(p[:3]) - pole).max() > 100 for p in poses)

    for gyro, expect in ((0, 2), (FAST.gyro_threshold, TRUTH["SIM_TURNS"] + 1)):
        board.quiet()
        dec = BoardPoseDecoder(K)
        settings = BoardPoseSettings(period_ms=1, holdoff_ms=200, gyro_threshold=gyro)
        board.port.write(settings.packet() + b"S")
        poses = read_poses(board, dec, off_pole)
        assert dec.settings == settings and dec.settings_accepted
        assert len(poses) == expect, [np.round(p[:3]) for p in poses]
        assert np.abs(np.array(poses[-1][:3]) - first_off_pole).max() < 2
    board.quiet()


def test_pose_settings_packet_is_checked(board):
    board.quiet()
    dec = BoardPoseDecoder(K)
    good = BoardPoseSettings(window=10)
    board.port.write(good.packet())
    read_poses(board, dec, lambda _: dec.settings is not None, timeout_s=5)
    assert dec.settings == good and dec.settings_accepted is True
    # values out of range with a good CRC: refused, and the board says what it keeps using
    body = bytearray(good.packet()[:-2])
    body[3] = 0  # window 0
    from triaxcal.io.protocol import crc16_ccitt

    dec = BoardPoseDecoder(K)
    board.port.write(bytes(body) + crc16_ccitt(bytes(body)).to_bytes(2, "little"))
    read_poses(board, dec, lambda _: dec.settings is not None, timeout_s=5)
    assert dec.settings_accepted is False and dec.settings == good
    # a damaged packet gets no answer; the board still answers requests afterwards
    bad = bytearray(BoardPoseSettings(window=20).packet())
    bad[5] ^= 0x40
    board.port.write(bytes(bad))
    time.sleep(0.3)
    assert not board.port.read(board.port.in_waiting)
    rows = board.poll(BinaryDecoder(K, polled=True))
    assert len(rows) == 1
    check_consistent(rows)
    board.port.write(BoardPoseSettings().packet())  # back to the defaults
    board.quiet()


ARDUINO_AVR = Path("/usr/share/arduino/hardware/arduino/avr")


@pytest.mark.slow
@pytest.mark.skipif(not (ARDUINO_AVR / "cores" / "arduino" / "Arduino.h").is_file() or
                    bool(MISSING), reason="no Arduino AVR core: apt-get install arduino-core-avr "
                    "(make deps)")
def test_arduino_sketch_compiles(tmp_path):
    """The sketch (with the still-pose mode and tone() on D8) builds against the Arduino AVR
    core, MPU-6050 and simulated, with the shared C files' warnings as errors. (It cannot run
    in QEMU: the Arduino core keeps time with Timer0, which QEMU's arduino-uno lacks.)"""
    proc = subprocess.run(["make", "-C", str(FIRMWARE), f"BUILD={tmp_path}", "arduino-check"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    for sim in (0, 1):
        assert (tmp_path / "sketch" / f"triaxcal_stream-sim{sim}.elf").is_file()
    assert proc.stdout.count("Program:") == 2
