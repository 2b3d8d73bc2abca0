"""Inputs that used to give wrong answers: repeated or reordered points, unaligned buffers,
huge and tiny magnitudes, and options that were clipped or coerced instead of refused."""

from __future__ import annotations

import time

import numpy as np
import pytest
import triaxcal as tc
from _synth import distorted_sphere
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from triaxcal.fit.select import fit_auto, fit_robust, information_criterion

OFFSET = np.array([412.0, -230.5, 97.25])  # counts
MATRIX = np.array([[1.05, 0.02, -0.01], [0.02, 0.97, 0.015], [-0.01, 0.015, 1.01]]) / 16384.0
SUBSAMPLE_ABOVE = 60_000  # rust/ellipsoid/mod.rs: larger inputs are solved on a subsample first


def _close(a: tc.EllipsoidFit, b: tc.EllipsoidFit, *, offset_se: float, matrix_rel: float):
    """Offsets within ``offset_se`` standard errors, matrices within ``matrix_rel`` relative."""
    assert np.all(np.abs(a.offset - b.offset) <= offset_se * b.stderr[:3]), (a.offset, b.offset)
    scale = np.abs(b.matrix).max()
    assert np.abs(a.matrix - b.matrix).max() <= matrix_rel * scale, (a.matrix, b.matrix)


# ------------------------------------------------------------------ order and repetition


def test_tiled_points_fit_like_their_tile():
    """A 100-point pattern repeated 10,000 times (period 100) used to be refused: the strided
    subsample saw two distinct points. The tile and its repetition have the same minimum."""
    pts100, _ = distorted_sphere(100, offset=OFFSET, matrix=MATRIX, noise=0.003, seed=1)
    big = np.tile(pts100, (10_000, 1))
    small = tc.fit_ellipsoid(pts100, radius=1.0, debias=False)
    tiled = tc.fit_ellipsoid(big, radius=1.0, debias=False)
    assert tiled.converged and tiled.n == 1_000_000
    _close(tiled, small, offset_se=1e-4, matrix_rel=1e-6)
    rob = fit_robust(big, radius=1.0, debias=False)
    rob_small = fit_robust(pts100, radius=1.0, debias=False)
    assert rob.fit.n == 10_000 * rob_small.fit.n  # the same readings rejected, every copy
    _close(rob.fit, rob_small.fit, offset_se=1e-4, matrix_rel=1e-6)
    # period 50 divides any stride the old subsample could take, too
    pts50 = pts100[:50]
    f = tc.fit_ellipsoid(np.tile(pts50, (2000, 1)), radius=1.0, debias=False)
    _close(f, tc.fit_ellipsoid(pts50, radius=1.0, debias=False), offset_se=1e-4, matrix_rel=1e-6)


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    seed=st.integers(0, 2**31),
    n=st.sampled_from([40, 900, 20_000, 90_000]),
    noise=st.sampled_from([0.0, 0.003, 0.03]),
    model=st.sampled_from(["sphere", "axis", "full"]),
)
def test_any_shuffle_gives_the_same_fit(seed, n, noise, model):
    """Property: the fit does not depend on the order of the points beyond round-off, small
    inputs and large (subsampled) ones alike."""
    raw, _ = distorted_sphere(n, offset=OFFSET, matrix=MATRIX, noise=noise, seed=seed % 1000)
    rng = np.random.default_rng(seed)
    a = tc.fit_ellipsoid(raw, model=model, radius=1.0)
    b = tc.fit_ellipsoid(raw[rng.permutation(n)], model=model, radius=1.0)
    scale = 16384.0  # offsets within 1e-9 of the radius in counts, matrices 1e-9 relative
    assert np.abs(a.offset - b.offset).max() <= 1e-9 * scale
    assert np.abs(a.matrix - b.matrix).max() <= 1e-9 * np.abs(a.matrix).max()
    assert abs(a.rms - b.rms) <= 1e-9 * a.rms + 1e-15
    if noise:  # (without noise the standard errors are round-off)
        np.testing.assert_allclose(a.stderr, b.stderr, rtol=1e-6)


