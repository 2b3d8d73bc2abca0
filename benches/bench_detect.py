"""Benchmark the stationary detectors against naive per-sample Python loops.

Run: ``python benches/bench_detect.py [N]``. Prints samples/s of the vectorised detectors and
the speed-up over a plain Python loop doing the same work (the loop is timed on a slice and
scaled, since it would take minutes on millions of samples).
"""

from __future__ import annotations

import sys
import time

import numpy as np
import triaxcal as tc


def recording(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    out, total, prev = [], 0, np.array([0.0, 0.0, 16384.0])
    while total < n:
        v = rng.normal(size=3)
        v *= 16384.0 / np.linalg.norm(v)
        move = np.linspace(prev, v, int(rng.integers(20, 60)))
        still = v + rng.normal(0, 40.0, (int(rng.integers(150, 500)), 3))
        out += [move, still]
        total += len(move) + len(still)
        prev = v
    return np.vstack(out)[:n]


def naive_seed(x: np.ndarray, window: int, thr: float) -> int:
    """The seed's firmware loop in Python: window means, compare with the previous one."""
    prev = None
    still_runs = 0
    run = 0
    acc = [0.0, 0.0, 0.0]
    cnt = 0
    for row in x.tolist():
        acc[0] += row[0]
        acc[1] += row[1]
        acc[2] += row[2]
        cnt += 1
        if cnt == window:
            m = [acc[0] / cnt, acc[1] / cnt, acc[2] / cnt]
            if prev is not None and all(abs(m[i] - prev[i]) <= thr for i in range(3)):
                run += 1
            else:
                still_runs += run > 0
                run = 0
            prev = m
            acc = [0.0, 0.0, 0.0]
            cnt = 0
    return still_runs


def naive_variance(x: np.ndarray, w: int) -> list[float]:
    """Per-sample sliding variance norm with a Python loop (running sums)."""
    out = []
    s1 = [0.0, 0.0, 0.0]
    s2 = [0.0, 0.0, 0.0]
    rows = x.tolist()
    for i, row in enumerate(rows):
        for k in range(3):
            s1[k] += row[k]
            s2[k] += row[k] * row[k]
        if i >= w:
            old = rows[i - w]
            for k in range(3):
                s1[k] -= old[k]
                s2[k] -= old[k] * old[k]
        n = min(i + 1, w)
        v = [s2[k] / n - (s1[k] / n) ** 2 for k in range(3)]
        out.append(sum(t * t for t in v) ** 0.5)
    return out


def timeit(fn, repeat: int = 3) -> float:
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 2_000_000
    x = recording(n)
    m = min(n, 200_000)
    t_seed = timeit(lambda: tc.detect_poses(x, units_per_g=16384, min_separation=0))
    t_seed_naive = timeit(lambda: naive_seed(x[:m], 25, 0.07 * 16384), repeat=1) * n / m
    det = tc.PoseDetector(units_per_g=16384, min_separation=0)
    t0 = time.perf_counter()
    for i in range(0, n, 1000):  # a live stream in chunks of 1000 samples
        det.update(x[i:i + 1000])
    det.finish()
    t_online = time.perf_counter() - t0
    t_var = timeit(lambda: tc.still_intervals(x, rate_hz=100, rest_s=1.0))
    t_var_naive = timeit(lambda: naive_variance(x[:m], 100), repeat=1) * n / m
    print(f"{n} samples")
    print(f"detect_poses (offline)  {n / t_seed / 1e6:8.2f} M samples/s   "
          f"naive loop {n / t_seed_naive / 1e6:6.3f} M/s   ratio {t_seed_naive / t_seed:6.1f}x")
    print(f"PoseDetector (1000/chunk){n / t_online / 1e6:7.2f} M samples/s   "
          f"ratio {t_seed_naive / t_online:6.1f}x")
    print(f"still_intervals          {n / t_var / 1e6:7.2f} M samples/s   "
          f"naive loop {n / t_var_naive / 1e6:6.3f} M/s   ratio {t_var_naive / t_var:6.1f}x")


if __name__ == "__main__":
    main()
