"""triaxcal.io.tables: reading tables of numbers from hostile files."""

from __future__ import annotations

import hashlib
import time
import tracemalloc

import numpy as np
import pytest
import triaxcal as tc
from triaxcal.io.tables import (
    MAX_COLUMNS,
    MAX_LINE_BYTES,
    BadLine,
    pick_columns,
    read_table,
)


def _w(tmp_path, text, name="t.csv"):
    p = tmp_path / name
    p.write_bytes(text.encode() if isinstance(text, str) else text)
    return p


def test_header_delimiter_and_hash(tmp_path):
    p = _w(tmp_path, "t;ax;ay;az\r\n0.0;1;2;3\r\n# a comment\r\n\r\n0.1;4;5;6\r\n")
    t = read_table(p)
    assert t.names == ("t", "ax", "ay", "az")
    np.testing.assert_array_equal(t.data, [[0, 1, 2, 3], [0.1, 4, 5, 6]])
    assert t.sha256 == hashlib.sha256(p.read_bytes()).hexdigest()
    assert t.skipped == 0 and t.notes == ()
    t = read_table(_w(tmp_path, "1 2 3\n4 5 6\n", "ws.txt"))
    assert t.names is None and t.data.shape == (2, 3)


def test_a_junk_first_line_is_reported_as_line_1(tmp_path):
    """Before: 'line 2: 3 values, expected 1' -- the junk line was taken for a header."""
    p = _w(tmp_path, "garbage from a serial monitor\n1,2,3\n4,5,6\n")
    with pytest.raises(tc.CalibrationError, match=r"line 1: not numbers, and not a header"):
        read_table(p)
    t = read_table(p, skip_bad_lines=True)
    assert t.names is None and t.data.shape == (2, 3) and t.skipped == 1
    assert t.bad_lines[0].line == 1 and "skipped 1 bad line" in t.notes[0]


def test_junk_before_the_header_and_after_it(tmp_path):
    p = _w(tmp_path, "sep=,\nt,ax,ay,az\n0,1,2,3\n")
    with pytest.raises(tc.CalibrationError, match="line 1:"):
        read_table(p)
    t = read_table(p, skip_bad_lines=True)
    assert t.names == ("t", "ax", "ay", "az") and t.data.shape == (1, 4)
    p = _w(tmp_path, "t,ax,ay,az\nERROR sensor reset\n0,1,2,3\n1,2,3,4\n")
    with pytest.raises(tc.CalibrationError, match="line 2:"):
        read_table(p)
    assert read_table(p, skip_bad_lines=True).names == ("t", "ax", "ay", "az")


@pytest.mark.parametrize("bad,lineno,why", [
    ("4,5\n", 3, "2 values, expected 3"),
    ("x,5,6\n", 3, "not all numbers"),
    ("1_000,5,6\n", 3, "not all numbers"),
    ("\u0661,5,6\n", 3, "not all numbers"),  # an Arabic-Indic digit, which float() reads
    ("1,2,3,4\n", 3, "4 values, expected 3"),
])
def test_bad_lines_name_their_number_and_can_be_skipped(tmp_path, bad, lineno, why):
    p = _w(tmp_path, "x,y,z\n1,2,3\n" + bad + "7,8,9\n")
    with pytest.raises(tc.CalibrationError) as exc:
        read_table(p)
    assert f"line {lineno}: {why}" in str(exc.value) and "--skip-bad-lines" in str(exc.value)
    t = read_table(p, skip_bad_lines=True)
    np.testing.assert_array_equal(t.data, [[1, 2, 3], [7, 8, 9]])
    assert t.skipped == 1 and t.bad_lines == (BadLine(lineno, why, t.bad_lines[0].text),)


def test_bad_lines_are_found_inside_large_files(tmp_path):
    """Rows are parsed in chunks by numpy; a chunk with a bad line is parsed line by line,
    so the line number is still exact."""
    rows = [f"{i},{i + 1},{i + 2}" for i in range(50_000)]
    rows[31_337] = "1,2"
    rows[40_000] = "# comment"
    p = _w(tmp_path, "a,b,c\n" + "\n".join(rows) + "\n")
    with pytest.raises(tc.CalibrationError, match="line 31339: 2 values"):
        read_table(p)
    t = read_table(p, skip_bad_lines=True)
    assert t.data.shape == (49_998, 3) and t.skipped == 1
    np.testing.assert_array_equal(t.data[31_337], [31_338, 31_339, 31_340])


