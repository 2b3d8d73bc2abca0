"""The Rust log readers against the Python ones they replace (pyulog, pymavlink), on the real
logs in ../shared/realdata and on a corpus of damaged copies of them (bytes changed, cut,
zeroed, inserted, deleted, repeated; message headers broken): every file gives the same
arrays, parameters and metadata with either reader, or a CalibrationError with both."""

from __future__ import annotations

import contextlib
import dataclasses
import io
import struct
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import triaxcal as tc
from triaxcal import _core
from triaxcal.io.logs import dataflash, read_log, ulog

pytest.importorskip("pyulog")
pytest.importorskip("pymavlink")

PX4_SMALL = "px4-pyulog-samples/sample_log_small.ulg"
PX4_BIG = "px4-pyulog-samples/sample.ulg"
AP_PXF = "ardupilot-erle-logs/PXFv2.0b+Rpi.BIN"
AP_ERLE = "ardupilot-erle-logs/Erle-Brain3.BIN"
SYNC = bytes([0x2F, 0x73, 0x13, 0x20, 0x25, 0x0C, 0xBB, 0x12])


def _same(a: Any, b: Any, where: str = "") -> None:
    """Equal values, types of containers and arrays (dtype, shape, NaN where NaN)."""
    if dataclasses.is_dataclass(a) and not isinstance(a, type):
        assert type(a) is type(b), where
        for f in dataclasses.fields(a):
            _same(getattr(a, f.name), getattr(b, f.name), f"{where}.{f.name}")
    elif isinstance(a, np.ndarray):
        assert isinstance(b, np.ndarray) and a.dtype == b.dtype and a.shape == b.shape, where
        assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), where
    elif isinstance(a, dict):
        assert isinstance(b, dict) and list(a) == list(b), f"{where}: {list(a)} != {list(b)}"
        for k in a:
            _same(a[k], b[k], f"{where}[{k!r}]")
    elif isinstance(a, (list, tuple)):
        assert type(a) is type(b) and len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            _same(x, y, f"{where}[{i}]")
    else:
        assert a == b and type(a) is type(b), f"{where}: {a!r} != {b!r}"


def _outcome(fn, *args, **kw):
    try:
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            return "ok", fn(*args, **kw)
    except tc.CalibrationError as exc:
        return "error", str(exc)


def _both_ulog(path: Path) -> tuple[str, Any]:
    """Both readers on one ULog: the parse of the Rust core equals pyulog's (topics, info,
    parameters), and so does the recording read from it."""
    a, b = _outcome(ulog._parse_core, path), _outcome(ulog._parse_pyulog, path)
    assert a[0] == b[0], f"{path.name}: core {a}, pyulog {b[0]}: {str(b[1])[:300]}"
    if a[0] == "ok" and a[1] is not None:
        _same(a[1], b[1], path.name)
    ra, rb = _outcome(ulog.read_ulog, path), _outcome(ulog.read_ulog, path, engine="pyulog")
    assert ra[0] == rb[0], f"{path.name}: core {ra}, pyulog {rb}"
    if ra[0] == "ok":
        _same(ra[1], rb[1], path.name)
    return ra


def _both_dataflash(path: Path, instance: int = 0) -> tuple[str, Any]:
    """Both readers on one DataFlash log (the count of damaged header bytes aside: pymavlink
    only prints it)."""
    ra = _outcome(dataflash.read_dataflash, path, instance=instance)
    rb = _outcome(dataflash.read_dataflash, path, instance=instance, engine="pymavlink")
    assert ra[0] == rb[0], f"{path.name}: core {ra}, pymavlink {rb}"
    if ra[0] == "ok":
        ma, mb = dict(ra[1].meta), dict(rb[1].meta)
        ma.pop("damaged_headers_skipped")
        mb.pop("damaged_headers_skipped")
        _same(ra[1].replace(meta=ma), rb[1].replace(meta=mb), path.name)
    return ra


def _mutate(src: bytes, rng: np.random.Generator, kind: str, defs_end: int) -> bytes:
    b = bytearray(src)
    n = len(b)
    if kind == "flip":
        for _ in range(int(rng.integers(1, 20))):
            b[int(rng.integers(0, n))] = int(rng.integers(0, 256))
    elif kind == "flip-definitions":
        for _ in range(int(rng.integers(1, 6))):
            b[int(rng.integers(0, defs_end))] = int(rng.integers(0, 256))
    elif kind == "cut":
        b = b[: int(rng.integers(0, n))]
    elif kind == "zero":
        a, k = int(rng.integers(0, n)), int(rng.integers(1, 5000))
        b[a:a + k] = bytes(len(b[a:a + k]))
    elif kind == "insert":
        a = int(rng.integers(0, n))
        b[a:a] = rng.bytes(int(rng.integers(1, 300)))
    elif kind == "delete":
        a = int(rng.integers(0, n))
        del b[a:a + int(rng.integers(1, 300))]
    elif kind == "repeat":
        a, k = int(rng.integers(0, n)), int(rng.integers(1, 3000))
        b[a:a] = b[a:a + k]
    elif kind == "headers":  # a message header's size and type bytes
        for _ in range(int(rng.integers(1, 5))):
            a = int(rng.integers(16, n - 3))
            b[a:a + 3] = bytes([int(rng.integers(0, 256)), int(rng.integers(0, 256)),
                                int(rng.choice([0, 255, 88, 68, 73, 65, 70, 83, 79, 76]))])
    return bytes(b)


