"""The full fit against the Cramer-Rao bound of the geometric model (benches/bench_crb.py has
the derivation and the 400-trial numbers): efficient, and its standard errors honest."""

from __future__ import annotations

import os
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "benches"))
from bench_crb import case, crb  # noqa: E402


def test_crb_of_a_sphere_matches_the_closed_form():
    """Unit sphere, W = I, N readings evenly spread: the offset's bound is 3 sigma^2 / N per
    axis (only the normal component of the noise informs it)."""
    rng = np.random.default_rng(0)
    u = rng.normal(size=(20000, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    bound = crb(np.zeros(3), np.eye(3), u, 0.01)
    np.testing.assert_allclose(np.diag(bound)[:3], 3 * 0.01**2 / 20000, rtol=0.05)


@pytest.mark.parametrize("n", [200, 10_000])
def test_the_fit_reaches_the_bound_and_reports_its_spread(n):
    r = case(n, 400)
    assert r["trace_ratio"] < 1.1 and r["whitened"] < 1.1, r
    # per parameter a variance from 400 trials is known to about +-7 %
    assert np.all(r["var_over_crb"] < 1.25), r["var_over_crb"]
    assert np.all(np.abs(r["se_over_sd"] - 1) < 0.1), r["se_over_sd"]
    assert np.all(np.abs(r["bias_sd"]) < 0.25), r["bias_sd"]
