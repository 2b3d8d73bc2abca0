"""Validators for values read from files people share: one validator per field, in tables.

Every value a calibration file (or any JSON the library reads) holds is checked for type and
range before it is used:

* numbers are finite real numbers -- not strings, not booleans, not 5000-digit integers;
* text is bounded in length and, for short identity fields (units, model, sensor id, dates,
  versions, paths), holds no control or invisible formatting characters;
* nested free-form JSON is bounded in depth.

The tables built from these validators live with the objects they describe
(:mod:`triaxcal.calibration.schema`).
"""

from __future__ import annotations

import json
import math
import re
import unicodedata
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from ..errors import CalibrationError
from .options import MAGNITUDE

#: Largest calibration file read, in bytes: 16 MiB. A calibration file is a few kB (a
#: million-point fit's statistics are summaries, not the points); reading and checking every
#: value of a file takes about a second per MB, so a bound far above any real file keeps a
#: hostile one from taking minutes and gigabytes.
MAX_FILE_BYTES = 16 * 1024 * 1024
#: Deepest nesting of JSON arrays/objects accepted anywhere in a calibration file.
MAX_DEPTH = 32
#: Most decimal digits of a JSON integer (a float64 holds about 17 significant digits).
MAX_INT_DIGITS = 30
#: Longest free-form text value (in ``stats`` and ``extra``), in characters.
MAX_TEXT = 65536

Validator = Callable[[Any, str], Any]


@dataclass(frozen=True)
class Field:
    """One row of a table: the validator (returns the normalised value or raises) and
    whether the field must be present."""

    check: Validator
    required: bool = False


# ------------------------------------------------------------------------------ primitives


def _type_name(value: Any) -> str:
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, str):
        return "text"
    if value is None:
        return "null"
    if isinstance(value, Mapping):
        return "an object"
    if isinstance(value, (list, tuple)):
        return "a list"
    return type(value).__name__


def _short(value: Any) -> str:
    """A bounded ``repr`` for error messages (a hostile value may be megabytes long)."""
    r = repr(value)
    return r if len(r) <= 60 else r[:57] + "..."


def real(value: Any, what: str) -> float:
    """A finite real number: int or float (numpy scalars too), not bool, not text."""
    if isinstance(value, bool) or not isinstance(
        value, (int, float, np.integer, np.floating)
    ):
        raise CalibrationError(f"{what} must be a number, got {_type_name(value)} {_short(value)}")
    try:
        v = float(value)
    except OverflowError:
        raise CalibrationError(f"{what} is too large for a double-precision number") from None
    if not math.isfinite(v):
        raise CalibrationError(f"{what} must be finite, got {v}")
    return v