KINDS = ("flip", "flip-definitions", "cut", "zero", "insert", "delete", "repeat", "headers")


# --------------------------------------------------------------------------------------------
# the real logs


@pytest.mark.parametrize("name", [PX4_SMALL, PX4_BIG])
def test_real_ulogs_read_the_same(realdata, name):
    kind, rec = _both_ulog(realdata / name)
    assert kind == "ok" and len(rec.accel) > 1000


@pytest.mark.parametrize("instance", [0, 1, 2])
def test_real_ulog_instances_read_the_same(realdata, instance):
    a = _outcome(ulog.read_ulog, realdata / PX4_SMALL, instance=instance)
    b = _outcome(ulog.read_ulog, realdata / PX4_SMALL, instance=instance, engine="pyulog")
    assert a[0] == b[0] == "ok"
    _same(a[1], b[1])


@pytest.mark.slow
@pytest.mark.parametrize("name", [AP_PXF, AP_ERLE])
def test_real_dataflash_logs_read_the_same(realdata, name):
    kind, rec = _both_dataflash(realdata / name)
    assert kind == "ok" and len(rec.accel) > 6000
    assert rec.meta["damaged_headers_skipped"] == 0


def test_ulog_columns_keep_their_types(realdata):
    d = _core.read_ulog(str(realdata / PX4_SMALL), ["sensor_combined"])
    [(name, multi_id, cols)] = d["datasets"]
    assert name == "sensor_combined" and multi_id == 0
    assert cols["timestamp"].dtype == np.uint64 and cols["gyro_rad[0]"].dtype == np.float32
    assert d["info"]["ver_hw"] == "CUBEPILOT_CUBEORANGE" and not d["corrupt"]


# --------------------------------------------------------------------------------------------
# damaged copies: the same result or the same refusal


@pytest.mark.parametrize("seed", range(48))
def test_damaged_ulog_reads_the_same(realdata, tmp_path, seed):
    src = (realdata / PX4_SMALL).read_bytes()
    rng = np.random.default_rng(seed)
    p = tmp_path / "damaged.ulg"
    p.write_bytes(_mutate(src, rng, KINDS[seed % len(KINDS)], defs_end=60_000))
    _both_ulog(p)


@pytest.mark.parametrize("seed", range(16))
def test_damaged_dataflash_reads_the_same(realdata, tmp_path, seed):
    rng = np.random.default_rng(1000 + seed)
    src = (realdata / (AP_PXF if seed % 2 else AP_ERLE)).read_bytes()
    src = src[: int(rng.integers(50_000, 250_000))]
    p = tmp_path / "damaged.bin"
    p.write_bytes(_mutate(src, rng, KINDS[seed % len(KINDS)], defs_end=12_000))
    _both_dataflash(p)


# --------------------------------------------------------------------------------------------
# crafted damage: each recovery path of the readers


def _ulog_messages(src: bytes) -> list[tuple[int, int, int]]:
    """(offset, size, type) of the messages of an undamaged ULog."""
    out, i = [], 16
    while i + 3 <= len(src):
        size, kind = struct.unpack_from("<HB", src, i)
        out.append((i, size, kind))
        i += 3 + size
    return out


