"""Fleet fits on Dask: throughput with 1 and 2 worker processes on a dataset in Parquet.

Run: ``python benches/bench_fleet.py`` (``--quick`` for a smaller run). It writes a fleet of
simulated devices (``--devices`` x ``--points`` readings, one row per reading, devices
each device's rows in one of ``--files`` Parquet files, or ``--interleaved`` across all of them
so that Dask must shuffle) to a temporary folder, then times
``triaxcal.dask.fit_groups(dd.read_parquet(folder))`` on a ``distributed.LocalCluster`` with 1
worker process and with 2 (one thread each, ``RAYON_NUM_THREADS=1`` so that one worker is
one core), best of ``--rounds``, next to the in-process
baseline ``triaxcal.fit_batch`` on the same sets held in memory, and checks that every run
gives exactly the in-process result. Prints devices per second and the 2-vs-1 worker ratio.

On a real cluster: ``python benches/bench_fleet.py --scheduler tcp://HOST:8786 --data
s3://bucket/fleet/`` connects a ``distributed.Client`` to that scheduler instead of starting
local clusters (the workers must be able to import triaxcal and read the data path; the
dataset is written there first unless ``--no-write``).
"""

from __future__ import annotations

import argparse
import tempfile
import time

import numpy as np
import triaxcal as tc


def make_fleet(devices: int, points: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    u = rng.normal(size=(devices, points, 3))
    u /= np.linalg.norm(u, axis=2, keepdims=True)
    gains = 1 + rng.uniform(-0.03, 0.03, (devices, 1, 3))
    off = rng.uniform(-900, 900, (devices, 1, 3))
    return np.rint(u * 16384 / gains + off + rng.normal(0, 30, (devices, points, 3)))


def write_parquet(raw: np.ndarray, folder: str, files: int, *, interleaved: bool,
                  seed: int = 1) -> np.ndarray:
    """Write the fleet (each device's rows in one file, or ``interleaved`` across all files);
    returns the sets (B, N, 3) as the files hold them: per device (ids sorted), its readings
    in file order."""
    import pandas as pd

    b, n, _ = raw.shape
    ids = np.repeat([f"SN{i:07d}" for i in range(b)], n)
    df = pd.DataFrame({"device_id": ids, "ax": raw[..., 0].ravel(), "ay": raw[..., 1].ravel(),
                       "az": raw[..., 2].ravel()})
    if interleaved:
        order = np.random.default_rng(seed).permutation(len(df))
        df = df.iloc[order].reset_index(drop=True)
    for k, rows in enumerate(np.array_split(np.arange(len(df)), files)):
        df.iloc[rows].to_parquet(f"{folder.rstrip('/')}/part{k:04d}.parquet")
    grouped = np.argsort(df["device_id"].to_numpy(), kind="stable")
    return df[["ax", "ay", "az"]].to_numpy()[grouped].reshape(b, n, 3)


def run(client: object, folder: str, rounds: int, want: tc.BatchFit) -> float:
    import dask.dataframe as dd
    import triaxcal.dask as tcd

    best = float("inf")
    for _ in range(rounds):
        t = time.perf_counter()
        got = tcd.fit_groups(dd.read_parquet(folder), by="device_id", radius=1.0)
        best = min(best, time.perf_counter() - t)
        for k in ("offsets", "matrices", "rms", "iterations"):
            assert np.array_equal(getattr(got, k), getattr(want, k), equal_nan=k != "iterations"
                                  ), f"{k} differs from the in-process fit"
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--devices", type=int, default=20_000)
    ap.add_argument("--points", type=int, default=200)
    ap.add_argument("--files", type=int, default=8)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="2,000 devices, 1 round")
    ap.add_argument("--scheduler", default=None, help="address of an existing scheduler")
    ap.add_argument("--data", default=None, help="folder or URL for the Parquet files")
    ap.add_argument("--no-write", action="store_true", help="the data is there already")
    ap.add_argument("--interleaved", action="store_true",
                    help="spread every device's rows over all files (fit_groups must shuffle)")
    a = ap.parse_args()
    if a.quick:
        a.devices, a.rounds = 2_000, 1
    from distributed import Client, LocalCluster

    raw = make_fleet(a.devices, a.points)
    folder = a.data or tempfile.mkdtemp(prefix="triaxcal-fleet-")
    if not a.no_write:
        raw = write_parquet(raw, folder, a.files, interleaved=a.interleaved)
    # the in-process baseline: the same sets, in id order, in memory
    t = time.perf_counter()
    want = tc.fit_batch(raw, radius=1.0)
    t_in = time.perf_counter() - t
    layout = ("devices interleaved across files: shuffled" if a.interleaved
              else "each device in one file: no shuffle")
    print(f"{a.devices} devices x {a.points} points, {a.files} Parquet files ({layout}) in "
          f"{folder}")
    print(f"in-process tc.fit_batch (numpy in memory, rayon): {t_in:.2f} s, "
          f"{a.devices / t_in:,.0f} devices/s")
    if a.scheduler:
        with Client(a.scheduler) as client:
            n = len(client.scheduler_info()["workers"])
            t = run(client, folder, a.rounds, want)
            print(f"cluster at {a.scheduler} ({n} workers): {t:.2f} s, "
                  f"{a.devices / t:,.0f} devices/s (read_parquet, shuffle if needed, fit)")
        return
    times = {}
    for workers in (1, 2):
        # one core per worker: rayon inside the core would otherwise use every CPU in each
        with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                          dashboard_address=None, env={"RAYON_NUM_THREADS": "1"}
                          ) as cluster, Client(cluster) as client:
            times[workers] = run(client, folder, a.rounds, want)
        print(f"LocalCluster, {workers} worker process(es): {times[workers]:.2f} s, "
              f"{a.devices / times[workers]:,.0f} devices/s (read_parquet, shuffle if needed, "
              "fit), identical to in-process")
    print(f"2 workers vs 1: {times[1] / times[2]:.2f}x faster")


if __name__ == "__main__":
    main()
