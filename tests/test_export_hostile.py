"""Hostile calibration files cannot put code into a generated C header.

Every string of a calibration file that can reach a header is set to each value of a corpus
of attacks (comment terminators, newlines with ``#include``, bidi and other invisible
characters, trigraphs, line splices, 10,000-character strings). Each header is compiled with
``gcc -std=c99 -Wall -Wextra -Werror -pedantic`` into an object file; then

* ``nm`` proves that no injected symbol exists,
* ``gcc -M`` proves that nothing but the expected headers is included,
* the preprocessed text and the macro table prove that no injected token survived outside a
  comment.

Two routes: files loaded through :meth:`Calibration.load` (its validation refuses much of the
corpus; what it accepts must still be harmless), and objects whose validation was bypassed,
so the header generator alone is shown to be enough.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
import triaxcal as tc
from triaxcal.export import c_fixed_header, c_header

GCC = shutil.which("gcc")
NM = shutil.which("nm")
CFLAGS = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic"]

# Every payload tries to define something whose name contains "injected" (or to include a
# file); none of it may survive outside a comment.
CORPUS = {
    "comment-terminator": "x */ int injected_symbol = 42; /*",
    "newline-include": 'x\n#include "/etc/hostname"\nint injected_nl = 1;\n/*',
    "crlf-define": "x\r\n#define injected_macro 1\r\n",
    "bidi": "board \u202e ;1 = injected_bidi tni \u2066\u2067\u2068\u2069\u200e\u200f\u061c",
    "trigraph-splice": "x ??/\nint injected_tri = 3;",
    "trigraph-alone": "??= define injected_tri2 ??( ??) ??< ??>",
    "backslash-splice": "x *\\\n/ int injected_splice = 5; /*",
    "backslash-end": "ends in a backslash \\",
    "control": "\x00\x01\x07\x1b[31m\x7f\x85 int injected_ctrl;",
    "line-separators": "a\u2028int injected_ls = 6;\u2029\u000b\u000c#include <stdio.h>",
    "fullwidth": "\uff0a\uff0f int injected_fw = 7; \uff0f\uff0a",
    "nested-open": "/* /* /* int injected_nest; */",
    "long-terminators": "*/" * 5000,
    "long-text": "A" * 10_000,
    "long-mixed": ("*/\n#include <stdlib.h>\nint injected_long; /*" * 300)[:10_000],
    "surrogate-ish": "x \ud800 int injected_sur;",
    "bom-zwsp": "\ufeff\u200b\u200c\u200d\u2060 int injected_zw;",
    "percent-and-quotes": "%s %n \" ' ` $(rm -rf /) int injected_q;",
}

# String fields of a file that may reach a header, and where they live in the JSON.
TOP_FIELDS = ("sensor_id", "created_utc", "library_version")
PART_FIELDS = ("unit", "raw_unit", "model", "source")


def _base_cal() -> tc.Calibration:
    rng = np.random.default_rng(2)
    m = np.eye(3) / 16384 + rng.normal(scale=1e-7, size=(3, 3))
    m = (m + m.T) / 2
    acc = tc.SensorCalibration(
        offset=[120.0, -40.0, 75.0], matrix=m, unit="g", radius=1.0, model="full",
        stats={"rms": 0.002, "n": 50, "rms_pct_of_radius": 0.2, "coverage_pct": 60.0,
               "norms": {"min": 0.99, "max": 1.01, "mean": 1.0, "std": 0.002,
                         "std_over_mean": 0.002}, "rejected": [1, 2]},
        source="session.csv",
    )
    temp = tc.TemperatureTerms(temp_ref_c=25.0, temp_range_c=(10.0, 40.0),
                               offset_poly=[[0, 0, 0], [1.5, -0.5, 0.2]])
    gyro = tc.SensorCalibration(offset=[10.0, -3.0, 2.0], matrix=np.eye(3) / 131,
                                unit="deg/s", model="bias", temperature=temp)
    return tc.Calibration(accel=acc, gyro=gyro, sensor_id="board-1")


def _set_file_field(d: dict, field: str, value: str) -> None:
    if field in TOP_FIELDS:
        d[field] = value
    else:
        for part in d["parts"].values():
            part[field] = value


def _compile_and_inspect(tmp_path: Path, header: str, name: str, fixed: bool) -> None:
    """Compile ``header`` into an object; assert nothing was injected or included."""
    d = tmp_path / name
    d.mkdir()
    (d / "cal.h").write_text(header, encoding="utf-8")
    (d / "main.c").write_text('#include "cal.h"\nint probe(void) { return 0; }\n')
    obj, dep = d / "main.o", d / "main.d"
    res = subprocess.run([GCC, *CFLAGS, "-c", "-MD", "-MF", str(dep), "-o", str(obj),
                          str(d / "main.c")], capture_output=True, text=True, cwd=d)
    assert res.returncode == 0, f"{name}: the header does not compile cleanly:\n{res.stderr}"
    syms = subprocess.run([NM, str(obj)], capture_output=True, text=True, check=True).stdout
    assert "injected" not in syms.lower(), f"{name}: injected symbol in the object:\n{syms}"
    names = [ln.split()[-1] for ln in syms.splitlines() if ln.strip()]
    assert all(n == "probe" or n.startswith("imu_") for n in names), syms  # only ours
    # nothing included but the header itself (and <stdint.h> for the fixed-point header)
    deps = _dep_files(dep.read_text(), d) - {str(d / "main.c"), str(d / "cal.h")}
    extra = deps - _system_deps(fixed)
    assert not extra, f"{name}: unexpected includes {sorted(extra)}"
    # no injected token outside comments, no injected macro (-dD keeps the #defines)
    pre = subprocess.run([GCC, "-std=c99", "-E", "-dD", "-P", str(d / "main.c")],
                         capture_output=True, text=True, check=True).stdout
    assert "injected" not in pre.lower(), f"{name}: injected code survived preprocessing"


def _dep_files(make_rule: str, cwd: Path) -> set[str]:
    toks = make_rule.replace("\\\n", " ").split()[1:]
    return {str((cwd / t).resolve()) for t in toks}


_SYSTEM_DEPS: dict[bool, set[str]] = {}


def _system_deps(fixed: bool) -> set[str]:
    """What ``#include <stdint.h>`` (fixed) or nothing (float) pulls in on this machine."""
    if fixed not in _SYSTEM_DEPS:
        src = "#include <stdint.h>\n" if fixed else "\n"
        out = subprocess.run([GCC, "-std=c99", "-M", "-x", "c", "-"], input=src,
                             capture_output=True, text=True, check=True).stdout
        _SYSTEM_DEPS[fixed] = _dep_files(out, Path("/"))
    return _SYSTEM_DEPS[fixed]


