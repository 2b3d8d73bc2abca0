"""The C library in ``firmware/lib/triaxcal``: equal to the Rust core, on the host and on both
targets, and the board that calibrates itself with it.

* The test vectors (``firmware/lib/triaxcal/test/vectors.h``) were written by the Rust core
  (``vectors.rs``, a cargo example); here they are computed again through ``triaxcal._core``,
  so a change of the core that the C library does not follow shows up as a failure.
* ``make -C firmware check-host`` runs the library's test program on the host in float and in
  double; ``check-avr`` and ``check-arm`` run it on an ATmega328P and a Cortex-M3 in QEMU.
* The record a board stores (``tc_store.h``) has the same bytes as
  :class:`triaxcal.io.board_store.BoardRecord` writes: one layout, one CRC.
* The simulated board in QEMU finds the 84 poses of the globe, fits them itself, stores and
  applies the result; ``triaxcal board read`` gets it, ``triaxcal fit`` of the captured poses
  agrees to 0.5 count; ``board write`` stores a host calibration; a damaged record is caught.
* The Arduino library's example compiles against Debian's Arduino AVR core.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
import serial
import triaxcal
from test_firmware import FIRMWARE, MISSING, OFFSET, PER_G, Board, qemu
from triaxcal.cli import main
from triaxcal.io.board_store import (
    BoardQuality,
    BoardRecord,
    BoardStoreDecoder,
    RecordReport,
    decode_record,
)

LIB = FIRMWARE / "lib" / "triaxcal"
VECTORS = LIB / "test" / "vectors.h"
NO_GCC = shutil.which("gcc") is None or shutil.which("make") is None
ARM_MISSING = [t for t in ("arm-none-eabi-gcc", "qemu-system-arm", "make")
               if shutil.which(t) is None]


# ---------------------------------------------------------------- the vectors and the core

def parse_vectors(text: str) -> list[dict]:
    """The cases of vectors.h, in the order of struct tcv_case (tcv.h)."""
    pts_block = text[text.index("TCV_POINTS"):text.index("TCV_CASES")]
    num = r"[-+]?\d+(?:\.\d+)?(?:e[-+]?\d+)?"
    points = np.array([float(v) for v in re.findall(num, pts_block.split("= {", 1)[1])]
                      ).reshape(-1, 3)
    table = text[text.index("TCV_CASES[TCV_NCASES]"):].split("= {", 1)[1]
    cases = []
    for m in re.finditer(r'\{"(\w+)",(.*?)\}\}\},\n', table, flags=re.S):
        v = [int(t, 16) if t.startswith("0x") else float(t)
             for t in re.findall(r"0x[0-9a-f]+|" + num, m.group(2))]
        fit = lambda a: {"code": int(a[0]), "offset": a[1:4],
                         "matrix": np.reshape(a[4:13], (3, 3)), "rms": a[13],
                         "warnings": int(a[14]), "se": a[15:17]}
        n, first = int(v[0]), int(v[1])
        cases.append({
            "name": m.group(1), "points": points[first:first + n], "radius": v[2],
            "start": v[3:6], "step": v[6], "min_step": v[7], "shrink": v[8],
            "dcode": int(v[9]), "center": v[10:13], "error": v[13], "iterations": int(v[14]),
            "converged": bool(v[15]), "axis": fit(v[16:33]), "full": fit(v[33:50]),
        })
    return cases


CASES = parse_vectors(VECTORS.read_text())

#: The C library's refusal codes (triaxcal.h, enum tc_code) by the core's message.
CODES = [("identical", 4), ("straight line", 5), ("on a plane", 6), ("factor of", 8),
         ("needs at least", 3), ("do not determine", 7)]


def code_of(exc: Exception) -> int:
    text = str(exc)
    return next((c for key, c in CODES if key in text), 1)


def test_the_vectors_are_the_cores():
    assert len(CASES) == 17 and sum(len(c["points"]) for c in CASES) == 527
    assert {c["dcode"] for c in CASES} >= {0, 4, 5, 6}
    assert {c["full"]["code"] for c in CASES} >= {0, 3, 4, 5, 6, 8}
    for c in CASES:
        pts = c["points"]
        # every coordinate is a float32 (the C library's float build reads them exactly)
        np.testing.assert_array_equal(pts.astype(np.float32).astype(float), pts)
        try:
            d = triaxcal.descend_center(pts, c["radius"], start=c["start"], step=c["step"],
                                        min_step=c["min_step"], shrink=c["shrink"])
            code = 0
        except triaxcal.CalibrationError as exc:
            code = code_of(exc)
        assert code == c["dcode"], c["name"]
        if code == 0:
            np.testing.assert_allclose(d.center, c["center"], atol=1e-9 * c["radius"],
                                       err_msg=c["name"])
            assert d.iterations == c["iterations"] and d.converged == c["converged"]
            assert d.error == pytest.approx(c["error"], rel=1e-12)
        for model in ("axis", "full"):
            want = c[model]
            try:
                f = triaxcal.fit_ellipsoid(pts, model=model, radius=c["radius"], debias=False,
                                           tol=1e-14)
                code = 0
            except triaxcal.CalibrationError as exc:
                code = code_of(exc)
            assert code == want["code"], (c["name"], model)
            if code == 0:
                np.testing.assert_allclose(f.offset, want["offset"], atol=1e-9 * c["radius"],
                                           err_msg=f"{c['name']} {model}")
                np.testing.assert_allclose(f.matrix, want["matrix"], atol=1e-9, rtol=1e-9)
                assert f.rms == pytest.approx(want["rms"], rel=1e-9)


def make(target: str, build: Path, timeout: int = 600) -> str:
    proc = subprocess.run(["make", "-C", str(FIRMWARE), f"BUILD={build}", target],
                          capture_output=True, text=True, timeout=timeout)
    assert proc.returncode == 0, proc.stdout[-4000:] + proc.stderr[-3000:]
    return proc.stdout


def results(out: str) -> list[tuple[int, int]]:
    return [(int(a), int(b)) for a, b in re.findall(r"^RESULT (\d+) checks, (\d+) failures",
                                                    out, flags=re.M)]


@pytest.mark.skipif(NO_GCC, reason="gcc and make are needed to build the C library's tests")
def test_c_library_on_the_host(tmp_path):
    """float and double builds against every vector; the double build takes the core's path
    (same descent iterations, fits to round-off)."""
    out = make("check-host", tmp_path)
    assert results(out) == [(193, 0), (207, 0)], out[-3000:]
    double = out[out.index("double, TC_FIT_MAX_P"):]
    for c in CASES:
        if c["dcode"] == 0:
            assert f"it {c['iterations']}/{c['iterations']}" in double.split(c["name"] + ":")[1]


@pytest.mark.skipif(NO_GCC, reason="gcc is needed to compile the C library")
def test_record_layout_is_the_c_librarys(tmp_path):
    """tc_store_pack (C) and BoardRecord.to_bytes (Python) give the same 72 bytes, and each
    reads the other's."""
    prog = tmp_path / "pack.c"
    prog.write_text(r"""
#include <stdio.h>
#include <string.h>
#include "tc_store.h"
int main(void) {
    struct tc_record r; uint8_t b[TC_STORE_BYTES];
    memset(&r, 0, sizeof r);
    r.sensor = 1; r.model = 6; r.origin = 1; r.n = 60; r.warnings = 0x40;
    r.radius = 16384.0f; r.offset[0] = 180.0625f; r.offset[1] = -239.5f; r.offset[2] = 350.25f;
    r.matrix[0][0] = 0.985f; r.matrix[1][1] = 1.0163f; r.matrix[2][2] = 0.996f;
    r.matrix[0][1] = 0.002f; r.rms = 0.29f; r.spread = 0.31f;
    tc_store_pack(&r, b);
    for (int i = 0; i < TC_STORE_BYTES; i++) printf("%02x", b[i]);
    struct tc_record back; uint8_t in[TC_STORE_BYTES]; char hex[3] = {0};
    for (int i = 0; i < TC_STORE_BYTES; i++) { if (scanf("%2c", hex) != 1) return 9;
        in[i] = (uint8_t)strtol(hex, 0, 16); }
    int st = tc_store_unpack(in, &back);
    printf(" %d %.4f %d\n", st, (double)back.offset[1], back.model);
    return 0;
}
""".replace("strtol", "(int)strtol").replace("#include <string.h>",
                                             "#include <string.h>\n#include <stdlib.h>"))
    exe = tmp_path / "pack"
    src = FIRMWARE / "lib" / "triaxcal" / "src"
    subprocess.run(["gcc", "-std=c99", "-Wall", "-Werror", f"-I{src}", str(prog),
                    str(src / "tc_store.c"), str(src / "crc16.c"), "-o", str(exe)], check=True)
    rec = BoardRecord(offset=(180.0625, -239.5, 350.25),
                      matrix=((0.985, 0.002, 0), (0, 1.0163, 0), (0, 0, 0.996)),
                      radius=16384, model="axis", origin="board", n=60, warnings=0x40,
                      rms=0.29, spread=0.31)
    host = BoardRecord(offset=(-1.5, 2.25, 3), matrix=((1, 0, 0), (0, 1, 0), (0, 0, 1)),
                       radius=16384, model="full", origin="host", n=9)
    out = subprocess.run([str(exe)], input=host.to_bytes().hex(), capture_output=True,
                         text=True, check=True).stdout.split()
    assert bytes.fromhex(out[0]) == rec.to_bytes()
    assert decode_record(bytes.fromhex(out[0])) == rec
    assert out[1:] == ["0", "2.2500", "9"]  # the C library reads the Python record: TC_STORE_OK


