"""Fitting engine vs numpy/scipy baselines, side by side in one process; prints ratios.

Run: ``python benches/bench_fit.py`` (add ``--quick`` for a smaller, faster run). Each case
times the baseline and triaxcal alternately, several rounds, and reports the best time of
each and their ratio, plus the accuracy of both against the known truth. Absolute times depend
on the machine; the ratios are what the README quotes.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time

import numpy as np
import triaxcal as tc

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "tests"))
from _synth import distorted_sphere  # noqa: E402

TRUE_OFFSET = np.array([412.0, -230.5, 97.25])  # counts
TRUE_MATRIX = np.array([[1.04, 0.01, -0.01], [0.01, 0.97, 0.015], [-0.01, 0.015, 1.0]]) / 16384


# ------------------------------------------------------------------------------- baselines


def numpy_algebraic(p: np.ndarray, radius: float = 1.0):
    """The common numpy ellipsoid fit: SVD of the 10-column design matrix, no refinement."""
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    d = np.column_stack(
        [x * x, y * y, z * z, 2 * x * y, 2 * x * z, 2 * y * z, 2 * x, 2 * y, 2 * z, np.ones_like(x)]
    )
    _, _, vt = np.linalg.svd(d, full_matrices=False)
    v = vt[-1]
    a = np.array([[v[0], v[3], v[4]], [v[3], v[1], v[5]], [v[4], v[5], v[2]]])
    if np.trace(a) < 0:
        a, v = -a, -v
    center = -np.linalg.solve(a, v[6:9])
    k = center @ a @ center - v[9]
    ev, evec = np.linalg.eigh(a / k)
    w = evec @ np.diag(np.sqrt(ev)) @ evec.T * radius
    return center, w


def scipy_geometric(p: np.ndarray, radius: float = 1.0, jac: str = "2-point"):
    """scipy.optimize.least_squares(method="lm") on the 9-parameter geometric residual."""
    from scipy.optimize import least_squares

    def unpack(th):
        return th[:3], np.array(
            [[th[3], th[6], th[7]], [th[6], th[4], th[8]], [th[7], th[8], th[5]]]
        )

    def resid(th):
        o, w = unpack(th)
        return np.linalg.norm((p - o) @ w.T, axis=1) - radius

    def jacobian(th):
        o, w = unpack(th)
        u = p - o
        v = u @ w.T
        n = np.linalg.norm(v, axis=1)
        wv = v @ w.T
        j = np.empty((len(p), 9))
        j[:, :3] = -wv / n[:, None]
        j[:, 3:6] = v * u / n[:, None]
        j[:, 6] = (v[:, 0] * u[:, 1] + v[:, 1] * u[:, 0]) / n
        j[:, 7] = (v[:, 0] * u[:, 2] + v[:, 2] * u[:, 0]) / n
        j[:, 8] = (v[:, 1] * u[:, 2] + v[:, 2] * u[:, 1]) / n
        return j

    s = np.std(p)
    x0 = np.r_[p.mean(0), np.full(3, radius / s / np.sqrt(3)), np.zeros(3)]
    r = least_squares(resid, x0, jac=jacobian if jac == "analytic" else jac, method="lm")
    o, w = unpack(r.x)
    return o, w


NEIGHBOURS = np.array(
    [
        (i, j, k)
        for i in (-1, 0, 1)
        for j in (-1, 0, 1)
        for k in (-1, 0, 1)
        if (i, j, k) != (0, 0, 0)
    ],
    dtype=float,
)


def numpy_descend(p, radius, start=(0.0, 0.0, 0.0), step=1000.0, min_step=0.01, shrink=10.0):
    """The seed's variable-step 26-neighbour descent, written with numpy (neighbours batched)."""
    r2 = radius * radius
    c = np.array(start, dtype=float)
    err = np.abs(((p - c) ** 2).sum(1) - r2).sum()
    while step >= min_step:
        cands = c + step * NEIGHBOURS  # (26, 3)
        d = p[None, :, :] - cands[:, None, :]  # (26, N, 3)
        errs = np.abs(np.einsum("knj,knj->kn", d, d) - r2).sum(1)
        i = int(np.argmin(errs))
        if errs[i] < err:
            c, err = cands[i], errs[i]
        else:
            step /= shrink
    return c, err


# ------------------------------------------------------------------------------- timing


def best_of(fn, rounds):
    best = np.inf
    out = None
    for _ in range(rounds):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def side_by_side(base, ours, rounds):
    """Alternate baseline and triaxcal runs; best time of each."""
    tb, to = np.inf, np.inf
    rb = ro = None
    for _ in range(rounds):
        t, rb = best_of(base, 1)
        tb = min(tb, t)
        t, ro = best_of(ours, 1)
        to = min(to, t)
    return tb, to, rb, ro


def err(offset, matrix, scale=16384.0):
    return np.linalg.norm(np.asarray(offset) - TRUE_OFFSET), np.linalg.norm(
        np.asarray(matrix) - TRUE_MATRIX
    ) * scale


