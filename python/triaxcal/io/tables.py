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

:func:`pick_columns` chooses the three columns of one sensor by name or index.
"""

from __future__ import annotations

import hashlib
import io
import os
import stat
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO, Iterator

import numpy as np

from .._checks.spelling import opt
from ..errors import CalibrationError
from .files import os_error_message

__all__ = [
    "MAX_COLUMNS",
    "MAX_LINE_BYTES",
    "SENSOR_COLUMNS",
    "BadLine",
    "Table",
    "pick_columns",
    "read_table",
]

#: Longest line read, in bytes (a row of 4096 numbers fits; a line of 100 MB fails fast).
MAX_LINE_BYTES = 1 << 20
#: Most columns a table may have.
MAX_COLUMNS = 4096
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


def _open(p: Path) -> BinaryIO:
    try:
        st = os.stat(p)
    except FileNotFoundError:
        raise CalibrationError(f"data file {p} not found") from None
    except OSError as exc:
        raise CalibrationError(os_error_message(exc, p, "read")) from None
    if stat.S_ISDIR(st.st_mode):
        try:
            inside = sorted(q.name for q in p.iterdir() if q.suffix.lower() in (".csv", ".txt"))
        except OSError:
            inside = []
        hint = (f" (it holds {', '.join(inside[:5])}{', ...' if len(inside) > 5 else ''})"
                if inside else "")
        raise CalibrationError(
            f"{p} is a folder, not a data file: give the session CSV inside it{hint}"
        )
    if stat.S_ISCHR(st.st_mode) or stat.S_ISBLK(st.st_mode):
        raise CalibrationError(f"{p} is a device, not a data file")
    try:
        return open(p, "rb")  # noqa: SIM115
    except OSError as exc:
        raise CalibrationError(os_error_message(exc, p, "read")) from None


def read_table(
    path: str | os.PathLike[str],
    *,
    skip_bad_lines: bool = False,
    allow_empty: bool = False,
    max_columns: int = MAX_COLUMNS,
    max_line_bytes: int = MAX_LINE_BYTES,
) -> Table:
    """Read a table of numbers; the header row and the delimiter are detected.

    Parameters
    ----------
    path : str or Path
        The file: a capture session (``t,ax,ay,az,...``) or any table of numbers separated
        by commas, semicolons, tabs or spaces.
    skip_bad_lines : bool
        Skip (and count) lines that are not a row of the table instead of failing on the
        first one.
    allow_empty : bool
        Return a table with no rows instead of failing when the file has none.
    max_columns, max_line_bytes : int
        Bounds: a wider table or a longer line fails at once (or is skipped).

    Returns
    -------
    Table

    Raises
    ------
    CalibrationError
        For a missing file, a folder, a device, a file with no rows, and (unless
        ``skip_bad_lines``) the first bad line, naming its line number.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "s.csv"
    >>> _ = p.write_text("t,ax,ay,az\\n0.0,1,2,3\\n0.1,4,5,6\\n0.2,7,8")
    >>> t = read_table(p)
    >>> t.names, t.data.shape, t.notes[0][:46]
    (('t', 'ax', 'ay', 'az'), (2, 4), 'line 4, the last, is cut short and was skipped')
    """
    p = Path(path)
    hasher = hashlib.sha256()
    bad: list[BadLine] = []
    n_bad = 0
    notes: list[str] = []
    names: tuple[str, ...] | None = None
    delim: str | None = None
    width: int | None = None
    pending: list[tuple[int, str]] = []  # non-numeric lines before the first row
    rows: list[list[float]] = []  # rows parsed one by one, not yet in pieces
    pieces: list[np.ndarray] = []
    last_bad: BadLine | None = None  # a bad line that may turn out to be the cut last one

    def fail_or_skip(b: BadLine, *, last_candidate: bool = False) -> None:
        nonlocal n_bad, last_bad
        if last_candidate:
            last_bad = b  # only the last line can lack its line break
            return
        if not skip_bad_lines:
            raise CalibrationError(
                f"{p}, {b}; fix or remove that line, or skip such lines (--skip-bad-lines)"
            )
        n_bad += 1
        if len(bad) < _KEEP_BAD:
            bad.append(b)

    def settle_last() -> None:
        nonlocal last_bad
        if last_bad is not None:
            b, last_bad = last_bad, None
            notes.append(
                f"line {b.line}, the last, is cut short and was skipped (the file ends in "
                "the middle of a row, as when a capture is stopped by a full disk or a "
                f"crash): {b.reason}"
            )

    def start_table(lineno: int, d: str | None, w: int) -> None:
        nonlocal names, delim, width
        delim, width = d, w
        header_at = next((i for i, (_, s) in enumerate(pending) if len(_split(s, d)) == w), None)
        if header_at is not None:
            names = tuple(t.strip().strip('"').strip("'") for t in _split(pending[header_at][1], d))
        for i, (ln, s) in enumerate(pending):
            if i == header_at:
                continue
            k = len(_split(s, d))
            fail_or_skip(BadLine(ln, f"not numbers, and not a header of the {w} columns of the "
                                     f"rows below ({k} values)", _excerpt(s)))
        pending.clear()

    def take_line(lineno: int, raw: bytes, terminated: bool) -> None:
        line = raw.decode("utf-8", errors="replace").strip()
        if not line or line.startswith("#"):
            return
        if width is None:
            nsplit = _numeric_split(line) if _plain(line) else None
            if nsplit is None:
                fields = max(line.count(d) for d in (",", ";", "\t")) + 1
                if fields > max_columns:
                    raise CalibrationError(
                        f"{p}, line {lineno}: {fields} columns; triaxcal reads tables of "
                        f"at most {max_columns} columns: is this the right file?"
                    )
                pending.append((lineno, line))
                if len(pending) > _LOOKAHEAD:
                    first = pending.pop(0)
                    fail_or_skip(BadLine(first[0], "not all numbers, and no row of "
                                         "numbers follows it", _excerpt(first[1])))
                return
            d, w = nsplit
            if w > max_columns:
                raise CalibrationError(
                    f"{p}, line {lineno}: {w} columns; triaxcal reads tables of at most "
                    f"{max_columns} columns: is this the right file?"
                )
            start_table(lineno, d, w)
        assert width is not None
        if delim is not None and line.count(delim) + 1 > max_columns:
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
                if terminated or names is None or names[0] != "t":
                    rows.append(row)
                    return
                reason = "a capture row without its line break"
        fail_or_skip(BadLine(lineno, reason, _excerpt(line)), last_candidate=not terminated)

    with _open(p) as f:
        for kind, first, payload in _events(f, hasher, max_line_bytes):
            if kind == "long":
                fail_or_skip(BadLine(first, f"more than {max_line_bytes} bytes without a line "
                                            "break (a row of numbers is far shorter): is this "
                                            "a table of numbers?", ""))
                continue
            if kind == "last":
                take_line(first, payload, False)
                settle_last()
                continue
            lines: list[bytes] = payload
            i = 0
            while i < len(lines) and width is None:
                take_line(first + i, lines[i], True)
                i += 1
            while i < len(lines):
                assert width is not None
                chunk = lines[i:i + _CHUNK]
                arr = _fast(chunk, delim, width)
                if arr is None:
                    for j, raw in enumerate(chunk):
                        take_line(first + i + j, raw, True)
                else:
                    if rows:
                        pieces.append(np.array(rows, dtype=np.float64).reshape(-1, width))
                        rows.clear()
                    pieces.append(arr)
                i += len(chunk)
    if width is None:  # no row of numbers at all
        if pending and allow_empty:
            d = next((x for x in (",", ";", "\t") if x in pending[0][1]), None)
            names = tuple(t.strip('"') for t in _split(pending[0][1], d))
            return Table(names, np.zeros((0, len(names))), p, hasher.hexdigest())
        if allow_empty:
            return Table(None, np.zeros((0, 0)), p, hasher.hexdigest())
        if pending and len(pending) > 1 and not skip_bad_lines:
            ln, s = pending[1]
            raise CalibrationError(f"{p}, line {ln}: not all numbers ({_excerpt(s)!r}); the "
                                   "file holds no row of numbers")
        raise CalibrationError(
            f"{p} holds no rows of numbers"
            + (" (only a header)" if len(pending) == 1 else "")
            + (f"; {n_bad} bad lines skipped" if n_bad else "")
        )
    if rows:
        pieces.append(np.array(rows, dtype=np.float64).reshape(-1, width))
    data = np.concatenate(pieces) if pieces else np.zeros((0, width))
    if not len(data) and not allow_empty:
        raise CalibrationError(
            f"{p} has a header but no rows of numbers"
            + (f"; {n_bad} bad lines skipped, first {bad[0]}" if n_bad else "")
        )
    if n_bad:
        notes.insert(0, f"skipped {n_bad} bad line{'s' if n_bad > 1 else ''} (first: {bad[0]})")
    skipped = n_bad + sum(1 for n in notes if "the last, is cut short" in n)
    return Table(names=names, data=data, path=p, sha256=hasher.hexdigest(), skipped=skipped,
                 bad_lines=tuple(bad), notes=tuple(notes))


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
