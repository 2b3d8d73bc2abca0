"""What the C exports share: identifiers, literals, the comment block and the header frame.

Everything that reaches generated C passes through here, so this is where text from a
calibration file is made safe to put into a header. A calibration file is something people
download and share, so every string in it is treated as hostile:

* text goes into comments only, through :func:`c_comment_text`: printable ASCII, no comment
  delimiters (``/*``, ``*/``), no trigraph start (``??``), no backslash (line splice), no
  newline, no control or bidi/format character (U+202E, U+2066-2069, U+200E/F ...), bounded in
  length;
* identifiers come from the ``prefix`` option (:func:`_ident`) and fixed sensor names only;
* numbers are written from validated finite floats;
* the finished header is checked once more (:func:`_verify_header`): printable ASCII, every
  comment closed and never nested, only the preprocessor directives this module writes.
"""

from __future__ import annotations

import re
import unicodedata
from typing import Any

import numpy as np

from .._core import __version__
from ..calibration.file import Calibration
from ..calibration.part import SensorCalibration
from ..errors import CalibrationError

#: Longest ``prefix``: with the longest suffix (``_CALIBRATION_FIXED_H``) every name stays
#: within the 63 significant characters C99 guarantees for macro and internal names.
MAX_PREFIX = 40
#: Longest line of text put into a comment (longer text is cut, ending in ``...``).
MAX_COMMENT = 300

# Characters worth spelling out rather than replacing with "?" (units, signs, quotes).
_TRANSLIT = {"\u00b5": "u", "\u03bc": "u", "\u00b0": "deg", "\u00b1": "+-", "\u00b2": "^2",
             "\u00b3": "^3", "\u00d7": "x", "\u2013": "-", "\u2014": "-", "\u2018": "'",
             "\u2019": "'", "\u201c": '"', "\u201d": '"', "\u2212": "-"}


def c_comment_text(value: Any, *, max_len: int = MAX_COMMENT) -> str:
    r"""``value`` as text that is safe inside a C block comment, on one line.

    Printable ASCII only (accents dropped, ``µ`` -> ``u``, ``°`` -> ``deg``, anything else
    -> ``?``); a newline, a control or an invisible formatting character (bidi overrides
    such as U+202E) becomes ``?``; a backslash becomes ``/`` (no line splice); ``*/`` and
    ``/*`` are split by a space; ``??`` (a trigraph start) is collapsed; at most ``max_len``
    characters.

    Examples
    --------
    >>> c_comment_text('x */ int injected = 42; /* \\n#include "/etc/passwd"')
    'x * / int injected = 42; / * /n#include "/etc/passwd"'
    >>> c_comment_text("board\u202e1\n#include <x>??/")
    'board?1?#include <x>?/'
    >>> c_comment_text("48 \u00b5T at 20 \u00b0C")
    '48 uT at 20 degC'
    """
    s = str(value)[: 4 * max_len]  # bound the work before any transliteration
    out = []
    for ch in s:
        if " " <= ch <= "~":
            out.append(ch)
        elif ch in _TRANSLIT:
            out.append(_TRANSLIT[ch])
        else:
            plain = unicodedata.normalize("NFKD", ch).encode("ascii", "ignore").decode()
            ok = plain and all(" " <= c <= "~" for c in plain)
            out.append(plain if ok else "?")
    t = "".join(out).replace("\\", "/")
    while "*/" in t or "/*" in t or "??" in t:
        t = t.replace("*/", "* /").replace("/*", "/ *").replace("??", "?")
    if len(t) > max_len:
        t = t[: max_len - 3].rstrip("?") + "..."
    return t


def _c_comment(text: str) -> str:
    """A one-line block comment holding ``text`` (made safe by :func:`c_comment_text`)."""
    return f"/* {c_comment_text(text)} */"


def _ident(prefix: str) -> str:
    if not isinstance(prefix, str):
        raise CalibrationError(f"prefix must be text, got {type(prefix).__name__}")
    s = re.sub(r"[^0-9A-Za-z_]", "_", prefix.strip())
    if not s or s[0].isdigit():
        raise CalibrationError(
            f"prefix {prefix[:40]!r} is not a C identifier: use letters, digits and _ (e.g. "
            "'imu')"
        )
    if len(s) > MAX_PREFIX:
        raise CalibrationError(
            f"prefix is {len(s)} characters long; at most {MAX_PREFIX} keep every generated "
            "name within the 63 characters C99 guarantees"
        )
    return s


#: Largest finite float32.
FLOAT32_MAX = 3.4028234663852886e38