@settings(max_examples=10, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    seed=st.integers(0, 2**31),
    base=st.sampled_from([30, 100, 333, 2000]),
    reps=st.integers(2, 400),
    shuffle=st.booleans(),
)
def test_any_tiling_gives_the_fit_of_its_tile(seed, base, reps, shuffle):
    """Property: repeating a point set k times (in order or shuffled) gives the same plain
    least-squares minimum as the set itself (the sums are k times larger)."""
    raw, _ = distorted_sphere(base, offset=OFFSET, matrix=MATRIX, noise=0.003, seed=seed % 997)
    big = np.tile(raw, (reps, 1))
    if shuffle:
        big = big[np.random.default_rng(seed).permutation(len(big))]
    a = tc.fit_ellipsoid(raw, radius=1.0, debias=False)
    b = tc.fit_ellipsoid(big, radius=1.0, debias=False)
    _close(b, a, offset_se=1e-3, matrix_rel=1e-6)


# ------------------------------------------------------------------ unaligned buffers


def _unaligned(a: np.ndarray) -> np.ndarray:
    """A C-contiguous float64 view at byte offset 1 of a buffer (as mmap/Arrow hand out)."""
    a = np.ascontiguousarray(a, dtype=np.float64)
    buf = np.zeros(a.nbytes + 8, dtype=np.uint8)
    v = np.ndarray(a.shape, dtype=np.float64, buffer=buf.data, offset=1)
    v[...] = a
    assert v.flags.c_contiguous and not v.flags.aligned
    return v


def test_unaligned_arrays_are_accepted_by_every_fit():
    raw, _ = distorted_sphere(300, offset=OFFSET, matrix=MATRIX, noise=0.003, seed=4)
    un = _unaligned(raw)
    sphere = distorted_sphere(300, offset=OFFSET, matrix=np.eye(3) / 16384, seed=5)[0]
    sph_un = _unaligned(sphere)
    pairs = [
        lambda p: tc.fit_ellipsoid(p, radius=1.0).offset,
        lambda p: tc.fit_sphere(p).offset,
        lambda p: tc.fit_sphere(p, radius=16384, scale="fixed").offset,
        lambda p: tc.fit_sphere_linear(p).center,
        lambda p: tc.fit_ellipsoid(p, model="auto", radius=1.0).offset,
        lambda p: fit_auto(p, radius=1.0).fit.offset,
        lambda p: fit_robust(p, radius=1.0).fit.offset,
        lambda p: tc.fit_batch(np.stack([p, p]) if p.flags.aligned else _unaligned(
            np.stack([raw, raw])), radius=1.0).offsets,
        lambda p: tc.fit_batch([p, p], radius=1.0).offsets,
        lambda p: tc.fit_ellipsoid(raw, radius=1.0).apply(p),
        lambda p: information_criterion(tc.fit_ellipsoid(raw, radius=1.0), p),
    ]
    for fn in pairs:
        np.testing.assert_array_equal(fn(un), fn(raw))
    searches = [
        lambda p: tc.descend_center(p, 16384.0).center,
        lambda p: tc.grid_center(p, 16384.0, lo=OFFSET - 10, hi=OFFSET + 10, step=5.0).center,
        lambda p: tc.sphere_error(p, OFFSET, 16384.0),
    ]
    for fn in searches:
        np.testing.assert_array_equal(fn(sph_un), fn(sphere))


def test_aligned_contiguous_float64_is_not_copied():
    raw, _ = distorted_sphere(100, offset=OFFSET, matrix=MATRIX, seed=1)
    from triaxcal._checks.arrays import as_points

    assert as_points(raw) is raw
    assert as_points(_unaligned(raw)).flags.aligned


# ------------------------------------------------------------------ huge and tiny magnitudes

S, _ = distorted_sphere(200, offset=[0.1, -0.2, 0.3], matrix=np.diag([1.05, 0.97, 1.0]),
                        noise=0.01, seed=2)