def integer(value: Any, what: str, *, minimum: int | None = 0) -> int:
    """A whole number (not bool, not float), at least ``minimum``."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise CalibrationError(
            f"{what} must be a whole number, got {_type_name(value)} {_short(value)}"
        )
    v = int(value)
    if abs(v) >= 2**63:
        raise CalibrationError(f"{what} is too large ({len(str(abs(v)))} digits)")
    if minimum is not None and v < minimum:
        raise CalibrationError(f"{what} must be at least {minimum}, got {v}")
    return v


def boolean(value: Any, what: str) -> bool:
    if not isinstance(value, (bool, np.bool_)):
        raise CalibrationError(f"{what} must be true or false, got {_type_name(value)}")
    return bool(value)


def reals(value: Any, shape: tuple[int, ...], what: str) -> np.ndarray:
    """A read-only float64 array of ``shape`` whose every element passed :func:`real`.

    ``shape`` may use -1 for "any length" in one dimension.
    """
    if isinstance(value, np.ndarray):
        if value.dtype.kind not in "iuf":
            raise CalibrationError(f"{what} must hold real numbers, got dtype {value.dtype}")
        arr = np.array(value, dtype=np.float64)
    else:
        flat = _flatten(value, len(shape), what)
        arr = np.array([_element(v, what) for v in flat[0]], dtype=np.float64).reshape(flat[1])
    if arr.ndim != len(shape) or any(s not in (-1, a) for s, a in zip(shape, arr.shape)):
        want = tuple("N" if s == -1 else s for s in shape)
        raise CalibrationError(f"{what} must have shape {want}, got {arr.shape}")
    if not np.isfinite(arr).all():
        raise CalibrationError(f"{what} must be finite, got {_short(arr.tolist())}")
    arr.setflags(write=False)
    return arr


def _element(value: Any, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise CalibrationError(
            f"{what} must hold numbers only, got {_type_name(value)} {_short(value)}"
        )
    return real(value, what)


def _flatten(value: Any, ndim: int, what: str) -> tuple[list[Any], tuple[int, ...]]:
    """Elements and shape of a rectangular nest of lists ``ndim`` deep."""
    if ndim == 0:
        return [value], ()
    if isinstance(value, (str, bytes, Mapping)) or not hasattr(value, "__len__"):
        raise CalibrationError(
            f"{what} must be a list of numbers, got {_type_name(value)} {_short(value)}"
        )
    items = list(value)
    out: list[Any] = []
    inner: tuple[int, ...] | None = None
    for v in items:
        sub, shp = _flatten(v, ndim - 1, what)
        if inner is None:
            inner = shp
        elif shp != inner:
            raise CalibrationError(f"{what} must be rectangular (rows of equal length)")
        out += sub
    if inner is None:
        inner = (0,) * (ndim - 1)
    return out, (len(items), *inner)


_CONTROL_CATEGORIES = ("Cc", "Cf", "Cs", "Co", "Cn", "Zl", "Zp")


def _bad_char(s: str) -> str | None:
    for ch in s:
        if unicodedata.category(ch) in _CONTROL_CATEGORIES:
            return f"U+{ord(ch):04X}"
    return None


def text(max_len: int, *, plain: bool = True, nonblank: bool = False) -> Validator:
    """A validator of text at most ``max_len`` characters; ``plain`` also refuses control
    characters, invisible formatting characters (bidi overrides, zero-width spaces) and line
    or paragraph separators."""

    def check(value: Any, what: str) -> str:
        if not isinstance(value, str):
            raise CalibrationError(f"{what} must be text, got {_type_name(value)} {_short(value)}")
        if len(value) > max_len:
            raise CalibrationError(
                f"{what} is {len(value)} characters long; at most {max_len} are allowed"
            )
        if nonblank and not value.strip():
            raise CalibrationError(f"{what} must not be empty")
        if plain:
            bad = _bad_char(value)
            if bad is not None:
                raise CalibrationError(
                    f"{what} holds the control or invisible character {bad}: remove it "
                    f"({_short(value)})"
                )
        else:
            _no_surrogates(value, what)
        return value

    return check


def _no_surrogates(value: str, what: str) -> None:
    try:
        value.encode("utf-8")
    except UnicodeEncodeError:
        raise CalibrationError(
            f"{what} holds an unpaired UTF-16 surrogate (\\ud800-\\udfff), which is not text"
        ) from None


def optional(check: Validator) -> Validator:
    """``None`` or what ``check`` accepts."""

    def opt(value: Any, what: str) -> Any:
        return None if value is None else check(value, what)

    return opt


def positive(value: Any, what: str) -> float:
    v = real(value, what)
    if v <= 0:
        raise CalibrationError(f"{what} must be greater than zero, got {v}")
    return v


def nonnegative(value: Any, what: str) -> float:
    v = real(value, what)
    if v < 0:
        raise CalibrationError(f"{what} must be zero or more, got {v}")
    return v


_HEX64 = re.compile(r"[0-9a-f]{64}")


def sha256_hex(value: Any, what: str) -> str:
    v = text(64)(value, what)
    if not _HEX64.fullmatch(v):
        raise CalibrationError(
            f"{what} must be 64 lowercase hex digits (a SHA-256), got {_short(v)}"
        )
    return v


def list_of(check: Validator, max_items: int | None = None) -> Validator:
    def lst(value: Any, what: str) -> list[Any]:
        if isinstance(value, (str, bytes, Mapping)) or not isinstance(
            value, (list, tuple, np.ndarray)
        ):
            raise CalibrationError(f"{what} must be a list, got {_type_name(value)}")
        if max_items is not None and len(value) > max_items:
            raise CalibrationError(f"{what} has {len(value)} items; at most {max_items}")
        return [check(v, f"{what}[{i}]") for i, v in enumerate(value)]

    return lst


def one_of(*checks: Validator) -> Validator:
    """The first of ``checks`` that accepts the value (the last one's error otherwise)."""

    def any_of(value: Any, what: str) -> Any:
        err: CalibrationError | None = None
        for c in checks:
            try:
                return c(value, what)
            except CalibrationError as exc:
                err = exc
        assert err is not None
        raise err

    return any_of


def json_value(value: Any, what: str, depth: int = 0) -> Any:
    """Deep-copy ``value`` into plain JSON types (dict/list/str/float/int/bool/None),
    checking numbers are finite, text is bounded and nesting is at most :data:`MAX_DEPTH`."""
    if depth > MAX_DEPTH:
        raise CalibrationError(f"{what} is nested more than {MAX_DEPTH} levels deep")
    if value is None or isinstance(value, (bool, np.bool_)):
        return None if value is None else bool(value)
    if isinstance(value, str):
        return text(MAX_TEXT, plain=False)(value, what)
    if isinstance(value, (int, np.integer)):
        return integer(value, what, minimum=None)
    if isinstance(value, (float, np.floating)):
        return real(value, what)
    if isinstance(value, np.ndarray):
        return json_value(value.tolist(), what, depth)
    if isinstance(value, Mapping):
        out = {}
        for k, v in value.items():
            key = text(256, plain=False)(k, f"a key of {what}") if isinstance(k, str) else str(k)
            out[key] = json_value(v, f"{what}.{key[:40]}", depth + 1)
        return out
    if isinstance(value, (list, tuple)):
        return [json_value(v, what, depth + 1) for v in value]
    raise CalibrationError(f"{what} holds {type(value).__name__}, which JSON cannot store")


def json_object(value: Any, what: str) -> dict[str, Any]:
    if not isinstance(value, Mapping):
        raise CalibrationError(f"{what} must be a JSON object, got {_type_name(value)}")
    return json_value(value, what)  # type: ignore[no-any-return]


# ------------------------------------------------------------------------------ tables


def check_fields(
    d: Any, table: Mapping[str, Field], what: str, *, open_ended: bool = False
) -> dict[str, Any]:
    """Validate the mapping ``d`` against ``table``; returns the normalised values.

    Unknown keys are an error unless ``open_ended`` (then they must be plain JSON and are
    kept as they are).
    """
    if not isinstance(d, Mapping):
        raise CalibrationError(f"{what} must be a JSON object, got {_type_name(d)}")
    missing = [k for k, f in table.items() if f.required and k not in d]
    if missing:
        raise CalibrationError(f"{what} lacks {missing}: the file is incomplete")
    out: dict[str, Any] = {}
    for key, value in d.items():
        if not isinstance(key, str):
            raise CalibrationError(f"{what} has a key that is not text: {_short(key)}")
        f = table.get(key)
        if f is None:
            if not open_ended:
                known = ", ".join(table)
                raise CalibrationError(
                    f"{what} has an unknown field {_short(key)} (known: {known}); put "
                    "free-form metadata under the top-level 'extra' object"
                )
            out[key] = json_value(value, f"{what}.{key[:40]}", 1)
        else:
            out[key] = f.check(value, f"{what}.{key}")
    return out


def check_matrix(m: np.ndarray, what: str) -> None:
    """A gain matrix must have a non-zero diagonal and be invertible (well conditioned)."""
    if not np.any(np.diag(m)):
        raise CalibrationError(
            f"{what}: the diagonal (diag) is all zero, so the matrix would not scale any axis "
            "by itself; the file is damaged or hand-made wrongly"
        )
    if float(np.abs(m).max()) > MAGNITUDE[1]:
        raise CalibrationError(
            f"{what} holds {float(np.abs(m).max()):.3g}, larger than {MAGNITUDE[1]:g} in any "
            "unit: the file is damaged or hand-made wrongly")
    s = np.linalg.svd(m, compute_uv=False)
    if not s[-1] > s[0] * 1e-12:
        raise CalibrationError(
            f"{what}: the matrix is singular (not invertible): it would map readings to a "
            "plane or a line"
        )


# ------------------------------------------------------------------------------ reading


def _parse_int(s: str) -> int:
    digits = len(s.lstrip("-"))
    if digits > MAX_INT_DIGITS:
        raise CalibrationError(
            f"an integer with {digits} digits (at most {MAX_INT_DIGITS} are accepted)"
        )
    return int(s)


def _parse_constant(name: str) -> float:
    raise CalibrationError(f"{name} is not a JSON number: every number must be finite")


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in pairs:
        if k in out:
            raise CalibrationError(
                f"the key {_short(k)} appears twice in one object: which value is meant is "
                "ambiguous"
            )
        out[k] = v
    return out


def parse_json(text_: str) -> Any:
    """``json.loads`` that refuses NaN/Infinity, huge integers, duplicate keys and nesting
    deeper than :data:`MAX_DEPTH`, with a :class:`CalibrationError` for every failure."""
    try:
        value = json.loads(
            text_,
            parse_int=_parse_int,
            parse_constant=_parse_constant,
            object_pairs_hook=_unique_keys,
        )
    except json.JSONDecodeError as exc:
        raise CalibrationError(f"invalid JSON ({exc})") from None
    except RecursionError:
        raise CalibrationError(f"JSON nested too deeply (at most {MAX_DEPTH} levels)") from None
    except CalibrationError as exc:
        raise CalibrationError(f"invalid JSON: {exc}") from None
    except ValueError as exc:  # e.g. Python's own integer-digit limit
        raise CalibrationError(f"invalid JSON ({exc})") from None
    _check_depth(value)
    return value


def _check_depth(value: Any) -> None:
    stack = [(value, 0)]
    while stack:
        v, d = stack.pop()
        if d > MAX_DEPTH:
            raise CalibrationError(f"JSON nested more than {MAX_DEPTH} levels deep")
        if isinstance(v, dict):
            stack += [(x, d + 1) for x in v.values()]
        elif isinstance(v, list):
            stack += [(x, d + 1) for x in v]
