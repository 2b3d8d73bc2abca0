"""Hostile input for the public API: every function of ``triaxcal.__all__`` called with each of its
parameters set, one at a time, to the edge values of its kind -- numbers (0, -1, -0.0, 1e308,
1e-308, the smallest denormal, NaN and inf of Python and numpy, integers past a double, a
string of digits, a unicode digit, a bool, a complex, None), arrays (NaN, inf, 1e308, denormal,
empty, one row, wrong shape, 3-D, object, complex, bool, text, ragged, masked, float16, uint64,
non-contiguous), strings (empty, terminal escapes, bidi, NUL, 100 kB); then arrays drawn by
hypothesis; then calibrations built from hostile values.

Every call must end in a result whose coefficients are finite, or a
:class:`~triaxcal.CalibrationError`: never another exception, a numpy warning (an overflow or an
invalid value leaking out as NaN), or a call that runs on (each is stopped after a time limit).
The valid call of each function and the edge values are in _hostile_api.py.
"""

from __future__ import annotations

import inspect

import numpy as np
import pytest
import triaxcal as tc
from _hostile_api import Call, base_calls, edge_values, outcome
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

#: Public functions the corpus does not call here, and where their hostile input is tested.
ELSEWHERE = {"read_log": "test_hostile_logs.py (mutated logs of every format)"}


@pytest.fixture(scope="module")
def calls(tmp_path_factory):
    return base_calls(tmp_path_factory.mktemp("api"))


def _functions() -> list[str]:
    return [n for n in tc.__all__ if inspect.isfunction(getattr(tc, n))]


#: The validated requests and records among the public classes (the others are results).
CLASSES = ("SensorCalibration", "TemperatureTerms", "Calibration", "Alignment", "FitRequest",
           "SourceOptions", "FieldOptions", "PoseSettings", "PoseDetector", "AllanAccumulator",
           "NoiseRequest", "Stream")


def test_every_public_function_is_in_the_corpus(calls):
    missing = set(_functions()) - set(calls) - set(ELSEWHERE)
    assert not missing, f"public functions without a hostile-input case: {sorted(missing)}"
    for name, call in calls.items():
        assert outcome(lambda c=call: c.fn(*c.args, **c.kwargs)) == "ok", name


def _parameters(call: Call) -> dict[str, object]:
    """Each parameter's valid value: the one the call gives, else its default."""
    given_ = call.params()
    out = {}
    for p in inspect.signature(call.fn).parameters.values():
        if p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD):
            continue
        if p.name in given_:
            out[p.name] = given_[p.name]
        elif p.default is not p.empty:
            out[p.name] = p.default
    return out


#: Functions whose every accepted call draws a figure or searches the sphere for empty caps
#: (0.1 to 0.5 s each): they get a representative share of the edge values.
HEAVY = {"quality_report", "plot_report", "plot_allan", "write_outputs", "align_mag_accel"}
_SHARE = {"nan", "1e308", "1e-308", "-1", "2**80", "None", "str-1", "complex", "opaque",
          "nan-one", "inf", "empty", "one-row", "wrong-width", "object-mixed", "strings",
          "esc", "long", "dict", "ragged", "huge-scaled"}
#: The report's figure and quality report (0.3 to 0.5 s a call) take a smaller share.
_SMALL_SHARE = {"nan", "1e308", "-1", "None", "str-1", "nan-one", "empty", "one-row",
                "wrong-width", "esc", "huge-scaled"}


@pytest.mark.timeout(120, method="thread")
@pytest.mark.parametrize("name", sorted(set(_functions()) - set(ELSEWHERE)) + list(CLASSES))
def test_each_parameter_at_its_edges(name, calls, tmp_path, monkeypatch):
    """One parameter at a time set to each edge value: a result or a CalibrationError."""
    monkeypatch.chdir(tmp_path)  # a path-like edge value ("session.csv") stays here
    call = calls[name]
    failures = {}
    for param, value in _parameters(call).items():
        for label, edge in edge_values(value).items():
            if name in HEAVY and label not in (
                    _SMALL_SHARE if name in ("plot_report", "quality_report") else _SHARE):
                continue
            got = outcome(call.with_(param, edge), limit_s=10.0)
            if got not in ("ok", "refused"):
                failures[f"{param}={label}"] = got
    assert not failures, f"{name}: {len(failures)} failures:\n" + "\n".join(
        f"  {k}: {v}" for k, v in failures.items())


