"""The fast call of ``fit_ellipsoid`` (``rust/py/fit.rs``): the core takes the user's arguments
as they are, fits only when each is already plain and valid, and builds the result object
itself; anything else goes through the facade's validation. These tests check that the fast
call accepts nothing the facade would refuse, gives bit-for-bit the facade's result, and builds
the same object the dataclass would."""

from __future__ import annotations

import dataclasses
import itertools
import math
import pickle

import numpy as np
import pytest
import triaxcal as tc
from _synth import distorted_sphere
from triaxcal import _core
from triaxcal.fit.ellipsoid import PARAM_NAMES, EllipsoidFit, _check_options

MATRIX = np.array([[1.04, 0.01, -0.02], [0.01, 0.97, 0.015], [-0.02, 0.015, 1.01]]) / 16384
RAW, _ = distorted_sphere(60, offset=[300.0, -120.0, 80.0], matrix=MATRIX, noise=0.01, seed=11)
RAW = np.ascontiguousarray(RAW)


def _slow(points, **kw) -> EllipsoidFit:
    """The facade's validating route, taken by handing it a list instead of an array."""
    return tc.fit_ellipsoid(points.tolist(), **kw)


def _same(a: EllipsoidFit, b: EllipsoidFit) -> None:
    for f in dataclasses.fields(EllipsoidFit):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if isinstance(x, np.ndarray):
            np.testing.assert_array_equal(x, y, err_msg=f.name)
            assert x.dtype == y.dtype and x.shape == y.shape, f.name
        else:
            assert x == y or (isinstance(x, float) and math.isnan(x) and math.isnan(y)), f.name


@pytest.mark.parametrize("model", ["sphere", "axis", "full"])
@pytest.mark.parametrize("radius", [None, 1.0, 16384])
def test_fast_call_gives_the_facades_result_bit_for_bit(model, radius):
    fast = _core.fit_ellipsoid(
        RAW, EllipsoidFit, model, radius, 100, 1e-10, "lm", True, None, ()
    )
    assert fast is not None
    assert fast.model == model and fast.param_names == PARAM_NAMES[model]
    assert fast.stderr.shape == (len(PARAM_NAMES[model]),)
    _same(fast, _slow(RAW, model=model, radius=radius))
    _same(fast, tc.fit_ellipsoid(RAW, model=model, radius=radius))


def test_fast_result_is_the_dataclass_with_every_field_and_nothing_else():
    fit = tc.fit_ellipsoid(RAW, radius=1.0)
    assert type(fit) is EllipsoidFit
    assert list(vars(fit)) == [f.name for f in dataclasses.fields(EllipsoidFit)]
    assert fit.param_names == PARAM_NAMES["full"] and fit.fixed == () and fit.model_reason is None
    for name in ("offset", "matrix", "stderr"):
        arr = getattr(fit, name)
        assert arr.dtype == np.float64 and arr.flags.c_contiguous
        assert not arr.flags.writeable, name
        with pytest.raises(ValueError):
            arr[0] = 1.0
    assert fit.matrix.shape == (3, 3) and fit.stderr.shape == (9,)
    with pytest.raises(dataclasses.FrozenInstanceError):
        fit.rms = 0.0  # type: ignore[misc]
    again = pickle.loads(pickle.dumps(fit))
    _same(again, fit)
    assert dataclasses.replace(fit, model_reason="x").model_reason == "x"


# values of every kind for each option: plain valid ones, valid ones of other types (which the
# facade converts), and invalid ones
OPTION_VALUES = {
    "model": ["full", "axis", "sphere", "Full", "auto ", np.str_("full"), b"full", None, 3],
    "radius": [None, 1.0, 16384, 0.0, -1.0, math.inf, math.nan, np.float64(2.0), np.int64(3),
               True, 10**400, "1.0", 2**63],
    "max_iter": [0, 100, 1_000_000, 1_000_001, -1, True, 5.0, np.int32(5), 2**70],
    "tol": [0.0, 1e-10, 0, 0.999, 1.0, -1e-12, math.nan, np.float32(1e-6), False, "0"],
    "method": ["lm", "gn", "algebraic", "LM", None],
    "debias": [True, False, np.bool_(True), 1, None],
}


def _accepts(opts) -> bool:
    try:
        _check_options(*opts)
    except tc.CalibrationError:
        return False
    return True


def _plain(case) -> bool:
    """Each option of the type the facade's validation returns it as (or an int for a float)."""
    real = (float, int)
    return (
        type(case["model"]) is str and type(case["method"]) is str
        and (case["radius"] is None or type(case["radius"]) in real)
        and type(case["max_iter"]) is int and type(case["tol"]) in real
        and type(case["debias"]) is bool
    )


