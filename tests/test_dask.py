"""triaxcal.dask on a real distributed.LocalCluster with two worker processes: the results
must equal the in-process fits exactly (bit for bit)."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("dask.dataframe")
pytest.importorskip("distributed")
pytest.importorskip("pyarrow")

import dask.array as da  # noqa: E402
import dask.dataframe as dd  # noqa: E402
import pandas as pd  # noqa: E402
import triaxcal as tc  # noqa: E402
from distributed import Client, LocalCluster, get_task_stream  # noqa: E402
from triaxcal.errors import CalibrationError  # noqa: E402

FIELDS = ("offsets", "matrices", "radii", "rms", "converged", "iterations", "errors")


@pytest.fixture(scope="module")
def client():
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster, Client(cluster) as c:
        yield c


def fleet(b: int, n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    u = rng.normal(size=(b, n, 3))
    u /= np.linalg.norm(u, axis=2, keepdims=True)
    gains = 1 + rng.uniform(-0.03, 0.03, (b, 1, 3))
    off = rng.uniform(-900, 900, (b, 1, 3))
    return np.rint(u * 16384 / gains + off + rng.normal(0, 30, (b, n, 3)))


def same(a, b) -> None:
    for k in FIELDS:
        x, y = getattr(a, k), getattr(b, k)
        if k == "errors":
            assert x == y
        else:
            assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), k


@pytest.mark.slow
def test_fit_batch_on_two_worker_processes_equals_in_process(client):
    assert len(client.scheduler_info()["workers"]) == 2
    raw = fleet(40, 250)
    raw[7] = 0.0  # one degenerate set: its error, not a crash, in both
    import triaxcal.dask as tcd

    with get_task_stream(client) as stream:
        got = tcd.fit_batch(da.from_array(raw, chunks=(7, 250, 3)), model="full", radius=1.0)
    want = tc.fit_batch(raw, model="full", radius=1.0)
    same(got, want)
    assert got.errors[7] is not None and sum(e is None for e in got.errors) == 39
    fit_tasks = [t for t in stream.data if "_block_fit" in t["key"]]
    assert len(fit_tasks) == 6  # one task per chunk of 7 sets
    assert len({t["worker"] for t in fit_tasks}) == 2  # on both worker processes
    lazy = tcd.fit_batch(da.from_array(raw, chunks=(40, 125, 3)), compute=False, radius=1.0)
    same(lazy.compute(), want)


@pytest.mark.slow
def test_fit_groups_from_parquet_equals_in_process(client, tmp_path):
    import triaxcal.dask as tcd

    b, n = 30, 200
    raw = fleet(b, n, seed=1)
    ids = np.repeat([f"SN{i:04d}" for i in range(b)], n)
    df = pd.DataFrame({"device_id": ids, "ax": raw[..., 0].ravel(), "ay": raw[..., 1].ravel(),
                       "az": raw[..., 2].ravel()})
    df = df.sample(frac=1.0, random_state=3).reset_index(drop=True)  # devices interleaved
    for k, rows in enumerate(np.array_split(np.arange(len(df)), 5)):
        df.iloc[rows].to_parquet(tmp_path / f"part{k}.parquet")
    frame = dd.read_parquet(str(tmp_path))
    with get_task_stream(client) as stream:
        got = tcd.fit_groups(frame, by="device_id", columns=["ax", "ay", "az"], radius=1.0,
                             model="axis")
    assert any("shuffle" in str(t["key"]) for t in stream.data)  # devices were spread
    order = sorted(set(ids))
    sets = [df.loc[df.device_id == i, ["ax", "ay", "az"]].to_numpy() for i in order]
    want = tc.fit_batch(sets, radius=1.0, model="axis")
    assert got.ids == tuple(order)
    same(got, want)
    assert isinstance(got, tc.BatchFit)
    # written one device per file, no shuffle is needed (and none is made): the same result
    grouped = tmp_path / "grouped"
    grouped.mkdir()
    for k, dev in enumerate(order):
        df[df.device_id == dev].to_parquet(grouped / f"{k:03d}.parquet")
    with get_task_stream(client) as stream:
        again = tcd.fit_groups(dd.read_parquet(str(grouped)), radius=1.0, model="axis")
    assert not any("shuffle" in str(t["key"]) for t in stream.data)
    same(again, want)


def test_bad_input_is_a_calibration_error(client):
    import triaxcal.dask as tcd

    with pytest.raises(CalibrationError, match="dask array"):
        tcd.fit_batch(np.zeros((2, 10, 3)))
    with pytest.raises(CalibrationError, match=r"\(B, N, 3\)"):
        tcd.fit_batch(da.zeros((2, 10, 4)))
    frame = dd.from_pandas(pd.DataFrame({"id": ["a"], "x": [1.0]}), npartitions=1)
    with pytest.raises(CalibrationError, match="no column"):
        tcd.fit_groups(frame, by="id", columns=["x", "y", "z"])
    with pytest.raises(CalibrationError, match="unknown fit option"):
        tcd.fit_batch(da.zeros((2, 10, 3)), modle="full")


def test_without_dask_the_error_names_the_extra(tmp_path):
    # a Python where importing dask fails
    (tmp_path / "dask").mkdir()
    (tmp_path / "dask" / "__init__.py").write_text("raise ImportError('no dask', name='dask')\n")
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(tmp_path), env.get("PYTHONPATH", "")])
    code = ("import triaxcal\n"
            "try:\n    import triaxcal.dask\nexcept triaxcal.CalibrationError as e:\n"
            "    print(e)\n")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         check=True).stdout
    assert "pip install 'triaxcal[dask]'" in out


def test_autocalibrate_many_one_task_per_recording(client, realdata):
    import triaxcal.dask as tcd
    from triaxcal.sim import FreeLivingSim

    pytest.importorskip("pygt3x")
    gt3x = realdata / "wearables-ggirread" / "actigraph_testfile.gt3x"
    sims = [FreeLivingSim(seed=s, days=0.25, rate_hz=5.0) for s in (2, 4)]
    arrays = [tuple(np.concatenate(x) for x in zip(*sim.chunks())) for sim in sims]
    recs = [str(gt3x), arrays[0], arrays[1][0], str(gt3x.with_name("missing.gt3x"))]
    with get_task_stream(client) as stream:
        got = tcd.autocalibrate_many(recs, rate_hz=5.0, min_hours=0)
    tasks = [t for t in stream.data if "autocalibrate_source" in t["key"]]
    assert len(tasks) == 4
    from triaxcal.io.wearables import read_wearable

    rec = read_wearable(gt3x)
    want = [tc.autocalibrate(rec.acc_g, rec.rate_hz, min_hours=0),
            tc.autocalibrate(arrays[0][0], 5.0, arrays[0][1], min_hours=0),
            tc.autocalibrate(arrays[1][0], 5.0, min_hours=0)]
    for g, w in zip(got, want):
        assert np.array_equal(g.offset, w.offset) and np.array_equal(g.gain, w.gain)
        assert g.status == w.status and g.n_still == w.n_still
    assert got[1].accepted and got[1].temp_ref_c is not None
    assert not got[3].accepted and "not found" in got[3].status
