"""Hostile input for the reading layer (``triaxcal.io``): files of every format it reads, mutated
-- cut at many offsets, bytes changed at header offsets, records renamed or repeated, lengths
declared huge, zero-filled, text with NUL bytes, byte-order marks, CRLF, non-UTF-8 bytes -- and
things that are not files (pipes, devices, folders, sockets, symbolic link loops).

Every case must end in a correct read or a :class:`~triaxcal.CalibrationError`: never another
exception, a crash, a hang or memory out of proportion. The mutation corpus of each format is
read in a child process (a crash of a reader must not take the test run with it; a hang is
killed after a time limit) that reports each case's outcome and its own peak memory.

The mutations start from the real recordings in ../shared/realdata and from small synthetic
files built here (the builders and the runner are in _hostile.py; the log readers' corpus is in
test_hostile_logs.py).
"""

from __future__ import annotations

import os
import socket
import tracemalloc
import zipfile
from pathlib import Path

import numpy as np
import pytest
import triaxcal as tc
from _hostile import (
    WEAR,
    changed,
    cuts,
    cwa_fix_checksum,
    cwa_with,
    flips,
    geneactiv_whole,
    needs_skdh,
    run_corpus,
    sparse,
    write,
    zip_of,
)
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

# --------------------------------------------------------------------------------------------
# things that are not regular files, for every reader


@pytest.fixture()
def not_files(tmp_path):
    """name -> (path, the words the refusal must hold)."""
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    folder = tmp_path / "folder"
    folder.mkdir()
    (tmp_path / "loop1").symlink_to(tmp_path / "loop2")
    (tmp_path / "loop2").symlink_to(tmp_path / "loop1")
    sock_path = tmp_path / "sock"
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    sock.bind(str(sock_path))
    out = {"fifo": (fifo, "named pipe (FIFO), not a regular file"),
           "folder": (folder, "is a folder"),
           "loop": (tmp_path / "loop1", "symbolic link"),
           "socket": (sock_path, "socket, not a regular file")}
    if os.path.exists("/dev/zero"):
        out["dev-zero"] = (Path("/dev/zero"), "character device, not a regular file")
    yield out
    sock.close()


def _as(path: Path, suffix: str, tmp: Path) -> Path:
    """``path`` under a name ending in ``suffix`` (a symbolic link to it)."""
    link = tmp / f"as-{path.name}{suffix}"
    if not link.is_symlink():
        link.symlink_to(path)
    return link


def _readers():
    from triaxcal.io.tables import iter_csv, iter_table, read_table
    from triaxcal.io.wearables import read_wearable

    return {
        "table": (lambda p: read_table(p), ""),
        "table-blocks": (lambda p: list(iter_table(p)), ""),
        "csv": (lambda p: list(iter_csv(p)), ""),
        "calibration": (tc.Calibration.load, ""),
        "ulog": (tc.read_log, ".ulg"),
        "dataflash": (tc.read_log, ".bin"),
        "ros1": (tc.read_log, ".bag"),
        "mcap": (tc.read_log, ".mcap"),
        "cwa": (read_wearable, ".cwa"),
        "geneactiv": (read_wearable, ".bin"),
        "gt3x": (read_wearable, ".gt3x"),
    }


@pytest.mark.timeout(60)
@pytest.mark.parametrize("reader", ["table", "table-blocks", "csv", "calibration", "ulog",
                                    "dataflash", "ros1", "mcap", "cwa", "geneactiv", "gt3x"])
def test_a_pipe_a_device_a_socket_a_folder_or_a_link_loop_is_refused_at_once(
        reader, not_files, tmp_path):
    """Before: a pipe hung fit, export, diff (and report) for ever -- open() waits for a
    writer; the log and wearable readers said "not found"."""
    read, suffix = _readers()[reader]
    if reader == "geneactiv":  # read_wearable tells GENEActiv from Axivity by the suffix
        read, suffix = _readers()["cwa"][0], ".bin"
    for kind, (path, words) in not_files.items():
        if suffix and kind == "folder":
            continue  # a folder named .bag is not a ROS 2 bag: covered by test_logs
        target = _as(path, suffix, tmp_path) if suffix else path
        with pytest.raises(tc.CalibrationError) as exc:
            read(target)
        assert words in str(exc.value), (kind, str(exc.value))
        assert str(target) in str(exc.value) or target.name in str(exc.value)


