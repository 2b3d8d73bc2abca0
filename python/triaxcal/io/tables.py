"""Tables of numbers from files: capture sessions and any numeric CSV or text table.

:func:`read_table` reads comma, semicolon, tab or space separated numbers, with or without a
header row (both detected), and treats the file as hostile: the file is read line by line
with a bounded line length (a 100 MB line fails after the first MiB, in constant memory),
the number of columns is bounded, every failure names the right line and says what to do,
and nothing of unbounded size is ever put into a message.

What it does with lines that are not a row of the table:

* blank lines and lines starting with ``#`` are comments;
* a last line cut short (a capture stopped by a full disk, a crash or a power cut: the file
  ends without a line break in a row that is incomplete, or anywhere in a row of a capture
  session, whose rows always end with one) is skipped, with a note;
* any other bad line -- wrong number of values, text, an overlong line -- is an error naming
  its line number, or, with ``skip_bad_lines=True`` (``--skip-bad-lines``), is skipped and
  counted.

:func:`iter_table` reads the same table in blocks of rows, in memory bounded by one block
(recordings of any length); :func:`iter_csv` reads the records of a CSV file of text (an id
column) with the same bounds. All three read only a regular file
(:func:`triaxcal.io.files.open_regular`: a pipe, a device or a socket is refused at once).
:func:`pick_columns` chooses the three columns of one sensor by name or index.
"""

from __future__ import annotations

import csv
import hashlib
import io
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO, Iterator

import numpy as np

from .._checks import options
from .._checks.spelling import opt
from ..errors import CalibrationError
from .files import open_regular, os_error_message

__all__ = [
    "MAX_COLUMNS",
    "MAX_LINE_BYTES",
    "MAX_VALUES",
    "SENSOR_COLUMNS",
    "BadLine",
    "Table",
    "iter_csv",
    "iter_table",
    "pick_columns",
    "read_table",
]

#: Longest line read, in bytes (a row of 4096 numbers fits; a line of 100 MB fails fast).
MAX_LINE_BYTES = 1 << 20
#: Most columns a table may have.
MAX_COLUMNS = 4096
#: Most values (rows x columns) :func:`read_table` holds in memory: 2 GiB of float64. A longer
#: recording is read in blocks by :func:`iter_table`.
MAX_VALUES = 1 << 28
#: Default column names per sensor (the device channel order, ``ax ay az gx gy gz mx my mz``).
SENSOR_COLUMNS = {"accel": ("ax", "ay", "az"), "gyro": ("gx", "gy", "gz"),
                  "mag": ("mx", "my", "mz")}

# Non-numeric lines looked at before the first row of numbers (header and preamble).
_LOOKAHEAD = 50
# Bad lines remembered one by one (all of them are counted).
_KEEP_BAD = 20
_DELIMITERS = (",", ";", "\t", None)


@dataclass(frozen=True)
class BadLine:
    """A line that is not a row of the table: its 1-based ``line`` number in the file, the
    ``reason`` and the start of its ``text`` (at most 60 characters)."""

    line: int
    reason: str
    text: str

    def __str__(self) -> str:
        return f"line {self.line}: {self.reason}" + (f" ({self.text!r})" if self.text else "")


@dataclass(frozen=True)
class Table:
    """A numeric table read by :func:`read_table`.

    Attributes
    ----------
    names : tuple of str or None
        Column names from the header row (None without one).
    data : ndarray, shape (N, K)
        The rows, float64.
    path : Path
        The file.
    sha256 : str
        SHA-256 of the file's bytes (``sha256sum FILE`` gives the same).
    skipped : int
        Lines skipped as not rows of the table (bad lines with ``skip_bad_lines``, and a cut
        last line), comments and blank lines not included.
    bad_lines : tuple of BadLine
        The first of those lines, with the reason.
    notes : tuple of str
        What a person should know about the reading (skipped lines), in words.
    """

    names: tuple[str, ...] | None
    data: np.ndarray
    path: Path
    sha256: str
    skipped: int = 0
    bad_lines: tuple[BadLine, ...] = ()
    notes: tuple[str, ...] = ()


def _excerpt(text: str) -> str:
    return text if len(text) <= 60 else text[:57] + "..."


def _is_number(tok: str) -> bool:
    try:
        float(tok)
    except ValueError:
        return False
    return True