@pytest.mark.qemu
@pytest.mark.skipif(bool(MISSING), reason="avr-gcc and qemu-system-avr are needed (make deps)")
def test_c_library_on_the_avr(tmp_path):
    out = make("check-avr", tmp_path)
    assert results(out) == [(169, 0), (24, 0)], out[-3000:]
    # the 32 KB of flash hold the library with the full model and the vector checks
    program = int(re.search(r"Program:\s+(\d+) bytes", out).group(1))
    assert program < 32768


@pytest.mark.qemu
@pytest.mark.skipif(bool(ARM_MISSING), reason="arm-none-eabi-gcc (gcc-arm-none-eabi, "
                    "libnewlib-arm-none-eabi) and qemu-system-arm are needed (make deps)")
def test_c_library_on_a_cortex_m3(tmp_path):
    out = make("check-arm", tmp_path)
    assert results(out) == [(193, 0)], out[-3000:]
    cost = re.search(r"cost globe84 \(instructions, QEMU -icount\): descent (\d+) axis (\d+) "
                     r"full (\d+)", out)
    assert cost, out[-2000:]
    descent, axis, full = map(int, cost.groups())
    print(f"\nCortex-M3 instructions (84 poses): descent {descent}, axis {axis}, full {full}")
    assert 0 < axis < full < descent  # an instruction count, not a clock that stood still


