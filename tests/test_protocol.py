"""Property tests of the pure wire-protocol code (triaxcal.io.protocol): bytes in, records out.

Round trips for every protocol, any chunking, garbage, dropped and flipped bytes, ``\\n`` bytes
inside binary data, and decoders that never raise. "Realistic" data below means what a sensor
sends: per-channel levels plus a few counts of noise, optionally with one channel stuck at a
value whose bytes contain 0x0A (a still axis reading 10, 2570 or -246 counts), which makes a
second, false frame phase in the legacy binary stream.
"""

from __future__ import annotations

import os
import random
import struct

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from triaxcal import CalibrationError
from triaxcal.io import motioncal as M
from triaxcal.io import protocol as P
from triaxcal.io.protocol import (
    MAX_LINE_BYTES,
    PROTOCOLS,
    RAW_SCALES,
    BinaryDecoder,
    FramedDecoder,
    RawDecoder,
    TextDecoder,
    cobs_decode,
    cobs_encode,
    crc16_ccitt,
    crc16_modbus,
    encode_binary,
    encode_framed,
    encode_raw,
    encode_text,
    make_decoder,
)

# TRIAXCAL_FUZZ_EXAMPLES=5000 for a longer fuzzing run
EXAMPLES = int(os.environ.get("TRIAXCAL_FUZZ_EXAMPLES", "120"))
SETTINGS = settings(
    max_examples=EXAMPLES,
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.too_slow],
)
# Legacy streaming has no checksum: wrong rows are rare (about 1 in 10^4 single corruptions
# of realistic data, measured with these generators), not impossible. These properties run a
# fixed set of examples so CI is repeatable; raise TRIAXCAL_FUZZ_EXAMPLES and set
# TRIAXCAL_FUZZ_RANDOM=1 to explore further.
LEGACY = settings(SETTINGS, derandomize=not os.environ.get("TRIAXCAL_FUZZ_RANDOM"))

NL_VALUES = [10, 0x0A0A, -246, 0x0A00, 2560, 2815, 0, -1, 32767, -32768, 0x0AFF, -2550]
int16 = st.integers(-32768, 32767)
# values rich in 0x0A bytes
nl_int16 = st.one_of(st.sampled_from(NL_VALUES), int16)


def records(k: int, values=nl_int16, min_size: int = 1, max_size: int = 40):
    return st.lists(st.tuples(*[values] * k), min_size=min_size, max_size=max_size)


def chunked(data: bytes, cuts: list[int]) -> list[bytes]:
    pos = sorted({c % (len(data) + 1) for c in cuts})
    out, last = [], 0
    for p in pos:
        out.append(data[last:p])
        last = p
    out.append(data[last:])
    return out


def decode_all(dec, chunks) -> list[tuple]:
    out: list[tuple] = []
    for c in chunks:
        out += dec.feed(c)
    flush = getattr(dec, "flush", None)
    if flush is not None:
        out += flush()
    return out


def in_order(out: list[tuple], recs: list[tuple]) -> tuple[list[tuple], list[tuple]]:
    """Split ``out`` into rows of ``recs`` met in order, and wrong rows (the rest)."""
    good, wrong, j = [], [], 0
    for r in out:
        try:
            j = recs.index(r, j) + 1
        except ValueError:
            wrong.append(r)  # not a row, or a row again / out of order
            continue
        good.append(r)
    return good, wrong


def realistic(seed: int, k: int, n: int, still_axis: bool = False) -> list[tuple[int, ...]]:
    """Sensor-like records: levels plus +-8 counts of noise.

    ``still_axis``: one channel reads 2600 +- 8 counts, so its high byte is 0x0A in every frame
    (a still axis tilted ~9 degrees), which makes a second, false frame phase.
    """
    rng = random.Random(seed)
    # levels whose high byte is never 0x0A (2560..2815 counts), unless asked for
    base = [rng.choice([rng.randint(-3000, 2540), rng.randint(2840, 6000)]) for _ in range(k)]
    base[min(2, k - 1)] = 16384
    if still_axis:
        # not the last channel: a 0x0A just before the terminator makes "terminator + the next
        # frame without its first byte" a perfect frame too (see BinaryDecoder's notes)
        base[seed % max(1, k - 1)] = 2600
    recs: list[tuple[int, ...]] = []
    while len(recs) < n:  # distinct rows, so that every row can be told apart
        r = tuple(b + rng.randint(-8, 8) for b in base)
        if r not in recs:
            recs.append(r)
    return recs


