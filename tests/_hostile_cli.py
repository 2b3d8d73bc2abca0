"""Helpers of the hostile command-line corpus (test_hostile_cli.py, test_hostile_live.py): a
valid session and calibration file of every part, the mutations of a calibration file, and the
runner of one command in this process that reports what went wrong."""

from __future__ import annotations

import contextlib
import io
import json
import math
import re
import signal
import sys
import unicodedata
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import triaxcal as tc
from triaxcal import sim

NAMES = ("ax", "ay", "az", "gx", "gy", "gz", "mx", "my", "mz", "temp")
#: The board driver's scales of the simulated board (counts per unit), for the exports in
#: physical units.
SCALE = "accel=16384:g,gyro=131:deg/s,mag=6.6667:uT"


def session(folder: Path, seconds_hold: float = 2.5, rate_hz: float = 50.0) -> Path:
    """A capture session of the simulated board turned through the globe of poses."""
    rec = sim.SimIMU(1).record(sim.globe_script(hold_s=seconds_hold), rate_hz=rate_hz)
    frames = rec.frames(10)
    t = np.arange(len(frames)) / rate_hz
    path = folder / "session.csv"
    np.savetxt(path, np.column_stack([t, frames]), delimiter=",",
               header="t," + ",".join(NAMES), comments="", fmt="%.6f")
    return path


def calibration(folder: Path, data: Path) -> Path:
    """A calibration file with every kind of part and record a file can hold: an
    accelerometer fit with bootstrap intervals and a previous fit, a magnetometer fit to the
    field in uT aligned to the accelerometer, a gyroscope bias with temperature terms."""
    out = folder / "cal.json"
    poses = tc.SourceOptions(poses=True)
    tc.fit_to_file(data, tc.FitRequest(sensor="accel", model="axis", radius=1.0, source=poses),
                   out, new=True, sensor_id="board-1")
    tc.fit_to_file(data, tc.FitRequest(sensor="accel", model="axis", radius=1.0, source=poses,
                                       bootstrap=40), out)
    tc.fit_to_file(data, tc.FitRequest(sensor="mag", model="axis", radius="48uT",
                                       field=tc.FieldOptions(align=True)), out)
    temp = np.linspace(20.0, 40.0, 200)
    rest = np.column_stack([50 + 2.0 * (temp - 20), -30 - 1.5 * (temp - 20), 10 + 0 * temp])
    model = tc.fit_temperature(rest, temp, reference_degC=25.0)
    gains = tc.SensorCalibration(offset=[0, 0, 0], matrix=np.eye(3) / 131, unit="deg/s",
                                 model="axis")
    gyro = tc.part_from_temperature(model, gains)
    cal = tc.Calibration.load(out)
    cal.replace(gyro=gyro).save(out)
    return out


# --------------------------------------------------------------------------------------------
# mutations of a calibration file

#: What a number in the file is replaced by, as JSON text (NaN and Infinity spelled every way
#: Python's and other writers' JSON does; a number past a double; a denormal; huge integers).
NUMBERS = {
    "NaN": "NaN", "nan": "nan", "-NaN": "-NaN", "Infinity": "Infinity", "-Infinity":
    "-Infinity", "inf": "inf", "1e309": "1e309", "1e308": "1e308", "-1e308": "-1e308",
    "1e-320": "1e-320", "-0.0": "-0.0", "0": "0", "int-400-digits": "9" * 400,
    "string": '"1.0"', "true": "true", "null": "null", "list": "[1.0]", "object": "{}",
    "deep": "[" * 30 + "1" + "]" * 30,
}
#: What a text in the file is replaced by.
TEXTS = {
    "empty": '""', "esc": json.dumps("x\x1b[31mred\x1b[0m\x07\r"), "csi-clear":
    json.dumps("\x1b[2J\x1b[H"), "bidi": json.dumps("\u202egnp.exe\u2066"), "nul":
    json.dumps("a\x00b"), "long": json.dumps("x" * 200_000), "number": "1", "null": "null",
    "list": '["a"]', "escaped-esc": '"\\u001b[2J\\u0007"', "c1": json.dumps("a\x9bb\x85c"),
    "newline-include": json.dumps("x\n#include </etc/passwd>\n"),
}
#: What a list in the file is replaced by.
LISTS = {"empty": "[]", "short": "[1.0]", "long": "[" + ",".join(["1.0"] * 4) + "]",
         "enormous": "[" + ",".join(["1.0"] * 300_000) + "]", "null": "null",
         "nested": "[[1.0, 2.0, 3.0]]", "strings": '["1", "2", "3"]'}


