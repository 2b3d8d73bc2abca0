"""The fitting engine on third-party recordings (../shared/realdata), against stored numbers."""

from __future__ import annotations

import numpy as np
import pytest
import triaxcal as tc


def load(realdata, rel):
    return np.loadtxt(realdata / rel, delimiter=",")


def test_icm20948_magnetometer_full_fit(realdata):
    mag = load(realdata, "icm20948-magneto/icm_20948_cal_mag.csv")  # raw counts, 0.15 uT/count
    fit = tc.fit_ellipsoid(mag, model="full", radius=1.0)
    assert fit.converged and fit.warnings == ()
    # regression numbers (this library, this data): offset in counts
    np.testing.assert_allclose(fit.offset, [-156.9, -52.5, -141.0], atol=1.5)
    norms = np.linalg.norm(fit.apply(mag), axis=1)
    assert np.std(norms) / np.mean(norms) < 0.03
    # the standard errors are honest: a few counts on a ~330-count radius
    assert np.all(fit.stderr[:3] < 2.0)
    sphere = tc.fit_sphere(mag)
    # the full model explains clearly more than a sphere
    assert fit.rms * sphere.radius / fit.radius < 0.98 * sphere.rms


def test_icm20948_accelerometer_in_g(realdata):
    acc = load(realdata, "icm20948-magneto/icm_20948_cal_acc.csv")  # counts, 16384/g nominal
    fit = tc.fit_ellipsoid(acc, model="axis", radius=1.0)
    gains_counts_per_g = 1.0 / np.diag(fit.matrix)
    # the nominal sensitivity is 16384 counts/g; the data are hand-held (dynamic), so loosely
    assert np.all(np.abs(gains_counts_per_g / 16384 - 1) < 0.05), gains_counts_per_g
    assert 0.03 < fit.rms < 0.1  # g: hand-held tumbling adds motion to gravity


def test_hmc5883l_band_data_is_reported_as_poor_coverage(realdata):
    mag = load(realdata, "hmc5883l-yaw-nliaudat/mag_out_sample.txt")  # uT, yaw-only motion
    sphere = tc.fit_sphere(mag)
    assert sphere.converged
    assert any("+Z, -Z" in w for w in sphere.warnings), sphere.warnings
    # the general models are not determined by a band of the sphere: a clear error, not a
    # silently wrong ellipsoid
    for model in ("axis", "full"):
        with pytest.raises(tc.DegenerateDataError, match="more orientations"):
            tc.fit_ellipsoid(mag, model=model)
    auto = tc.fit_ellipsoid(mag, model="auto")
    assert auto.model == "sphere" and auto.warnings


def test_mag3_raw_strong_soft_iron(realdata):
    mag = load(realdata, "icm20948-magneto/mag3_raw.csv")  # counts, large offsets
    full = tc.fit_ellipsoid(mag, model="full")
    sphere = tc.fit_sphere(mag)
    assert full.rms < 0.25 * sphere.rms  # soft iron: a sphere cannot describe these data
    np.testing.assert_allclose(full.offset, [9956, -7949, 8513], atol=15)


def test_batch_over_real_sets_matches_single_fits(realdata):
    sets = [
        load(realdata, "icm20948-magneto/icm_20948_cal_mag.csv"),
        load(realdata, "icm20948-magneto/mag3_raw.csv"),
        load(realdata, "hmc5883l-yaw-nliaudat/mag_out_sample.txt"),
    ]
    b = tc.fit_batch(sets, model="full")
    assert b.ok.tolist() == [True, True, False]
    assert "more orientations" in b.errors[2]
    for i in (0, 1):
        np.testing.assert_allclose(b.offsets[i], tc.fit_ellipsoid(sets[i]).offset, rtol=1e-12)