def _plain(line: str) -> bool:
    """ASCII without ``_`` (Python's float() also reads ``1_000`` and non-ASCII digits)."""
    return line.isascii() and "_" not in line


def _split(line: str, delim: str | None) -> list[str]:
    if delim is None:
        return line.split()
    return [t.strip() for t in line.split(delim)]


def _numeric_split(line: str) -> tuple[str | None, int] | None:
    """(delimiter, field count) under which ``line`` is all numbers, or None."""
    for d in _DELIMITERS:
        if d is not None and d not in line:
            continue
        toks = _split(line, d)
        if toks and all(_is_number(t) for t in toks):
            return d, len(toks)
    return None


def _events(
    f: BinaryIO, hasher: Any, max_line: int, block: int = 1 << 22
) -> Iterator[tuple[str, int, Any]]:
    """The file as events, reading ``block`` bytes at a time (memory stays bounded):

    * ``("lines", n, [bytes, ...])``: complete lines (without the line break), the first of
      them line ``n``;
    * ``("long", n, None)``: line ``n`` is longer than ``max_line`` bytes (reported as soon
      as seen; the rest of it is passed over);
    * ``("last", n, bytes)``: line ``n``, the last, has no line break.
    """
    lineno = 0
    carry = b""
    skipping = False
    while True:
        data = f.read(block)
        if not data:
            break
        hasher.update(data)
        if skipping:
            i = data.find(b"\n")
            if i < 0:
                continue
            skipping = False
            data = data[i + 1:]
        parts = (carry + data).split(b"\n")
        carry = parts.pop()
        start = 0
        for k, line in enumerate(parts):
            if len(line) > max_line:
                if k > start:
                    yield "lines", lineno + 1, parts[start:k]
                    lineno += k - start
                lineno += 1
                yield "long", lineno, None
                start = k + 1
        if start < len(parts):
            yield "lines", lineno + 1, parts[start:]
            lineno += len(parts) - start
        if len(carry) > max_line:
            lineno += 1
            yield "long", lineno, None
            carry = b""
            skipping = True
    if carry and not skipping:
        yield "last", lineno + 1, carry


# Lines parsed at once by numpy's C parser (a chunk with a bad line is parsed line by line).
_CHUNK = 8192


def _fast(lines: list[bytes], delim: str | None, width: int) -> np.ndarray | None:
    """Rows of ``lines`` parsed by numpy, or None when any line needs a closer look."""
    blob = b"\n".join(lines)
    if not blob.isascii() or b"_" in blob:
        return None
    if b"\r" in blob:
        blob = blob.replace(b"\r", b"")
    try:
        arr = np.loadtxt(io.StringIO(blob.decode("ascii")), delimiter=delim, comments="#",
                         ndmin=2, dtype=np.float64)
    except ValueError:
        return None
    if arr.size == 0:
        return np.zeros((0, width))
    return arr if arr.shape[1] == width else None


def _open(p: Path, what: str = "data file") -> BinaryIO:
    """``p`` opened by :func:`~triaxcal.io.files.open_regular` (a regular file only: a pipe,
    a device or a socket is refused without blocking); a folder names the tables inside."""
    if p.is_dir():
        try:
            inside = sorted(q.name for q in p.iterdir() if q.suffix.lower() in (".csv", ".txt"))
        except OSError:
            inside = []
        hint = (f" (it holds {', '.join(inside[:5])}{', ...' if len(inside) > 5 else ''})"
                if inside else "")
        raise CalibrationError(
            f"{p} is a folder, not a {what}: give the file inside it{hint}"
        )
    return open_regular(p, what=what)