# ----------------------------------------------------------------------- checksums and COBS

def test_crc_check_values():
    # the catalogue check values of CRC-16/CCITT-FALSE and CRC-16/MODBUS
    assert crc16_ccitt(b"123456789") == 0x29B1
    assert crc16_modbus(b"123456789") == 0x4B37
    assert crc16_ccitt(b"") == 0xFFFF


@SETTINGS
@given(st.binary(max_size=700))
def test_cobs_round_trip(data):
    enc = cobs_encode(data)
    assert 0 not in enc
    assert len(enc) <= len(data) + 1 + len(data) // 254 + 1
    assert cobs_decode(enc) == data


@SETTINGS
@given(st.binary(min_size=1, max_size=300))
def test_cobs_decode_rejects_or_decodes_without_crashing(data):
    try:
        out = cobs_decode(data)
    except CalibrationError:
        return
    assert isinstance(out, bytes)


def test_cobs_known_vectors():
    assert cobs_encode(b"") == b"\x01"
    assert cobs_encode(b"\x00") == b"\x01\x01"
    assert cobs_encode(b"\x00\x00") == b"\x01\x01\x01"
    assert cobs_encode(b"\x11\x22\x00\x33") == b"\x03\x11\x22\x02\x33"
    assert cobs_encode(bytes(range(1, 255))) == b"\xff" + bytes(range(1, 255)) + b"\x01"
    with pytest.raises(CalibrationError, match="past the end"):
        cobs_decode(b"\x05\x11")


# ------------------------------------------------------------------------------ round trips

@SETTINGS
@given(st.integers(1, 12).flatmap(lambda k: records(k)), st.lists(st.integers(0, 10_000)))
def test_binary_stream_round_trip_any_chunking(recs, cuts):
    k = len(recs[0])
    data = b"".join(encode_binary(r) for r in recs)
    assert decode_all(BinaryDecoder(k), [data]) == recs
    assert decode_all(BinaryDecoder(k), chunked(data, cuts)) == recs


@SETTINGS
@given(st.integers(1, 12).flatmap(lambda k: records(k)), st.lists(st.integers(0, 10_000)))
def test_binary_polled_round_trip_any_chunking(recs, cuts):
    k = len(recs[0])
    dec = BinaryDecoder(k, polled=True)
    out = []
    for r in recs:
        dec.reset()
        for c in chunked(encode_binary(r), cuts):
            out += dec.feed(c)
    assert out == recs
    assert dec.stats.dropped_frames == 0 and dec.stats.dropped_bytes == 0


@SETTINGS
@given(
    st.integers(1, 12).flatmap(lambda k: records(k)),
    st.integers(0, 1000),
    st.lists(st.integers(0, 10_000)),
)
def test_framed_round_trip_any_chunking(recs, seq0, cuts):
    k = len(recs[0])
    data = b"".join(encode_framed(r, seq0 + i) for i, r in enumerate(recs))
    for channels in (k, None):
        dec = FramedDecoder(channels)
        assert decode_all(dec, chunked(data, cuts)) == recs
        assert dec.stats.lost_frames == 0
        assert dec.stats.last_seq == (seq0 + len(recs) - 1) % 256


number = st.one_of(
    int16.map(int),
    st.floats(-1e6, 1e6, allow_nan=False, allow_infinity=False),
)


@SETTINGS
@given(
    st.integers(1, 10).flatmap(lambda k: records(k, values=number, min_size=2)),
    st.sampled_from([None, "acc", "imu_0"]),
    st.sampled_from([b"\n", b"\r\n"]),
    st.lists(st.integers(0, 10_000)),
    st.booleans(),
)
def test_text_round_trip(recs, label, eol, cuts, give_k):
    k = len(recs[0])
    data = b"".join(encode_text(r, label=label)[:-1] + eol for r in recs)
    out = decode_all(TextDecoder(k if give_k else None), chunked(data, cuts))
    assert out == recs
    # ints stay ints, floats stay floats
    assert [type(v) for r in out for v in r] == [type(v) for r in recs for v in r]