@pytest.mark.skipif(GCC is None or NM is None, reason="gcc and nm needed")
@pytest.mark.parametrize("case", sorted(CORPUS))
def test_hostile_file_cannot_inject_code(tmp_path, case):
    """Through a file: every field set to the attack is either refused by load (with a
    CalibrationError) or, if accepted, gives headers that compile to nothing injected."""
    payload = CORPUS[case]
    base = _base_cal().to_dict()
    accepted = []
    for field in (*TOP_FIELDS, *PART_FIELDS):
        d = json.loads(json.dumps(base))
        _set_file_field(d, field, payload)
        p = tmp_path / f"{field}.json"
        p.write_text(json.dumps(d), encoding="utf-8")
        try:
            tc.Calibration.load(p)
        except tc.CalibrationError as exc:
            assert field in str(exc) or "part" in str(exc), str(exc)[:200]
        else:
            accepted.append(field)
    d = json.loads(json.dumps(base))
    for field in accepted:
        _set_file_field(d, field, payload)
    p = tmp_path / "cal.json"
    p.write_text(json.dumps(d), encoding="utf-8")
    cal = tc.Calibration.load(p)
    _compile_and_inspect(tmp_path, c_header(cal, prefix="imu"), f"{case}-float", False)
    if "raw_unit" in accepted:  # the fixed-point header takes raw counts only
        with pytest.raises(tc.CalibrationError, match="integer raw readings"):
            c_fixed_header(cal, prefix="imu")
    else:
        _compile_and_inspect(tmp_path, c_fixed_header(cal, prefix="imu"), f"{case}-fixed", True)


@pytest.mark.slow
@pytest.mark.skipif(GCC is None or NM is None, reason="gcc and nm needed")
@pytest.mark.parametrize("case", sorted(CORPUS))
def test_generator_alone_neutralises_every_string(tmp_path, case):
    """Defence in depth: objects with the attack forced into every text field (bypassing
    validation), including free-form statistics, still give harmless headers."""
    payload = CORPUS[case]
    for fixed in (False, True):
        cal = _base_cal()
        for field in TOP_FIELDS:
            object.__setattr__(cal, field, payload)
        for sensor in cal.sensors:
            part = cal.part(sensor)
            # the fixed-point header takes raw counts only, so raw_unit is attacked in the
            # float header
            for field in ("unit", "model", "source", *(() if fixed else ("raw_unit",))):
                object.__setattr__(part, field, payload)
            stats = dict(part.stats)
            stats["n"] = payload
            object.__setattr__(part, "stats", stats)
        header = c_fixed_header(cal, prefix="imu") if fixed else c_header(cal, prefix="imu")
        assert all(" " <= c <= "~" or c == "\n" for c in header)
        _compile_and_inspect(tmp_path, header, f"{case}-{fixed}", fixed)


def test_comment_text_properties():
    from triaxcal.export._cgen import c_comment_text

    for payload in CORPUS.values():
        t = c_comment_text(payload)
        assert all(" " <= c <= "~" for c in t), repr(t)
        for bad in ("*/", "/*", "??", "\\"):
            assert bad not in t
        assert len(t) <= 300
    # and the parts a person should still read survive
    assert c_comment_text("IMU-7 (bench 2) 48 \u00b5T, caf\u00e9") == "IMU-7 (bench 2) 48 uT, cafe"


@pytest.mark.parametrize("text,why", [
    ("/* a */\nint x;\n#include <stdio.h>\n", "includes"),
    ("/* a /* b */\n", "nested comment"),
    ("/* a \n", "unclosed"),
    ("int x; */\n", "never opened"),
    ("/* \u202e */\n", "printable ASCII"),
    ("/* ??/ */\n", "trigraph"),
    ("#pragma once\n", "directive"),
])
def test_verify_header_refuses_what_the_generator_never_writes(text, why):
    from triaxcal.export._cgen import _verify_header

    with pytest.raises(tc.CalibrationError, match=why):
        _verify_header(text, ())


def test_prefix_is_validated():
    cal = _base_cal()
    for bad in ("9lives", "", "x" * 41, " "):
        with pytest.raises(tc.CalibrationError, match="prefix"):
            c_header(cal, prefix=bad)
    assert "my_imu_accel_apply(" in c_header(cal, prefix="my-imu")
