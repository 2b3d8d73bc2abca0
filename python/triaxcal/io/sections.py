"""Recordings cut into labelled sections: a tilt rig's four tilts, a Ferraris session's six faces
and three turns.

Two layouts of one file, read by :func:`read_sections`:

* a label on a line of its own (the tilt-rig method's ``FD``, ``AD``, ...), followed by that
  section's rows;
* a label in the first column of every row (imucal's ``annotated_session.csv``:
  ``part,samples,acc_x,...`` then ``x_p,0,...``).

Rows are numbers separated by commas, semicolons, tabs or spaces; an optional header row names
the columns (with or without the label column). A continuous recording with a separate list of
sections (imucal's ``example_ferraris_session_list.json``: ``{"x_p": {"start": 0, "end":
1028}, ...}``) is cut by :func:`read_section_list`.

The file is hostile: its size is bounded, every failure names the line and says what to do.
"""

from __future__ import annotations

import hashlib
import json
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import CalibrationError
from .files import read_bounded
from .tables import Table

__all__ = [
    "FERRARIS_SECTIONS",
    "MAX_ROWS",
    "TILT_LABELS",
    "TILT_SECTIONS",
    "Sections",
    "read_section_list",
    "read_sections",
    "read_tilts",
    "tilt_points",
]

#: The four tilts of a tilt rig, in the order the method takes them.
TILT_SECTIONS = ("fore_down", "aft_down", "left_down", "right_down")
#: Labels a tilt-rig file may use for them (the sphere-centre method's FD, AD, LD, RD among them).
TILT_LABELS = {"fd": "fore_down", "ad": "aft_down", "ld": "left_down", "rd": "right_down",
               **{k: k for k in TILT_SECTIONS}, "fore-down": "fore_down",
               "aft-down": "aft_down", "left-down": "left_down", "right-down": "right_down"}
#: The sections of a Ferraris session (imucal's names): each axis up (``_p``) and down
#: (``_a``), and a full turn about each axis.
FERRARIS_SECTIONS = ("x_p", "x_a", "y_p", "y_a", "z_p", "z_a", "x_rot", "y_rot", "z_rot")

#: Most rows a section file may hold.
MAX_ROWS = 1_000_000
#: Largest section file read, in bytes.
MAX_BYTES = 256 << 20
#: Largest list of sections (JSON), in bytes.
MAX_LIST_BYTES = 1 << 20


@dataclass(frozen=True)
class Sections:
    """A file read by :func:`read_sections`.

    Attributes
    ----------
    names : tuple of str or None
        Column names from the header row, without the label column (None without a header).
    groups : dict of str -> ndarray (n_i, K)
        The rows of each section, in the order they appear in the file.
    path : Path
        The file.
    sha256 : str
        SHA-256 of the file's bytes.
    """

    names: tuple[str, ...] | None
    groups: dict[str, np.ndarray]
    path: Path
    sha256: str

    @property
    def width(self) -> int:
        """Values per row."""
        return next(iter(self.groups.values())).shape[1]

    def table(self) -> Table:
        """All rows as one :class:`~triaxcal.io.tables.Table` (section after section), e.g.
        for :func:`~triaxcal.io.tables.pick_columns`."""
        return Table(names=self.names, data=np.vstack(list(self.groups.values())),
                     path=self.path, sha256=self.sha256)


def _split(line: str) -> list[str]:
    return [t for t in re.split(r"[,;\t ]+", line.strip()) if t]


def _number(tok: str) -> float | None:
    try:
        v = float(tok)
    except ValueError:
        return None
    return v if math.isfinite(v) else None


def _labels_text(keys: Sequence[str]) -> str:
    return ", ".join(keys)