def test_text_separators_and_labels():
    data = b"acc: 1, 2, 3\r\ngyr:\t4\t5\t6\n7 8 9\n  10,11,  12  \n"
    assert TextDecoder(3).feed(data) == [(1, 2, 3), (4, 5, 6), (7, 8, 9), (10, 11, 12)]


@SETTINGS
@given(records(9, values=int16), st.lists(st.integers(0, 10_000)))
def test_raw_round_trip(recs, cuts):
    data = b"".join(encode_raw(r) for r in recs)
    dec = RawDecoder()
    assert decode_all(dec, chunked(data, cuts)) == recs
    assert dec.stats.lines_skipped == 0


def test_raw_scales_and_other_lines():
    assert RAW_SCALES == {"accel": 8192.0, "gyro": 16.0, "mag": 10.0}
    data = (
        b"Raw:0,0,8192,0,0,16,100,-200,300\r\n"
        b"Uni:0.00,0.00,1.00\r\n"
        b"Raw:1,2,3\r\n"  # too few
        b"Raw:1,2,3,4,5,6,7,8,9,10\r\n"  # too many
        b"Raw:1,2,3,4,5,6,7,8,x\r\n"
        b"Raw:1,2,3,4,5,6,7,8,99999\r\n"  # not int16
        b"Cal1:0.0000,0.0000\r\n"
        b"Raw:-1,-2,-3,-4,-5,-6,-7,-8,-9\n"
    )
    dec = RawDecoder()
    out = dec.feed(data)
    assert out == [(0, 0, 8192, 0, 0, 16, 100, -200, 300), (-1, -2, -3, -4, -5, -6, -7, -8, -9)]
    assert dec.stats.lines_skipped == 6
    g = out[0][2] / RAW_SCALES["accel"]
    assert g == 1.0


# ------------------------------------------------------------------------ binary specifics

def test_binary_values_with_newline_bytes():
    recs = [(10, 0x0A0A, -246), (0x0A00, 10, 10), (10, 10, 10)] * 5
    data = b"".join(encode_binary(r) for r in recs)
    assert data.count(b"\n") > 2 * len(recs)  # many more 0x0A bytes than frames
    assert decode_all(BinaryDecoder(3), [data]) == recs


def test_binary_frames_are_cut_by_length_not_newline():
    # a naive split on b"\n" would cut this frame in four
    data = encode_binary([10, 2570, -246])
    assert data.count(b"\n") == 5  # one terminator, four 0x0A data bytes
    d = BinaryDecoder(3)
    assert d.feed(data) + d.flush() == [(10, 2570, -246)]


@LEGACY
@given(
    st.integers(0, 2**32 - 1),
    st.sampled_from([3, 6, 7, 10]),
    st.booleans(),
    st.sampled_from(["drop", "drop_run", "insert", "flip_term", "flip_data"]),
    st.data(),
)
def test_binary_stream_single_corruption_realistic(seed, k, still_axis, kind, data):
    """Legacy streaming: one corruption costs at most a few neighbouring frames, no wrong row.

    With a still axis whose high byte is 0x0A in every frame, a run of bytes lost or inserted
    whose length moves the stream exactly onto the false phase cannot be told from a clean
    stream whose values jumped (documented in BinaryDecoder); so there only single-byte drops
    and flips are drawn.
    """
    if still_axis and kind in ("drop_run", "insert"):
        kind = "drop"
    n = 40
    recs = realistic(seed, k, n, still_axis)
    L = 2 * k + 1
    stream = bytearray(b"".join(encode_binary(r) for r in recs))
    # away from the first and last 4 frames (no history / no look-ahead there)
    frame = data.draw(st.integers(4, n - 5), label="frame")
    rng = random.Random(seed ^ 0x5A5A)
    touched = 1
    if kind == "drop":
        del stream[frame * L + data.draw(st.integers(0, L - 1))]
    elif kind == "drop_run":
        # a run of exactly one frame's length leaves a stream with every terminator in place:
        # the remains of two frames then form one frame that no check can refuse
        m = data.draw(st.integers(2, 2 * L).filter(lambda m: m % L != 0))
        start = frame * L + data.draw(st.integers(0, L - 1))
        del stream[start : start + m]
        touched = 1 + (m + L - 1) // L
    elif kind == "insert":
        # line noise: uniformly random bytes
        g = bytes(rng.randrange(256) for _ in range(data.draw(st.integers(1, 3 * L))))
        pos = frame * L + data.draw(st.integers(0, L))
        stream[pos:pos] = g
    elif kind == "flip_term":
        stream[frame * L + L - 1] ^= data.draw(st.integers(1, 255))
    else:
        stream[frame * L + data.draw(st.integers(0, L - 2))] ^= data.draw(st.integers(1, 255))
    dec = BinaryDecoder(k)
    cuts = data.draw(st.lists(st.integers(0, 10_000), max_size=8), label="cuts")
    out = decode_all(dec, chunked(bytes(stream), cuts))
    # same output whatever the chunking
    assert out == decode_all(BinaryDecoder(k), [bytes(stream)])
    good, wrong = in_order(out, recs)
    if kind == "flip_data":
        # no checksum: the damaged frame itself may come out changed, nothing else
        assert len(wrong) <= 1
    else:
        assert wrong == []
    assert len(good) >= n - touched - 3
    if kind != "flip_data":
        assert dec.stats.dropped_bytes > 0


