"""Hostile input for the log readers (``triaxcal.read_log``): ROS 1 bags, ROS 2 storage,
PX4 ULog and ArduPilot DataFlash files, mutated as in test_hostile_io.py. Every case ends in a
correct read or a CalibrationError: never another exception, a crash, a hang or memory out of
proportion; a bag is checked (magic, record lengths, chunk sizes) before rosbags reads it."""

from __future__ import annotations

import functools
import os
import re
import struct
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
import triaxcal as tc
from _hostile import (
    ROS,
    changed,
    cuts,
    flips,
    ros1_bomb,
    ros1_build,
    ros1_records,
    ros1_uncompressed,
    run_corpus,
    sparse,
    write,
)
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

# --------------------------------------------------------------------------------------------
# ROS bags


@pytest.fixture(scope="module")
def bag_corpus(realdata, tmp_path_factory):
    d = tmp_path_factory.mktemp("bag")
    bag = (realdata / ROS / "sparkfun_razor.bag").read_bytes()
    recs = ros1_records(bag)
    index_pos = struct.unpack("<Q", dict(recs[0][1])[b"index_pos"])[0]
    cases = {}
    cases |= cuts(bag, [0, 5, 12, 13, 14, 17, 30, 100, 4100, 4200, index_pos - 1, index_pos,
                        index_pos + 10, len(bag) - 1], "bag", d, ".bag", n_random=4)
    cases |= flips(bag, [0, 11, 12, 13, 16, 17, 20, 30, 40, 60, 70, 80, 90, 4109, 4113, 4120,
                         index_pos + 2, index_pos + 30, len(bag) - 10], "bag", d, ".bag")

    def with_field(k, name, value):
        r = list(recs)
        pos, fields, data = r[k]
        r[k] = (pos, [(n, value if n == name else v) for n, v in fields], data)
        return ros1_build(r)

    chunk = next(i for i, (_, f, _) in enumerate(recs) if dict(f).get(b"op") == b"\x05")
    crafted = {
        "bomb": ros1_bomb(bag, 48 << 20),
        "op-renamed": with_field(chunk, b"op", b"\x09"),
        "op-header-twice": ros1_build(recs[:1] + recs),
        "chunk-repeated": ros1_build(recs[:chunk + 1] + recs[chunk:]),
        "compression-unknown": with_field(chunk, b"compression", b"zip"),
        "size-huge": with_field(chunk, b"size", struct.pack("<I", 0xFFFFFFF0)),
        "size-small": with_field(chunk, b"size", struct.pack("<I", 10)),
        "index-pos-past-end": with_field(0, b"index_pos", struct.pack("<Q", 1 << 62)),
        "index-pos-zero": with_field(0, b"index_pos", struct.pack("<Q", 0)),
        "conn-count-huge": with_field(0, b"conn_count", struct.pack("<I", 0xFFFFFFFF)),
        "header-length-huge": bag[:13] + struct.pack("<I", 0xFFFFFFF0) + bag[17:],
        "version-1.2": b"#ROSBAG V1.2\n" + bag[13:],
        "zeros-after-magic": bag[:13] + bytes(len(bag) - 13),
        "text": b"#ROSBAG" + b" not really\n" * 100,
    }
    for name, data in crafted.items():
        cases |= write(d, f"{name}.bag", data)
    cases["zeros-64MiB"] = sparse(d / "zeros-64MiB.bag", 64 << 20)
    return cases


@pytest.mark.slow
def test_bag_corpus_reads_or_refuses(bag_corpus):
    pytest.importorskip("rosbags")
    out = run_corpus("log", bag_corpus, timeout=150, max_rss_mb=700)
    assert out["bomb"] == out["zeros-64MiB"] == out["op-renamed"] == "refused"


def test_a_file_of_zeros_named_bag_is_refused_before_rosbags_reads_it(tmp_path):
    """Before: rosbags read the first "line" whole (8 GiB of zeros: 17 GB, 192 s)."""
    pytest.importorskip("rosbags")
    import rosbags.highlevel  # noqa: F401 - imported before the memory is traced

    p = sparse(tmp_path / "zeros.bag", 64 << 20)
    tracemalloc.start()
    try:
        with pytest.raises(tc.CalibrationError) as exc:
            tc.read_log(p)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 8 << 20, peak / 1e6
    assert "does not start with '#ROSBAG V2.0'" in str(exc.value)


