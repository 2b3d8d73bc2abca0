"""The seeds' fits: fixed gains and six readings (sphere-fit-offset-gain), and a sphere of
known radius from a cap (sphere-center-descent), each against a direct solve of the seed's
objective with scipy."""

from __future__ import annotations

import json

import numpy as np
import pytest
import triaxcal as tc
from _synth import distorted_sphere

least_squares = pytest.importorskip("scipy.optimize").least_squares

R = 16384.0  # counts at +-2 g: the seed's target radius
OFFSET = np.array([412.0, -230.5, 97.25])
GAINS = np.array([1.021, 0.987, 1.0])  # calibrated = (raw - offset) * gain; the z gain is 1


def cube_faces(offset=OFFSET, gains=GAINS, noise=0.0, seed=0, tilt_deg=2.0):
    """One reading per face of a cube (+X, -X, +Y, -Y, +Z, -Z down), slightly tilted."""
    rng = np.random.default_rng(seed)
    u = np.vstack([np.eye(3), -np.eye(3)])
    u = u + rng.normal(scale=np.radians(tilt_deg), size=u.shape)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    raw = u * R / gains + offset
    return raw + rng.normal(scale=noise, size=raw.shape)


def seed_objective(raw, fixed: dict[int, float]):
    """The spreadsheet's sum of (R1 - 16384)^2, R1 = |(X - Xoffset) * Xgain, ...|, solved by
    scipy over the parameters not in ``fixed`` (0-2 offsets, 3-5 gains)."""
    free = [i for i in range(6) if i not in fixed]

    def full(x):
        th = np.empty(6)
        th[free] = x
        for i, v in fixed.items():
            th[i] = v
        return th

    def resid(x):
        th = full(x)
        return np.linalg.norm((raw - th[:3]) * th[3:], axis=1) - R

    x0 = np.r_[raw.mean(0), np.ones(3)][free]
    sol = least_squares(resid, x0, method="trf" if len(free) > len(raw) - 1 else "lm",
                        xtol=1e-15, ftol=1e-15, gtol=1e-15)
    return full(sol.x), 2 * sol.cost


def test_fixed_z_gain_equals_the_spreadsheet_solver():
    """Offsets and the x and y gains varied, the z gain fixed at 1: the seed's Solver run."""
    for seed in range(3):
        raw = np.vstack([cube_faces(noise=3.0, seed=seed + 10 * k) for k in range(4)])  # 24
        fit = tc.fit_ellipsoid(raw, model="axis", radius=R, fixed={"gain_z": 1.0},
                               debias=False, tol=1e-15)
        want, cost = seed_objective(raw, {5: 1.0})
        np.testing.assert_allclose(fit.offset, want[:3], rtol=0, atol=1e-6)
        np.testing.assert_allclose(np.diag(fit.matrix), want[3:], rtol=1e-10)
        assert fit.matrix[2, 2] == 1.0 and fit.fixed == ("gain_z",)
        assert fit.stderr[5] == 0.0 and np.all(fit.stderr[:5] > 0)
        ours = np.sum((np.linalg.norm(fit.apply(raw), axis=1) - R) ** 2)
        assert ours <= cost * (1 + 1e-12)
        assert fit.rms == pytest.approx(np.sqrt(ours / len(raw)), rel=1e-9)
        # the default (debiased) fit is the same here: the noise is far below 0.1/sqrt(N)
        same = tc.fit_ellipsoid(raw, model="axis", radius=R, fixed={"gain_z": 1.0}, tol=1e-15)
        np.testing.assert_array_equal(same.offset, fit.offset)