# --------------------------------------------------------------------------------------------
# readings drawn by hypothesis


def _finite_or_not(width: int = 64):
    return st.floats(allow_nan=True, allow_infinity=True, width=width)


@st.composite
def readings(draw, channels: int = 3, max_rows: int = 60):
    """Arrays of readings: anything from hypothesis's floats (NaN, inf, subnormals, 1e308)
    to an ellipsoid with a few entries replaced by extremes; int16 and float32 now and then."""
    n = draw(st.integers(0, max_rows))
    kind = draw(st.sampled_from(["any", "spiked", "scaled", "int16", "float32"]))
    if kind == "any":
        return draw(hnp.arrays(np.float64, (n, channels), elements=_finite_or_not()))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    u = rng.normal(size=(n, channels))
    u /= np.maximum(np.linalg.norm(u, axis=1, keepdims=True), 1e-12)
    base = u * 16384 + rng.normal(0, 30, (n, channels))
    if kind == "scaled":
        return base * draw(st.sampled_from([1e-320, 1e-300, 1e-15, 1e15, 1e300]))
    if kind == "int16":
        return base.clip(-32768, 32767).astype(np.int16)
    if kind == "float32":
        return base.astype(np.float32)
    spikes = draw(st.lists(st.tuples(st.integers(0, max(n * channels - 1, 0)),
                                     _finite_or_not()), max_size=4))
    flat = base.reshape(-1)
    for at, v in spikes:
        if flat.size:
            flat[at] = v
    return base


#: Functions of readings: the first argument drawn, the other arguments valid.
_OF_READINGS = {
    "fit_ellipsoid": lambda x: tc.fit_ellipsoid(x, radius=1.0),
    "fit_sphere": lambda x: tc.fit_sphere(x),
    "fit_sphere_linear": tc.fit_sphere_linear,
    "fit_robust": lambda x: tc.fit_robust(x, radius=1.0),
    "fit_auto": lambda x: tc.fit_auto(x, radius=1.0),
    "sphere_center": lambda x: tc.sphere_center(x, 16384.0),
    "detect_poses": lambda x: tc.detect_poses(x, window=5, threshold=500.0),
    "detect_still": lambda x: tc.detect_still(x, rate_hz=10.0, rest_s=1.0, window_s=0.5),
    "six_position": tc.six_position,
    "fit_yaw": lambda x: tc.fit_yaw(x),
    "bootstrap": lambda x: tc.bootstrap(x, model="sphere", n_boot=20),
    "allan": lambda x: tc.allan(x, 10.0),
    "noise_figures": lambda x: tc.noise_figures(x, 10.0),
    "check_rest": lambda x: tc.check_rest(x, 10.0),
    "gyro_bias": lambda x: tc.gyro_bias(x),
    "find_rotations": lambda x: tc.find_rotations(x, rate_hz=10.0, rest_s=1.0),
    "autocalibrate": lambda x: tc.autocalibrate(x, 10.0, window_s=1.0, min_hours=0.0),
    "fit_temperature": lambda x: tc.fit_temperature(x, np.linspace(20, 40, len(x))),
    "information_criterion": lambda x: tc.information_criterion(
        tc.fit_ellipsoid(np.eye(3).repeat(3, 0) * [1, 2, 3] + 0.1 * np.arange(9)[:, None],
                         model="sphere"), x),
}


@pytest.mark.timeout(120, method="thread")
@pytest.mark.parametrize("name", sorted(_OF_READINGS))
def test_functions_of_readings_on_drawn_arrays(name):
    """Arrays drawn by hypothesis: a result with finite coefficients or a CalibrationError."""
    fn = _OF_READINGS[name]

    @settings(max_examples=25, deadline=None, derandomize=True, database=None,
              suppress_health_check=list(HealthCheck))
    @given(readings())
    def run(x):
        got = outcome(lambda: fn(x), limit_s=10.0)
        assert got in ("ok", "refused"), f"{name} on {x.dtype} {x.shape}: {got}"

    run()
