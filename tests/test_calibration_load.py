"""Calibration.load validates every value of a shared file: one test per rule.

Each case is a small change to a valid file (or a file that is not one at all); each must
give a CalibrationError whose message names the problem -- never a traceback, a hang, or a
calibration that loads with a wrong meaning.
"""

from __future__ import annotations

import json
import os
import sys

import numpy as np
import pytest
import triaxcal as tc


def _valid() -> dict:
    temp = tc.TemperatureTerms(temp_ref_c=25.0, temp_range_c=(10.0, 40.0),
                               offset_poly=[[0, 0, 0], [1.5, -0.5, 0.2]],
                               gain_poly=[[0, 0, 0], [1e-4, 0, 0]])
    acc = tc.SensorCalibration(offset=[12.5, -3.25, 100.0], matrix=np.eye(3) / 16384,
                               unit="g", radius=1.0, model="full", temperature=temp,
                               stats={"rms": 0.01, "n": 40, "rejected": [3]},
                               input_sha256="ab" * 32, source="session.csv")
    return tc.Calibration(accel=acc, sensor_id="board-1").to_dict()


def _acc(d: dict) -> dict:
    return d["parts"]["accel"]


def _write(tmp_path, d_or_text) -> os.PathLike:
    p = tmp_path / "cal.json"
    if isinstance(d_or_text, (bytes, bytearray)):
        p.write_bytes(d_or_text)
    else:
        p.write_text(d_or_text if isinstance(d_or_text, str) else json.dumps(d_or_text),
                     encoding="utf-8")
    return p


def test_the_valid_file_loads(tmp_path):
    cal = tc.Calibration.load(_write(tmp_path, _valid()))
    assert cal.accel.model == "full" and cal.accel.temperature.gain_poly.shape == (2, 3)


# (rule, change to the valid dict, words the message must contain)
RULES = [
    ("number given as text", lambda d: _acc(d).update(offset=["12.5", "-3.25", "100"]),
     "accel.offset must hold numbers only, got text"),
    ("radius given as text", lambda d: _acc(d).update(radius="1.0"),
     "accel.radius must be a number, got text"),
    ("boolean as a number", lambda d: _acc(d).update(diag=[True, 1e-4, 1e-4]),
     "accel.diag must hold numbers only, got a boolean"),
    ("boolean radius", lambda d: _acc(d).update(radius=True),
     "accel.radius must be a number, got a boolean"),
    ("overflow to infinity", lambda d: _acc(d).update(offset=[1e308 * 10, 0, 0]),
     "finite"),
    ("diag all zero though invertible", lambda d: _acc(d).update(diag=[0, 0, 0],
                                                                  offdiag=[1, 1, 1]),
     "diagonal (diag) is all zero"),
    ("nearly singular matrix", lambda d: _acc(d).update(diag=[1, 1, 1],
                                                         offdiag=[1, 1, 1 - 1e-14]),
     "singular"),
    ("unknown model name", lambda d: _acc(d).update(model="x */ int injected; /*"),
     "not a known model"),
    ("model not text", lambda d: _acc(d).update(model=3), "accel.model must be text"),
    ("offset_poly of degree 4", lambda d: _acc(d)["temperature"].update(
        offset_poly=[[0, 0, 0]] * 5), "at most degree 3"),
    ("gain_poly with 4 columns", lambda d: _acc(d)["temperature"].update(
        gain_poly=[[0, 0, 0, 0], [1, 2, 3, 4]]), "shape"),
    ("gain_poly ragged", lambda d: _acc(d)["temperature"].update(
        gain_poly=[[0, 0, 0], [1, 2]]), "rectangular"),
    ("temperature below absolute zero", lambda d: _acc(d)["temperature"].update(
        temp_ref_c=-300), "absolute zero"),
    ("sensor_id too long", lambda d: d.update(sensor_id="A" * 10_000),
     "sensor_id is 10000 characters long; at most 256"),
    ("unit too long", lambda d: _acc(d).update(unit="g" * 33), "at most 32"),
    ("source too long", lambda d: _acc(d).update(source="/" * 5000), "at most 4096"),
    ("bidi character in sensor_id", lambda d: d.update(sensor_id="board\u202e1"), "U+202E"),
    ("newline in unit", lambda d: _acc(d).update(unit="g\n#include <x>"), "U+000A"),
    ("unpaired surrogate in free text", lambda d: d.update(extra={"note": "\ud800"}),
     "surrogate"),
    ("blank unit", lambda d: _acc(d).update(unit="  "), "must not be empty"),
    ("input_sha256 not a hash", lambda d: _acc(d).update(input_sha256="xyz"),
     "64 lowercase hex"),
    ("typed statistic of the wrong type", lambda d: _acc(d)["stats"].update(rms="0.01"),
     "accel.stats.rms must be a number"),
    ("rejected indices not integers", lambda d: _acc(d)["stats"].update(rejected=[1.5]),
     "whole number"),
    ("extra not an object", lambda d: d.update(extra=[1, 2]), "extra must be a JSON object"),
    ("extra nested too deeply", lambda d: d.update(extra={"a": json.loads("[" * 40 + "]" * 40)}),
     "nested"),
]