@LEGACY
@given(
    st.integers(0, 2**32 - 1),
    st.sampled_from([3, 7]),
    st.binary(min_size=1, max_size=60),
    st.data(),
)
def test_binary_stream_adversarial_garbage_costs_few_frames(seed, k, garbage, data):
    """Any garbage (even 0x0A-rich, frame-like) between noisy frames: real frames survive."""
    n = 30
    recs = realistic(seed, k, n)
    L = 2 * k + 1
    stream = bytearray(b"".join(encode_binary(r) for r in recs))
    pos = data.draw(st.integers(4 * L, (n - 4) * L))
    stream[pos:pos] = garbage
    out = decode_all(BinaryDecoder(k), [bytes(stream)])
    good, _ = in_order(out, recs)
    assert len(good) >= n - 4
    # extra rows can only come from the garbage itself
    assert len(out) - len(good) <= len(garbage) // L + 1


@LEGACY
@given(st.integers(0, 2**32 - 1), st.sampled_from([3, 7]), st.binary(max_size=80))
def test_binary_stream_garbage_prepended(seed, k, garbage):
    recs = realistic(seed, k, 20)
    stream = garbage + b"".join(encode_binary(r) for r in recs)
    out = decode_all(BinaryDecoder(k), [stream])
    good, wrong = in_order(out, recs)
    assert good == recs[len(recs) - len(good) :]  # a suffix, in order
    assert len(good) >= len(recs) - 2


reply_damage = st.sampled_from(["ok", "short", "long_tail", "long_head", "no_term", "empty"])


@SETTINGS
@given(
    st.integers(1, 10).flatmap(lambda k: records(k, max_size=15)),
    st.lists(st.tuples(reply_damage, st.binary(min_size=1, max_size=8)), min_size=15),
)
def test_binary_polled_never_a_wrong_row(recs, damage):
    """Polled: a reply too short, too long or without terminator is dropped, never decoded."""
    k = len(recs[0])
    dec = BinaryDecoder(k, polled=True)
    expect, got = [], []
    for r, (how, junk) in zip(recs, damage):
        frame = encode_binary(r)
        reply = {
            "ok": frame,
            "short": frame[: -min(len(junk), len(frame) - 1)],
            "long_tail": frame + junk,
            "long_head": junk + frame,
            "no_term": frame[:-1] + bytes([frame[-1] ^ 0x80]),
            "empty": b"",
        }[how]
        dec.reset()
        got += dec.feed(reply)  # the reader reads a whole reply before the next request
        if how == "ok":
            expect.append(r)
    dec.reset()
    assert got == expect
    bad = sum(1 for _, (how, _) in zip(recs, damage) if how not in ("ok", "empty"))
    assert dec.stats.dropped_frames == bad


