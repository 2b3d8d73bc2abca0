"""The fitting engine's public API: accuracy, bad input, batches, searches, the GIL."""

from __future__ import annotations

import threading

import numpy as np
import pytest
import triaxcal as tc
from _synth import distorted_sphere, random_sym

OFFSET = np.array([412.0, -230.5, 97.25])  # counts
MATRIX = np.array([[1.05, 0.02, -0.01], [0.02, 0.97, 0.015], [-0.01, 0.015, 1.01]]) / 16384.0


def test_full_fit_recovers_exact_data_to_rounding():
    raw, _ = distorted_sphere(300, offset=OFFSET, matrix=MATRIX)
    fit = tc.fit_ellipsoid(raw, model="full", radius=1.0)
    assert fit.converged and fit.model == "full"
    np.testing.assert_allclose(fit.offset, OFFSET, atol=1e-7)
    np.testing.assert_allclose(fit.matrix, MATRIX, rtol=0, atol=1e-13)
    assert fit.rms < 1e-10 and fit.n == 300 and fit.warnings == ()
    np.testing.assert_allclose(np.linalg.norm(fit.apply(raw), axis=1), 1.0, atol=1e-9)


def test_apply_convention_is_offset_then_matrix_transpose():
    raw, field = distorted_sphere(200, offset=OFFSET, matrix=MATRIX, seed=3)
    fit = tc.fit_ellipsoid(raw, radius=1.0)
    np.testing.assert_allclose(fit.apply(raw), (raw - fit.offset) @ fit.matrix.T, atol=1e-12)
    np.testing.assert_allclose(fit.apply(raw), field, atol=1e-9)


def test_int16_input_straight_from_a_sensor():
    raw, _ = distorted_sphere(2000, offset=OFFSET, matrix=MATRIX, noise=0.002, seed=1)
    counts = np.round(raw).astype(np.int16)
    fit = tc.fit_ellipsoid(counts, radius=16384.0)
    # with radius in counts the matrix is dimensionless (close to 16384 * MATRIX)
    np.testing.assert_allclose(fit.offset, OFFSET, atol=2.0)
    np.testing.assert_allclose(fit.matrix, MATRIX * 16384, atol=3e-3)
    assert fit.radius == 16384.0


@pytest.mark.parametrize("model,nstd", [("sphere", 4), ("axis", 6), ("full", 9)])
def test_models_and_stderr_shapes(model, nstd):
    raw, _ = distorted_sphere(
        500, offset=OFFSET, matrix=np.diag([1.03, 0.98, 1.0]) / 16384, noise=0.003, seed=2
    )
    fit = tc.fit_ellipsoid(raw, model=model, radius=1.0)
    assert fit.stderr.shape == (nstd,) and len(fit.param_names) == nstd
    assert np.all(fit.stderr > 0) and np.all(np.isfinite(fit.stderr))
    if model == "sphere":
        assert np.allclose(fit.matrix, np.eye(3) * fit.matrix[0, 0])
    if model == "axis":
        assert np.allclose(fit.matrix, np.diag(np.diag(fit.matrix)))
    # the offset standard error is honest: the true offset is within 5 sigma
    if model != "sphere":
        assert np.all(np.abs(fit.offset - OFFSET) < 5 * fit.stderr[:3])


def test_stderr_matches_scatter_over_repeated_noise():
    """Reported standard errors agree with the spread of offsets over 40 noisy repeats."""
    offs, ses = [], []
    for seed in range(40):
        raw, _ = distorted_sphere(400, offset=OFFSET, matrix=MATRIX, noise=0.01, seed=seed)
        fit = tc.fit_ellipsoid(raw, radius=1.0)
        offs.append(fit.offset)
        ses.append(fit.stderr[:3])
    ratio = np.std(offs, axis=0) / np.mean(ses, axis=0)
    assert np.all((ratio > 0.6) & (ratio < 1.5)), ratio


