"""Allan deviation: triaxcal against allantools on the same data, side by side; prints ratios.

Run: ``python benches/bench_noise.py`` (``--quick`` for a smaller run, ``--stream N`` for the
length of the streamed log, default 1e8 samples). Cases:

* three axes of rate readings (bias, white noise, random walk) of 10^5, 10^6 and 10^7 samples:
  ``allantools.oadev(y, rate, data_type="freq", taus="octave")`` per axis against
  ``tc.allan(y, rate)`` (every cluster exact up to 2^21 samples, strided beyond, see
  ``triaxcal.methods.allan``); best of several rounds, alternating; the largest relative
  difference over the taus both compute the same way;
* a streamed log (default 10^8 samples of one axis at 1 kHz, in chunks of 2^21): time, and
  the resident memory after the second chunk and at the end.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import triaxcal as tc
from triaxcal.sim import NoiseTruth, noise_chunks


def rss_mb() -> float:
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmRSS"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return float("nan")


def best(fn, rounds):
    times = []
    out = None
    for _ in range(rounds):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return min(times), out


def compare(n: int, rounds: int) -> None:
    import allantools

    rng = np.random.default_rng(n)
    rate = 100.0
    y = 250.0 + rng.normal(0, 0.05, (n, 3)) + np.cumsum(rng.normal(0, 2e-4, (n, 3)), 0)

    def ref():
        return [allantools.oadev(y[:, k], rate=rate, data_type="freq", taus="octave")
                for k in range(3)]

    def ours():
        return tc.allan(y, rate)

    t_ref = t_ours = float("inf")
    r_ref = r_ours = None
    for _ in range(rounds):  # alternate, keep the best of each
        a, r_ref = best(ref, 1)
        b, r_ours = best(ours, 1)
        t_ref, t_ours = min(t_ref, a), min(t_ours, b)
    assert r_ref is not None and r_ours is not None
    exact = r_ours.stride == 1
    worst = 0.0
    for k in range(3):
        taus, dev, _, _ = r_ref[k]
        np.testing.assert_array_equal(taus, r_ours.taus)
        worst = max(worst, float(np.max(np.abs(r_ours.adev[exact, k] / dev[exact] - 1))))
    print(f"  n={n:>10,}  allantools {t_ref:8.3f} s   triaxcal {t_ours:7.3f} s   "
          f"ratio {t_ref / t_ours:5.1f}x   max rel diff {worst:.1e} "
          f"({int(exact.sum())} of {len(exact)} taus exact)")


def stream(n: int) -> None:
    acc = tc.AllanAccumulator(1000.0, axes=1, unit="deg/s")
    truth = NoiseTruth(white=0.005, random_walk=1e-4)
    t0 = time.perf_counter()
    gen_s = 0.0
    after2 = float("nan")
    it = noise_chunks(truth, n, 1000.0, axes=1, chunk=1 << 21)
    i = 0
    while True:
        tg = time.perf_counter()
        c = next(it, None)
        gen_s += time.perf_counter() - tg
        if c is None:
            break
        acc.add(c)
        if i == 1:
            after2 = rss_mb()
        i += 1
    total = time.perf_counter() - t0
    r = acc.result()
    end = rss_mb()
    print(f"  streamed {n:,} samples: {total - gen_s:.1f} s in triaxcal "
          f"({(total - gen_s) / n * 1e9:.1f} ns per sample; generating them took {gen_s:.1f} s), "
          f"{len(r.taus)} taus up to {r.taus[-1]:.0f} s")
    print(f"  accumulator holds {acc.memory_bytes / 1e6:.1f} MB; resident memory after 2 "
          f"chunks {after2:.0f} MB, at the end {end:.0f} MB (growth {end - after2:+.1f} MB; "
          f"the samples themselves would be {n * 8 / 1e6:.0f} MB)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--stream", type=float, default=1e8)
    args = ap.parse_args()
    sizes = [100_000, 1_000_000] if args.quick else [100_000, 1_000_000, 10_000_000]
    print("overlapping Allan deviation, 3 axes, octave taus (allantools.oadev per axis vs "
          "tc.allan):")
    for n in sizes:
        compare(n, 2 if n >= 10_000_000 else 3)
    print("streaming:")
    stream(int(args.stream if not args.quick else min(args.stream, 1e7)))


if __name__ == "__main__":
    main()
