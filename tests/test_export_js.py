"""export --format js / js-espruino: the module runs under node and computes cal.apply."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
import triaxcal as tc
from triaxcal.cli import main
from triaxcal.export.js import js_module, js_string

NODE = shutil.which("node")
needs_node = pytest.mark.skipif(NODE is None, reason="node is not installed")


def _cal(sensor_id: str = "board-7") -> tc.Calibration:
    rng = np.random.default_rng(3)
    m = np.eye(3) / 16384 + rng.normal(0, 1e-7, (3, 3))  # not symmetric: offdiag_lower too
    accel = tc.SensorCalibration(offset=[812.5, -244.25, 650.0], matrix=m, unit="g",
                                 radius=1.0, model="full")
    terms = tc.TemperatureTerms(temp_ref_c=25.0, temp_range_c=(10.0, 40.0),
                                offset_poly=[[0, 0, 0], [2.5, -1.25, 0.5], [0.01, 0, -0.02]],
                                gain_poly=[[0, 0, 0], [1e-4, -2e-4, 5e-5]])
    gyro = tc.SensorCalibration(offset=[211.0, 188.0, 222.0], matrix=np.eye(3) / 131,
                                unit="deg/s", model="axis", temperature=terms)
    mag = tc.SensorCalibration(offset=[-210.7, 246.9, 300.8],
                               matrix=np.array([[0.1035, 0.0, -0.0027], [0.0, 0.102, 0.0],
                                                [-0.0027, 0.0, 0.1057]]),
                               unit="uT", radius=50.0, model="full")
    return tc.Calibration(accel=accel, gyro=gyro, mag=mag, sensor_id=sensor_id)


_RUNNER = """
import { readFileSync } from "fs";
import { createRequire } from "module";
const require = createRequire(import.meta.url);
const esm = await import(process.argv[2]);
const plain = require(process.argv[3]);
const cases = JSON.parse(readFileSync(process.argv[4], "utf8"));
const out = { esm: [], plain: [], sensorId: esm.calibration.sensorId,
              plainSensorId: plain.calibration.sensorId, units: {}, errors: [],
              injected: typeof globalThis.injected };