def test_own_scale_when_radius_is_none():
    raw, _ = distorted_sphere(300, offset=OFFSET, matrix=MATRIX)
    fit = tc.fit_ellipsoid(raw)
    assert abs(np.linalg.det(fit.matrix) - 1.0) < 1e-9
    np.testing.assert_allclose(np.linalg.norm(fit.apply(raw), axis=1), fit.radius, rtol=1e-9)
    sph = tc.fit_sphere(raw)
    assert np.array_equal(sph.matrix, np.eye(3))
    assert 14000 < sph.radius < 18000  # the data's own radius, in counts


def test_full_fit_is_at_least_as_accurate_as_scipy_least_squares():
    scipy_opt = pytest.importorskip("scipy.optimize")
    rng = np.random.default_rng(7)
    for trial in range(3):
        m = random_sym(rng) / 1000.0
        off = rng.uniform(-300, 300, 3)
        raw, _ = distorted_sphere(3000, offset=off, matrix=m, noise=0.01, seed=trial)
        ours = tc.fit_ellipsoid(raw, radius=1.0, debias=False)  # the same residual as scipy's

        def resid(th, raw=raw):
            w = np.array([[th[3], th[6], th[7]], [th[6], th[4], th[8]], [th[7], th[8], th[5]]])
            return np.linalg.norm((raw - th[:3]) @ w.T, axis=1) - 1.0

        x0 = np.r_[raw.mean(0), np.full(3, 1 / np.std(raw) / np.sqrt(3)), np.zeros(3)]
        ref = scipy_opt.least_squares(resid, x0, method="lm", xtol=1e-15, ftol=1e-15)
        w_ref = np.array(
            [
                [ref.x[3], ref.x[6], ref.x[7]],
                [ref.x[6], ref.x[4], ref.x[8]],
                [ref.x[7], ref.x[8], ref.x[5]],
            ]
        )
        err_ours = np.linalg.norm(ours.offset - off) + 1000 * np.linalg.norm(ours.matrix - m)
        err_ref = np.linalg.norm(ref.x[:3] - off) + 1000 * np.linalg.norm(np.abs(w_ref) - m)
        cost_ours = np.sum((np.linalg.norm(ours.apply(raw), axis=1) - 1) ** 2)
        assert cost_ours <= 2 * ref.cost * (1 + 1e-9)  # scipy's cost is half the sum of squares
        assert err_ours <= err_ref * (1 + 1e-6) + 1e-9
        # and the default (debiased) fit is closer to the truth than scipy's at large N
        if trial == 0:
            raw, _ = distorted_sphere(100_000, offset=off, matrix=m, noise=0.03, seed=99)
            deb = tc.fit_ellipsoid(raw, radius=1.0)
            ref = scipy_opt.least_squares(resid, x0, method="lm")
            w_ref = np.array(
                [
                    [ref.x[3], ref.x[6], ref.x[7]],
                    [ref.x[6], ref.x[4], ref.x[8]],
                    [ref.x[7], ref.x[8], ref.x[5]],
                ]
            )
            assert np.linalg.norm(deb.matrix - m) < 0.5 * np.linalg.norm(np.abs(w_ref) - m)


@pytest.mark.parametrize(
    "m,factor",
    [
        (np.array([[1.04, 0.01, 0.0], [0.01, 0.97, 0.015], [0.0, 0.015, 1.0]]), 0.3),  # MEMS-like
        (np.array([[1.2, 0.1, 0.0], [0.1, 0.8, 0.05], [0.0, 0.05, 1.0]]), 0.8),  # strong soft iron
    ],
)
def test_geometric_fit_beats_algebraic_at_large_n(m, factor):
    raw, _ = distorted_sphere(200_000, offset=[0.3, -0.2, 0.1], matrix=m, noise=0.05, seed=11)
    geo = tc.fit_ellipsoid(raw, radius=1.0)
    alg = tc.fit_ellipsoid(raw, radius=1.0, method="algebraic")
    plain = tc.fit_ellipsoid(raw, radius=1.0, debias=False)
    err = lambda f: np.linalg.norm(f.offset - [0.3, -0.2, 0.1]) + np.linalg.norm(f.matrix - m)
    assert err(geo) < factor * err(alg), (err(geo), err(alg))
    assert err(geo) < factor * err(plain), (err(geo), err(plain))
    assert geo.converged and alg.iterations == 0


