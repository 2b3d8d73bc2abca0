"""JavaScript module: the coefficients and an ``apply`` function, for a browser, node or an
Espruino board (the spreadsheet sphere fit coded its coefficients into an Espruino program).

Two forms of the same code:

* ``js`` (:func:`js_module`) -- an ES module: ``import { calibration, apply } from
  "./calibration.mjs"``;
* ``js-espruino`` (:func:`js_module` with ``form="espruino"``) -- plain ECMAScript 5.1, which
  Espruino's interpreter runs pasted into its IDE or uploaded as a module: a global
  ``<prefix>`` object with ``calibration`` and ``apply``, also set on ``exports`` when loaded
  with ``require()`` (node, Espruino modules).

``apply(sensor, raw, tempC)`` returns ``matrix * (raw - offset(T)) * gain(T)`` as
:meth:`triaxcal.SensorCalibration.apply` does: the matrix **multiplies**, offsets are in raw
units, ``tempC`` (deg C) is required when the part has temperature terms. Numbers are written
with Python's ``repr`` (the shortest text that reads back to the same double), so the module
computes what ``cal.apply`` computes to the last bits of the arithmetic.

Every string of the calibration (sensor id, units, model...) goes into the module only as a
string literal escaped to ASCII (quotes, backslashes, control and non-ASCII characters,
``<``, ``>``, ``&`` and ``/`` as escapes), never into a comment or an identifier; the prefix
must be a plain identifier that is not a reserved word.
"""

from __future__ import annotations

import json
import math
import re
from typing import Any

from ..calibration.file import Calibration
from ..calibration.part import SensorCalibration
from ..errors import CalibrationError
from ._trust import mark_lines, prepare

__all__ = ["JS_FORMS", "js_module", "js_string"]

#: The forms :func:`js_module` writes.
JS_FORMS = ("esm", "espruino")

_RESERVED = frozenset("""
    abstract arguments await boolean break byte case catch char class const continue debugger
    default delete do double else enum eval export extends false final finally float for
    function goto if implements import in instanceof int interface let long native new null
    package private protected public return short static super switch synchronized this throw
    throws transient true try typeof undefined var void volatile while with yield NaN Infinity
    exports require module
""".split())


def js_string(text: Any) -> str:
    """A JavaScript string literal for ``text``, ASCII only and safe inside HTML.

    >>> js_string('x */ "y" \\u2028 </script>')
    '"x *\\\\/ \\\\"y\\\\" \\\\u2028 \\\\u003c\\\\/script\\\\u003e"'
    """
    if not isinstance(text, str):
        raise CalibrationError(f"expected a string, got {type(text).__name__}")
    s = json.dumps(text, ensure_ascii=True)
    return (s.replace("/", "\\/").replace("<", "\\u003c").replace(">", "\\u003e")
            .replace("&", "\\u0026"))


def _ident(prefix: str) -> str:
    if not isinstance(prefix, str) or not re.fullmatch(r"[A-Za-z_$][A-Za-z0-9_$]{0,63}", prefix) \
            or prefix in _RESERVED:
        raise CalibrationError(
            f"prefix {prefix!r} is not a usable JavaScript name: letters, digits, _ and $, not "
            "starting with a digit, not a reserved word (e.g. 'imu')"
        )
    return prefix


def _num(v: Any) -> str:
    f = float(v)
    if not math.isfinite(f):
        raise CalibrationError(f"cannot write {f} into a JavaScript module")
    return repr(f)


def _vec(v: Any) -> str:
    return "[" + ", ".join(_num(x) for x in v) + "]"


def _rows(m: Any) -> str:
    return "[" + ", ".join(_vec(r) for r in m) + "]"


def _part(part: SensorCalibration, indent: str, reasons: tuple[str, ...] | None = None) -> str:
    t = part.temperature
    if t is None:
        temp = "null"
    else:
        gain = "null" if t.gain_poly is None else _rows(t.gain_poly)
        temp = (f"{{tempRefC: {_num(t.temp_ref_c)}, tempRangeC: {_vec(t.temp_range_c)}, "
                f"offsetPoly: {_rows(t.offset_poly)}, gainPoly: {gain}}}")
    radius = "null" if part.radius is None else _num(part.radius)
    model = "null" if part.model is None else js_string(part.model)
    fields = [
        f"rawUnit: {js_string(part.raw_unit)}",
        f"unit: {js_string(part.unit)}",
        f"offset: {_vec(part.offset)}",
        f"matrix: {_rows(part.matrix)}",
        f"radius: {radius}",
        f"model: {model}",
        f"temperature: {temp}",
    ]
    if reasons is not None:
        fields += ["valid: false",
                   "invalidReasons: [" + ", ".join(js_string(r) for r in reasons) + "]"]
    return "{\n" + ",\n".join(indent + "  " + f for f in fields) + "\n" + indent + "}"