def test_open_regular_checks_the_open_file_too(tmp_path, monkeypatch):
    """A file swapped for a pipe between the check and the open is caught on the descriptor
    (opened without blocking)."""
    from triaxcal.io import files

    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    calls = []
    real = files.check_regular

    def first_says_regular(path, **kw):
        calls.append(path)
        return os.stat(__file__)  # the check before the open is fooled

    monkeypatch.setattr(files, "check_regular", first_says_regular)
    with pytest.raises(tc.CalibrationError, match="named pipe"):
        files.open_regular(fifo, what="table")
    assert calls
    monkeypatch.setattr(files, "check_regular", real)
    p = tmp_path / "ok.txt"
    p.write_bytes(b"12")
    with files.open_regular(p, limit=2) as f:
        assert f.read() == b"12"
    with pytest.raises(tc.CalibrationError, match="larger than any"):
        files.open_regular(p, limit=1, what="thing")
    with pytest.raises(tc.CalibrationError, match="not found"):
        files.open_regular(tmp_path / "none")
    with pytest.raises(tc.CalibrationError, match="NUL"):
        files.check_regular("a\0b")


# --------------------------------------------------------------------------------------------
# sizes and lines


def test_a_calibration_file_is_at_most_16_mib(tmp_path):
    """Before: up to 64 MB were read and checked value by value (a 62 MB file took 159 s and
    2.8 GB to export)."""
    from triaxcal.calibration.schema import MAX_FILE_BYTES

    assert MAX_FILE_BYTES == 16 << 20
    p = sparse(tmp_path / "big.json", (16 << 20) + 1)
    with pytest.raises(tc.CalibrationError, match=r"larger than any calibration file \(16 MiB"):
        tc.Calibration.load(p)


def test_a_huge_file_without_a_line_break_costs_bounded_memory(tmp_path):
    """512 MiB of zeros (sparse: no disk) is refused after the first MiB, in blocks or not."""
    from triaxcal.io.tables import iter_table, read_table

    p = sparse(tmp_path / "zeros.csv", 512 << 20)
    tracemalloc.start()
    try:
        with pytest.raises(tc.CalibrationError, match="line 1: more than 1048576 bytes"):
            read_table(p)
        with pytest.raises(tc.CalibrationError, match="line 1: more than 1048576 bytes"):
            list(iter_table(p))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 64 << 20


def test_a_csv_field_past_the_csv_limit_is_a_clear_error(tmp_path):
    """Before: `triaxcal batch` raised _csv.Error from its own csv.reader (a traceback)."""
    from triaxcal.io.tables import iter_csv

    p = tmp_path / "boards.csv"
    p.write_text("id,x\nb1,0.5\nb2," + "9" * 200_000 + "\n")
    rows = iter_csv(p)
    assert next(rows) == (1, ["id", "x"]) and next(rows) == (2, ["b1", "0.5"])
    with pytest.raises(tc.CalibrationError, match=r"boards.csv, line 3: field larger than"):
        next(rows)
    p.write_text('id,x\n"b1,0.5\n' + "x" * 200_000 + "\n")  # a quote never closed
    with pytest.raises(tc.CalibrationError, match="unclosed quote"):
        list(iter_csv(p))
    p.write_bytes(b"\xef\xbb\xbfid,x\r\n\"two\nlines\",\xff1\r\n")
    assert list(iter_csv(p)) == [(1, ["id", "x"]), (2, ["two\nlines", "\ufffd1"])]


def test_a_table_past_max_values_is_refused_with_what_to_do(tmp_path):
    from triaxcal.io.tables import read_table

    p = tmp_path / "t.csv"
    p.write_text("".join(f"{i},1,2\n" for i in range(30_000)))
    assert read_table(p).data.shape == (30_000, 3)
    with pytest.raises(tc.CalibrationError, match=r"more than 60,000 values.*iter_table"):
        read_table(p, max_values=60_000)