def test_a_chunk_that_unpacks_to_more_than_it_says_is_refused_in_bounded_memory(realdata,
                                                                              tmp_path):
    """Before: rosbags unpacked the whole chunk (here 64 MB more than declared)."""
    pytest.importorskip("rosbags")
    import rosbags.highlevel  # noqa: F401

    bag = (realdata / ROS / "sparkfun_razor.bag").read_bytes()
    ok = tmp_path / "rebuilt.bag"
    ok.write_bytes(ros1_build(ros1_records(bag)))  # the rewriter itself changes nothing
    assert ok.read_bytes() == bag
    p = tmp_path / "bomb.bag"
    p.write_bytes(ros1_bomb(bag, 64 << 20))
    assert p.stat().st_size < len(bag) + (64 << 10)
    tracemalloc.start()
    try:
        with pytest.raises(tc.CalibrationError, match=r"at byte \d+: a chunk declared as \d+ "
                                                      r"bytes unpacks to more"):
            tc.read_log(p)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 24 << 20, peak / 1e6


def test_ros2_storage_and_metadata_are_checked(tmp_path):
    pytest.importorskip("rosbags")
    from triaxcal.io.logs.bagcheck import check_bag

    folder = tmp_path / "bag2"
    folder.mkdir()
    (folder / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    (folder / "bag2_0.db3").write_bytes(b"not sqlite" * 10)
    with pytest.raises(tc.CalibrationError, match="does not start with 'SQLite format 3'"):
        tc.read_log(folder)
    (folder / "bag2_0.db3").unlink()
    os.mkfifo(folder / "bag2_0.mcap")
    with pytest.raises(tc.CalibrationError, match="named pipe"):
        check_bag(folder, "ros2-bag")
    (folder / "bag2_0.mcap").unlink()
    sparse(folder / "metadata.yaml", 5 << 20)
    with pytest.raises(tc.CalibrationError, match="larger than any"):
        tc.read_log(folder)
    lone = tmp_path / "lone.mcap"
    for data, words in [(b"", "does not start with the MCAP magic"),
                        (b"\x89MCAP0\r\n" + bytes(100), "does not end with the MCAP magic"),
                        (b"\x89MCAP0\r\n\x06" + struct.pack("<Q", 1 << 40) + b"\x89MCAP0\r\n",
                         "past the end of the file")]:
        lone.write_bytes(data)
        with pytest.raises(tc.CalibrationError, match=words):
            tc.read_log(lone)


# --------------------------------------------------------------------------------------------
# PX4 ULog and ArduPilot DataFlash (their readers are being ported to Rust: the cases here
# are the corpus that port must pass)


@pytest.fixture(scope="module")
def ulog_corpus(realdata, tmp_path_factory):
    d = tmp_path_factory.mktemp("ulg")
    ulg = (realdata / "px4-pyulog-samples" / "sample_log_small.ulg").read_bytes()
    cases = {}
    cases |= cuts(ulg, [0, 7, 8, 15, 16, 17, 100, 1000, 5000, len(ulg) // 2], "ulg", d, ".ulg",
                  n_random=3)
    cases |= flips(ulg, [0, 6, 7, 8, 15, 16, 17, 18, 19, 20], "ulg", d, ".ulg")
    cases |= flips(ulg, [40, 200, 2000], "ulg", d, ".ulg", extremes=False)
    cases |= write(d, "zeros.ulg", bytes(len(ulg)))
    cases |= write(d, "header-only.ulg", ulg[:16] + b"\xff" * 3 + b"B" + bytes(100))
    cases["zeros-64MiB"] = sparse(d / "zeros-64MiB.ulg", 64 << 20)
    return cases


def test_ulog_corpus_reads_or_refuses(ulog_corpus):
    pytest.importorskip("pyulog")
    run_corpus("log", ulog_corpus, timeout=150, max_rss_mb=900)


def _dataflash_prefix(realdata: Path) -> bytes:
    """The first 120 kB of a real DataFlash log (its formats, parameters, 650 IMU and 130 MAG
    messages): fast to read many times."""
    return (realdata / "ardupilot-erle-logs" / "PXFv2.0b+Rpi.BIN").read_bytes()[:120_000]


@pytest.fixture(scope="module")
def dataflash_corpus(realdata, tmp_path_factory):
    d = tmp_path_factory.mktemp("df")
    df = _dataflash_prefix(realdata)
    cases = {}
    cases |= cuts(df, [0, 1, 2, 3, 89, 90, 1000, 100_000], "df", d, ".bin", n_random=1)
    cases |= flips(df, [0, 1, 2, 3, 4], "df", d, ".bin")
    cases |= flips(df, [5, 6, 90, 91, 92, 180, 267 + 5, 267 + 9, 1000], "df", d, ".bin",
                   extremes=False)
    cases |= write(d, "zeros.bin", bytes(10_000))
    cases["zeros-64MiB"] = sparse(d / "zeros-64MiB.bin", 64 << 20)
    return cases


@pytest.mark.slow
def test_dataflash_corpus_reads_or_refuses(dataflash_corpus):
    pytest.importorskip("pymavlink")
    run_corpus("log", dataflash_corpus, timeout=150, max_rss_mb=900)


@pytest.mark.parametrize(("edit", "says"), [({1376: 151}, "no field MagY"),
                                             ({100_003 + 10: 0x9D}, "TimeUS beyond 2^63")],
                         ids=["fmt-renamed", "time-huge"])
def test_dataflash_damaged_format_or_time_refused(realdata, tmp_path, edit, says):
    """Byte 1376 is in the MAG format's column names ("MagY" becomes "Ma\x97Y"); byte
    100,013 the top byte of an IMU message's TimeUS (a uint64). Both are refused with a
    CalibrationError naming the damage (they were a KeyError and an OverflowError)."""
    p = tmp_path / "x.bin"
    p.write_bytes(changed(_dataflash_prefix(realdata), edit))
    with pytest.raises(tc.CalibrationError, match=re.escape(says)):
        tc.read_log(p)


# --------------------------------------------------------------------------------------------
# the bag check alone, on many random mutations (in this process: it is Python)


@functools.lru_cache(maxsize=1)
def _uncompressed_razor(realdata: Path) -> bytes:
    return ros1_uncompressed((realdata / ROS / "sparkfun_razor.bag").read_bytes())


@settings(max_examples=80, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(edits=st.lists(st.tuples(st.integers(0, 1_300_000), st.integers(0, 255)), min_size=1,
                      max_size=4),
       near_start=st.booleans(), cut=st.one_of(st.none(), st.integers(0, 1_300_000)))
def test_check_bag_refuses_or_passes_never_raises_otherwise(realdata, tmp_path, edits,
                                                             near_start, cut):
    """Bytes changed (in the headers near the start, or anywhere) and cuts anywhere, in a bag
    with unpacked chunks (so that the walk itself is what is tested, fast): check_bag refuses
    with a CalibrationError naming the file, or passes (what rosbags then does with such
    files is the bag corpus's business)."""
    pytest.importorskip("rosbags")
    from triaxcal.io.logs.bagcheck import check_bag

    b = bytearray(_uncompressed_razor(realdata))
    for at, value in edits:
        b[at % (300 if near_start else len(b))] = value
    p = tmp_path / "m.bag"
    p.write_bytes(bytes(b[:cut]))
    try:
        check_bag(p, "ros1-bag")
    except tc.CalibrationError as exc:
        assert str(p) in str(exc)


def test_the_uncompressed_bag_reads_as_the_real_one(realdata, tmp_path):
    pytest.importorskip("rosbags")
    real = tc.read_log(realdata / ROS / "sparkfun_razor.bag")
    p = tmp_path / "none.bag"
    p.write_bytes(ros1_uncompressed((realdata / ROS / "sparkfun_razor.bag").read_bytes()))
    rec = tc.read_log(p)
    assert np.array_equal(rec.accel.data, real.accel.data)
    assert np.array_equal(rec.mag.data, real.mag.data)


def test_control_characters_from_a_bag_do_not_reach_the_terminal(realdata, tmp_path):
    """A topic name is text from the file: ESC, BEL and CR in it are shown as '?' (before:
    printed raw, so a crafted bag could drive the terminal)."""
    pytest.importorskip("rosbags")
    recs = ros1_records((realdata / ROS / "sparkfun_razor.bag").read_bytes())
    evil = b"/imu\x1b]0;owned\x07\x1b[2J\r"

    def fields_of(h):
        out, i = [], 0
        while i < len(h):
            n = struct.unpack_from("<I", h, i)[0]
            k, _, v = h[i + 4:i + 4 + n].partition(b"=")
            out.append((k, v))
            i += 4 + n
        return out

    def encode(fields):
        return b"".join(struct.pack("<I", len(k) + 1 + len(v)) + k + b"=" + v for k, v in fields)

    out = []
    for pos, fields, data in recs:
        if dict(fields).get(b"op") == b"\x07":  # a connection: its header and its data
            fields = [(k, evil if k == b"topic" else v) for k, v in fields]
            data = encode([(k, evil if k == b"topic" else v) for k, v in fields_of(data)])
        out.append((pos, fields, data))
    p = tmp_path / "evil.bag"
    p.write_bytes(ros1_build(out))
    with pytest.raises(tc.CalibrationError) as exc:
        tc.read_log(p, topic="/nothing")
    msg = str(exc.value)
    assert "owned" in msg and not any(c in msg for c in "\x1b\x07\r"), repr(msg)
