"""Fitting engine vs numpy baselines, side by side in one process; prints ratios.

Run: ``python benches/bench_fit.py`` (``--quick`` for a smaller, faster run; ``--rows`` to pick
rows). Each case runs the baseline and triaxcal alternately, in paired rounds (the order
inside a round alternates too), and reports the median of the per-round ratios with their
range, the median times, and the accuracy of both against the known truth. On a shared
machine the ratios move from run to run; the instruction counts of ``make bench-instructions``
(valgrind) do not.

Rows (issue targets in brackets):

1. ``fit_ellipsoid(model="full")`` vs the 10-column normal-equations algebraic fit (numpy
   ``X.T @ X`` + ``eigh``) at N = 1e3 .. 1e6 [>= 2x faster; >= 5x more accurate at N >= 1e5]
2. ``fit_batch``, 10,000 sets x 200 points, vs a Python loop of the numpy SVD fit and of the
   normal-equations fit [>= 25x, >= 10x]; 2 threads vs 1 [>= 1.7x]
3. ``descend_center``, N = 1e4, vs the same descent written with numpy [>= 50x]
4. call overhead: what a Python ``fit_ellipsoid`` call of 10 points takes beyond the same fit
   run inside the compiled core [<= 3 us]
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


def _quadric_to_fit(v: np.ndarray, radius: float):
    """Quadric coefficients [xx yy zz 2xy 2xz 2yz 2x 2y 2z 1] to (center, W)."""
    a = np.array([[v[0], v[3], v[4]], [v[3], v[1], v[5]], [v[4], v[5], v[2]]])
    if np.trace(a) < 0:
        a, v = -a, -v
    center = -np.linalg.solve(a, v[6:9])
    k = center @ a @ center - v[9]
    ev, evec = np.linalg.eigh(a / k)
    return center, evec @ np.diag(np.sqrt(np.abs(ev))) @ evec.T * radius


def numpy_svd(p: np.ndarray, radius: float = 1.0):
    """The common numpy ellipsoid fit: SVD of the 10-column design matrix, no refinement."""
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    d = np.column_stack(
        [x * x, y * y, z * z, 2 * x * y, 2 * x * z, 2 * y * z, 2 * x, 2 * y, 2 * z, np.ones_like(x)]
    )
    _, _, vt = np.linalg.svd(d, full_matrices=False)
    return _quadric_to_fit(vt[-1], radius)


def numpy_normal_equations(p: np.ndarray, radius: float = 1.0):
    """The cheapest algebraic fit (what magyc does): the 10 x 10 normal matrix ``X.T @ X`` and
    its smallest eigenvector (``eigh``). Centred and scaled first, as a careful user would:
    in raw counts the normal matrix spans 17 orders of magnitude and ``eigh`` returns noise."""
    m = p.mean(axis=0)
    q = p - m
    s = np.sqrt(np.mean(np.einsum("ij,ij->i", q, q)))
    q = q / s
    x, y, z = q[:, 0], q[:, 1], q[:, 2]
    d = np.column_stack(
        [x * x, y * y, z * z, 2 * x * y, 2 * x * z, 2 * y * z, 2 * x, 2 * y, 2 * z, np.ones_like(x)]
    )
    _, vecs = np.linalg.eigh(d.T @ d)
    center, w = _quadric_to_fit(vecs[:, 0], radius)
    return m + s * center, w / s


NEIGHBOURS = np.array(
    [(i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1)
     if (i, j, k) != (0, 0, 0)],
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


def paired(base, ours, rounds: int):
    """Alternate baseline and triaxcal (swapping who goes first each round); per-round times."""
    tb, to = [], []
    rb = ro = None
    for r in range(rounds):
        order = (0, 1) if r % 2 == 0 else (1, 0)
        for who in order:
            t0 = time.perf_counter()
            out = (base if who == 0 else ours)()
            dt = time.perf_counter() - t0
            if who == 0:
                tb.append(dt)
                rb = out
            else:
                to.append(dt)
                ro = out
    return np.array(tb), np.array(to), rb, ro


def summary(tb: np.ndarray, to: np.ndarray) -> tuple[float, float, float]:
    r = tb / to
    return float(np.median(r)), float(r.min()), float(r.max())


def matrix_err(matrix) -> float:
    """Frobenius norm of the matrix error, relative to the matrix (x 16384 counts per g)."""
    return float(np.linalg.norm(np.asarray(matrix) - TRUE_MATRIX) * 16384)


ROWS: list[tuple[str, str, str, str]] = []


def report(name: str, target: str, tb, to, extra: str = "") -> None:
    med, lo, hi = summary(tb, to)
    ROWS.append((name, target, f"{med:.1f}x ({lo:.1f}-{hi:.1f}x)", extra))
    print(
        f"{name:<58} {np.median(tb) * 1e3:10.3f} ms {np.median(to) * 1e3:10.3f} ms  "
        f"{med:6.1f}x [{lo:.1f}-{hi:.1f}] (target {target}) {extra}",
        flush=True,
    )


# ------------------------------------------------------------------------------- rows


def row_full_fit(sizes, rounds) -> None:
    for n in sizes:
        raw, _ = distorted_sphere(n, offset=TRUE_OFFSET, matrix=TRUE_MATRIX, noise=0.01, seed=1)
        k = max(1, int(2e4 // n))  # repeat tiny cases so that one timing is ~ms
        base = lambda raw=raw, k=k: [numpy_normal_equations(raw) for _ in range(k)][-1]  # noqa: E731
        ours = lambda raw=raw, k=k: [tc.fit_ellipsoid(raw, radius=1.0) for _ in range(k)][-1]  # noqa: E731
        tb, to, rb, ro = paired(base, ours, rounds if n < 10**6 else max(3, rounds // 2))
        eb, eo = matrix_err(rb[1]), matrix_err(ro.matrix)
        acc = f"| matrix error {eb:.2e} vs {eo:.2e} ({eb / eo:.1f}x more accurate)"
        report(f"full fit, N={n:,} vs numpy normal equations", ">= 2x", tb / k, to / k, acc)
    # accuracy alone, more noise: where the algebraic fit's O(noise^2) bias dominates
    for noise in (0.01, 0.02, 0.03):
        for n in (100_000, 1_000_000):
            if n not in sizes:
                continue
            errs = []
            for seed in range(3):
                raw, _ = distorted_sphere(
                    n, offset=TRUE_OFFSET, matrix=TRUE_MATRIX, noise=noise, seed=seed
                )
                errs.append(
                    (matrix_err(numpy_normal_equations(raw)[1]),
                     matrix_err(tc.fit_ellipsoid(raw, radius=1.0).matrix))
                )
            eb, eo = np.median(errs, axis=0)
            print(f"  accuracy N={n:,}, noise {noise:.0%} (median of 3 draws): normal equations "
                  f"{eb:.2e}, triaxcal {eo:.2e}: {eb / eo:.1f}x more accurate", flush=True)


def row_batch(b, rounds) -> None:
    sets = np.stack(
        [
            distorted_sphere(200, offset=TRUE_OFFSET, matrix=TRUE_MATRIX, noise=0.003,
                             seed=100 + i)[0]
            for i in range(b)
        ]
    )
    ours = lambda: tc.fit_batch(sets, radius=1.0)  # noqa: E731
    for label, fn, target in (
        ("numpy SVD loop", numpy_svd, ">= 25x"),
        ("numpy normal-equations loop", numpy_normal_equations, ">= 10x"),
    ):
        tb, to, rb, ro = paired(lambda fn=fn: [fn(s) for s in sets], ours, rounds)
        eb = np.median([matrix_err(r[1]) for r in rb])
        eo = np.median([matrix_err(m) for m in ro.matrices])
        report(f"fit_batch, {b:,} sets x 200 vs {label}", target, tb, to,
               f"| median matrix error {eb:.2e} vs {eo:.2e}; {np.median(to) / b * 1e6:.2f} us/set")
    threads_row(b, rounds)


THREAD_PROBE = """
import os, sys, time, numpy as np, triaxcal as tc
sys.path.insert(0, {tests!r})
from _synth import distorted_sphere
sets = np.stack([distorted_sphere(200, offset=[412.0, -230.5, 97.25],
    matrix=np.eye(3) / 16384, noise=0.003, seed=100 + i)[0] for i in range({b})])