@pytest.mark.parametrize("rule,mutate,words", RULES, ids=[r[0] for r in RULES])
def test_each_rule(tmp_path, rule, mutate, words):
    d = _valid()
    mutate(d)
    p = _write(tmp_path, d)
    with pytest.raises(tc.CalibrationError) as exc:
        tc.Calibration.load(p)
    assert words in str(exc.value), str(exc.value)[:300]
    assert len(str(exc.value)) < 1000  # a 10,000-character value is not echoed back whole


def _text_rules():
    valid = json.dumps(_valid())
    deep = '{"schema": "triaxcal.calibration/1", "parts": ' + "[" * 100_000 + "]" * 100_000 + "}"
    return [
        ("NaN in the JSON", valid.replace('"radius": 1.0', '"radius": NaN'), "NaN"),
        ("Infinity in the JSON", valid.replace('"radius": 1.0', '"radius": Infinity'),
         "Infinity"),
        ("5000-digit integer", valid.replace('"radius": 1.0', '"radius": ' + "9" * 5000),
         "5000 digits"),
        ("deep nesting", deep, "nested too deeply"),
        ("duplicate key", valid.replace('"sensor_id": "board-1"',
                                        '"sensor_id": "board-1", "sensor_id": "board-2"'),
         "appears twice"),
    ]


@pytest.mark.parametrize("rule,text,words", _text_rules(), ids=[r[0] for r in _text_rules()])
def test_each_rule_of_the_json_text(tmp_path, rule, text, words):
    with pytest.raises(tc.CalibrationError) as exc:
        tc.Calibration.load(_write(tmp_path, text))
    assert words in str(exc.value), str(exc.value)[:300]


def test_a_directory(tmp_path):
    with pytest.raises(tc.CalibrationError, match="is a folder"):
        tc.Calibration.load(tmp_path)


def test_a_file_that_is_not_utf8(tmp_path):
    with pytest.raises(tc.CalibrationError, match="not UTF-8"):
        tc.Calibration.load(_write(tmp_path, b'{"schema": "\xff\xfe"}'))


def test_a_utf8_bom_is_accepted(tmp_path):
    p = _write(tmp_path, b"\xef\xbb\xbf" + json.dumps(_valid()).encode())
    assert tc.Calibration.load(p).sensor_id == "board-1"


def test_a_huge_file(tmp_path):
    p = tmp_path / "huge.json"
    with open(p, "wb") as f:  # sparse: 80 MB of zeros costs no disk
        f.truncate(80 * 1024 * 1024)
    with pytest.raises(tc.CalibrationError, match="larger than any calibration file"):
        tc.Calibration.load(p)


@pytest.mark.skipif(not os.path.exists("/dev/zero"), reason="needs /dev/zero")
def test_an_endless_device_is_refused_unread():
    with pytest.raises(tc.CalibrationError, match="is a character device, not a regular file"):
        tc.Calibration.load("/dev/zero")


def test_a_file_that_cannot_be_read(tmp_path):
    if os.geteuid() == 0:
        pytest.skip("root reads any file")
    p = _write(tmp_path, _valid())
    p.chmod(0)
    with pytest.raises(tc.CalibrationError, match="permission denied"):
        tc.Calibration.load(p)


def test_constructors_apply_the_same_rules():
    part = tc.SensorCalibration(offset=[0, 0, 0], matrix=np.eye(3))
    with pytest.raises(tc.CalibrationError, match="not a known model"):
        tc.SensorCalibration(offset=[0, 0, 0], matrix=np.eye(3), model="magic")
    with pytest.raises(tc.CalibrationError, match="U\\+2066"):
        tc.Calibration(accel=part, sensor_id="a\u2066b")
    with pytest.raises(tc.CalibrationError, match="must hold numbers only"):
        tc.SensorCalibration(offset=[0, "1", 0], matrix=np.eye(3))
    with pytest.raises(tc.CalibrationError, match="too large"):
        tc.SensorCalibration(offset=[0, 10**400, 0], matrix=np.eye(3))


def test_errors_are_calibration_errors_not_tracebacks(tmp_path):
    """A small fuzz: random byte flips of a valid file give either a calibration or a
    CalibrationError, nothing else."""
    rng = np.random.default_rng(0)
    base = bytearray(json.dumps(_valid()).encode())
    for _ in range(300):
        b = bytearray(base)
        for i in rng.integers(0, len(b), size=int(rng.integers(1, 4))):
            b[i] = int(rng.integers(0, 256))
        p = _write(tmp_path, bytes(b))
        try:
            tc.Calibration.load(p)
        except tc.CalibrationError:
            pass
    assert sys.getrecursionlimit() >= 1000