def check_float_range(part: SensorCalibration, sensor: str) -> None:
    """Refuse a part with a coefficient a C ``float`` cannot hold (beyond +-3.4e38, where the
    literal would be ``inf``, or not finite)."""
    t = part.temperature
    items = [("offset", part.offset), ("matrix", part.matrix),
             ("radius", [] if part.radius is None else [part.radius])]
    if t is not None:
        items += [("offset_poly", t.offset_poly),
                  ("gain_poly", [] if t.gain_poly is None else t.gain_poly)]
    for name, values in items:
        a = np.abs(np.asarray(values, dtype=float))
        if a.size and not (np.isfinite(a).all() and a.max() < FLOAT32_MAX):
            raise CalibrationError(
                f"the {sensor} {name} reaches {a.max():.4g}, beyond what a C float holds "
                f"(+-{FLOAT32_MAX:.4g}): the float header cannot carry this calibration; "
                "refit it (its units or its fit are wrong), or export --format json")


def _cf(v: float) -> str:
    """A float literal that reads back to the nearest float32 (9 significant digits)."""
    x = float(v)
    if not (np.isfinite(x) and abs(x) < FLOAT32_MAX):
        raise CalibrationError(f"{x:.4g} cannot be written as a C float (beyond +-"
                               f"{FLOAT32_MAX:.4g}): the header cannot carry this calibration")
    v = float(np.float32(x))
    s = f"{v:.9g}"
    if "e" not in s and "." not in s and "inf" not in s and "nan" not in s:
        s += ".0"
    return s + "f"


def _fmt(v: float) -> str:
    return f"{v:.6g}"


def _vec(v: Any) -> str:
    return "{" + ", ".join(_fmt(x) for x in v) + "}"


_AX = "XYZ"
_OFFD = (("XY", 0, 1), ("XZ", 0, 2), ("YZ", 1, 2), ("YX", 1, 0), ("ZX", 2, 0), ("ZY", 2, 1))


def _test_raw(part: SensorCalibration) -> np.ndarray:
    """A test vector: the raw reading that calibrates to ``radius`` along +Z, in whole counts
    when the raw unit is counts."""
    r = part.radius if part.radius is not None else float(
        np.mean(np.linalg.norm(np.linalg.inv(part.matrix), axis=0)) ** -1
    )
    target = np.array([0.3, -0.4, 0.866]) * r
    raw = part.offset + np.linalg.solve(part.matrix, target)
    if part.raw_unit == "counts":
        raw = np.clip(np.round(raw), -32768, 32767)
    return raw


def _stats_lines(part: SensorCalibration) -> list[str]:
    s = part.stats
    lines = []
    if "rms" in s:
        rms = s["rms"]
        pct = s.get("rms_pct_of_radius")
        lines.append(
            f"fit: model {part.model}, n = {s.get('n')}, residual RMS {_fmt(rms)} {part.unit}"
            + (f" ({pct:.3g} % of radius)" if pct is not None else "")
        )
    if "norms" in s:
        n = s["norms"]
        lines.append(
            f"calibrated norms: min {_fmt(n['min'])}, max {_fmt(n['max'])}, mean "
            f"{_fmt(n['mean'])}, std {_fmt(n['std'])} {part.unit}"
        )
    if s.get("coverage_pct") is not None:
        lines.append(f"sphere coverage: {s['coverage_pct']:.0f} % of equal-area cells")
    if s.get("rejected"):
        lines.append(f"outliers rejected before the fit: {len(s['rejected'])}")
    return lines


def _header_comment(cal: Calibration, kind: str, body: list[str],
                    marks: tuple[str, ...] = ()) -> str:
    """The comment block at the top of a header; every line passes :func:`c_comment_text`.
    ``marks`` (the reasons a forced part is not a valid calibration) come first, wrapped."""
    import textwrap

    lines = [*(w for m in marks for w in textwrap.wrap(m, 96)), *([""] if marks else []),
        f"{kind} generated by triaxcal {__version__} -- do not edit; regenerate with",
        "  triaxcal export CAL.json --format " + ("c-fixed" if "fixed" in kind else "c"),
        f"sensor id: {cal.sensor_id or '(none)'}",
        f"calibration created {cal.created_utc or '(unknown)'} by triaxcal "
        f"{cal.library_version or '(unknown)'}",
        "Model: calibrated = matrix * (raw - offset); the matrix MULTIPLIES.",
        *body,
    ]
    out = ["/*", *((" * " + c_comment_text(line)).rstrip() for line in lines), " */"]
    return "\n".join(out)