tc.fit_batch(sets[:100], radius=1.0)
best = (1e9, 0.0)
for _ in range(3):
    w, c = time.perf_counter(), time.process_time()
    tc.fit_batch(sets, radius=1.0)
    best = min(best, (time.perf_counter() - w, time.process_time() - c))
print(best[0], best[1])
"""


def threads_row(b, rounds) -> None:
    """fit_batch with 1 and 2 rayon threads, each in a fresh process (RAYON_NUM_THREADS is read
    once), alternating; the CPU time shows whether the run was CPU-bound (2 threads should use
    about twice the CPU time of the wall time)."""
    code = THREAD_PROBE.format(tests=os.path.join(os.path.dirname(__file__), "..", "tests"), b=b)
    wall = {1: [], 2: []}
    cpu = {1: [], 2: []}
    for r in range(rounds):
        for t in ((1, 2) if r % 2 == 0 else (2, 1)):
            env = dict(os.environ, RAYON_NUM_THREADS=str(t), OPENBLAS_NUM_THREADS="1")
            out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                                 text=True, check=True).stdout.split()
            wall[t].append(float(out[0]))
            cpu[t].append(float(out[1]))
    tb, to = np.array(wall[1]), np.array(wall[2])
    load = os.getloadavg()[0]
    report(f"fit_batch, {b:,} sets x 200: 2 threads vs 1", ">= 1.7x", tb, to,
           f"| CPU/wall with 2 threads {np.median(np.array(cpu[2]) / to):.2f}, "
           f"load average {load:.1f} on {os.cpu_count()} cores")


def row_descend(rounds) -> None:
    raw, _ = distorted_sphere(
        10_000, offset=TRUE_OFFSET, matrix=np.eye(3) / 16384, noise=0.002, seed=3
    )
    tb, to, rb, ro = paired(
        lambda: numpy_descend(raw, 16384.0), lambda: tc.descend_center(raw, 16384.0), rounds
    )
    same = np.max(np.abs(rb[0] - ro.center))
    report("descend_center, N=10,000 vs numpy descent", ">= 50x", tb, to,
           f"| centres differ by {same:.3g} counts")


def row_overhead(rounds) -> None:
    """What a Python call adds to a fit of 10 points: each round times ``calls`` whole
    ``fit_ellipsoid`` calls, then the same fit run ``calls`` times inside the compiled core with
    no Python in between (``_core.time_fit``); the overhead is the difference, per round."""
    from triaxcal import _core

    if not hasattr(_core, "time_fit"):
        raise SystemExit("the call-overhead row needs the benchmark hooks: build with `make "
                         "install` (cargo feature bench-hooks)")
    raw, _ = distorted_sphere(10, offset=TRUE_OFFSET, matrix=TRUE_MATRIX, noise=0.01, seed=4)
    calls = 2000
    per, core = [], []
    for _ in range(rounds):
        t0 = time.perf_counter()
        for _ in range(calls):
            tc.fit_ellipsoid(raw, radius=1.0)
        per.append((time.perf_counter() - t0) / calls)
        core.append(_core.time_fit(raw, 1.0, calls))
    per_us, core_us = np.array(per) * 1e6, np.array(core) * 1e6
    over = per_us - core_us
    med, cmed, omed = (float(np.median(a)) for a in (per_us, core_us, over))
    ROWS.append(("call overhead: fit_ellipsoid of 10 points", "<= 3 us",
                 f"{omed:.1f} us ({over.min():.1f}-{over.max():.1f})",
                 f"(full model, radius 1: the whole call {med:.1f} us, the fit alone "
                 f"{cmed:.1f} us)"))
    print(f"{'call overhead: fit_ellipsoid, N=10 (full model)':<58} median {omed:.2f} us "
          f"({over.min():.2f}-{over.max():.2f}) per call (target <= 3 us): the whole call "
          f"{med:.2f} us, the fit alone in Rust {cmed:.2f} us", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="smaller sizes, fewer rounds")
    ap.add_argument("--rounds", type=int, default=None, help="paired rounds per case")
    ap.add_argument("--rows", default="fit,batch,descend,overhead",
                    help="comma-separated subset of: fit, batch, descend, overhead")
    args = ap.parse_args()
    q = args.quick
    rounds = args.rounds or (3 if q else 7)
    rows = set(args.rows.split(","))
    print(f"triaxcal {tc.__version__}, numpy {np.__version__}, {os.cpu_count()} cores, "
          f"load average {os.getloadavg()[0]:.1f}")
    print(f"{'case':<58} {'baseline':>13} {'triaxcal':>13}  {'ratio':>7}")
    if "fit" in rows:
        row_full_fit((1000, 10_000, 100_000) if q else (1000, 10_000, 100_000, 1_000_000), rounds)
    if "batch" in rows:
        row_batch(2_000 if q else 10_000, max(3, rounds // 2))
    if "descend" in rows:
        row_descend(rounds)
    if "overhead" in rows:
        row_overhead(rounds)
    print("\n| case | target | median ratio (range) | notes |\n|---|---|---|---|")
    for name, target, ratio, extra in ROWS:
        print(f"| {name} | {target} | {ratio} | {extra.lstrip('| ')} |")


if __name__ == "__main__":
    main()