def read_sections(
    path: str | Path,
    keys: Sequence[str],
    *,
    labels: Mapping[str, str] | None = None,
    what: str = "section file",
    section: str = "section",
    hint: str = "",
) -> Sections:
    """The rows of each labelled section of ``path``.

    Parameters
    ----------
    path : str or Path
        The file (see the module notes for the layouts).
    keys : sequence of str
        The sections the file must hold, each at least one row.
    labels : mapping, optional
        Labels as written in the file (lower case) -> section key; default: the keys
        themselves.
    what, section : str
        What the file is and what a section is called, for messages ("tilt-rig file",
        "tilt").
    hint : str
        How to label the sections, added to the message about a missing one.

    Returns
    -------
    Sections

    Examples
    --------
    >>> import pathlib, tempfile
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "t.csv"
    >>> _ = p.write_text("label,ax,ay,az\\nup,0,0,1\\ndown,0,0,-1\\nup,0,0,1.01\\n")
    >>> s = read_sections(p, ("up", "down"))
    >>> s.names, s.groups["up"].tolist()
    (('ax', 'ay', 'az'), [[0.0, 0.0, 1.0], [0.0, 0.0, 1.01]])
    """
    p = Path(path)
    labels = {k.lower(): k for k in keys} if labels is None else dict(labels)
    raw = read_bounded(p, limit=MAX_BYTES, what=what)
    text = raw.decode("utf-8", errors="replace")
    names: tuple[str, ...] | None = None
    groups: dict[str, list[list[float]]] = {}
    current: str | None = None
    width: int | None = None
    count = 0
    for lineno, line in enumerate(text.splitlines(), start=1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        toks = _split(line)
        key = labels.get(toks[0].rstrip(":").lower())
        if key is not None and len(toks) == 1:  # a label line
            current = key
            groups.setdefault(key, [])
            continue
        values = toks[1:] if key is not None else toks
        nums = [_number(t) for t in values]
        if any(v is None for v in nums):
            if names is None and not groups and key is None:
                names = tuple(t[:64] for t in values[:4096])
                continue
            raise CalibrationError(
                f"{p}, line {lineno}: not all finite numbers ({line[:60]!r})"
                + ("" if key is not None or current is not None else
                   f"; label the sections {_labels_text(keys)}")
            )
        row_key = key if key is not None else current
        if row_key is None:
            raise CalibrationError(
                f"{p}, line {lineno}: a reading before any {section} label; "
                + (hint or f"start each section with a line naming it ({_labels_text(keys)}), "
                   "or put the label first on every row")
            )
        if width is None:
            width = len(nums)
        if len(nums) != width:
            raise CalibrationError(f"{p}, line {lineno}: {len(nums)} values, expected {width}")
        groups.setdefault(row_key, []).append(nums)  # type: ignore[arg-type]
        count += 1
        if count > MAX_ROWS:
            raise CalibrationError(f"{p} has more than {MAX_ROWS} readings: is it a {what}?")
    missing = [k for k in keys if not groups.get(k)]
    if missing:
        raise CalibrationError(
            f"{p}: no readings for {', '.join(missing)}" + (f" ({hint})" if hint else
                                                          f" (sections: {_labels_text(keys)})")
        )
    if names is not None and width is not None and len(names) == width + 1:
        names = names[1:]  # the header names the label column too
    if names is not None and width is not None and len(names) != width:
        raise CalibrationError(
            f"{p}: the header names {len(names)} columns, the rows have {width}")
    return Sections(names=names, groups={k: np.array(v) for k, v in groups.items()}, path=p,
                    sha256=hashlib.sha256(raw).hexdigest())


def read_tilts(path: str | Path) -> Sections:
    """A tilt-rig file: the rows of the four tilts (:data:`TILT_SECTIONS`), labelled FD, AD, LD,
    RD (or fore_down, ...) on a line of their own or first on every row."""
    return read_sections(path, TILT_SECTIONS, labels=TILT_LABELS, what="tilt-rig file",
                         section="tilt", hint="label them FD, AD, LD, RD: fore down, aft down, "
                                              "left down, right down")


def tilt_points(path: str | Path, columns: Sequence[int]) -> np.ndarray:
    """Every reading of a tilt-rig file (the four tilts in order), its ``columns`` only."""
    s = read_tilts(path)
    cols = [int(c) for c in columns]
    if len(cols) != 3 or not all(0 <= c < s.width for c in cols):
        raise CalibrationError(f"{s.path}: columns {cols} do not fit rows of {s.width} values")
    return np.vstack([s.groups[k][:, cols] for k in TILT_SECTIONS])


def read_section_list(path: str | Path, keys: Sequence[str], n_rows: int
                      ) -> dict[str, tuple[int, int]]:
    """Where each section lies in a continuous recording of ``n_rows`` rows: ``{name: (start,
    end)}``, row positions from 0, ``end`` exclusive.

    The file is a JSON object ``{name: {"start": S, "end": E}}`` (imucal's section list) or
    ``{name: [S, E]}``; it must name every one of ``keys``, each inside the recording.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "s.json"
    >>> _ = p.write_text('{"up": {"start": 0, "end": 10}, "down": [12, 20]}')
    >>> read_section_list(p, ("up", "down"), 20)
    {'up': (0, 10), 'down': (12, 20)}
    """
    p = Path(path)
    raw = read_bounded(p, limit=MAX_LIST_BYTES, what="list of sections")
    try:
        obj: Any = json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as exc:
        raise CalibrationError(f"{p} is not JSON ({str(exc)[:80]}): give the list of sections "
                               'as {"x_p": {"start": 0, "end": 1028}, ...}') from None
    if not isinstance(obj, dict):
        raise CalibrationError(f"{p}: the list of sections must be a JSON object "
                               '{name: {"start": S, "end": E}}')
    missing = [k for k in keys if k not in obj]
    if missing:
        raise CalibrationError(f"{p}: no section {', '.join(missing)} (it names "
                               f"{', '.join(str(k)[:20] for k in list(obj)[:12])})")
    out: dict[str, tuple[int, int]] = {}
    for k in keys:
        v = obj[k]
        pair = (v.get("start"), v.get("end")) if isinstance(v, dict) else (
            tuple(v) if isinstance(v, list) and len(v) == 2 else (None, None))
        if not all(isinstance(x, int) and not isinstance(x, bool) for x in pair):
            raise CalibrationError(f"{p}: section {k} must be {{\"start\": S, \"end\": E}} with "
                                   f"whole row numbers, got {str(v)[:60]}")
        a, b = pair
        if not 0 <= a < b <= n_rows:
            raise CalibrationError(f"{p}: section {k} is rows {a}..{b}, outside the recording's "
                                   f"{n_rows} rows (start from 0, end exclusive, start < end)")
        out[k] = (a, b)
    return out