@pytest.mark.parametrize(
    "fixed,index",
    [
        ({"gain_x": 1.02}, {3: 1.02}),
        ({"offset_y": -230.0}, {1: -230.0}),
        ({"offset_x": 410.0, "gain_y": 0.99}, {0: 410.0, 4: 0.99}),
        ({"diag_z": 1.0, "offset_z": 97.0}, {5: 1.0, 2: 97.0}),
    ],
)
def test_any_gain_or_offset_can_be_fixed(fixed, index):
    raw, _ = distorted_sphere(60, offset=OFFSET, matrix=np.diag(GAINS) / R, noise=0.001,
                              radius=1.0, seed=3)
    fit = tc.fit_ellipsoid(raw, model="axis", radius=R, fixed=fixed, debias=False, tol=1e-15)
    want, _ = seed_objective(raw, index)
    np.testing.assert_allclose(fit.offset, want[:3], atol=1e-6)
    np.testing.assert_allclose(np.diag(fit.matrix), want[3:], rtol=1e-10)
    for name, value in fixed.items():
        i = tc.fit.FIXABLE["axis"][name]
        got = fit.offset[i] if i < 3 else fit.matrix[i - 3, i - 3]
        assert got == pytest.approx(value, rel=1e-15)


def test_fixed_terms_of_the_full_model():
    """The full model fixes off-diagonal terms too (here: no cross-axis between x and y)."""
    m = np.array([[1.03, 0.0, 0.01], [0.0, 0.98, -0.02], [0.01, -0.02, 1.0]])
    raw, _ = distorted_sphere(300, offset=OFFSET, matrix=m / R, radius=1.0, noise=0.001, seed=1)
    fit = tc.fit_ellipsoid(raw, radius=R, fixed={"offdiag_xy": 0.0}, debias=False)
    assert fit.matrix[0, 1] == 0.0 == fit.matrix[1, 0]
    np.testing.assert_allclose(fit.matrix, m, atol=1e-3)
    free = tc.fit_ellipsoid(raw, radius=R, debias=False)
    cost = lambda f: np.sum((np.linalg.norm(f.apply(raw), axis=1) - R) ** 2)  # noqa: E731
    assert cost(free) <= cost(fit)  # one constraint more: never a lower minimum


def test_six_readings_are_an_exactly_determined_solve():
    """One reading per face and six unknowns: accepted, solved exactly, with a note."""
    raw = cube_faces(noise=2.0, seed=5)
    fit = tc.fit_ellipsoid(raw, model="axis", radius=R)
    want, cost = seed_objective(raw, {})
    assert cost < 1e-12  # scipy also drives all six residuals to zero
    np.testing.assert_allclose(fit.offset, want[:3], atol=1e-7)
    np.testing.assert_allclose(np.diag(fit.matrix), want[3:], rtol=1e-11)
    np.testing.assert_allclose(np.linalg.norm(fit.apply(raw), axis=1), R, rtol=1e-12)
    assert fit.converged and fit.n == 6 and np.isnan(fit.stderr).all()
    assert any("exactly determined" in w and "no residual" in w for w in fit.warnings)
    # five readings cannot determine six unknowns
    with pytest.raises(tc.TooFewPointsError, match="at least 6 points, got 5"):
        tc.fit_ellipsoid(raw[:5], model="axis", radius=R)
    # with the z gain fixed, six readings leave one degree of freedom: standard errors exist
    fixed = tc.fit_ellipsoid(raw, model="axis", radius=R, fixed={"gain_z": 1.0})
    assert np.all(np.isfinite(fixed.stderr)) and not any("exactly" in w for w in fixed.warnings)


def test_six_readings_in_a_batch():
    sets = [cube_faces(noise=2.0, seed=s) for s in range(5)]
    b = tc.fit_batch(sets, model="axis", radius=R)
    for s, o in zip(sets, b.offsets):
        np.testing.assert_allclose(o, tc.fit_ellipsoid(s, model="axis", radius=R).offset,
                                   atol=1e-8)
    b = tc.fit_batch(sets, model="axis", radius=R, fixed={"gain_z": 1.0})
    assert np.all(b.matrices[:, 2, 2] == 1.0)


# ------------------------------------------------------------------ known radius, a cap