def test_a_row_cut_by_a_full_disk_is_skipped_with_a_note(tmp_path):
    """The half-written last row of a capture does not make the file unreadable."""
    p = _w(tmp_path, "t,ax,ay,az\n0.0,1,2,3\n0.1,4,5,6\n0.2,7,8")
    t = read_table(p)
    assert t.data.shape == (2, 4) and t.skipped == 1
    assert "line 4, the last, is cut short" in t.notes[0]
    # a capture row is always written with its line break: a last row without one was cut,
    # even if what is left happens to parse ("-3933" cut to "-39")
    p = _w(tmp_path, "t,ax,ay,az\n0.0,1,2,3\n0.1,4,5,-39")
    t = read_table(p)
    assert t.data.shape == (1, 4) and "cut short" in t.notes[0]
    # a plain table without a final line break keeps its last row
    assert read_table(_w(tmp_path, "1,2,3\n4,5,6", "plain.csv")).data.shape == (2, 3)


def test_a_folder_a_device_and_a_missing_file(tmp_path):
    (tmp_path / "session.csv").write_text("1,2,3\n")
    with pytest.raises(tc.CalibrationError, match=r"is a folder.*it holds session.csv"):
        read_table(tmp_path)
    with pytest.raises(tc.CalibrationError, match="is a character device, not a regular file"):
        read_table("/dev/zero")
    with pytest.raises(tc.CalibrationError, match="not found"):
        read_table(tmp_path / "nope.csv")


def test_a_million_columns_fail_fast_with_a_short_message(tmp_path):
    """Before: every column name was printed (8.9 MB of stderr)."""
    n = 1_000_000
    p = _w(tmp_path, ",".join(f"c{i}" for i in range(n)) + "\n" + ",".join("1" * n) + "\n")
    with pytest.raises(tc.CalibrationError) as exc:
        read_table(p)
    assert len(str(exc.value)) < 400 and "line 1" in str(exc.value)
    p = _w(tmp_path, ",".join(["1"] * (MAX_COLUMNS + 1)) + "\n", "wide.csv")
    with pytest.raises(tc.CalibrationError, match=f"{MAX_COLUMNS + 1} columns"):
        read_table(p)
    # column names in messages are bounded too
    names = [f"channel_{i}" for i in range(1000)]
    p = _w(tmp_path, ",".join(names) + "\n" + ",".join(["1"] * 1000) + "\n", "many.csv")
    t = read_table(p)
    with pytest.raises(tc.CalibrationError) as exc:
        pick_columns(t, None, "accel")
    assert len(str(exc.value)) < 500 and "(1000 columns)" in str(exc.value)


def test_a_100_mb_line_fails_fast_in_bounded_memory(tmp_path):
    """Before: 25 s and 1.2 GB before failing."""
    p = tmp_path / "long.csv"
    with open(p, "wb") as f:
        f.write(b"1" * 100_000_000 + b"\n1,2,3\n4,5,6\n")
    tracemalloc.start()
    t0 = time.perf_counter()
    with pytest.raises(tc.CalibrationError, match=f"line 1: more than {MAX_LINE_BYTES} bytes"):
        read_table(p)
    elapsed = time.perf_counter() - t0
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 64e6, peak  # a few read buffers, not the line
    assert elapsed < 10, elapsed  # stops after the first block, not the whole line
    tracemalloc.start()
    t = read_table(p, skip_bad_lines=True)  # passes over the line in bounded chunks
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert t.data.shape == (2, 3) and t.bad_lines[0].line == 1 and peak < 64e6
    assert t.sha256 == hashlib.sha256(p.read_bytes()).hexdigest()


def test_header_only_and_empty_files(tmp_path):
    with pytest.raises(tc.CalibrationError, match="no rows of numbers"):
        read_table(_w(tmp_path, "t,ax,ay,az\n"))
    with pytest.raises(tc.CalibrationError, match="no rows of numbers"):
        read_table(_w(tmp_path, "", "empty.csv"))
    t = read_table(_w(tmp_path, "t,ax,ay,az\n", "h.csv"), allow_empty=True)
    assert t.names == ("t", "ax", "ay", "az") and t.data.shape == (0, 4)


def test_non_utf8_bytes_are_bad_lines_not_crashes(tmp_path):
    p = _w(tmp_path, b"x,y,z\n1,2,3\n\xff\xfe,\x00,3\n4,5,6\n")
    with pytest.raises(tc.CalibrationError, match="line 3: not all numbers"):
        read_table(p)
    assert read_table(p, skip_bad_lines=True).data.shape == (2, 3)


def test_fuzzed_tables_give_a_table_or_a_calibration_error(tmp_path):
    rng = np.random.default_rng(1)
    base = b"t,ax,ay,az\n" + b"".join(
        b"%d.%02d,%d,%d,%d\n" % (i, i % 100, i, -i, 2 * i) for i in range(200))
    for k in range(200):
        b = bytearray(base)
        for i in rng.integers(0, len(b), size=int(rng.integers(1, 6))):
            b[i] = int(rng.integers(0, 256))
        p = _w(tmp_path, bytes(b), f"f{k % 3}.csv")
        for skip in (False, True):
            try:
                t = read_table(p, skip_bad_lines=skip)
            except tc.CalibrationError:
                continue
            assert t.data.ndim == 2 and np.isfinite(t.data).any()