class _Reader:
    """One reading of a table: the header, the delimiter, the bad lines and the notes, and
    :meth:`blocks`, the rows in blocks (see :func:`read_table` for the rules)."""

    def __init__(self, p: Path, *, skip_bad_lines: bool, max_columns: int,
                 max_line_bytes: int) -> None:
        self.p = p
        self.skip_bad_lines = skip_bad_lines
        self.max_columns = max_columns
        self.max_line_bytes = max_line_bytes
        self.hasher = hashlib.sha256()
        self.bad: list[BadLine] = []
        self.n_bad = 0
        self.notes: list[str] = []
        self.names: tuple[str, ...] | None = None
        self.delim: str | None = None
        self.width: int | None = None
        self.pending: list[tuple[int, str]] = []  # non-numeric lines before the first row
        self.rows: list[list[float]] = []  # rows parsed one by one, not yet in a block
        self.last_bad: BadLine | None = None  # a bad line that may be the cut last one

    def fail_or_skip(self, b: BadLine, *, last_candidate: bool = False) -> None:
        if last_candidate:
            self.last_bad = b  # only the last line can lack its line break
            return
        if not self.skip_bad_lines:
            raise CalibrationError(
                f"{self.p}, {b}; fix or remove that line, or skip such lines (--skip-bad-lines)"
            )
        self.n_bad += 1
        if len(self.bad) < _KEEP_BAD:
            self.bad.append(b)

    def settle_last(self) -> None:
        if self.last_bad is not None:
            b, self.last_bad = self.last_bad, None
            self.notes.append(
                f"line {b.line}, the last, is cut short and was skipped (the file ends in "
                "the middle of a row, as when a capture is stopped by a full disk or a "
                f"crash): {b.reason}"
            )

    def too_wide(self, lineno: int, fields: int) -> CalibrationError:
        return CalibrationError(
            f"{self.p}, line {lineno}: {fields} columns; triaxcal reads tables of at most "
            f"{self.max_columns} columns: is this the right file?"
        )

    def start_table(self, d: str | None, w: int) -> None:
        self.delim, self.width = d, w
        pending = self.pending
        header_at = next((i for i, (_, s) in enumerate(pending) if len(_split(s, d)) == w), None)
        if header_at is not None:
            self.names = tuple(t.strip().strip('"').strip("'")
                               for t in _split(pending[header_at][1], d))
        for i, (ln, s) in enumerate(pending):
            if i == header_at:
                continue
            k = len(_split(s, d))
            self.fail_or_skip(BadLine(ln, f"not numbers, and not a header of the {w} columns "
                                          f"of the rows below ({k} values)", _excerpt(s)))
        pending.clear()

    def take_line(self, lineno: int, raw: bytes, terminated: bool) -> None:
        line = raw.decode("utf-8", errors="replace").strip()
        if not line or line.startswith("#"):
            return
        if self.width is None:
            nsplit = _numeric_split(line) if _plain(line) else None
            if nsplit is None:
                fields = max(line.count(d) for d in (",", ";", "\t")) + 1
                if fields > self.max_columns:
                    raise self.too_wide(lineno, fields)
                self.pending.append((lineno, line))
                if len(self.pending) > _LOOKAHEAD:
                    first = self.pending.pop(0)
                    self.fail_or_skip(BadLine(first[0], "not all numbers, and no row of "
                                              "numbers follows it", _excerpt(first[1])))
                return
            d, w = nsplit
            if w > self.max_columns:
                raise self.too_wide(lineno, w)
            self.start_table(d, w)
        width, delim = self.width, self.delim
        assert width is not None
        if delim is not None and line.count(delim) + 1 > self.max_columns:
            toks = None
            reason = f"{line.count(delim) + 1} values, expected {width}"
        else:
            toks = _split(line, delim)
            reason = f"{len(toks)} values, expected {width}"
        if toks is not None and len(toks) == width:
            try:
                if not _plain(line):
                    raise ValueError
                row = [float(t) for t in toks]
            except ValueError:
                reason = "not all numbers"
            else:
                if terminated or self.names is None or self.names[0] != "t":
                    self.rows.append(row)
                    return
                reason = "a capture row without its line break"
        self.fail_or_skip(BadLine(lineno, reason, _excerpt(line)),
                          last_candidate=not terminated)

    def _settle_rows(self, out: list[np.ndarray]) -> None:
        if self.rows:
            assert self.width is not None
            out.append(np.array(self.rows, dtype=np.float64).reshape(-1, self.width))
            self.rows.clear()

    def blocks(self, rows: int | None, max_values: int | None = None) -> Iterator[np.ndarray]:
        """The rows in blocks of ``rows`` rows (the last one shorter; ``None``: one block).

        ``max_values`` bounds the values (rows x columns) read in all, so that memory stays
        bounded by it whatever the file holds."""
        out: list[np.ndarray] = []
        held = 0  # rows in out
        total = 0  # rows read in all

        def count(arr: np.ndarray) -> None:
            nonlocal held, total
            held += len(arr)
            total += len(arr)
            if max_values is not None and total * (self.width or 1) > max_values:
                raise CalibrationError(
                    f"{self.p} holds more than {max_values:,} values ({total:,} rows of "
                    f"{self.width} columns so far), more than triaxcal holds in memory at "
                    "once: is it the right file? A long recording can be read in blocks "
                    "(triaxcal.io.tables.iter_table)"
                )

        def settle() -> None:
            n = len(out)
            self._settle_rows(out)
            for arr in out[n:]:
                count(arr)

        with _open(self.p) as f:
            try:
                for kind, first, payload in _events(f, self.hasher, self.max_line_bytes):
                    if kind == "long":
                        self.fail_or_skip(BadLine(first, f"more than {self.max_line_bytes} "
                                                         "bytes without a line break (a row "
                                                         "of numbers is far shorter): is this "
                                                         "a table of numbers?", ""))
                        continue
                    if kind == "last":
                        self.take_line(first, payload, False)
                        self.settle_last()
                        continue
                    lines: list[bytes] = payload
                    i = 0
                    while i < len(lines) and self.width is None:
                        self.take_line(first + i, lines[i], True)
                        i += 1
                    while i < len(lines):
                        assert self.width is not None
                        chunk = lines[i:i + _CHUNK]
                        arr = _fast(chunk, self.delim, self.width)
                        if arr is None:
                            for j, raw in enumerate(chunk):
                                self.take_line(first + i + j, raw, True)
                            if len(self.rows) >= _CHUNK:
                                settle()
                        else:
                            settle()
                            out.append(arr)
                            count(arr)
                        i += len(chunk)
                    while rows is not None and held >= rows:
                        block = np.concatenate(out) if len(out) > 1 else out[0]
                        out = [block[rows:]] if len(block) > rows else []
                        held -= rows
                        yield block[:rows]
            except OSError as exc:
                raise CalibrationError(os_error_message(exc, self.p, "read")) from None
        settle()
        if out:
            yield np.concatenate(out) if len(out) > 1 else out[0]

    def finish(self, n_rows: int, allow_empty: bool) -> None:
        """After the last block: refuse a file without rows (unless ``allow_empty``) and
        write the notes."""
        if self.width is None:  # no row of numbers at all
            pending = self.pending
            if pending and allow_empty:
                d = next((x for x in (",", ";", "\t") if x in pending[0][1]), None)
                self.names = tuple(t.strip('"') for t in _split(pending[0][1], d))
                self.width = len(self.names)
                return
            if allow_empty:
                self.width = 0
                return
            if len(pending) > 1 and not self.skip_bad_lines:
                ln, s = pending[1]
                raise CalibrationError(f"{self.p}, line {ln}: not all numbers ({_excerpt(s)!r}); "
                                       "the file holds no row of numbers")
            raise CalibrationError(
                f"{self.p} holds no rows of numbers"
                + (" (only a header)" if len(pending) == 1 else "")
                + (f"; {self.n_bad} bad lines skipped" if self.n_bad else "")
            )
        if not n_rows and not allow_empty:
            raise CalibrationError(
                f"{self.p} has a header but no rows of numbers"
                + (f"; {self.n_bad} bad lines skipped, first {self.bad[0]}" if self.n_bad else "")
            )
        if self.n_bad:
            s = "s" if self.n_bad > 1 else ""
            self.notes.insert(0, f"skipped {self.n_bad} bad line{s} (first: {self.bad[0]})")

    def table(self, data: np.ndarray, *, final: bool = True) -> Table:
        if not final:
            return Table(names=self.names, data=data, path=self.p, sha256="")
        skipped = self.n_bad + sum(1 for n in self.notes if "the last, is cut short" in n)
        return Table(names=self.names, data=data, path=self.p, sha256=self.hasher.hexdigest(),
                     skipped=skipped, bad_lines=tuple(self.bad), notes=tuple(self.notes))