def test_gauss_newton_and_lm_agree():
    raw, _ = distorted_sphere(1000, offset=OFFSET, matrix=MATRIX, noise=0.01, seed=5)
    lm = tc.fit_ellipsoid(raw, radius=1.0, method="lm")
    gn = tc.fit_ellipsoid(raw, radius=1.0, method="gn")
    # the same minimum, to well within a thousandth of a standard error
    assert np.all(np.abs(gn.offset - lm.offset) < 1e-3 * lm.stderr[:3])
    assert np.all(np.abs(np.diag(gn.matrix) - np.diag(lm.matrix)) < 1e-3 * lm.stderr[3:6])


# ---------------------------------------------------------------------------- bad input

GOOD, _ = distorted_sphere(100, offset=OFFSET, matrix=MATRIX, noise=0.001)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_points_are_named(bad):
    pts = GOOD.copy()
    pts[17, 1] = bad
    with pytest.raises(tc.NonFiniteError, match="point 17 has a NaN or infinite"):
        tc.fit_ellipsoid(pts)
    b = tc.fit_batch([GOOD, pts])
    assert b.errors[0] is None and "point 17" in b.errors[1]


@pytest.mark.parametrize("model,need", [("sphere", 4), ("axis", 6), ("full", 9)])
def test_too_few_points(model, need):
    """The fewest points a model takes is its number of unknowns (an exact solve)."""
    with pytest.raises(tc.TooFewPointsError, match=f"at least {need} points.*collect more"):
        tc.fit_ellipsoid(GOOD[: need - 1], model=model)
    tc.fit_ellipsoid(GOOD[: need + 20], model=model)  # enough is fine


def test_points_on_a_plane_or_a_line():
    t = np.linspace(0, 2 * np.pi, 60, endpoint=False)
    ring = np.c_[np.cos(t), np.sin(t), np.zeros_like(t)] * 100 + [5, 6, 7]
    tilted = ring @ np.array([[1, 0, 0], [0, 0.6, -0.8], [0, 0.8, 0.6]]).T
    for model in tc.MODELS:
        with pytest.raises(tc.DegenerateDataError, match="plane.*turn the board on its side"):
            tc.fit_ellipsoid(tilted, model=model)
    line = np.outer(np.linspace(-1, 1, 30), [1.0, 2.0, 3.0])
    with pytest.raises(tc.DegenerateDataError, match="straight line"):
        tc.fit_sphere(line)
    with pytest.raises(tc.DegenerateDataError, match="identical"):
        tc.fit_ellipsoid(np.ones((50, 3)))


