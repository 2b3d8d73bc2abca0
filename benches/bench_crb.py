"""The physical limit of accuracy: the full ellipsoid fit against the Cramer-Rao bound.

Run: ``python benches/bench_crb.py`` (``--trials 400`` by default, ``--quick`` for 100).

Geometric model: raw readings ``p_i = offset + inv(W) @ (R u_i) + e_i`` with ``u_i`` unit
directions (a fixed design per case), ``R = 1`` g, and isotropic Gaussian noise ``e_i`` of
``sigma`` = 1 % of the radius in raw units; the unknowns are ``offset`` (3) and the symmetric
``W`` (6), the directions are nuisance parameters. Eliminating the directions leaves, per
reading, only the displacement along the surface normal, so with ``g(p) = |W (p - offset)| - R``

    FIM = sum_i (dg/dtheta)(dg/dtheta)^T / (sigma^2 |grad_p g|^2),    CRB = inv(FIM),

evaluated at the truth. Over ``--trials`` noise draws (seeds 0..trials-1) the script fits
``tc.fit_ellipsoid(model="full", radius=1.0)`` (defaults: debiased Levenberg-Marquardt) and
prints, for 200 and 10,000 readings:

* per parameter, the observed variance over the CRB (1 = efficient), the bias in standard
  deviations, and the mean reported standard error over the observed standard deviation;
* the ratio of traces, for the parameters made dimensionless (offset over the raw radius, W over
  the mean gain), and the whitened ratio ``tr(CRB^-1 Cov) / 9``.

With 400 trials a variance is known to about +-7 % (sqrt(2 / 399)), which bounds how closely a
per-parameter ratio can be read; the trace ratios average nine of them.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import triaxcal as tc
from triaxcal.methods.bootstrap import fit_params
from triaxcal.sim import SimIMU

NAMES = ("offset_x", "offset_y", "offset_z", "diag_x", "diag_y", "diag_z", "offdiag_xy",
         "offdiag_xz", "offdiag_yz")


def crb(offset: np.ndarray, w: np.ndarray, pts: np.ndarray, sigma: float) -> np.ndarray:
    """Cramer-Rao bound (9x9) of (offset, diag, offdiag) at the true points ``pts``."""
    d = pts - offset
    v = d @ w.T
    nv = np.linalg.norm(v, axis=1)
    wv = v @ w.T
    g = np.empty((len(pts), 9))
    g[:, 0:3] = -wv / nv[:, None]
    for a in range(3):
        g[:, 3 + a] = v[:, a] * d[:, a] / nv
    for k, (a, b) in enumerate(((0, 1), (0, 2), (1, 2))):
        g[:, 6 + k] = (v[:, a] * d[:, b] + v[:, b] * d[:, a]) / nv
    grad2 = np.sum(wv**2, axis=1) / nv**2
    fim = (g / grad2[:, None]).T @ g / sigma**2
    return np.linalg.inv(fim)


def case(n: int, trials: int, noise: float = 0.01) -> dict:
    truth = SimIMU(1).truth.accel
    offset, w = np.asarray(truth.offset), np.asarray(truth.matrix)
    rng = np.random.default_rng([n, 0xD1])  # the design; noise draws use [n, trial, 1]
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    clean = u @ np.linalg.inv(w).T + offset
    raw_radius = 1.0 / float(np.mean(np.diag(w)))
    sigma = noise * raw_radius
    bound = crb(offset, w, clean, sigma)
    true = fit_params("full", offset, w, [1.0], 1.0)[0]
    est = np.empty((trials, 9))
    se = np.empty((trials, 9))
    t0 = time.perf_counter()
    for k in range(trials):
        e = np.random.default_rng([n, k, 1]).normal(0.0, sigma, clean.shape)
        f = tc.fit_ellipsoid(clean + e, model="full", radius=1.0)
        est[k] = fit_params("full", f.offset, f.matrix, [f.radius], 1.0)[0]
        se[k] = f.stderr
    secs = time.perf_counter() - t0
    cov = np.cov(est, rowvar=False)
    scale = np.array([1 / raw_radius] * 3 + [1 / np.mean(np.diag(w))] * 6)
    s = np.diag(scale)
    return {
        "n": n, "trials": trials, "seconds": secs,
        "var_over_crb": np.diag(cov) / np.diag(bound),
        "bias_sd": (est.mean(0) - true) / np.sqrt(np.diag(cov)),
        "se_over_sd": se.mean(0) / np.sqrt(np.diag(cov)),
        "trace_ratio": float(np.trace(s @ cov @ s) / np.trace(s @ bound @ s)),
        "whitened": float(np.trace(np.linalg.solve(bound, cov)) / 9.0),
        "crb_sd": np.sqrt(np.diag(bound)),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--trials", type=int, default=400)
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    trials = 100 if args.quick else args.trials
    for n in (200, 10_000):
        r = case(n, trials)
        print(f"{n} readings, 1 % noise, {trials} trials ({r['seconds']:.1f} s of fits): "
              f"trace ratio {r['trace_ratio']:.3f}, whitened tr(CRB^-1 Cov)/9 "
              f"{r['whitened']:.3f}")
        print(f"  {'parameter':<11} {'var/CRB':>8} {'bias/sd':>8} {'stderr/sd':>10} "
              f"{'CRB sd':>11}")
        for i, name in enumerate(NAMES):
            print(f"  {name:<11} {r['var_over_crb'][i]:8.3f} {r['bias_sd'][i]:+8.3f} "
                  f"{r['se_over_sd'][i]:10.3f} {r['crb_sd'][i]:11.3g}")
        print(f"  var/CRB range {r['var_over_crb'].min():.3f}..{r['var_over_crb'].max():.3f}; "
              f"stderr/sd range {r['se_over_sd'].min():.3f}..{r['se_over_sd'].max():.3f} "
              f"(a variance from {trials} trials is known to +-"
              f"{100 * np.sqrt(2 / (trials - 1)):.0f} %)")


if __name__ == "__main__":
    main()