@pytest.mark.parametrize("k", [1e154, 1e300, 1e-300, 1e-160, 1e100])
def test_fits_of_huge_and_tiny_magnitudes_scale_exactly(k):
    """Readings times k fit like the readings: offsets times k, matrices over k (the
    power-of-two rescaling inside is exact, so agreement is to round-off)."""
    base = tc.fit_ellipsoid(S, radius=1.0)
    f = tc.fit_ellipsoid(S * k, radius=1.0)
    np.testing.assert_allclose(f.offset / k, base.offset, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(f.matrix * k, base.matrix, rtol=1e-9, atol=1e-12)
    own = tc.fit_ellipsoid(S * k)  # the data's own scale: radius in raw units
    assert own.radius / k == pytest.approx(tc.fit_ellipsoid(S).radius, rel=1e-9)
    assert tc.fit_sphere(S * k).radius / k == pytest.approx(tc.fit_sphere(S).radius, rel=1e-9)
    lin = tc.fit_sphere_linear(S * k)
    np.testing.assert_allclose(lin.center / k, tc.fit_sphere_linear(S).center, rtol=1e-9,
                               atol=1e-12)
    rob = fit_robust(S * k, radius=1.0)
    np.testing.assert_allclose(rob.fit.offset / k, fit_robust(S, radius=1.0).fit.offset,
                               rtol=1e-9, atol=1e-12)


def test_results_that_do_not_fit_in_double_precision_are_refused():
    with pytest.raises(tc.CalibrationError, match="overflows or underflows double precision"):
        tc.fit_ellipsoid(S * 1e-300, radius=1e300)
    # subnormal readings (about 14 significant bits left) still fit in their own scale, but a
    # gain that maps them to 1 would be about 1e319, beyond the largest double
    tiny = S * 2.0**-1060
    own = tc.fit_ellipsoid(tiny, model="sphere")
    want = tc.fit_ellipsoid(S, model="sphere").radius
    assert own.radius * 2.0**530 * 2.0**530 == pytest.approx(want, rel=1e-3)
    with pytest.raises(tc.CalibrationError, match="overflows or underflows double precision"):
        tc.fit_ellipsoid(tiny, radius=1.0)


SPHERE, _ = distorted_sphere(500, offset=[0.03, -0.02, 0.01], matrix=np.eye(3), noise=0.002,
                             seed=6)


@pytest.mark.parametrize("k", [1e-300, 1e-160, 1e100, 1e154])
def test_searches_scale_with_the_data(k):
    """descend_center and grid_center on readings times k find k times the centre."""
    base = tc.descend_center(SPHERE, 1.0, step=0.5, min_step=1e-4)
    d = tc.descend_center(SPHERE * k, k, start=(0, 0, 0), step=0.5 * k, min_step=1e-4 * k)
    np.testing.assert_allclose(d.center / k, base.center, rtol=1e-9, atol=1e-12)
    assert d.converged and d.iterations == base.iterations
    if k > 1e-100:  # (below, the error sum itself is under the smallest double)
        assert d.error / k / k == pytest.approx(base.error, rel=1e-9)
    g0 = tc.grid_center(SPHERE, 1.0, lo=-0.05, hi=0.05, step=0.01)
    g = tc.grid_center(SPHERE * k, k, lo=-0.05 * k, hi=0.05 * k, step=0.01 * k)
    np.testing.assert_allclose(g.center / k, g0.center, rtol=1e-9, atol=1e-12)
    if k > 1e-100:
        assert tc.sphere_error(SPHERE * k, base.center * k, k) / k / k == pytest.approx(
            tc.sphere_error(SPHERE, base.center, 1.0), rel=1e-9)


@pytest.mark.parametrize("k", [1e155, 1e300])
def test_searches_say_when_the_error_sum_overflows(k):
    """Squared distances of readings near 1e155 exceed the largest double: the searches find
    the centre on rescaled values and refuse, naming it, instead of stopping at the start (at
    1e154 these readings' sum, 1.6e308, still fits: see the test above)."""
    for search in (
        lambda: tc.descend_center(SPHERE * k, k, step=0.5 * k, min_step=1e-4 * k),
        lambda: tc.grid_center(SPHERE * k, k, lo=-0.05 * k, hi=0.05 * k, step=0.01 * k),
        lambda: tc.sphere_error(SPHERE * k, (0, 0, 0), k),
    ):
        with pytest.raises(tc.CalibrationError, match="largest double"):
            search()
    # noise-free readings on the sphere have a representable error sum: then it is found
    exact = distorted_sphere(300, offset=[0.03, -0.02, 0.01], matrix=np.eye(3), seed=7)[0]
    d = tc.descend_center(exact * 1e154, 1e154, step=0.5e154, min_step=1e150)
    np.testing.assert_allclose(d.center / 1e154, [0.03, -0.02, 0.01], atol=2e-4)
    assert d.converged and np.isfinite(d.error)


# ------------------------------------------------------------------ options


GOOD, _ = distorted_sphere(100, offset=OFFSET, matrix=MATRIX, noise=0.001)


@pytest.mark.parametrize(
    "kwargs,match",
    [
        ({"max_iter": 2**70}, r"max_iter must be a whole number from 0 to 1000000, got 1180"),
        ({"max_iter": 10.0}, "max_iter must be a whole number"),
        ({"max_iter": True}, "max_iter must be a whole number"),
        ({"tol": "x"}, r"tol must be a number in \[0, 1\), got 'x'"),
        ({"tol": np.nan}, r"tol must be a number in \[0, 1\)"),
        ({"tol": -1e-3}, r"tol must be"),
        ({"radius": True}, "radius must be a number"),
        ({"radius": "1"}, "radius must be a number"),
        ({"debias": "no"}, "debias must be True or False, got 'no'"),
        ({"debias": 0}, "debias must be True or False"),
        ({"model": ["full"]}, "unknown model"),
        ({"fixed": {"gain_q": 1.0}, "radius": 1.0}, "cannot fix 'gain_q'.*choose from"),
        ({"fixed": {"gain_z": 1.0}}, "fixing 'gain_z' needs radius"),
        ({"fixed": {"gain_z": -1.0}, "radius": 1.0}, "must be a number in"),
        ({"fixed": {"offset_x": np.nan}}, "must be a number in"),
        ({"fixed": {"gain_z": 1.0, "diag_z": 1.0}, "radius": 1.0}, "given twice"),
        ({"fixed": [1.0]}, "fixed must be a dict"),
    ],
)
def test_fit_options_are_validated_not_coerced(kwargs, match):
    with pytest.raises(tc.CalibrationError, match=match):
        tc.fit_ellipsoid(GOOD, **kwargs)


@pytest.mark.parametrize(
    "kwargs,match",
    [
        ({"min_keep": np.nan}, r"min_keep must be a number in \[0, 1\]"),
        ({"min_keep": 1.5}, "min_keep must be"),
        ({"sigma": np.nan}, "sigma must be"),
        ({"sigma": "2"}, "sigma must be"),
        ({"max_rounds": 2**70}, "max_rounds must be a whole number from 0 to 1000"),
        ({"lengths": "both"}, "lengths must be one of"),
        ({"max_iter": 2**70}, "max_iter must be a whole number"),
        ({"debias": "no"}, "debias must be True or False"),
    ],
)
def test_robust_options_are_validated(kwargs, match):
    with pytest.raises(tc.CalibrationError, match=match):
        fit_robust(GOOD, **kwargs)


def test_batch_and_auto_options_are_validated():
    with pytest.raises(tc.CalibrationError, match="max_iter"):
        tc.fit_batch([GOOD], max_iter=2**70)
    with pytest.raises(tc.CalibrationError, match="debias"):
        tc.fit_batch([GOOD], debias="no")
    with pytest.raises(tc.CalibrationError, match="criterion must be one of"):
        fit_auto(GOOD, criterion="xic")
    with pytest.raises(tc.CalibrationError, match="models must be chosen"):
        fit_auto(GOOD, models="full")
    with pytest.raises(tc.CalibrationError, match="scale must be one of"):
        tc.fit_sphere(GOOD, radius=1.0, scale="fix")
    with pytest.raises(tc.CalibrationError, match="scale='fixed' needs radius"):
        tc.fit_sphere(GOOD, scale="fixed")


def test_descent_work_is_bounded_before_it_starts():
    """shrink=1.0001 down to min_step=1e-300 used to run for minutes: refused at once."""
    pts = SPHERE * 16384
    t0 = time.perf_counter()
    limit = r"at least 6.9\d+e6 neighbourhoods.*limit of 5e8"
    with pytest.raises(tc.CalibrationError, match=limit):
        tc.descend_center(pts, 16384.0, shrink=1.0001, min_step=1e-300)
    assert time.perf_counter() - t0 < 1.0
    for kwargs, match in [
        ({"shrink": 1.0}, r"shrink must be a number in \(1, inf\]"),
        ({"shrink": np.inf}, "shrink must be"),
        ({"min_step": 0.0}, "min_step must be"),
        ({"min_step": 2000.0}, r"min_step must be a number in \(0, 1000\]"),
        ({"step": "1"}, "step must be"),
        ({"max_iter": 2**70}, "max_iter must be a whole number"),
    ]:
        with pytest.raises(tc.CalibrationError, match=match):
            tc.descend_center(pts, 16384.0, **kwargs)


def test_grid_work_is_bounded_before_it_starts():
    pts = SPHERE * 16384
    t0 = time.perf_counter()
    with pytest.raises(tc.CalibrationError, match=r"over the limit of 2e10"):
        tc.grid_center(pts, 16384.0, lo=-400, hi=400, step=1.0)  # 6.4e8 nodes x 500
    assert time.perf_counter() - t0 < 1.0
    with pytest.raises(tc.CalibrationError, match="step must be"):
        tc.grid_center(pts, 16384.0, lo=-1, hi=1, step=np.nan)