def cap(n, half_angle_deg, noise, seed, center=OFFSET):
    """n readings within ``half_angle_deg`` of +Z on a sphere of radius R counts."""
    rng = np.random.default_rng(seed)
    u = rng.normal(size=(n * 40, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    u = u[u[:, 2] >= np.cos(np.radians(half_angle_deg))][:n]
    return u * R + center + rng.normal(scale=noise, size=u.shape)


def test_known_radius_fits_the_centre_like_scipy():
    p = cap(84, 30, 10.0, seed=1)
    fit = tc.fit_sphere(p, radius=R, scale="fixed")
    sol = least_squares(lambda c: np.linalg.norm(p - c, axis=1) - R, p.mean(0) - [0, 0, R],
                        method="lm", xtol=1e-15, ftol=1e-15)
    np.testing.assert_allclose(fit.offset, sol.x, atol=1e-6)
    np.testing.assert_array_equal(fit.matrix, np.eye(3))
    assert fit.radius == R and fit.fixed == ("gain",) and fit.stderr[3] == 0.0
    assert fit.rms == pytest.approx(np.sqrt(2 * sol.cost / len(p)), rel=1e-9)


@pytest.mark.parametrize("half_angle", [30, 60])
def test_known_radius_beats_the_mean_and_matches_the_descent_on_a_cap(half_angle):
    """The seed's point: with the radius known, a wedge of the sphere gives the centre. On
    caps of 60 deg (30 deg half-angle) and 120 deg, 84 readings with 10 counts of noise, over
    20 draws: the fixed-scale fit's centre error is at most the descent's (median), far below
    the free-scale fit's and the plain mean's."""
    errs = []
    for seed in range(20):
        p = cap(84, half_angle, 10.0, seed)
        fixed = tc.fit_sphere(p, radius=R, scale="fixed").offset
        free = tc.fit_sphere(p, radius=R).offset
        desc = tc.descend_center(p, R).center
        errs.append([np.linalg.norm(x - OFFSET) for x in (p.mean(0), free, desc, fixed)])
    mean, free, desc, fixed = np.median(errs, axis=0)
    print(f"\n{2 * half_angle} deg cap, median centre error in counts: mean {mean:.0f}, "
          f"free scale {free:.1f}, descend_center {desc:.2f}, fixed scale {fixed:.2f}")
    assert fixed <= desc
    assert fixed < 0.8 * free and fixed < 1e-2 * mean
    assert np.all(np.array(errs)[:, 3] < np.array(errs)[:, 0])


# ------------------------------------------------------------------ the CLI


def test_cli_fix_gain_z(tmp_path, capsys):
    from triaxcal.cli import main

    raw = np.vstack([cube_faces(noise=3.0, seed=k) for k in range(4)])
    data = tmp_path / "faces.csv"
    np.savetxt(data, raw, delimiter=",", header="ax,ay,az", comments="", fmt="%.3f")
    out = tmp_path / "cal.json"
    code = main(["fit", str(data), "--model", "axis", "--radius", "16384", "--sigma", "0",
                 "--fix", "gain_z=1", "-o", str(out)])
    assert code == 0
    accel = json.loads(out.read_text())["parts"]["accel"]
    want = tc.fit_ellipsoid(np.loadtxt(data, delimiter=",", skiprows=1), model="axis",
                            radius=R, fixed={"gain_z": 1.0})
    np.testing.assert_allclose(accel["offset"], want.offset, atol=1e-9)
    assert accel["diag"][2] == 1.0
    for bad in (["--fix", "gain_z"], ["--fix", "gain_z=x"], ["--fix", "gain_q=1"]):
        code = main(["fit", str(data), "--model", "axis", "--radius", "16384", *bad, "-o",
                     str(tmp_path / "bad.json")])
        assert code == 1  # the CLI's exit status for a CalibrationError
    err = capsys.readouterr().err
    assert "NAME=VALUE" in err and "cannot fix 'gain_q'" in err