def read_table(
    path: str | os.PathLike[str],
    *,
    skip_bad_lines: bool = False,
    allow_empty: bool = False,
    max_columns: int = MAX_COLUMNS,
    max_line_bytes: int = MAX_LINE_BYTES,
    max_values: int = MAX_VALUES,
) -> Table:
    """Read a table of numbers; the header row and the delimiter are detected.

    Parameters
    ----------
    path : str or Path
        The file: a capture session (``t,ax,ay,az,...``) or any table of numbers separated
        by commas, semicolons, tabs or spaces. Only a regular file is read (a pipe, a device
        or a socket is refused, see :func:`triaxcal.io.files.open_regular`).
    skip_bad_lines : bool
        Skip (and count) lines that are not a row of the table instead of failing on the
        first one.
    allow_empty : bool
        Return a table with no rows instead of failing when the file has none.
    max_columns, max_line_bytes : int
        Bounds: a wider table or a longer line fails at once (or is skipped).
    max_values : int
        Most values (rows x columns) held in memory (8 bytes each); a larger table fails
        once it is reached (:func:`iter_table` reads any length in blocks).

    Returns
    -------
    Table

    Raises
    ------
    CalibrationError
        For a missing file, a folder, a device, a pipe, a file with no rows, a table past
        ``max_values``, and (unless ``skip_bad_lines``) the first bad line, naming its line
        number.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "s.csv"
    >>> _ = p.write_text("t,ax,ay,az\\n0.0,1,2,3\\n0.1,4,5,6\\n0.2,7,8")
    >>> t = read_table(p)
    >>> t.names, t.data.shape, t.notes[0][:46]
    (('t', 'ax', 'ay', 'az'), (2, 4), 'line 4, the last, is cut short and was skipped')
    """
    p = Path(options.path(path, "path"))
    max_columns = options.integer(max_columns, "max_columns", ge=1)
    max_line_bytes = options.integer(max_line_bytes, "max_line_bytes", ge=1)
    max_values = options.integer(max_values, "max_values", ge=1)
    r = _Reader(p, skip_bad_lines=skip_bad_lines, max_columns=max_columns,
                max_line_bytes=max_line_bytes)
    try:
        data = next(iter(r.blocks(None, max_values)), None)
    except MemoryError:
        raise CalibrationError(
            f"{p}: not enough memory to hold the table (limit its size, or read it in blocks "
            "with triaxcal.io.tables.iter_table)"
        ) from None
    r.finish(0 if data is None else len(data), allow_empty)
    assert r.width is not None
    return r.table(np.zeros((0, r.width)) if data is None else data)