def test_lost_framing_is_found_again_at_a_sync_marker(realdata, tmp_path):
    src = bytearray((realdata / PX4_SMALL).read_bytes())
    data = [m for m in _ulog_messages(bytes(src)) if m[2] == ord("D")]
    a, b = data[len(data) // 3], data[len(data) // 2]
    src[a[0]:a[0] + 3] = struct.pack("<HB", 20_000, 0)     # framing lost here...
    src[b[0]:b[0]] = SYNC                                   # ...and found again here
    p = tmp_path / "sync.ulg"
    p.write_bytes(bytes(src))
    kind, rec = _both_ulog(p)
    whole = read_log(realdata / PX4_SMALL)
    assert kind == "ok" and 0 < len(rec.accel) < len(whole.accel)
    # without a marker the read goes on from one byte past the broken header, until its
    # framing meets the messages again: nothing up to the marker's place is skipped
    del src[b[0]:b[0] + 8]
    p.write_bytes(bytes(src))
    kind2, rec2 = _both_ulog(p)
    assert kind2 == "ok" and len(rec.accel) < len(rec2.accel) < len(whole.accel)


def test_unknown_message_types_are_skipped(realdata, tmp_path):
    src = bytearray((realdata / PX4_SMALL).read_bytes())
    data = [m for m in _ulog_messages(bytes(src)) if m[2] == ord("D")]
    for off, _, _ in data[100:110]:
        src[off + 2] = ord("Z")   # a type this reader does not know, sane size: skipped
    p = tmp_path / "unknown.ulg"
    p.write_bytes(bytes(src))
    assert _both_ulog(p)[0] == "ok"


def test_appended_data_goes_to_pyulog(realdata, tmp_path):
    src = bytearray((realdata / PX4_SMALL).read_bytes())
    first = _ulog_messages(bytes(src))[0]
    assert first[2] == ord("B")               # the flag bits, first after the header
    o = first[0] + 3
    src[o + 8] = 1                            # incompatible flag: data appended...
    src[o + 16:o + 24] = struct.pack("<Q", len(src) - 5000)   # ...at this offset
    p = tmp_path / "appended.ulg"
    p.write_bytes(bytes(src))
    assert _core.read_ulog(str(p))["appended"]
    assert ulog._parse_core(p) is None
    kind, rec = _both_ulog(p)
    assert kind == "ok"


def test_a_definitions_section_that_loops_is_refused(tmp_path):
    """pyulog loops forever on this file: a header too large near the end sends its framing
    back to where it came from. The core refuses it."""
    body = b"ULog\x01\x12\x35\x01" + bytes(8) + b"\x00\x00M" * 7000
    body += struct.pack("<HB", 20_000, 0) + b"\x00"
    p = tmp_path / "loop.ulg"
    p.write_bytes(body)
    with pytest.raises(tc.CalibrationError, match="loops back"):
        read_log(p)


def test_a_format_that_contains_itself_is_refused(tmp_path):
    def msg(kind: bytes, payload: bytes) -> bytes:
        return struct.pack("<H", len(payload)) + kind + payload

    body = b"ULog\x01\x12\x35\x01" + bytes(8)
    body += msg(b"F", b"loop:uint64_t timestamp;loop inner;")
    body += msg(b"A", b"\x00\x01\x00loop")
    p = tmp_path / "nested.ulg"
    p.write_bytes(body)
    with pytest.raises(tc.CalibrationError, match="contains itself"):
        _core.read_ulog(str(p), None)
    assert _outcome(ulog._parse_pyulog, p)[0] == "error"   # RecursionError there


def _df_messages(src: bytes) -> list[tuple[int, int, str]]:
    """(offset, type, name) of the messages of an undamaged DataFlash log."""
    lengths, names, out, i = {0x80: 89}, {0x80: "FMT"}, [], 0
    while i + 3 < len(src) and src[i:i + 2] == b"\xa3\x95":
        t = src[i + 2]
        if t == 0x80:
            lengths[src[i + 3]] = src[i + 4]
            names[src[i + 3]] = src[i + 5:i + 9].rstrip(b"\0").decode()
        out.append((i, t, names[t]))
        i += lengths[t]
    return out


@pytest.mark.slow
def test_a_dataflash_format_that_does_not_match_its_length_goes_to_pymavlink(realdata,
                                                                            tmp_path):
    src = bytearray((realdata / AP_PXF).read_bytes()[:300_000])
    fmt = next(o for o, t, n in _df_messages(bytes(src)) if t == 0x80
               and src[o + 5:o + 8] == b"IMU" and src[o + 8] == 0)
    src[fmt + 9:fmt + 21] = b"QffffffIIfbb"[:12]     # same size: still decoded here
    p = tmp_path / "ok.bin"
    p.write_bytes(bytes(src))
    assert _core.read_dataflash(str(p), ["IMU"])["fallback"] is None
    _both_dataflash(p)
    src[fmt + 9:fmt + 21] = b"QffffffIIfHB"          # one byte longer than its length
    p.write_bytes(bytes(src))
    assert "IMU" in _core.read_dataflash(str(p), ["IMU"])["fallback"]
    assert dataflash._parse_core(p, ["IMU", "MAG", "MSG", "PARM"], 0) is None
    assert _both_dataflash(p)[0] == "ok"


def test_dataflash_damage_is_counted_and_stops_where_pymavlink_stops(realdata, tmp_path):
    src = bytearray((realdata / AP_PXF).read_bytes()[:200_000])
    msgs = _df_messages(bytes(src))
    imu = [o for o, _, n in msgs if n == "IMU"]
    src[imu[10]:imu[10] + 2] = b"\x00\x00"        # a broken header: 49 bytes skipped
    src[imu[20] + 2] = 0x42                         # a type without a format: the end
    p = tmp_path / "damaged.bin"
    p.write_bytes(bytes(src))
    kind, rec = _both_dataflash(p)
    assert kind == "ok" and len(rec.accel) == 19
    assert rec.meta["damaged_headers_skipped"] > 0


def test_dataflash_unknown_format_character_is_refused(realdata, tmp_path):
    src = bytearray((realdata / AP_PXF).read_bytes()[:100_000])
    fmt = next(o for o, t, _ in _df_messages(bytes(src)) if t == 0x80 and src[o + 3] != 0x80)
    src[fmt + 9] = ord("X")
    p = tmp_path / "badfmt.bin"
    p.write_bytes(bytes(src))
    assert _both_dataflash(p)[0] == "error"
    with pytest.raises(tc.CalibrationError, match="unknown format character"):
        read_log(p)
