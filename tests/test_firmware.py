"""The AVR firmware, built with avr-gcc and run in QEMU's Arduino Uno, captured like a board.

Builds ``firmware/`` with ``SIMULATED=1`` (QEMU's AVR machine has no TWI/I2C device), starts
``qemu-system-avr -machine arduino-uno ... -serial pty``, opens the pseudo-terminal it prints
with pyserial and talks to it as to a real board: polled legacy frames, the framed, text, Raw:
and legacy binary streams, and a MotionCal calibration packet. The values are checked against
``firmware/src/sim_truth.h``. QEMU runs the CPU faster or slower than real time, so every wait
is "until enough has arrived or a generous deadline", never a fixed sleep that must be right.

Skipped only when avr-gcc or qemu-system-avr is missing (``make deps`` installs both; CI does).
"""

from __future__ import annotations

import os
import re
import select
import shutil
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
import serial
import triaxcal
from triaxcal.io.motioncal import encode_motioncal, parse_motioncal_echo
from triaxcal.io.protocol import (
    BinaryDecoder,
    FramedDecoder,
    RawDecoder,
    TextDecoder,
)

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


@pytest.fixture(scope="module")
def board(firmware_elf):
    proc = subprocess.Popen(
        [
            "qemu-system-avr", "-machine", "arduino-uno", "-bios", str(firmware_elf),
            "-nographic", "-serial", "pty", "-monitor", "none",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        stdin=subprocess.DEVNULL,
    )
    port = None
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
        port = serial.Serial(m.group(1).decode(), 115200, timeout=1.0, write_timeout=2.0)
        b = Board(port)
        b.quiet()
        yield b
    finally:
        if port is not None:
            port.close()
        proc.kill()
        proc.wait(timeout=10)
        proc.stdout.close()


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