def iter_table(
    path: str | os.PathLike[str],
    *,
    rows: int = 65536,
    skip_bad_lines: bool = False,
    allow_empty: bool = False,
    max_columns: int = MAX_COLUMNS,
    max_line_bytes: int = MAX_LINE_BYTES,
) -> Iterator[Table]:
    """The table :func:`read_table` reads, in blocks of ``rows`` rows, in memory bounded by
    one block: for tables of any length (hours of readings at kHz rates).

    Each block is a :class:`Table` with the header's names and that block's rows; the file's
    ``sha256``, ``skipped``, ``bad_lines`` and ``notes`` are known at the end, so only the
    last block carries them (the others have ``sha256 == ""``). The same rules and errors as
    :func:`read_table` apply, each raised when the reading reaches it.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "s.csv"
    >>> _ = p.write_text("t,gx,gy,gz\\n" + "".join(f"{i},1,2,3\\n" for i in range(5)))
    >>> [(b.names[1], len(b.data), bool(b.sha256)) for b in iter_table(p, rows=2)]
    [('gx', 2, False), ('gx', 2, False), ('gx', 1, True)]
    """
    if isinstance(rows, bool) or not isinstance(rows, int) or rows < 1:
        raise CalibrationError(f"rows must be a whole number >= 1, got {rows!r}")
    p = Path(path)
    r = _Reader(p, skip_bad_lines=skip_bad_lines, max_columns=max_columns,
                max_line_bytes=max_line_bytes)
    held: np.ndarray | None = None  # one block behind, so that the last can carry the notes
    total = 0
    for block in r.blocks(rows):
        if held is not None:
            yield r.table(held, final=False)
        held = block
        total += len(block)
    r.finish(total, allow_empty)
    assert r.width is not None
    yield r.table(np.zeros((0, r.width)) if held is None else held)