for (const c of cases) {
  const args = c.temp === null ? [c.sensor, c.raw] : [c.sensor, c.raw, c.temp];
  out.esm.push(esm.apply(...args));
  out.plain.push(plain.apply(...args));
}
for (const s of Object.keys(esm.calibration.parts)) {
  out.units[s] = [esm.calibration.parts[s].rawUnit, esm.calibration.parts[s].unit];
}
for (const bad of [["gyro", [1, 2, 3]], ["pressure", [1, 2, 3]], ["accel", [1, 2]],
                   ["constructor", [1, 2, 3]]]) {
  try { esm.apply(...bad); out.errors.push(null); } catch (e) { out.errors.push(e.message); }
}
console.log(JSON.stringify(out));
"""


def _run_node(tmp_path: Path, cal: tc.Calibration, cases: list[dict]) -> dict:
    (tmp_path / "cal.mjs").write_text(js_module(cal, form="esm"))
    (tmp_path / "cal.js").write_text(js_module(cal, prefix="imu", form="espruino"))
    (tmp_path / "cases.json").write_text(json.dumps(cases))
    (tmp_path / "run.mjs").write_text(_RUNNER)
    res = subprocess.run([NODE, str(tmp_path / "run.mjs"), str(tmp_path / "cal.mjs"),
                          str(tmp_path / "cal.js"), str(tmp_path / "cases.json")],
                         capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout)


@needs_node
def test_node_computes_what_cal_apply_computes(tmp_path):
    cal = _cal()
    rng = np.random.default_rng(1)
    cases = []
    for sensor in cal.sensors:
        for raw in rng.uniform(-32768, 32767, (40, 3)).round():
            temp = float(rng.uniform(5, 45)) if sensor == "gyro" else None
            cases.append({"sensor": sensor, "raw": raw.tolist(), "temp": temp})
    out = _run_node(tmp_path, cal, cases)
    want = np.array([cal.apply([c["raw"]], sensor=c["sensor"], temperature=c["temp"])[0]
                     for c in cases])
    for form in ("esm", "plain"):
        got = np.array(out[form])
        np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-13 * np.abs(want).max())
    assert out["sensorId"] == out["plainSensorId"] == "board-7"
    assert out["units"] == {"accel": ["counts", "g"], "gyro": ["counts", "deg/s"],
                            "mag": ["counts", "uT"]}
    assert "temperature terms" in out["errors"][0]
    assert out["errors"][1].startswith("no calibration for sensor pressure")
    assert out["errors"][2].startswith("raw must be 3 numbers")
    assert out["errors"][3].startswith("no calibration for sensor constructor")


HOSTILE = [
    '"; globalThis.injected = 1; "',
    "*/ globalThis.injected = 1; /*",
    "line\nbreak globalThis.injected = 1;",
    "para\u2028graph\u2029 globalThis.injected = 1;",
    "</script><script>globalThis.injected = 1</script>",
    "\\\"); globalThis.injected = 1; //",
    "bidi \u202e reversed \x00 nul \x7f del",
    "x" * 10_000,
]


@needs_node
@pytest.mark.parametrize("text", HOSTILE, ids=range(len(HOSTILE)))
def test_every_string_stays_a_string(tmp_path, text):
    """Calibration files are validated on load (control characters are refused there), so the
    attack is forced into the objects: the generator alone must keep every string a string."""
    cal = _cal()
    object.__setattr__(cal, "sensor_id", text)
    for field in ("raw_unit", "unit"):
        object.__setattr__(cal.accel, field, text)
    out = _run_node(tmp_path, cal, [{"sensor": "accel", "raw": [0, 0, 16384], "temp": None}])
    assert out["injected"] == "undefined"
    assert out["sensorId"] == out["plainSensorId"] == text
    assert out["units"]["accel"] == [text, text]
    for name in ("cal.mjs", "cal.js"):
        body = (tmp_path / name).read_text()
        assert body.isascii() and "</script" not in body and "\u2028" not in body


def test_the_espruino_form_is_ecmascript_5():
    pyjsparser = pytest.importorskip("pyjsparser")
    text = js_module(_cal(sensor_id=HOSTILE[0]), prefix="imu", form="espruino")
    pyjsparser.PyJsParser().parse(text)  # raises on anything beyond ECMAScript 5.1
    with pytest.raises(Exception, match="ECMA 5.1"):
        pyjsparser.PyJsParser().parse(js_module(_cal(), form="esm"))


def test_prefix_and_form_are_validated():
    for bad in ("1abc", "a-b", "var", "function", "exports", "", "x" * 65, "a b"):
        with pytest.raises(tc.CalibrationError, match="JavaScript name"):
            js_module(_cal(), prefix=bad, form="espruino")
    with pytest.raises(tc.CalibrationError, match="form"):
        js_module(_cal(), form="commonjs")
    assert js_string("a/b") == '"a\\/b"'
    with pytest.raises(tc.CalibrationError):
        js_string(3)  # type: ignore[arg-type]


@needs_node
def test_cli_export_js(tmp_path, capsys):
    path = tmp_path / "cal.json"
    _cal().save(path)
    for fmt, name in (("js", "cal.mjs"), ("js-espruino", "cal.js")):
        assert main(["export", str(path), "--format", fmt, "--prefix", "imu", "-o",
                     str(tmp_path / name)]) == 0
    script = tmp_path / "use.cjs"
    script.write_text('const imu = require("./cal.js");\n'
                      'console.log(JSON.stringify(imu.apply("accel", [812.5, -244.25, 17034])));\n')
    res = subprocess.run([NODE, str(script)], capture_output=True, text=True, timeout=60,
                         cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    got = json.loads(res.stdout)
    np.testing.assert_allclose(got, _cal().apply([[812.5, -244.25, 17034]])[0], rtol=1e-13)