ROWS = []


def report(name, target, tb, to, extra=""):
    ratio = tb / to
    ROWS.append((name, target, ratio, tb, to, extra))
    print(
        f"{name:<48} {tb * 1e3:10.1f} ms {to * 1e3:10.2f} ms  {ratio:7.1f}x "
        f"(target {target}x) {extra}",
        flush=True,
    )


def memory_probe(n: int) -> str:
    """Peak RSS added by one fit of n points, measured in a fresh process."""
    code = f"""
import resource, numpy as np, triaxcal as tc
rng = np.random.default_rng(0)
u = rng.normal(size=({n}, 3)); u /= np.linalg.norm(u, axis=1, keepdims=True)
p = np.ascontiguousarray(u * [1.1, 0.9, 1.0] + 0.1)
tc.fit_ellipsoid(p[:1000])
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
tc.fit_ellipsoid(p)
after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print((after - before) * 1024, p.nbytes)
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    extra, nbytes = (int(v) for v in out.stdout.split())
    return (
        f"fit of {n:,} points: peak RSS +{extra / 2**20:.1f} MiB "
        f"for {nbytes / 2**20:.0f} MiB of input"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true", help="smaller sizes, fewer rounds")
    args = ap.parse_args()
    q = args.quick
    rounds = 2 if q else 3
    print(f"triaxcal {tc.__version__}, numpy {np.__version__}, {os.cpu_count()} cores")
    print(f"{'case':<48} {'baseline':>13} {'triaxcal':>13}  {'ratio':>8}")

    # 1. N = 1e6, full model, vs the numpy algebraic fit
    n = 200_000 if q else 1_000_000
    raw, _ = distorted_sphere(n, offset=TRUE_OFFSET, matrix=TRUE_MATRIX, noise=0.01, seed=1)
    tb, to, rb, ro = side_by_side(
        lambda: numpy_algebraic(raw), lambda: tc.fit_ellipsoid(raw, radius=1.0), rounds
    )
    eb, eo = err(*rb), err(ro.offset, ro.matrix)
    report(
        f"full fit, N={n:,} vs numpy algebraic (SVD)",
        3,
        tb,
        to,
        f"| offset err {eb[0]:.3f} vs {eo[0]:.3f} counts, matrix err {eb[1]:.2e} vs {eo[1]:.2e}",
    )

    # 2. N = 1e5, full model, vs scipy least_squares lm
    n = 20_000 if q else 100_000
    raw, _ = distorted_sphere(n, offset=TRUE_OFFSET, matrix=TRUE_MATRIX, noise=0.01, seed=2)
    for jac in ("2-point", "analytic"):
        tb, to, rb, ro = side_by_side(
            lambda jac=jac: scipy_geometric(raw, jac=jac),
            lambda: tc.fit_ellipsoid(raw, radius=1.0),
            1,
        )
        eb, eo = err(*rb), err(ro.offset, ro.matrix)
        report(
            f"full fit, N={n:,} vs scipy lm ({jac} jacobian)",
            30,
            tb,
            to,
            f"| offset err {eb[0]:.3f} vs {eo[0]:.3f}, matrix err {eb[1]:.2e} vs {eo[1]:.2e}",
        )

    # 3. batch of 10,000 sets x 200 points vs a Python loop of the numpy algebraic fit
    b = 2_000 if q else 10_000
    sets = np.stack(
        [
            distorted_sphere(
                200, offset=TRUE_OFFSET, matrix=TRUE_MATRIX, noise=0.003, seed=100 + i
            )[0]
            for i in range(b)
        ]
    )
    tb, to, rb, ro = side_by_side(
        lambda: [numpy_algebraic(s) for s in sets], lambda: tc.fit_batch(sets, radius=1.0), rounds
    )
    eb = np.median([err(*r)[1] for r in rb])
    eo = np.median([err(o, m)[1] for o, m in zip(ro.offsets, ro.matrices)])
    report(
        f"fit_batch, {b:,} sets x 200 points vs numpy loop",
        10,
        tb,
        to,
        f"| median matrix err {eb:.2e} vs {eo:.2e}",
    )

    # 4. descend_center, 10,000 points, vs the same search in numpy
    raw, _ = distorted_sphere(
        10_000, offset=TRUE_OFFSET, matrix=np.eye(3) / 16384, noise=0.002, seed=3
    )
    tb, to, rb, ro = side_by_side(
        lambda: numpy_descend(raw, 16384.0), lambda: tc.descend_center(raw, 16384.0), rounds
    )
    same = np.max(np.abs(rb[0] - ro.center))
    report(
        "descend_center, N=10,000 vs numpy descent",
        20,
        tb,
        to,
        f"| centres differ by {same:.3g} counts",
    )

    if not q:
        print(memory_probe(2_000_000))
    print("\n| case | target | measured ratio |\n|---|---|---|")
    for name, target, ratio, *_ in ROWS:
        print(f"| {name} | >= {target}x | {ratio:.1f}x |")


if __name__ == "__main__":
    main()