def _guard(prefix: str, suffix: str) -> str:
    return f"{prefix.upper()}_{suffix}_H"




def _wrap_header(head: str, guard: str, code: list[str], *, includes: tuple[str, ...],
                 not_valid: str | None = None) -> str:
    """The parts every generated header shares: comment, include guard, includes, the
    ``TRIAXCAL_UNUSED`` attribute for the static tables, then ``code``; checked by
    :func:`_verify_header` before it is returned."""
    inc = [f"#include {i}" for i in includes]
    return _verify_header("\n".join(
        [
            head,
            f"#ifndef {guard}",
            f"#define {guard}",
            "",
            *inc,
            *([""] if inc else []),
            "#ifndef TRIAXCAL_UNUSED",
            "#if defined(__GNUC__)",
            "#define TRIAXCAL_UNUSED __attribute__((unused))",
            "#else",
            "#define TRIAXCAL_UNUSED",
            "#endif",
            "#endif",
            "",
            *([f"#define {not_valid} 1", _c_comment(
                "a part of this calibration is NOT VALID (written with --force): see above"),
               ""] if not_valid else []),
            *code,
            f"#endif /* {guard} */",
            "",
        ]
    ), includes)


_DIRECTIVES = ("ifndef", "define", "endif", "if", "else")


def _verify_header(text: str, includes: tuple[str, ...]) -> str:
    """Last line of defence: refuse a generated header that is not plain, balanced C.

    Printable ASCII and newlines only; no backslash and no ``??`` anywhere; every ``/*`` is
    closed by ``*/`` with no ``/*`` inside; no ``*/`` outside a comment; and outside comments
    the only preprocessor lines are the guard, the ``TRIAXCAL_UNUSED`` definition and the
    ``includes`` asked for. Never fails for text that went through :func:`c_comment_text`.
    """

    def refuse(why: str) -> CalibrationError:
        return CalibrationError(f"refusing to write a C header that {why} (please report this)")

    if any(not (" " <= c <= "~" or c == "\n") for c in text):
        raise refuse("holds a character other than printable ASCII")
    if "\\" in text or "??" in text:
        raise refuse("holds a backslash or a trigraph")
    code, i = [], 0
    while True:
        j = text.find("/*", i)
        if j < 0:
            code.append(text[i:])
            break
        k = text.find("*/", j + 2)
        if k < 0:
            raise refuse("has an unclosed comment")
        if "/*" in text[j + 2:k]:
            raise refuse("has a nested comment")
        code.append(text[i:j] + " ")
        i = k + 2
    outside = "".join(code)
    if "*/" in outside:
        raise refuse("closes a comment that was never opened")
    for line in outside.split("\n"):
        st = line.strip()
        if not st.startswith("#"):
            continue
        word = st[1:].split(None, 1)
        if not word:
            raise refuse("has an empty preprocessor line")
        if word[0] == "include":
            if len(word) < 2 or word[1].strip() not in includes:
                raise refuse(f"includes {st[:60]!r}")
        elif word[0] not in _DIRECTIVES:
            raise refuse(f"has the directive {st[:60]!r}")
    return text


def _c_poly_array(name: str, poly: np.ndarray, fmt: Any, ctype: str) -> list[str]:
    rows = ", ".join("{" + ", ".join(fmt(v) for v in row) + "}" for row in poly)
    return [f"TRIAXCAL_UNUSED static const {ctype} {name}[{len(poly)}][3] = {{{rows}}};"]


def _blocks(cal: Calibration) -> list[tuple[str, SensorCalibration, str | None]]:
    """``(name, part, note)`` per block of a header: every part, and for a part with an
    alignment a second block ``<sensor>_aligned`` whose matrix is ``rotation @ matrix`` (its
    output is in the frame the alignment turns into; ``note`` says so)."""
    out: list[tuple[str, SensorCalibration, str | None]] = []
    for sensor in cal.sensors:
        part = cal.part(sensor)
        out.append((sensor, part, None))
        al = part.alignment
        if al is not None:
            folded = part.replace(matrix=al.rotation @ part.matrix, alignment=None)
            mnt = ("" if al.mounting is None else
                   f"; mounting {al.mounting} + {al.mounting_residual_deg:.3g} deg")
            note = (f"{sensor}_aligned: the {sensor} calibration followed by its alignment, "
                    f"out = R * matrix * (raw - offset), in the {al.to} frame{mnt}")
            out.append((f"{sensor}_aligned", folded, note))
    return out