def test_fast_call_accepts_no_option_the_facade_refuses():
    """Over the values above (one option varied at a time, and pairs of unusual ones): the core
    fits straight away exactly when every option is plain and the facade's own validation
    accepts them, and then gives the fit of the validated options; whatever the facade refuses
    still raises its CalibrationError."""
    base = {"model": "full", "radius": 1.0, "max_iter": 100, "tol": 1e-10, "method": "lm",
            "debias": True}
    names = list(base)
    cases = []
    for name in names:
        for v in OPTION_VALUES[name]:
            cases.append({**base, name: v})
    for a, b in itertools.combinations(names, 2):
        for va, vb in itertools.product(OPTION_VALUES[a][-3:], OPTION_VALUES[b][-3:]):
            cases.append({**base, a: va, b: vb})
    fast_count = 0
    for case in cases:
        opts = tuple(case[n] for n in names)
        fast = _core.fit_ellipsoid(RAW, EllipsoidFit, *opts, None, ())
        assert (fast is not None) == (_plain(case) and _accepts(opts)), case
        if fast is None:
            continue
        fast_count += 1
        _same(fast, _core.fit_ellipsoid(RAW, EllipsoidFit, *_check_options(*opts), None, ()))
    refused = [c for c in cases if not _accepts(tuple(c[n] for n in names))]
    assert len(refused) > 50 and fast_count > 15
    for case in refused:
        with pytest.raises(tc.CalibrationError):
            tc.fit_ellipsoid(RAW, **case)


class _Sub(np.ndarray):
    pass


def _unaligned(a: np.ndarray) -> np.ndarray:
    buf = np.zeros(a.nbytes + 1, dtype=np.uint8)
    out = np.frombuffer(buf[1:].data, dtype=np.float64).reshape(a.shape)
    out[...] = a
    return out


@pytest.mark.parametrize(
    "make",
    [
        lambda a: a.tolist(),
        lambda a: np.asfortranarray(a),
        lambda a: a.astype(">f8"),
        lambda a: a.astype(np.float32),
        lambda a: np.round(a).astype(np.int16),
        lambda a: a.view(_Sub),
        lambda a: np.ma.masked_array(a),
        _unaligned,
        lambda a: np.repeat(a, 2, axis=0)[::2],
    ],
    ids=["list", "fortran", "big-endian", "float32", "int16", "subclass", "masked",
         "unaligned", "strided"],
)
def test_points_that_are_not_plain_go_through_the_facade(make):
    pts = make(RAW)
    assert _core.fit_ellipsoid(pts, EllipsoidFit, "full", 1.0, 100, 1e-10, "lm", True,
                               None, ()) is None
    fit = tc.fit_ellipsoid(pts, radius=1.0)
    converted = tc.fit_ellipsoid(np.ascontiguousarray(np.asarray(pts, dtype=np.float64)),
                                 radius=1.0)
    _same(fit, converted)


def test_read_only_points_are_fitted_in_place():
    pts = RAW.copy()
    pts.setflags(write=False)
    fast = _core.fit_ellipsoid(pts, EllipsoidFit, "full", 1.0, 100, 1e-10, "lm", True, None, ())
    assert fast is not None
    _same(fast, tc.fit_ellipsoid(RAW, radius=1.0))


@pytest.mark.parametrize("n", [1024, 1025, 5000])
def test_fits_either_side_of_the_gil_threshold_agree(n):
    """Up to 1,024 points the core reads the array in place under the GIL; above, it borrows
    the array and releases the GIL. Either way the result is the facade's validating route's."""
    pts, _ = distorted_sphere(n, offset=[300.0, -120.0, 80.0], matrix=MATRIX, noise=0.01, seed=3)
    pts = np.ascontiguousarray(pts)
    fast = _core.fit_ellipsoid(pts, EllipsoidFit, "full", 1.0, 100, 1e-10, "lm", True, None, ())
    assert fast is not None and fast.n == n
    _same(fast, _slow(pts, radius=1.0))


def test_fast_call_keeps_the_errors_of_bad_points():
    bad = RAW.copy()
    bad[3, 1] = np.nan
    with pytest.raises(tc.NonFiniteError, match="NaN"):
        tc.fit_ellipsoid(bad, radius=1.0)
    with pytest.raises(tc.TooFewPointsError):
        tc.fit_ellipsoid(RAW[:5], radius=1.0)
    with pytest.raises(tc.CalibrationError, match="shape"):
        tc.fit_ellipsoid(np.zeros((10, 4)), radius=1.0)


needs_hooks = pytest.mark.skipif(
    not hasattr(_core, "repeat_call"),
    reason="the benchmark hooks are built only by `make install` (cargo feature bench-hooks)")


@needs_hooks
def test_time_fit_times_the_compiled_fit_and_refuses_what_it_cannot_time():
    s = _core.time_fit(RAW[:10], 1.0, 50)
    assert 0 < s < 0.01
    with pytest.raises(tc.CalibrationError, match="at most 1024 points"):
        _core.time_fit(np.zeros((2000, 3)), 1.0, 1)
    with pytest.raises(tc.CalibrationError, match="float64"):
        _core.time_fit(RAW.astype(np.float32), 1.0, 1)


@needs_hooks
def test_repeat_call_calls_and_passes_errors_on():
    seen = []
    assert _core.repeat_call(lambda: seen.append(1), 3) is None
    assert seen == [1, 1, 1]

    def bad():
        raise tc.CalibrationError("stop")

    with pytest.raises(tc.CalibrationError, match="stop"):
        _core.repeat_call(bad, 5)