def iter_csv(
    path: str | os.PathLike[str],
    *,
    what: str = "CSV file",
    max_fields: int = MAX_COLUMNS,
    max_line_bytes: int = MAX_LINE_BYTES,
) -> Iterator[tuple[int, list[str]]]:
    """The records of a CSV file of text and numbers (Python's :mod:`csv` rules: quotes,
    commas), each with the number of the line it starts on, read as :func:`read_table` reads:
    a regular file only, lines of at most ``max_line_bytes``, at most ``max_fields`` fields,
    UTF-8 (a byte-order mark is dropped, bytes that are not UTF-8 become U+FFFD). A field past
    :mod:`csv`'s field limit, an unclosed quote or an overlong line is a
    :class:`~triaxcal.CalibrationError` naming the line, never a :class:`csv.Error`.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "b.csv"
    >>> _ = p.write_text('id,x\\n"board 1",0.5\\n')
    >>> list(iter_csv(p))
    [(1, ['id', 'x']), (2, ['board 1', '0.5'])]
    """
    p = Path(path)
    hasher = hashlib.sha256()
    where = [0]  # the number of the last line handed to csv

    def lines(f: BinaryIO) -> Iterator[str]:
        for kind, first, payload in _events(f, hasher, max_line_bytes):
            if kind == "long":
                raise CalibrationError(
                    f"{p}, line {first}: more than {max_line_bytes} bytes without a line break: "
                    f"is this a {what}?"
                )
            for k, raw in enumerate(payload if kind == "lines" else [payload]):
                where[0] = first + k
                if where[0] == 1 and raw.startswith(b"\xef\xbb\xbf"):
                    raw = raw[3:]
                yield raw.decode("utf-8", errors="replace") + "\n"

    with _open(p, what) as f:
        reader = csv.reader(lines(f))
        while True:
            try:
                rec = next(reader)
            except StopIteration:
                return
            except csv.Error as exc:
                raise CalibrationError(
                    f"{p}, line {where[0]}: {exc} (an unclosed quote, or a field longer than "
                    f"{csv.field_size_limit()} characters): is this a {what}?"
                ) from None
            except OSError as exc:
                raise CalibrationError(os_error_message(exc, p, "read")) from None
            if len(rec) > max_fields:
                raise CalibrationError(
                    f"{p}, line {where[0]}: {len(rec)} fields; at most {max_fields} are read: "
                    f"is this a {what}?"
                )
            yield where[0] - _extra_lines(rec), rec


def _extra_lines(rec: list[str]) -> int:
    """Line breaks inside the quoted fields of ``rec`` (its first line is that many lines up)."""
    return sum(f.count("\n") for f in rec)


def _names_text(names: tuple[str, ...], limit: int = 12) -> str:
    shown = ", ".join(_excerpt(n if n.isprintable() else repr(n)) for n in names[:limit])
    return shown + (f", ... ({len(names)} columns)" if len(names) > limit else "")


def pick_columns(table: Table, spec: str | None, sensor: str, *,
                 option: str = "columns") -> list[int]:
    """Indices of the three columns named by ``spec`` (names or zero-based indices).

    Without ``spec``: the sensor's named columns (:data:`SENSOR_COLUMNS`), the only three
    columns other than ``t``, or the three columns of a headerless file of width 3.
    ``option`` is the option that gave ``spec`` (its Python name), for the messages.
    """
    flag = opt(option)
    ncol = table.data.shape[1]
    if spec is None:
        if table.names is not None:
            want = SENSOR_COLUMNS[sensor]
            if all(w in table.names for w in want):
                return [table.names.index(w) for w in want]
            numeric = [i for i, n in enumerate(table.names) if n != "t"]
            if len(numeric) == 3:
                return numeric
            raise CalibrationError(
                f"{table.path} has columns {_names_text(table.names)} but not "
                f"{', '.join(want)}: pass {flag} (names or zero-based indices, e.g. 0,1,2)"
            )
        if ncol == 3:
            return [0, 1, 2]
        raise CalibrationError(
            f"{table.path} has {ncol} unnamed columns: pass {flag} with three zero-based "
            f"indices, e.g. {opt(option, '0,1,2')}"
        )
    parts = [s.strip() for s in spec.split(",") if s.strip()]
    if len(parts) != 3:
        raise CalibrationError(f"{flag} needs three columns (x,y,z), got {_excerpt(spec)!r}")
    out = []
    for s in parts:
        if s.lstrip("-").isdigit():
            i = int(s)
            if not 0 <= i < ncol:
                raise CalibrationError(
                    f"{flag}: index {i} is out of range; {table.path} has {ncol} columns "
                    f"(0..{ncol - 1})"
                )
            out.append(i)
        elif table.names is not None and s in table.names:
            out.append(table.names.index(s))
        else:
            have = (_names_text(table.names) if table.names
                    else "none (headerless: use indices)")
            raise CalibrationError(f"{flag}: no column {_excerpt(s)!r}; names are: {have}")
    return out