def test_binary_polled_extra_bytes_after_a_frame_are_counted():
    dec = BinaryDecoder(2, polled=True)
    assert dec.feed(encode_binary([1, 2])) == [(1, 2)]
    assert dec.feed(b"xx") == []
    assert dec.stats.dropped_bytes == 2
    dec.reset()
    assert dec.feed(encode_binary([3, 4])[:3]) == []
    dec.reset()  # a timeout: the short reply counts as a dropped frame
    assert dec.stats.dropped_frames == 1


# ------------------------------------------------------------------------ framed specifics

@SETTINGS
@given(
    st.integers(1, 10).flatmap(lambda k: records(k, min_size=3, max_size=20)),
    st.sampled_from(["flip", "drop", "insert", "zero"]),
    st.data(),
)
def test_framed_corruption_always_detected(recs, kind, data):
    recs = [(i, *r) for i, r in enumerate(recs)]  # rows told apart by their first value
    k = len(recs[0])
    frames = [encode_framed(r, i) for i, r in enumerate(recs)]
    j = data.draw(st.integers(0, len(frames) - 1), label="frame")
    f = bytearray(frames[j])
    p = data.draw(st.integers(0, len(f) - 1), label="byte")
    if kind == "flip":
        f[p] ^= data.draw(st.integers(1, 255))
    elif kind == "drop":
        del f[p]
    elif kind == "insert":
        f[p:p] = data.draw(st.binary(min_size=1, max_size=10))
    else:
        f[p] = 0
    frames[j] = bytes(f)
    dec = FramedDecoder(k)
    out = decode_all(dec, [b"".join(frames)])
    # never a wrong row; order kept; at most the damaged frame and its neighbour lost
    assert all(r in recs for r in out)
    idx = [recs.index(r) for r in out]
    assert idx == sorted(idx) and len(set(idx)) == len(idx)
    assert len(out) >= len(recs) - 2
    if kind != "insert" and frames[j] != encode_framed(recs[j], j):
        assert recs[j] not in out  # a damaged frame never passes
    # sequence gaps between the first and last good frame are counted
    assert dec.stats.lost_frames == idx[-1] - idx[0] + 1 - len(idx)


@SETTINGS
@given(
    st.integers(1, 8).flatmap(lambda k: records(k, min_size=2, max_size=20)),
    st.lists(st.binary(max_size=30), min_size=1, max_size=20),
    st.lists(st.integers(0, 10_000), max_size=10),
)
def test_framed_garbage_interleaved_loses_nothing(recs, garbage, cuts):
    """Garbage between frames (and before the first) costs no valid frame and no wrong row."""
    k = len(recs[0])
    parts = []
    for i, r in enumerate(recs):
        parts.append(garbage[i % len(garbage)])
        parts.append(encode_framed(r, i))
    stream = b"".join(parts)
    dec = FramedDecoder(k)
    out = decode_all(dec, chunked(stream, cuts))
    assert out == recs


def test_framed_sequence_gaps_counted():
    recs = [(i, -i) for i in range(10)]
    frames = [encode_framed(r, 250 + i) for i, r in enumerate(recs)]  # wraps past 255
    del frames[3:6]
    dec = FramedDecoder(2)
    out = dec.feed(b"".join(frames))
    assert out == recs[:3] + recs[6:]
    assert dec.stats.lost_frames == 3
    assert dec.stats.last_seq == (250 + 9) % 256


def test_framed_learns_channels_then_drops_other_lengths():
    dec = FramedDecoder()
    data = encode_framed([1, 2, 3], 0) + encode_framed([1, 2], 1) + encode_framed([4, 5, 6], 2)
    out = dec.feed(data)
    assert out == [(1, 2, 3), (4, 5, 6)]
    assert dec.channels == 3 and dec.stats.dropped_frames == 1


# -------------------------------------------------------------------------- text specifics

# garbage lines: some byte that no number, separator or label can contain
bad_text_line = st.binary(max_size=40).map(lambda b: b.replace(b"\n", b"") + b"#?\x00")


@SETTINGS
@given(
    st.integers(1, 6).flatmap(lambda k: records(k, values=int16, min_size=2, max_size=25)),
    st.lists(st.one_of(bad_text_line, st.just(b"1,2"), st.just(b"label:")), max_size=20),
    st.lists(st.integers(0, 10_000), max_size=10),
    st.data(),
)
def test_text_malformed_lines_skipped_and_counted(recs, junk, cuts, data):
    k = len(recs[0])
    lines = [encode_text(r) for r in recs]
    assume(k != 2 or all(j != b"1,2" for j in junk))
    for j in junk:
        lines.insert(data.draw(st.integers(1, len(lines))), j + b"\r\n")
    dec = TextDecoder(k)
    out = decode_all(dec, chunked(b"".join(lines), cuts))
    assert out == recs
    assert dec.stats.lines_skipped == len(junk)