def leaves(d: Any, path: tuple = ()) -> Iterator[tuple[tuple, Any]]:
    """Every (path, value) of a JSON tree; lists of numbers count as one leaf (and their
    first number as another)."""
    if isinstance(d, dict):
        for k, v in d.items():
            yield from leaves(v, (*path, k))
    elif isinstance(d, list):
        yield path, d
        if d and isinstance(d[0], (dict, list)):
            yield from leaves(d[0], (*path, 0))
        elif d:
            yield (*path, 0), d[0]
    else:
        yield path, d


_MARK = "\u2603MUTANT\u2603"


def mutate(doc: dict, path: tuple, text: str) -> str:
    """The JSON text of ``doc`` with the value at ``path`` replaced by the JSON text ``text``
    (which need not be valid JSON: NaN, -NaN, inf)."""
    d = json.loads(json.dumps(doc))
    node = d
    for k in path[:-1]:
        node = node[k]
    node[path[-1]] = _MARK
    return json.dumps(d, indent=1).replace(json.dumps(_MARK), text)


def mutants(doc: dict) -> dict[str, str]:
    """Name -> JSON text of each mutation of ``doc``: every leaf set to the values of its kind,
    and files that are valid JSON but describe an impossible calibration."""
    out: dict[str, str] = {}
    for path, value in leaves(doc):
        where = "/".join(map(str, path))
        # statistics are free-form records: their numbers and lists get a share of the values
        in_stats = "stats" in path[:-1] or "previous" in path
        if isinstance(value, bool) or value is None:
            kinds = {**{k: NUMBERS[k] for k in ("NaN", "1e309", "string", "list")},
                     "text": '"yes"'}
        elif isinstance(value, (int, float)):
            kinds = ({k: NUMBERS[k] for k in ("NaN", "Infinity", "1e309", "string", "deep")}
                     if in_stats else NUMBERS)
        elif isinstance(value, str):
            kinds = ({k: TEXTS[k] for k in ("esc", "bidi", "long", "number")}
                     if in_stats else TEXTS)
        elif isinstance(value, list):
            kinds = ({k: LISTS[k] for k in ("empty", "enormous", "strings")}
                     if in_stats else LISTS)
        else:
            kinds = {"null": "null", "list": "[]", "text": '"x"', "number": "1"}
        for k, v in kinds.items():
            out[f"{where}={k}"] = mutate(doc, path, v)
    base = json.dumps(doc, indent=1)
    acc = doc["parts"]["accel"]
    impossible = {
        "singular-matrix": ("diag", [0.0, 0.0, 0.0]),
        "negative-radius": ("radius", -1.0),
        "zero-radius": ("radius", 0.0),
        "huge-offset": ("offset", [1e300, -1e300, 1e300]),
        "huge-diag": ("diag", [1e300, 1e300, 1e300]),
        "tiny-diag": ("diag", [1e-300, 1e-300, 1e-300]),
        "mirrored": ("diag", [-acc["diag"][0], acc["diag"][1], acc["diag"][2]]),
        "unknown-model": ("model", "banana"),
        "unit-mismatch": ("unit", "deg/s"),
        "raw-unit-odd": ("raw_unit", "parsecs"),
    }
    for name, (key, value) in impossible.items():
        out[f"impossible:{name}"] = mutate(doc, ("parts", "accel", key), json.dumps(value))
    temp = doc["parts"]["gyro"].get("temperature")
    if temp:
        lo, hi = temp["temp_range_c"]
        out["impossible:temperature-range-reversed"] = mutate(
            doc, ("parts", "gyro", "temperature", "temp_range_c"), json.dumps([hi, lo]))
        out["impossible:temperature-poly-huge"] = mutate(
            doc, ("parts", "gyro", "temperature", "offset_poly"),
            json.dumps([[0, 0, 0], [1e300, 1e300, 1e300]]))
    out["duplicate-keys"] = base.replace('"sensor_id": "board-1"',
                                         '"sensor_id": "a", "sensor_id": "b"', 1)
    out["duplicate-parts"] = base.replace('"parts": {', '"parts": {"accel": {}, ', 1)
    out["unknown-top-key"] = base[:-1] + ', "surprise": 1}'
    out["unknown-part-key"] = base.replace('"raw_unit"', '"wat": 1, "raw_unit"', 1)
    out["no-parts"] = mutate(doc, ("parts",), "{}")
    out["bom-and-crlf"] = "\ufeff" + base.replace("\n", "\r\n")
    out["truncated"] = base[: len(base) // 2]
    out["trailing-garbage"] = base + "\x1b[2J"
    return out


# --------------------------------------------------------------------------------------------
# running one command in this process


class Hang(BaseException):
    pass


def _alarm(signum: int, frame: Any) -> None:
    raise Hang()


_SAFE = set("\n\t")


def raw_controls(text: str) -> list[str]:
    """Characters in ``text`` that a terminal would act on: C0/C1 controls other than a line
    break or a tab, DEL, and format characters (bidi overrides, zero-width joiners)."""
    return sorted({repr(c) for c in text if c not in _SAFE and (
        unicodedata.category(c) in ("Cc", "Cf", "Zl", "Zp"))})


def run(argv: list[str], *, limit_s: float = 20.0) -> tuple[str | None, int, str, str]:
    """Run ``triaxcal argv`` in this process: (what went wrong or None, exit status, stdout,
    stderr). Wrong: an exception escaped ``main`` (a traceback for the user), an exit status
    other than 0, 1, 2 (or diff's 3, 4), raw control characters printed, a hang."""
    from triaxcal.cli import main

    out, err = io.StringIO(), io.StringIO()
    old = signal.signal(signal.SIGALRM, _alarm)
    signal.setitimer(signal.ITIMER_REAL, limit_s)
    code: Any = None
    wrong = None
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code = main(argv)
    except SystemExit as exc:  # argparse
        code = exc.code
    except Hang:
        wrong = f"hang past {limit_s:g} s"
    except BaseException as exc:  # noqa: BLE001 - the corpus reports every escape
        wrong = f"traceback: {type(exc).__name__}: {str(exc)[:200]}"
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
    so, se = out.getvalue(), err.getvalue()
    code = 0 if code is None and wrong is None else code
    if wrong is None and code not in (0, 1, 2, 3, 4):
        wrong = f"exit status {code!r}"
    if wrong is None and "Traceback (most recent call last)" in so + se:
        wrong = "a traceback was printed"
    bad = raw_controls(so + se)
    if wrong is None and bad:
        wrong = f"raw control characters printed: {bad[:6]}"
    return wrong, code if isinstance(code, int) else -1, so, se


def nonfinite_tokens(text: str) -> list[str]:
    """NaN or infinity written into a generated file (a C header, a parameter file)."""
    return sorted(set(re.findall(r"(?<![\w.])(?:nan|inf|infinity|NaN|Infinity|INFINITY|NAN)"
                                 r"(?![\w])", text)))


def finite(x: float) -> bool:
    return math.isfinite(x)


def python() -> str:
    return sys.executable