_APPLY = """\
function apply(sensor, raw, tempC) {
  var p = calibration.parts.hasOwnProperty(sensor) ? calibration.parts[sensor] : null;
  if (!p) {
    throw new Error("no calibration for sensor " + String(sensor));
  }
  if (!raw || raw.length !== 3) {
    throw new Error("raw must be 3 numbers in " + p.rawUnit);
  }
  var d = [raw[0] - p.offset[0], raw[1] - p.offset[1], raw[2] - p.offset[2]];
  var t = p.temperature;
  if (t) {
    if (typeof tempC !== "number" || !isFinite(tempC)) {
      throw new Error("this part has temperature terms: pass tempC in deg C (" + t.tempRefC +
                      " skips the correction)");
    }
    var dt = tempC - t.tempRefC;
    for (var i = 0; i < 3; i++) {
      var off = 0;
      var k;
      for (k = t.offsetPoly.length - 1; k >= 0; k--) {
        off = off * dt + t.offsetPoly[k][i];
      }
      d[i] -= off;
      if (t.gainPoly) {
        var g = 0;
        for (k = t.gainPoly.length - 1; k >= 0; k--) {
          g = g * dt + t.gainPoly[k][i];
        }
        d[i] *= 1 + g;
      }
    }
  }
  var m = p.matrix;
  return [m[0][0] * d[0] + m[0][1] * d[1] + m[0][2] * d[2],
          m[1][0] * d[0] + m[1][1] * d[1] + m[1][2] * d[2],
          m[2][0] * d[0] + m[2][1] * d[1] + m[2][2] * d[2]];
}"""


def js_module(cal: Calibration, *, prefix: str = "triaxcal", form: str = "esm",
              force: bool = False) -> str:
    """The calibration as a JavaScript module (see the module docstring).

    Parameters
    ----------
    cal : Calibration
    prefix : str
        ``espruino`` form: the name of the global object (``imu.apply("accel", raw)``).
    form : {"esm", "espruino"}
        ES module, or plain ECMAScript 5.1 for Espruino, ``<script>`` and ``require()``.
    force : bool
        Write parts the validity gate refuses; the module then says so in a comment and in
        the part (``valid: false``, ``invalidReasons``).

    Examples
    --------
    >>> import numpy as np, triaxcal as tc
    >>> part = tc.SensorCalibration(offset=[10, 0, 0], matrix=np.eye(3) / 16384, unit="g")
    >>> text = js_module(tc.Calibration(accel=part), form="espruino")
    >>> "var triaxcal = (function () {" in text and "export {" not in text
    True
    """
    if not isinstance(cal, Calibration):
        raise CalibrationError(f"expected a Calibration, got {type(cal).__name__}")
    if form not in JS_FORMS:
        raise CalibrationError(f"form must be one of {JS_FORMS}, got {form!r}")
    name = _ident(prefix)
    prep = prepare(cal, fmt="a JavaScript module", force=force)
    cal = prep.cal
    bad = {s: v.reasons for s, v in prep.invalid}
    ind = "  " if form == "espruino" else ""
    parts = ",\n".join(f"{ind}    {s}: {_part(cal.part(s), ind + '    ', bad.get(s))}"
                        for s in cal.sensors)
    obj = (
        f"{ind}var calibration = {{\n"
        f"{ind}  schema: {js_string('triaxcal.calibration/1')},\n"
        f"{ind}  sensorId: {js_string(cal.sensor_id)},\n"
        f"{ind}  createdUtc: {js_string(cal.created_utc)},\n"
        f"{ind}  libraryVersion: {js_string(cal.library_version)},\n"
        f"{ind}  parts: {{\n{parts}\n{ind}  }}\n"
        f"{ind}}};"
    )
    apply_fn = "\n".join(ind + ln if ln else ln for ln in _APPLY.splitlines())
    head = (
        "// Sensor calibration written by triaxcal: calibrated = matrix * (raw - offset(T)) *\n"
        "// gain(T); the matrix multiplies, offsets are in raw units (see rawUnit, unit).\n"
        f"// Sensors: {', '.join(cal.sensors)}. apply(sensor, raw, tempC) -> [x, y, z].\n"
        + "".join(f"// {_comment(line)}\n" for line in (*mark_lines(prep.invalid), *prep.notes))
    )
    if form == "esm":
        return (head + "\n" + obj + "\n\n" + apply_fn + "\n\n"
                "export { calibration, apply };\n"
                "export default { calibration: calibration, apply: apply };\n")
    return (
        head + "// Plain ECMAScript 5.1 (Espruino, <script>, require()).\n\n"
        f"var {name} = (function () {{\n{obj}\n\n{apply_fn}\n\n"
        "  return { calibration: calibration, apply: apply };\n"
        "})();\n"
        'if (typeof exports !== "undefined") {\n'
        f"  exports.calibration = {name}.calibration;\n"
        f"  exports.apply = {name}.apply;\n"
        "}\n"
    )


def _comment(text: str) -> str:
    """Text safe in a ``//`` comment: printable ASCII on one line (no line terminator, which
    in JavaScript includes U+2028 and U+2029, can end the comment)."""
    return "".join(ch if " " <= ch <= "~" else "?" for ch in str(text))[:4000]