@pytest.mark.slow
def test_rows_parsed_one_by_one_do_not_pile_up_as_python_floats(tmp_path):
    """Rows from chunks with a bad line were kept as lists of Python floats (32 bytes a value
    instead of 8) until the end of the file: 30 MB traced for these 100,000 rows, now half
    (most of it the lines of one 4 MiB block of the file, the same for any length)."""
    from triaxcal.io.tables import read_table

    lines = []
    for i in range(100_000):
        lines.append(f"{i},{i},{i}")
        if i % 2000 == 0:
            lines.append("junk")
    p = tmp_path / "t.csv"
    p.write_text("\n".join(lines) + "\n")
    tracemalloc.start()
    try:
        t = read_table(p, skip_bad_lines=True)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert t.data.shape == (100_000, 3) and t.skipped == 50
    assert np.array_equal(t.data[:, 0], np.arange(100_000))
    assert peak < 22e6, peak / 1e6


# --------------------------------------------------------------------------------------------
# tables: numbers at the edge of a double, text that is not quite text


_EDGE = ["1e308", "-1e308", "1e309", "-0", "0", "nan", "NaN", "inf", "-inf", "Infinity",
         "1e-320", "4.9e-324", "1e-400", "+1", ".5", "5.", "1_000", "0x10", "\u0661", "",
         "1e", "--1", "1e+308", "9" * 400]


def _expected(tok: str) -> float | None:
    if not tok.isascii() or "_" in tok:
        return None
    try:
        return float(tok)
    except ValueError:
        return None