def test_small_cap_is_refused_for_full_model_but_sphere_warns():
    rng = np.random.default_rng(4)
    u = rng.normal(size=(400, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    cap = u[u[:, 2] > 0.8] * 100.0 + rng.normal(scale=0.2, size=(1, 3))
    cap = cap + rng.normal(scale=0.3, size=cap.shape)
    with pytest.raises(tc.DegenerateDataError, match="turn the sensor through more orientations"):
        tc.fit_ellipsoid(cap, model="full")
    fit = tc.fit_sphere(cap, radius=100.0)
    assert any("cap" in w or "poorly determined" in w for w in fit.warnings), fit.warnings


def test_partial_coverage_converges_with_large_stderr_and_says_so():
    rng = np.random.default_rng(9)
    u = rng.normal(size=(3000, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    half = u[u[:, 2] > -0.2]
    full = tc.fit_ellipsoid(u + rng.normal(scale=0.01, size=u.shape), model="axis", radius=1.0)
    part = tc.fit_ellipsoid(
        half + rng.normal(scale=0.01, size=half.shape), model="axis", radius=1.0
    )
    assert part.converged
    assert part.stderr[2] > 3 * full.stderr[2]  # the z offset is the poorly covered one
    assert any("-Z" in w for w in part.warnings), part.warnings  # says which side is empty


@pytest.mark.parametrize(
    "points,match",
    [
        (np.zeros((10, 2)), r"shape \(N, 3\).*got shape \(10, 2\)"),
        (np.zeros(30), r"shape \(N, 3\)"),
        (np.zeros((2, 10, 3)), r"shape \(N, 3\)"),
        (np.array([["a", "b", "c"]] * 10), "real numbers"),
        (np.ones((10, 3), dtype=complex), "real numbers"),
        (np.ones((10, 3), dtype=bool), "real numbers"),
        ([[1, 2, 3], [4, 5]], "could not convert|shape"),
        ("not points", "real numbers|shape"),
    ],
)
def test_wrong_shapes_and_dtypes(points, match):
    with pytest.raises(tc.CalibrationError, match=match):
        tc.fit_ellipsoid(points)


def test_bad_options():
    with pytest.raises(tc.CalibrationError, match="unknown model 'ellipse'"):
        tc.fit_ellipsoid(GOOD, model="ellipse")
    for r in (0, -1, np.nan, "1g"):
        with pytest.raises(tc.CalibrationError, match="radius"):
            tc.fit_ellipsoid(GOOD, radius=r)
    with pytest.raises(tc.CalibrationError, match="max_iter"):
        tc.fit_ellipsoid(GOOD, max_iter=-1)
    with pytest.raises(tc.CalibrationError, match="unknown method"):
        tc.fit_ellipsoid(GOOD, method="newton")
    assert issubclass(tc.CalibrationError, ValueError)


def test_non_contiguous_and_float32_inputs_give_the_same_fit():
    big = np.asfortranarray(GOOD)
    f1 = tc.fit_ellipsoid(GOOD, radius=1.0)
    f2 = tc.fit_ellipsoid(big, radius=1.0)
    f3 = tc.fit_ellipsoid(np.hstack([GOOD, GOOD])[:, ::2][:, :3] * 0 + GOOD, radius=1.0)
    np.testing.assert_array_equal(f1.offset, f2.offset)
    np.testing.assert_array_equal(f1.offset, f3.offset)


# ---------------------------------------------------------------------------- batches


def test_batch_matches_single_fits_and_isolates_bad_sets():
    rng = np.random.default_rng(3)
    sets, truth = [], []
    for i in range(20):
        m = random_sym(rng) / 16384
        off = rng.uniform(-500, 500, 3)
        raw, _ = distorted_sphere(200, offset=off, matrix=m, noise=0.003, seed=i)
        sets.append(raw)
        truth.append((off, m))
    sets[5] = sets[5][:6]  # too few points
    sets[9] = sets[9].copy()
    sets[9][0, 0] = np.nan  # NaN
    b = tc.fit_batch(sets, radius=1.0)
    assert len(b) == 20 and b.offsets.shape == (20, 3) and b.matrices.shape == (20, 3, 3)
    assert "at least 9 points" in b.errors[5] and "NaN" in b.errors[9]
    assert not b.ok[5] and not b.ok[9] and b.ok.sum() == 18
    assert np.isnan(b.offsets[5]).all() and not b.converged[9]
    for i in np.flatnonzero(b.ok):
        single = tc.fit_ellipsoid(sets[i], radius=1.0)
        np.testing.assert_allclose(b.offsets[i], single.offset, rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(b.matrices[i], single.matrix, rtol=1e-12, atol=1e-15)
        assert abs(b.rms[i] - single.rms) < 1e-12 and b.radii[i] == 1.0
        np.testing.assert_allclose(b.offsets[i], truth[i][0], atol=40)  # ~5 sigma


def test_batch_from_a_3d_array():
    axis = np.diag(np.diag(MATRIX))
    raws = np.stack(
        [distorted_sphere(150, offset=OFFSET + i, matrix=axis, seed=i)[0] for i in range(8)]
    )
    b = tc.fit_batch(raws, model="axis")
    np.testing.assert_allclose(b.offsets, OFFSET + np.arange(8)[:, None], atol=1e-6)
    with pytest.raises(tc.CalibrationError, match=r"\(B, N, 3\)"):
        tc.fit_batch(np.zeros((4, 10, 2)))


def test_batch_of_equal_sets_splits_in_the_core_as_bounds_would():
    from triaxcal import _core

    sets = np.stack([distorted_sphere(120, offset=OFFSET, matrix=MATRIX, noise=0.003,
                                      seed=40 + i)[0] for i in range(6)])
    sets[2, 7, 1] = np.inf  # one bad set among good ones
    flat = sets.reshape(-1, 3)
    args = ("full", 1.0, 100, 1e-10, "lm", True)
    by_size = _core.fit_batch(flat, 120, *args)
    by_bounds = _core.fit_batch(flat, np.arange(7, dtype=np.int64) * 120, *args)
    for k in ("offsets", "matrices", "radii", "rms", "converged", "iterations"):
        np.testing.assert_array_equal(by_size[k], by_bounds[k])
        assert not by_size[k].flags.writeable  # read-only as they come
    assert by_size["matrices"].shape == (6, 3, 3) and by_size["errors"] == by_bounds["errors"]
    assert by_size["errors"][2] is not None and by_size["error_kinds"][2] == "NonFiniteError"
    # a size that does not split the rows into whole sets is refused, not rounded
    for size in (0, 7, -120):
        with pytest.raises(tc.CalibrationError, match="bounds out of range"):
            _core.fit_batch(flat, size, *args)
    # the facade's result (a view of the same array, no copy) agrees
    b = tc.fit_batch(sets, radius=1.0)
    np.testing.assert_array_equal(b.offsets, by_size["offsets"])
    assert not b.offsets.flags.writeable and b.errors[2] is not None


# ---------------------------------------------------------------------------- seed searches


def test_sphere_error_is_the_seed_sum():
    pts = np.array([[1.0, 2.0, 3.0], [-1.0, 0.0, 2.0], [0.5, 0.5, 0.5]])
    c, r = np.array([0.1, 0.2, 0.3]), 2.0
    want = np.abs(((pts - c) ** 2).sum(1) - r * r).sum()
    assert tc.sphere_error(pts, c, r) == pytest.approx(want, rel=1e-15)


def test_descent_and_grid_find_the_centre_in_counts():
    raw, _ = distorted_sphere(1000, offset=OFFSET, matrix=np.eye(3) / 16384, noise=0.002, seed=8)
    d = tc.descend_center(raw, 16384.0)
    assert d.converged and d.step < 0.01 and d.evaluations > d.iterations
    np.testing.assert_allclose(d.center, OFFSET, atol=30)
    # the descent's centre is a local minimum of the error sum at the final resolution
    for k in range(3):
        for s in (-0.01, 0.01):
            c = d.center.copy()
            c[k] += s
            assert tc.sphere_error(raw, c, 16384.0) >= d.error * (1 - 1e-12)
    fixed = tc.descend_center(raw, 16384.0, step=10.0, min_step=10.0)
    assert np.all(np.abs(fixed.center - d.center) <= 10.0 + 1e-9)
    g = tc.grid_center(
        raw, 16384.0, lo=np.round(d.center) - 20, hi=np.round(d.center) + 20, step=5.0
    )
    assert g.iterations == 9**3
    assert np.all(np.abs(g.center - d.center) <= 5.0)


def test_search_bad_input():
    with pytest.raises(tc.CalibrationError, match="shrink must be"):
        tc.descend_center(GOOD, 1.0, shrink=0.5)
    with pytest.raises(tc.CalibrationError, match="too long|limit"):
        tc.grid_center(GOOD, 1.0, lo=-1e6, hi=1e6, step=1e-3)
    with pytest.raises(tc.CalibrationError, match="radius"):
        tc.descend_center(GOOD, None)
    d = tc.descend_center(GOOD, 1.0 / np.mean(np.diag(MATRIX)), step=1.0, min_step=1e-6, max_iter=3)
    assert not d.converged and d.iterations == 3  # the guard against a hang


def test_linear_sphere_fit():
    raw, _ = distorted_sphere(500, offset=OFFSET, matrix=np.eye(3) / 16384, seed=1)
    lin = tc.fit_sphere_linear(raw)
    np.testing.assert_allclose(lin.center, OFFSET, atol=1e-6)
    assert lin.radius == pytest.approx(16384, rel=1e-12) and lin.rms < 1e-6


# ---------------------------------------------------------------------------- the GIL


def test_fits_release_the_gil():
    """A pure-Python thread keeps running while the core fits: the GIL is released."""
    raw, _ = distorted_sphere(400_000, offset=OFFSET, matrix=MATRIX, noise=0.01)
    counter = [0]
    stop = threading.Event()
    started = threading.Event()

    def spin():
        started.set()
        while not stop.is_set():
            counter[0] += 1

    t = threading.Thread(target=spin)
    t.start()
    started.wait()
    try:
        before = counter[0]
        for _ in range(3):
            tc.fit_ellipsoid(raw, method="gn")  # one long call per loop
        during = counter[0] - before
    finally:
        stop.set()
        t.join()
    assert during > 10_000, during


def test_concurrent_fits_from_a_thread_pool_are_correct():
    from concurrent.futures import ThreadPoolExecutor

    sets = [
        distorted_sphere(3000, offset=OFFSET * (i + 1), matrix=MATRIX, seed=i)[0] for i in range(8)
    ]
    with ThreadPoolExecutor(4) as ex:
        fits = list(ex.map(lambda s: tc.fit_ellipsoid(s, radius=1.0), sets))
    for i, f in enumerate(fits):
        np.testing.assert_allclose(f.offset, OFFSET * (i + 1), atol=1e-6)


def test_auto_model_picks_by_information_criterion_and_says_why():
    rng = np.random.default_rng(2)
    u = rng.normal(size=(800, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    sphere_like = u * 50 + [3, -2, 1] + rng.normal(scale=0.3, size=u.shape)
    f = tc.fit_ellipsoid(sphere_like, model="auto")
    assert f.model == "sphere" and "sphere" in f.model_reason
    skewed, _ = distorted_sphere(800, offset=OFFSET, matrix=MATRIX, noise=0.002, seed=4)
    f = tc.fit_ellipsoid(skewed, model="auto", radius=1.0)
    assert f.model == "full" and f.model_reason
    assert tc.fit_ellipsoid(skewed, model="full").model_reason is None


def test_fit_streams_without_copying_the_points():
    """Peak memory of a fit on 3M points stays far below one copy of the input (72 MB)."""
    import subprocess
    import sys

    code = """
import resource, numpy as np, triaxcal as tc
rng = np.random.default_rng(0)
u = rng.normal(size=(3_000_000, 3)); u /= np.linalg.norm(u, axis=1, keepdims=True)
p = np.ascontiguousarray(u * [1.1, 0.9, 1.0] + 0.1)
del u
tc.fit_ellipsoid(p[:1000])
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
f = tc.fit_ellipsoid(p)
after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
assert f.converged
print((after - before) * 1024, p.nbytes)
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    extra, nbytes = (int(v) for v in out.stdout.split())
    assert extra < 0.25 * nbytes, (extra, nbytes)


def test_a_sensor_that_never_turned_is_called_out():
    """Readings of a sensor held still are a cloud of noise about one vector: the geometric fit
    may wrap a small sphere round the cloud, with low residuals in absolute terms and every
    direction "covered". The fit must say that the readings do not lie on a sphere; a real
    turned sensor with MEMS noise and a sphere fitted to strong soft iron must not be told so."""
    rng = np.random.default_rng(11)
    still = np.array([43.0, -12.0, -6.0]) + rng.normal(scale=0.5, size=(300, 3))
    fit = tc.fit_sphere(still)
    rms = np.sqrt(np.mean((np.linalg.norm(still - fit.offset, axis=1) - fit.radius) ** 2))
    assert fit.radius < 5.0 and rms > 0.2 * fit.radius  # the small sphere round the cloud
    assert any("do not lie on a sphere" in w for w in fit.warnings), fit.warnings
    u = rng.normal(size=(2000, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    turned = u * 48.0 + rng.normal(scale=0.5, size=u.shape)
    assert not any("do not lie" in w for w in tc.fit_sphere(turned).warnings)
    soft = (u * 48.0) @ np.diag([1.0, 1.5, 1.2]).T
    sphere = tc.fit_sphere(soft)
    assert not any("do not lie" in w for w in sphere.warnings), sphere.warnings
    assert not any("do not lie" in w for w in tc.fit_ellipsoid(soft).warnings)