# ----------------------------------------------------------- the board calibrates itself

@pytest.fixture(scope="module")
def sim_elf(tmp_path_factory) -> Path:
    if MISSING:
        pytest.skip("avr-gcc and qemu-system-avr are needed (make deps)")
    build = tmp_path_factory.mktemp("avr-board")
    make("sim", build)
    return build / "triaxcal-sim.elf"


def interrupt_frame(objects: Path) -> int:
    """Bytes of stack the deepest interrupt takes: its frame (registers and return address)
    plus the frames of what it calls, from the ``.su`` files that ``-fstack-usage`` leaves
    beside the objects. Interrupts do not nest (the AVR clears I on entry)."""
    frame: dict[str, int] = {}
    for su in objects.glob("*.su"):
        for line in su.read_text().splitlines():
            where, size, _kind = line.split("\t")
            frame[where.rsplit(":", 1)[-1]] = int(size)
    calls = {"__vector_11": ["buzzer_tick"], "__vector_18": []}  # TIMER1_COMPA, USART_RX
    bodies = dict(re.findall(r"^ISR\((\w+)\)\s*\{(.*?)^\}", "".join(
        f.read_text() for f in sorted((FIRMWARE / "src").glob("*.c"))), flags=re.M | re.S))
    assert sorted(bodies) == ["TIMER1_COMPA_vect", "USART_RX_vect"], sorted(bodies)
    assert re.findall(r"(\w+)\(", bodies["TIMER1_COMPA_vect"]) == ["buzzer_tick"]
    assert re.findall(r"(\w+)\(", bodies["USART_RX_vect"]) == []
    return max(frame[v] + sum(frame[c] for c in called) for v, called in calls.items())