def test_text_rejects_non_numbers():
    dec = TextDecoder(3)
    data = b"1,2,nan\n1,2,inf\n0x10,2,3\n1,,2\n1;2;3\n1,2,3,4\n1.5e3,-2,+3\n"
    assert dec.feed(data) == [(1500.0, -2, 3)]
    assert dec.stats.lines_skipped == 6


def test_text_skips_readings_no_sensor_makes():
    """A damaged line whose number is past any sensor's range (1e15) is skipped and counted like
    a NaN: the pose detectors refuse such a reading, so it would end a capture."""
    dec = TextDecoder(3)
    data = (b"1,2,1e300\n1,2," + b"9" * 40 + b"\n1,-1e16,3\n1,2,1000000000000001\n"
            b"1,2,-1e15\n4,5,1000000000000000\n")
    assert dec.feed(data) == [(1, 2, -1e15), (4, 5, 10**15)]
    assert dec.stats.lines_skipped == 4


def test_a_damaged_huge_reading_does_not_end_a_live_capture(tmp_path):
    from triaxcal.capture.run import channel_names
    from triaxcal.io.serial import Record
    from triaxcal.live import LiveState

    names = channel_names("text", 9)
    st = LiveState(tmp_path / "s.csv", names)
    dec = TextDecoder(9)
    good = b"0,0,16384,0,0,0,300,0,400\n"
    rows = dec.feed(good * 60 + b"0,0,1e300,0,0,0,300,0,400\n" + good * 60)
    assert dec.stats.lines_skipped == 1 and len(rows) == 120
    st.on_records([Record(1.7e9 + 0.01 * i, r) for i, r in enumerate(rows)])
    assert st.rows == 120


def test_text_unknown_channels_skip_a_partial_first_line():
    dec = TextDecoder()
    out = dec.feed(b"2,3\n1,2,3\n4,5,6\n7,8\n") + dec.flush()
    assert out == [(1, 2, 3), (4, 5, 6)]
    assert dec.channels == 3 and dec.stats.lines_skipped == 2


# -------------------------------------------------------------- every decoder, any bytes

def all_decoders():
    return [
        BinaryDecoder(3),
        BinaryDecoder(7, polled=True),
        FramedDecoder(3),
        FramedDecoder(),
        TextDecoder(3),
        TextDecoder(),
        RawDecoder(),
    ]


@settings(max_examples=2 * EXAMPLES, deadline=None, database=None)
@given(st.lists(st.binary(max_size=200), max_size=10))
def test_decoders_never_raise(chunks):
    for dec in all_decoders():
        out = []
        for c in chunks:
            out += dec.feed(c)
            if isinstance(dec, BinaryDecoder) and dec.polled:
                dec.reset()
        out += dec.flush()
        assert all(isinstance(r, tuple) for r in out)
        assert dec.stats.bytes_in == sum(len(c) for c in chunks)


def streaming_decoders():
    return [BinaryDecoder(3), BinaryDecoder(7), FramedDecoder(3), FramedDecoder(), TextDecoder(3),
            TextDecoder(), RawDecoder()]


frame_soup = st.lists(
    st.one_of(
        st.binary(max_size=20),
        st.lists(nl_int16, min_size=3, max_size=3).map(encode_binary),
        st.lists(nl_int16, min_size=7, max_size=7).map(encode_binary),
        st.tuples(st.lists(int16, min_size=3, max_size=3), st.integers(0, 255)).map(
            lambda a: encode_framed(*a)
        ),
        st.lists(int16, min_size=3, max_size=3).map(encode_text),
        st.sampled_from([b"\n", b"\r\n", b"\x00", b"Raw:", b"1,2,3", b"acc: "]),
    ),
    max_size=30,
).map(b"".join)