@settings(max_examples=120, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(rows=st.lists(st.lists(st.sampled_from(_EDGE), min_size=3, max_size=3), min_size=1,
                     max_size=6),
       delim=st.sampled_from([",", ";", "\t", " "]), crlf=st.booleans(), bom=st.booleans(),
       header=st.booleans(), last_break=st.booleans(), skip=st.booleans())
def test_tables_of_edge_numbers_read_exactly_or_refuse(tmp_path, rows, delim, crlf, bom, header,
                                                      last_break, skip):
    """Any mix of edge values: a correct read (every value as float() reads it) or a
    CalibrationError; in blocks the same."""
    from triaxcal.io.tables import iter_table, read_table

    if delim in " \t":  # blanks at the ends of a line are not values (nor empty ones)
        rows = [[x or "0" for x in r] for r in rows]
    nl = "\r\n" if crlf else "\n"
    text = (f"ax{delim}ay{delim}az{nl}" if header else "") + nl.join(
        delim.join(r) for r in rows) + (nl if last_break else "")
    raw = (b"\xef\xbb\xbf" if bom else b"") + text.encode()
    p = tmp_path / "edge.csv"
    p.write_bytes(raw)
    try:
        t = read_table(p, skip_bad_lines=skip)
    except tc.CalibrationError:
        with pytest.raises(tc.CalibrationError):
            list(iter_table(p, rows=2, skip_bad_lines=skip))
        return
    assert t.data.dtype == np.float64 and t.data.ndim == 2
    # every row read is a row of the file, value for value
    want = [[_expected(x) for x in r] for r in rows]
    for row in t.data:
        assert any(all((np.isnan(a) and np.isnan(b)) or a == b for a, b in zip(row, w))
                   for w in want if None not in w), (row, rows)
    blocks = list(iter_table(p, rows=2, skip_bad_lines=skip))
    assert np.array_equal(np.concatenate([b.data for b in blocks]), t.data, equal_nan=True)
    assert blocks[-1].sha256 == t.sha256 and blocks[-1].notes == t.notes
    assert all(b.names == t.names for b in blocks)


@pytest.mark.parametrize("raw", [
    b"", b"\n\n\n", b"\x00" * 5000, b"\xef\xbb\xbf", b"\xff\xfe1,2,3\n", b"1,2,3\x00\n4,5,6\n",
    b"\xff\xfe\x001\x00,\x002\x00\n\x00", b"1,2,3\r\r\r4,5,6", b"#" * 3_000_000,
    b"1," * 5000 + b"\n", b"t,ax,ay,az\n0,1,2", b"1 2 3\n" * 3 + b"\x1b[2J\x07\n",
])
def test_odd_bytes_in_a_table_read_or_refuse(tmp_path, raw):
    from triaxcal.io.tables import read_table

    p = tmp_path / "odd.csv"
    p.write_bytes(raw)
    try:
        t = read_table(p)
    except tc.CalibrationError as exc:
        assert "\x1b" not in str(exc) and "\x07" not in str(exc) and len(str(exc)) < 1000
        return
    assert np.all(np.isfinite(t.data))


# --------------------------------------------------------------------------------------------
# Axivity .cwa


@pytest.fixture(scope="module")
def cwa_corpus(realdata, tmp_path_factory):
    d = tmp_path_factory.mktemp("cwa")
    ax3 = (realdata / WEAR / "ax3_testfile.cwa").read_bytes()
    ax6 = (realdata / WEAR / "ax6_testfile.cwa").read_bytes()
    n3 = len(ax3) // 512
    cases = {}
    cases |= cuts(ax3, [0, 1, 2, 100, 1023, 1024, 1100, 1535, 1536, 2049, 7000, len(ax3) - 1],
                  "ax3", d, ".cwa", n_random=1)
    cases |= cuts(ax6, [1030, len(ax6) // 2 + 7], "ax6", d, ".cwa", n_random=0)
    cases |= flips(ax3, [0, 1, 2, 3, 35, 1024, 1025, 1026, 1027, 1034, 1049, 1052, 1053],
                   "ax3", d, ".cwa")
    cases |= flips(ax3, [5, 12, 36, 1534, 5000, len(ax3) - 2], "ax3", d, ".cwa",
                   extremes=False)
    crafted = {
        "seq-past-end": cwa_with(ax3, 5, "<I", 10, 10**6),  # before: SIGSEGV
        "seq-negative": cwa_with(ax3, 5, "<I", 10, 0xFFFFFFF0),  # before: a silent heap write
        "seq-last-plus-one": cwa_with(ax3, n3 - 1, "<I", 10, n3 - 2),
        "seq-repeated": cwa_with(ax3, 6, "<I", 10, 3),
        "count-zero": cwa_with(ax3, 2, "<H", 28, 0),
        "count-negative": cwa_with(ax3, 2, "<H", 28, 0xFFF0),
        "packing-1": cwa_with(ax3, 2, "B", 25, 0x31),
        "axes-9": cwa_with(changed(ax3, {35: 0x11}), 2, "B", 25, 0x92),
        "other-format-later": cwa_with(ax3, 9, "B", 25, 0x32),
        "length-huge": changed(ax3, {2: 0xFF, 3: 0xFF}),
        "zero-block": ax3[:512 * 20] + bytes(512) + ax3[512 * 21:],
        "zero-last-block": ax3[:-512] + bytes(512),
        "block-repeated": ax3[:512 * 12] + ax3[512 * 11:],
        "blocks-swapped": ax3[:512 * 10] + ax3[512 * 11:512 * 12] + ax3[512 * 10:512 * 11]
        + ax3[512 * 12:],
        "zeros": bytes(len(ax3)),
        "md-then-junk": b"MD" + bytes(2) + os.urandom(4000),
        "text": b"not an Axivity file\n" * 200,
    }
    for name, data in crafted.items():
        cases |= write(d, f"{name}.cwa", data)
    return cases


@needs_skdh
@pytest.mark.slow
def test_cwa_corpus_reads_or_refuses(cwa_corpus):
    """Before: a block numbered past the file's end was a SIGSEGV in skdh's reader (the test
    process died); a negative number wrote before its array without a word."""
    out = run_corpus("wearable", cwa_corpus, timeout=150)
    assert out["seq-past-end"] == out["seq-negative"] == "refused"
    assert out["ax3-cut1536"] == out["ax3-cut7000"] == out["zero-block"] == "ok"
    assert out["zeros"] == out["text"] == out["md-then-junk"] == "refused"


@needs_skdh
def test_cwa_checks_name_the_damage(realdata, tmp_path):
    from triaxcal.io.wearables import check_cwa, read_wearable

    ax3 = (realdata / WEAR / "ax3_testfile.cwa").read_bytes()
    info = check_cwa(realdata / WEAR / "ax3_testfile.cwa")
    assert info == {"device_id": info["device_id"], "axes": 3, "count": 120, "blocks": 145,
                    "bad_blocks": 0}
    p = tmp_path / "x.cwa"
    for data, words in [
        (cwa_with(ax3, 5, "<I", 10, 10**6), "block 5 says it is number 1000000 of a file of "
                                             "145 blocks"),
        (cwa_with(ax3, 2, "<H", 28, 0), "0 samples of 3 axes"),
        (changed(ax3, {0: ord("X")}), "does not start with the 'MD' header"),
        (ax3[:1500], "too short"),
        (ax3[:-512] + bytes(512), "its last block is one of them"),
        (cwa_with(ax3, 9, "B", 25, 0x32), "block 9 holds another sample format"),
    ]:
        p.write_bytes(data)
        with pytest.raises(tc.CalibrationError, match="not a readable Axivity .cwa file") as e:
            read_wearable(p)
        assert words in str(e.value)
    # a damaged block in the middle is skipped by skdh, as it always was
    p.write_bytes(ax3[:512 * 20] + bytes(512) + ax3[512 * 21:])
    rec = read_wearable(p)
    assert rec.meta["bad_blocks"] == 1 and len(rec) == 145 * 120
    assert np.array_equal(rec.acc_g[:18 * 120], read_wearable(realdata / WEAR /
                                                               "ax3_testfile.cwa").acc_g[:18 * 120])


@needs_skdh
def test_a_crash_of_the_native_reader_is_a_calibration_error(realdata, tmp_path, monkeypatch,
                                                             capfd):
    """Isolation, with the structure check switched off: the block numbered past the end
    crashes skdh's reader in its child process, and that is a CalibrationError here. Nothing
    the reader prints reaches this process's output."""
    from triaxcal.io import wearables

    p = tmp_path / "crash.cwa"
    p.write_bytes(cwa_with((realdata / WEAR / "ax3_testfile.cwa").read_bytes(), 5, "<I", 10,
                           10**6))
    monkeypatch.setattr(wearables, "check_cwa", lambda path, size=None: {
        "device_id": 0, "axes": 3, "count": 120, "blocks": 0, "bad_blocks": 0})
    with pytest.raises(tc.CalibrationError, match=r"looks damaged.*crashed on it \(SIG"):
        wearables.read_wearable(p)
    # skdh prints "WARNING: 1 bad blocks" to standard output (C's stdout) for a bad block
    data = bytearray((realdata / WEAR / "ax3_testfile.cwa").read_bytes())
    data[512 * 20 + 100] ^= 0xFF
    p.write_bytes(bytes(data))
    monkeypatch.undo()
    rec = wearables.read_wearable(p)
    assert rec.meta["bad_blocks"] == 1
    assert any("bad blocks" in w for w in rec.meta["warnings"])
    out, err = capfd.readouterr()
    assert "bad blocks" not in out and "bad blocks" not in err


# --------------------------------------------------------------------------------------------
# GENEActiv .bin


@pytest.fixture(scope="module")
def bin_corpus(realdata, tmp_path_factory):
    d = tmp_path_factory.mktemp("bin")
    whole = geneactiv_whole(realdata)
    cut = (realdata / WEAR / "GENEActiv_testfile.bin").read_bytes()
    head = whole.index(b"Recorded Data")
    cases = {}
    cases |= cuts(whole, [0, 1, 15, 16, 17, 300, head - 1, head, head + 20, head + 3700,
                          len(whole) - 3, len(whole) - 1], "whole", d, ".bin", n_random=4)
    cases |= cuts(cut, [2000, 40000], "cut", d, ".bin", n_random=2)
    lines = {
        "no-calibration-data": (b"Calibration Data", b"Calibration Dat4"),  # before: a hang
        "no-colon-line-20": (b"Measurement Frequency:85.7 Hz", b"Measurement Frequency 85.7"),
        "no-colon-gain": (b"x gain:25875", b"x gain 25875"),
        "gain-zero": (b"x gain:25875", b"x gain:0"),
        "gain-tiny": (b"x gain:25875", b"x gain:1e-320"),
        "gain-huge": (b"x gain:25875", b"x gain:1e308"),
        "gain-nan": (b"x gain:25875", b"x gain:nan"),
        "offset-inf": (b"z offset:-3056", b"z offset:inf"),
        "pages-zero": (b"Number of Pages:16", b"Number of Pages:0"),
        "pages-negative": (b"Number of Pages:16", b"Number of Pages:-5"),
        "pages-huge": (b"Number of Pages:16", b"Number of Pages:99999999999"),
        "pages-float": (b"Number of Pages:16", b"Number of Pages:1e308"),
        "seq-past-end": (b"Sequence Number:3\r", b"Sequence Number:9999999\r"),  # SIGSEGV
        "seq-negative": (b"Sequence Number:3\r", b"Sequence Number:-99999\r"),
        "seq-empty": (b"Sequence Number:3\r", b"Sequence Number:\r"),
        "temp-nan": (b"Temperature:21.5", b"Temperature:nan"),
        "temp-huge": (b"Temperature:21.5", b"Temperature:1e308"),
        "rate-zero": (b"Measurement Frequency:85.7\r", b"Measurement Frequency:0\r"),
        "rate-inf": (b"Measurement Frequency:85.7\r", b"Measurement Frequency:inf\r"),
        "rate-negative-zero": (b"Measurement Frequency:85.7\r", b"Measurement Frequency:-0\r"),
        "page-time": (b"Page Time:2013-05-30 10:12:54:500", b"Page Time:2013-5-3 1:1:1:1"),
        "lf-only": (b"\r\n", b"\n"),
        "nul-in-data": (b"0C4FFDF3D004", b"0C4\x00FDF3D004"),
        "not-hex": (b"0C4FFDF3D004", b"0C4FFDF3DZZZ"),
        "identity": (b"Device Identity", b"Device Identit\xff"),
    }
    for name, (a, b) in lines.items():
        cases |= write(d, f"{name}.bin", whole.replace(a, b, 1 if name != "lf-only" else -1))
    long_line = whole.replace(b"Unassigned:", b"Unassigned:" + b"u" * 5000, 1)
    cases |= write(d, "long-page-line.bin", long_line)
    cases |= write(d, "bom.bin", b"\xef\xbb\xbf" + whole)
    cases |= write(d, "doubled-page.bin", whole + whole[head:head + 3700])
    cases |= write(d, "zeros.bin", bytes(20000))
    cases |= write(d, "header-only.bin", whole[:head])
    return cases


@needs_skdh
def test_geneactiv_corpus_reads_or_refuses(bin_corpus):
    """Before: no 'Calibration Data' line made skdh's reader loop for ever; no ':' on line 20,
    or a page numbered past the header's count, was a SIGSEGV."""
    out = run_corpus("wearable", bin_corpus, timeout=150)
    assert out["no-calibration-data"] == out["seq-past-end"] == out["no-colon-line-20"] == "ok"
    assert out["zeros"] == out["gain-zero"] == out["gain-nan"] == "refused"


@needs_skdh
def test_geneactiv_mutations_read_the_right_samples(realdata, tmp_path):
    """The pristine whole file goes to skdh (in its child process) and the page decoder gives
    the same samples; a file laid out otherwise goes to the page decoder, with the reason."""
    from triaxcal.io.wearables import (
        read_geneactiv_pages,
        read_wearable,
        skdh_geneactiv_problem,
    )

    whole = geneactiv_whole(realdata)
    p = tmp_path / "whole.bin"
    p.write_bytes(whole)
    assert skdh_geneactiv_problem(p) is None
    rec = read_wearable(p)
    assert rec.reader == "scikit-digital-health ReadBin" and rec.acc_g.shape == (4800, 3)
    counts, temp, rate, pages = read_geneactiv_pages(p)
    assert pages == 16 and rate == 85.7
    assert np.allclose(rec.factory.apply(counts.astype(float)), rec.acc_g, rtol=0, atol=1e-12)
    assert np.array_equal(temp, rec.temp_c)
    for a, b, why in [
        (b"Calibration Data", b"Calibration Dat4", "no 'Calibration Data' line"),
        (b"Sequence Number:3\r", b"Sequence Number:9999999\r", "page 3 is numbered 9999999"),
        (b"Measurement Frequency:85.7 Hz", b"Measurement Frequency 85", "line 20"),
        (b"Number of Pages:16", b"Number of Pages:99999", "holds at most"),
        # before: skdh read 0 samples without a word, and 1 page of "1e308"
        (b"Number of Pages:16", b"Number of Pages:0", "holds at most"),
        (b"Number of Pages:16", b"Number of Pages:1e308", "is not 'Number of Pages:N'"),
    ]:
        q = tmp_path / "m.bin"
        q.write_bytes(whole.replace(a, b, 1))
        assert why in skdh_geneactiv_problem(q)
        got = read_wearable(q)
        assert got.reader.endswith("page decoder") and why in got.meta["skdh_refused"]
        assert got.meta["pages"] == 16 and got.meta["pages_left_out"] is None
        assert np.allclose(got.acc_g, rec.acc_g, rtol=0, atol=1e-12)  # the same samples


@needs_skdh
@pytest.mark.parametrize("a,b,words", [
    (b"Measurement Frequency:85.7\r", b"Measurement Frequency:0\r", "'0' is not a rate"),
    (b"Measurement Frequency:85.7\r", b"Measurement Frequency:inf\r", "'inf' is not a rate"),
    (b"Temperature:21.5", b"Temperature:nan", "'nan' is not a temperature"),
    (b"Temperature:21.5", b"Temperature:1e308", "'1e308' is not a temperature"),
])
def test_geneactiv_pages_with_impossible_values_are_not_read(realdata, tmp_path, a, b, words):
    """Before: skdh read a rate of 0 or inf Hz, or a NaN temperature, without a word."""
    from triaxcal.io.wearables import read_wearable

    q = tmp_path / "m.bin"
    q.write_bytes(geneactiv_whole(realdata).replace(a, b, 1))  # page 0 only
    with pytest.raises(tc.CalibrationError, match=f"no complete data page \\(page 0: .*{words}"):
        read_wearable(q)
    parts = geneactiv_whole(realdata).split(b"Recorded Data")  # the header, then the pages
    page5 = parts[6].split(b"\r\n")
    page5[5] = b"Temperature:nan"
    parts[6] = b"\r\n".join(page5)
    q.write_bytes(b"Recorded Data".join(parts))
    rec = read_wearable(q)
    assert rec.meta["pages"] == 5 and "page 5: Temperature 'nan'" in rec.meta["pages_left_out"]


@needs_skdh
@pytest.mark.timeout(120)
def test_a_hang_of_the_native_reader_is_ended(realdata, tmp_path, monkeypatch):
    """Isolation, with the layout check switched off: skdh's reader loops for ever on a header
    without 'Calibration Data'; it is killed after the time limit and the file is decoded page
    by page instead."""
    from triaxcal.io import isolate, wearables

    p = tmp_path / "hang.bin"
    p.write_bytes(geneactiv_whole(realdata).replace(b"Calibration Data", b"Calibration Dat4"))
    monkeypatch.setattr(wearables, "skdh_geneactiv_problem", lambda path, size=None: None)
    monkeypatch.setattr(isolate, "TIMEOUT_S", 3.0)
    monkeypatch.setattr(isolate, "TIMEOUT_S_PER_MB", 0.0)
    rec = wearables.read_wearable(p)
    assert "did not finish within 3 s" in rec.meta["skdh_refused"]
    assert rec.reader.endswith("page decoder") and rec.acc_g.shape == (4800, 3)


# --------------------------------------------------------------------------------------------
# ActiGraph .gt3x


@pytest.fixture(scope="module")
def gt3x_corpus(realdata, tmp_path_factory):
    d = tmp_path_factory.mktemp("gt3x")
    raw = (realdata / WEAR / "actigraph_testfile.gt3x").read_bytes()
    with zipfile.ZipFile(realdata / WEAR / "actigraph_testfile.gt3x") as z:
        info, log = z.read("info.txt"), z.read("log.bin")
    cases = {}
    cases |= cuts(raw, [0, 4, 30, 100, 1000, len(raw) // 2, len(raw) - 22, len(raw) - 1],
                  "gt3x", d, ".gt3x", n_random=3)
    cases |= flips(raw, [0, 1, 2, 3, 8, 18, 22, 26, 30, 40, 100, 200, len(raw) - 20], "gt3x", d,
                   ".gt3x")
    for name, entries in {
        "bomb": {"info.txt": info, "log.bin": bytes(100 << 20)},
        "no-log": {"info.txt": info},
        "no-info": {"log.bin": log},
        "many": {"info.txt": info, "log.bin": log, **{f"x{i}": b"" for i in range(100)}},
        "log-zeros": {"info.txt": info, "log.bin": bytes(len(log))},
        "log-cut": {"info.txt": info, "log.bin": log[:len(log) // 3]},
        "info-junk": {"info.txt": b"\x1b[2J\xff\xfe" * 100, "log.bin": log},
        "info-edges": {"info.txt": info.replace(b"Sample Rate: 30", b"Sample Rate: 1e308"),
                       "log.bin": log},
    }.items():
        cases[name] = zip_of(d / f"{name}.gt3x", entries)
    return cases


def test_gt3x_corpus_reads_or_refuses(gt3x_corpus):
    pytest.importorskip("pygt3x")
    out = run_corpus("wearable", gt3x_corpus, timeout=150)
    assert out["bomb"] == out["no-log"] == out["many"] == "refused"


def test_a_gt3x_zip_bomb_is_refused_unopened(tmp_path, realdata, capsys):
    """100 MiB of zeros in a 100 kB zip: refused from the zip's directory. And pygt3x's
    complaints about damaged events do not reach the terminal (before: one line each, on
    standard error) but the recording's warnings, bounded."""
    pytest.importorskip("pygt3x")
    from triaxcal.io.wearables import read_wearable

    with zipfile.ZipFile(realdata / WEAR / "actigraph_testfile.gt3x") as z:
        info, log = z.read("info.txt"), z.read("log.bin")
    import pygt3x.reader  # noqa: F401 - imported before the memory is traced

    p = zip_of(tmp_path / "bomb.gt3x", {"info.txt": info, "log.bin": bytes(100 << 20)})
    assert p.stat().st_size < 1 << 20
    tracemalloc.start()
    try:
        with pytest.raises(tc.CalibrationError, match=r"would unpack to 105 MB"):
            read_wearable(p)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 16 << 20
    bad = bytearray(log)
    for k in range(40, len(bad), 997):
        bad[k] ^= 0x55
    q = zip_of(tmp_path / "damaged.gt3x", {"info.txt": info, "log.bin": bytes(bad)})
    try:
        rec = read_wearable(q)
    except tc.CalibrationError:
        rec = None
    out, err = capsys.readouterr()
    assert "checksum" not in out + err, (out + err)[:300]
    if rec is not None:
        assert any("checksum" in w for w in rec.meta["warnings"])
        assert len(rec.meta["warnings"]) < 20  # the first few, and how many more


# --------------------------------------------------------------------------------------------
# the structure check alone, on many random mutations (in this process: it is Python)


@settings(max_examples=60, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(edits=st.lists(st.tuples(st.integers(0, 7 * 512 - 1), st.integers(0, 255)), min_size=1,
                      max_size=6),
       fix=st.booleans(), keep=st.integers(2, 7))
def test_check_cwa_never_lets_an_unsafe_block_through(realdata, tmp_path, edits, fix, keep):
    """Bytes of the header and the first blocks changed (checksums made good again or not):
    check_cwa refuses, or every block skdh would take is numbered inside the file."""
    from triaxcal.io.wearables import check_cwa

    b = bytearray((realdata / WEAR / "ax3_testfile.cwa").read_bytes()[:512 * keep])
    for at, value in edits:
        if at < len(b):
            b[at] = value
    if fix:
        for k in range(2, keep):
            cwa_fix_checksum(b, k)
    p = tmp_path / "m.cwa"
    p.write_bytes(bytes(b))
    try:
        info = check_cwa(p)
    except tc.CalibrationError as exc:
        assert "Axivity" in str(exc)
        return
    blocks = np.frombuffer(bytes(b[1024:]), np.uint8).reshape(-1, 512)
    w = blocks.view("<u2")
    good = (w[:, 0] == 0x5841) & (w[:, 1] == 508) & (w.astype(np.int64).sum(1) % 65536 == 0)
    seq = blocks[:, 10:14].copy().view("<i4").ravel()
    assert np.all((seq[good] >= 0) & (seq[good] < info["blocks"]))
    assert b[:2] == b"MD" and info["axes"] == 3