def frames_after(port, command: bytes, want, timeout_s: float = 30.0) -> list:
    """Send ``command``; decode K and Q frames until ``want(frames)`` holds."""
    dec = BoardStoreDecoder()
    port.reset_input_buffer()
    port.write(command)
    got: list = []
    deadline = time.monotonic() + timeout_s
    while not want(got) and time.monotonic() < deadline:
        got += dec.feed(port.read(port.in_waiting or 1))
    return got


def polled_accel(port, n: int) -> np.ndarray:
    """``n`` polled samples' accelerometer counts (the board in polled mode first)."""
    from triaxcal.io.protocol import BinaryDecoder

    board, dec, rows = Board(port), BinaryDecoder(7, polled=True), []
    board.quiet()
    for _ in range(n):
        rows += board.poll(dec)
    assert len(rows) == n, dec.stats
    return np.asarray(rows, dtype=float)[:, :3]


@pytest.mark.qemu
@pytest.mark.slow
def test_the_board_calibrates_itself(sim_elf, tmp_path, capsys):
    session, board_json, host_json = (tmp_path / n for n in ("globe.csv", "board.json",
                                                               "host.json"))
    with qemu(sim_elf) as pty:
        # a new board holds no calibration, and says so
        assert main(["board", "read", "--port", pty, "--timeout", "10"]) == 1
        assert "holds no calibration" in capsys.readouterr().err
        # the seed's program: the board finds the 84 poses of the globe, fits and stores
        assert main(["capture", "--port", pty, "--protocol", "framed", "--board-poses",
                     "--rate-hz", "1000", "--holdoff", "0.2", "--poses", "84", "--seconds",
                     "240", "-o", str(session), "--quiet"]) == 0
        capsys.readouterr()
        assert main(["board", "read", "--port", pty, "--timeout", "30", "-o",
                     str(board_json)]) == 0
        out = capsys.readouterr().out
        assert "fitted on the board" in out and "applied to the streams" in out
        with serial.Serial(pty, 115200, timeout=0.2) as port:
            # the fit once more on command: its quality frame, and the same record
            got = frames_after(port, b"c", lambda f: any(isinstance(x, RecordReport) for x in f))
            q = next(x for x in got if isinstance(x, BoardQuality))
            rep = next(x for x in got if isinstance(x, RecordReport))
            assert q.code == 0 and q.descent_code == 0 and rep.reason == "fitted"
            assert q.n == 60 and min(q.faces) >= 9  # the 60 poses kept cover every face
            # RAM the stack never reached. An interrupt taken at the fit's deepest point adds
            # its frame to the measured depth or not, as the timing falls (41 and 56 bytes to
            # spare seen): what is left must hold the deepest interrupt once more.
            isr = interrupt_frame(sim_elf.parent / "sim")
            assert 0 < isr < 40, isr
            assert q.stack_free >= isr, (q.stack_free, isr)
            with capsys.disabled():
                print(f"\nboard: {q.n} poses kept, seed's centre {np.round(q.center, 3)}, "
                      f"RMS {q.rms:.3f} counts, spread {q.spread:.3f}, faces {q.faces}, "
                      f"{q.stack_free} bytes of stack to spare")
            # calibrated streams: |a| = 16384 counts (1 g) in every pose of the quick globe
            calibrated = polled_accel(port, 84)
            port.write(b"a")
            raw = polled_accel(port, 84)
        norm = np.linalg.norm(calibrated, axis=1)
        assert np.abs(norm - 16384).max() < 8, np.abs(norm - 16384).max()
        assert np.abs(np.linalg.norm(raw, axis=1) - 16384).max() > 100
        # the host fits the same session: offsets within 0.5 count of the board's
        assert main(["fit", str(session), "--model", "axis", "-o", str(host_json)]) == 0
        board = triaxcal.Calibration.load(board_json).accel
        host = triaxcal.Calibration.load(host_json).accel
        d_off = np.asarray(board.offset) - np.asarray(host.offset)
        cpg_board, cpg_host = 1 / np.diag(board.matrix), 1 / np.diag(host.matrix)
        with capsys.disabled():
            print(f"board - host offset {np.round(d_off, 3)} counts; board - truth "
                  f"{np.round(np.asarray(board.offset) - OFFSET, 3)}; host - truth "
                  f"{np.round(np.asarray(host.offset) - OFFSET, 3)}; counts per g: board/host"
                  f" - 1 {cpg_board / cpg_host - 1}; board/truth - 1 {cpg_board / PER_G - 1};"
                  f" host/truth - 1 {cpg_host / PER_G - 1}; calibrated |a| - 16384: max "
                  f"{np.abs(norm - 16384).max():.2f} counts")
        assert np.abs(d_off).max() < 0.5
        assert np.abs(cpg_board / cpg_host - 1).max() < 1e-4
        assert board.stats["origin"] == "board" and board.stats["n_poses"] == 60
        # a host calibration stored on the board, read back as sent
        assert main(["board", "write", str(host_json), "--port", pty, "--apply"]) == 0
        assert main(["board", "read", "--port", pty, "-o", str(tmp_path / "back.json")]) == 0
        back = triaxcal.Calibration.load(tmp_path / "back.json").accel
        np.testing.assert_allclose(back.offset, host.offset, rtol=1e-6)
        np.testing.assert_allclose(back.matrix, host.matrix, rtol=1e-6)
        assert back.stats["origin"] == "host"
        # a damaged record (the simulated build's 'X' flips a stored bit) is caught
        with serial.Serial(pty, 115200, timeout=0.2) as port:
            got = frames_after(port, b"X", lambda f: bool(f))
        assert got[0].status == 2 and not got[0].applied  # the board stops applying it
        capsys.readouterr()
        assert main(["board", "read", "--port", pty]) == 1
        assert "damaged" in capsys.readouterr().err
        assert json.loads(board_json.read_text())["parts"]["accel"]["unit"] == "g"


ARDUINO_AVR = Path("/usr/share/arduino/hardware/arduino/avr")


@pytest.mark.slow
@pytest.mark.skipif(not (ARDUINO_AVR / "cores" / "arduino" / "Arduino.h").is_file() or
                    bool(MISSING), reason="no Arduino AVR core: apt-get install arduino-core-avr "
                    "(make deps)")
def test_arduino_library_example_compiles(tmp_path):
    """The library as an Arduino library (library.properties, src/, examples/) builds its
    MPU-6050 example against the Arduino AVR core with Wire and EEPROM."""
    props = (LIB / "library.properties").read_text()
    assert re.search(r"^name=triaxcal$", props, flags=re.M)
    assert re.search(r"^architectures=\*$", props, flags=re.M)
    out = make("arduino-lib-check", tmp_path)
    assert (tmp_path / "libsketch" / "calibrate_mpu6050.elf").is_file()
    flash = int(re.search(r"Program:\s+(\d+) bytes", out).group(1))
    ram = int(re.search(r"Data:\s+(\d+) bytes", out).group(1))
    # an Uno: 32 KB less Optiboot's 512 B; 2 KB of RAM of which a fit's stack takes about 480 B
    assert flash < 32256 and ram < 1500, (flash, ram)