@settings(max_examples=2 * EXAMPLES, deadline=None, database=None)
@given(frame_soup, st.lists(st.integers(0, 10_000), max_size=20))
def test_any_chunking_gives_the_same_records(data, cuts):
    """Whatever the bytes, feeding them in pieces gives what feeding them at once gives."""
    for whole, pieces in zip(streaming_decoders(), streaming_decoders()):
        assert decode_all(pieces, chunked(data, cuts)) == decode_all(whole, [data])


@pytest.mark.parametrize("dec", all_decoders(), ids=lambda d: type(d).__name__)
def test_buffer_is_bounded(dec):
    rng = random.Random(3)
    junk = bytes(rng.choice(b"abcdefghij0123456789,") for _ in range(20_000))  # no 0x00, no \n
    for _ in range(10):
        dec.feed(junk)
        assert dec.buffered <= max(MAX_LINE_BYTES, 2 * 131, 6 * 15) + 1
    assert dec.stats.dropped_bytes >= 200_000 - dec.buffered - 1000


# --------------------------------------------------------------------- factory and encoders

def test_make_decoder():
    assert PROTOCOLS == ("binary", "framed", "text", "raw")
    assert isinstance(make_decoder("binary", 7, polled=True), BinaryDecoder)
    assert isinstance(make_decoder("framed", None), FramedDecoder)
    assert isinstance(make_decoder("text", 3), TextDecoder)
    assert isinstance(make_decoder("raw", None), RawDecoder)
    with pytest.raises(CalibrationError, match="channel count"):
        make_decoder("binary", None)
    with pytest.raises(CalibrationError, match="unknown protocol"):
        make_decoder("morse", 3)
    with pytest.raises(CalibrationError, match="polled"):
        make_decoder("text", 3, polled=True)
    with pytest.raises(CalibrationError, match="9 values"):
        make_decoder("raw", 7)
    with pytest.raises(CalibrationError, match="channels must be"):
        BinaryDecoder(0)


def test_encoders_check_their_input():
    with pytest.raises(CalibrationError, match="int16"):
        encode_binary([40000])
    with pytest.raises(CalibrationError, match="integers"):
        encode_framed([1.5], 0)
    with pytest.raises(CalibrationError, match="9 values"):
        encode_raw([1, 2, 3])
    with pytest.raises(CalibrationError, match="label"):
        encode_text([1], label="a b:")
    assert encode_framed([1, 2], seq=256 + 5) == encode_framed([1, 2], seq=5)
    # the framed layout: seq, K int16 LE, CRC LE, COBS, 0x00
    raw = cobs_decode(encode_framed([258, -1], seq=9)[:-1])
    assert raw[:5] == bytes([9]) + struct.pack("<2h", 258, -1)
    assert struct.unpack("<H", raw[5:])[0] == crc16_ccitt(raw[:5])


def test_motioncal_packet_round_trip():
    soft = [[1.01, 0.01, -0.02], [0.01, 0.99, 0.03], [-0.02, 0.03, 1.02]]
    pkt = M.encode_motioncal(accel_offset=[0.1, -0.2, 0.3], gyro_offset=[1, 2, 3],
                             mag_offset=[10.5, -20.25, 30.0], field=48.5, soft_iron=soft)
    assert len(pkt) == M.MOTIONCAL_SIZE and pkt[:2] == bytes([117, 84])
    cal = M.decode_motioncal(pkt)
    lines = M.format_cal_lines(cal)
    assert lines.startswith(b"Cal1:0.1000,-0.2000,0.3000,1.0000,2.0000,3.0000,10.5000,-20.2500,")
    parsed = M.parse_motioncal_echo(b"noise\r\n" + lines)
    assert parsed is not None
    assert parsed[0][9] == pytest.approx(48.5)
    assert parsed[1] == pytest.approx(np.ravel(soft), abs=1e-4)
    bad = bytearray(pkt)
    bad[10] ^= 1
    with pytest.raises(CalibrationError, match="CRC"):
        M.decode_motioncal(bytes(bad))


def test_docstring_examples_run():
    import doctest

    from triaxcal.io import framing

    attempted = 0
    for mod in (P, framing):
        result = doctest.testmod(mod, optionflags=doctest.ELLIPSIS)
        assert result.failed == 0
        attempted += result.attempted
    assert attempted >= 14
