"""Fits over Dask collections, on whatever Dask scheduler is in use (``triaxcal.dask``).

Nothing here starts a cluster: the work is handed to ``dask.compute``, which runs it on the
scheduler the caller has set up -- a ``distributed.Client`` (local or remote: once a client
exists, Dask uses it), ``dask.config.set(scheduler=...)``, or the default thread pool. Each
task calls the in-process fit (:func:`triaxcal.fit_batch`, which fits every set on its own),
so the results are exactly those of one in-process call on the same sets in the same order.

* :func:`fit_batch` -- a dask array (B, N, 3) chunked along B: one task per chunk.
* :func:`fit_groups` -- a dask DataFrame with a device id column (e.g. from
  ``dask.dataframe.read_parquet``): rows are shuffled so that each device's rows meet in one
  partition, in the frame's row order, then each partition's devices are fitted in one call.
* :func:`autocalibrate_many` -- free-living auto-calibration, one task per recording.

Needs the ``dask`` extra: ``pip install 'triaxcal[dask]'`` (dask[dataframe], distributed,
pyarrow).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import CalibrationError
from ..fit.ellipsoid import BatchFit
from ..fit.ellipsoid import fit_batch as _fit_batch

try:
    import dask
    import dask.array as da
    import dask.dataframe as dd
except ImportError as _exc:  # pragma: no cover - exercised without the extra
    raise CalibrationError(
        f"triaxcal.dask needs Dask ({_exc.name} is missing): pip install 'triaxcal[dask]'"
    ) from None

__all__ = ["GroupFit", "autocalibrate_many", "fit_batch", "fit_groups"]

_FIELDS = ("offsets", "matrices", "radii", "rms", "converged", "iterations")


@dataclass(frozen=True)
class GroupFit(BatchFit):
    """A :class:`~triaxcal.BatchFit` whose row ``i`` belongs to device ``ids[i]`` (sorted)."""

    ids: tuple[Any, ...] = ()


def _fit_kwargs(opts: dict[str, Any]) -> dict[str, Any]:
    unknown = set(opts) - {"model", "radius", "max_iter", "tol", "method", "debias"}
    if unknown:
        raise CalibrationError(f"unknown fit option(s) {sorted(unknown)}")
    return opts


def _block_fit(block: np.ndarray, opts: dict[str, Any]) -> dict[str, Any]:
    res = _fit_batch(block, **opts)
    d: dict[str, Any] = {k: np.array(getattr(res, k)) for k in _FIELDS}
    d["errors"] = list(res.errors)
    return d


def _join(parts: Sequence[dict[str, Any]], model: str) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k in _FIELDS:
        arr = np.concatenate([p[k] for p in parts]) if parts else np.zeros(0)
        arr.setflags(write=False)
        out[k] = arr
    out["errors"] = tuple(e for p in parts for e in p["errors"])
    out["model"] = model
    return out


def _to_batch_fit(d: dict[str, Any]) -> BatchFit:
    return BatchFit(**d)


def fit_batch(sets: Any, *, compute: bool = True, **options: Any) -> Any:
    """:func:`triaxcal.fit_batch` over a dask array of shape (B, N, 3), one task per chunk.

    Parameters
    ----------
    sets : dask.array.Array, shape (B, N, 3)
        One set of raw readings per device, chunked along B (chunks along N or the last axis
        are merged first).
    compute : bool
        ``True``: compute now on the current scheduler and return the :class:`BatchFit`;
        ``False``: return a ``dask.delayed`` object that computes to it.
    **options
        ``model``, ``radius``, ``max_iter``, ``tol``, ``method``, ``debias``: as for
        :func:`triaxcal.fit_batch`.

    Returns
    -------
    BatchFit
        Row ``i`` belongs to set ``i``; exactly what ``triaxcal.fit_batch(sets.compute())``
        returns.

    Examples
    --------
    >>> import numpy as np, dask.array as da, triaxcal as tc, triaxcal.dask as tcd
    >>> rng = np.random.default_rng(0)
    >>> u = rng.normal(size=(6, 200, 3)); u /= np.linalg.norm(u, axis=2, keepdims=True)
    >>> raw = u * 16384 + [300, -200, 100]
    >>> fit = tcd.fit_batch(da.from_array(raw, chunks=(2, 200, 3)), model="sphere")
    >>> bool(np.array_equal(fit.offsets, tc.fit_batch(raw, model="sphere").offsets))
    True
    """
    opts = _fit_kwargs(dict(options))
    if not isinstance(sets, da.Array):
        raise CalibrationError(
            f"sets must be a dask array of shape (B, N, 3), got {type(sets).__name__} (for "
            "numpy arrays use triaxcal.fit_batch)"
        )
    if sets.ndim != 3 or sets.shape[2] != 3:
        raise CalibrationError(f"sets must have shape (B, N, 3), got {sets.shape}")
    if len(sets.chunks[1]) > 1 or len(sets.chunks[2]) > 1:
        sets = sets.rechunk({1: -1, 2: -1})
    model = opts.get("model", "full")
    blocks = sets.to_delayed().ravel().tolist()
    parts = [dask.delayed(_block_fit, pure=True)(b, opts) for b in blocks]
    joined = dask.delayed(_join, pure=True)(parts, model)
    result = dask.delayed(_to_batch_fit, pure=True)(joined)
    return result.compute() if compute else result


_WIDE = ([f"offset_{a}" for a in "xyz"] + [f"m{i}{j}" for i in range(3) for j in range(3)]
         + ["radius", "rms", "converged", "iterations", "error"])


def _fit_partition(df: Any, by: str, columns: Sequence[str], opts: dict[str, Any]) -> Any:
    """Fit every device of one partition (all its rows are here); one row per device."""
    import pandas as pd

    codes, uniques = pd.factorize(df[by], sort=True)
    order = np.lexsort((df["_row"].to_numpy(), codes))
    codes = codes[order]
    pts = df[list(columns)].to_numpy(dtype=np.float64)[order]
    cut = np.flatnonzero(codes[1:] != codes[:-1]) + 1
    starts, ends = np.r_[0, cut], np.r_[cut, len(codes)]
    sets = [pts[a:b] for a, b in zip(starts, ends)] if len(codes) else []
    res = _fit_batch(sets, **opts)
    b = len(sets)
    out = {by: pd.Series(np.asarray(uniques)[codes[starts]] if b else [],
                         dtype=df[by].dtype)}
    flat = np.column_stack([res.offsets.reshape(b, 3), res.matrices.reshape(b, 9),
                            res.radii, res.rms]) if b else np.zeros((0, 14))
    for k, name in enumerate(_WIDE[:14]):
        out[name] = flat[:, k]
    out["converged"] = np.asarray(res.converged, dtype=bool)
    out["iterations"] = np.asarray(res.iterations, dtype=np.int64)
    out["error"] = pd.Series(list(res.errors), dtype=object)
    return pd.DataFrame(out)


def _unique_ids(ids: Any) -> Any:
    import pandas as pd

    return pd.Series([list(pd.unique(ids))], dtype=object)


def _local_rows(df: Any) -> Any:
    return df.assign(_row=np.arange(len(df), dtype=np.int64))


def fit_groups(
    frame: Any,
    by: str = "device_id",
    columns: Sequence[str] = ("ax", "ay", "az"),
    *,
    npartitions: int | None = None,
    shuffle: bool | None = None,
    **options: Any,
) -> GroupFit:
    """Fit every device of a dask DataFrame: the rows with the same ``by`` form one set.

    Parameters
    ----------
    frame : dask.dataframe.DataFrame
        One reading per row, e.g. ``dask.dataframe.read_parquet("fleet/")``.
    by : str
        The device id column.
    columns : 3 str
        The x, y, z columns (raw units).
    npartitions : int, optional
        Partitions after the shuffle (default: as many as the frame has).
    shuffle : bool, optional
        Bring each device's rows into one partition first. ``None`` (default): only when
        some device's rows are spread over several partitions (checked with one pass over the
        id column; data written one device per file, or sorted by device, needs none --
        much faster); ``False``: trust that they are not.
    **options
        As for :func:`triaxcal.fit_batch`.

    Returns
    -------
    GroupFit
        A :class:`~triaxcal.BatchFit` with ``ids``: row ``i`` is device ``ids[i]``, ids sorted.
        Each device's readings are fitted in the frame's row order, so the result equals
        ``triaxcal.fit_batch([rows of id in file order for id in sorted ids])`` exactly.
    """

    opts = _fit_kwargs(dict(options))
    if not isinstance(frame, dd.DataFrame):
        raise CalibrationError(
            f"frame must be a dask DataFrame, got {type(frame).__name__} (wrap a pandas frame "
            "with dask.dataframe.from_pandas)"
        )
    cols = [str(c) for c in columns]
    if len(cols) != 3:
        raise CalibrationError(f"columns must name 3 columns (x, y, z), got {cols}")
    missing = [c for c in (by, *cols) if c not in frame.columns]
    if missing:
        raise CalibrationError(
            f"the frame has no column(s) {missing}; it has {list(frame.columns)}")
    sub = frame[[by, *cols]]
    if shuffle is None:  # do the partitions hold whole devices already? (one pass over ids)
        per_part = frame[by].map_partitions(_unique_ids, meta=(by, object)).compute()
        seen = [i for ids in per_part for i in ids]
        shuffle = len(seen) != len(set(seen))
    if shuffle:
        sub = sub.assign(_row=1)
        sub = sub.assign(_row=sub["_row"].cumsum())  # the frame's row order, across partitions
        n = npartitions or frame.npartitions
        shuffled = sub.shuffle(on=by, npartitions=n)
    else:
        shuffled = sub.map_partitions(_local_rows)
    meta = _fit_partition(shuffled._meta, by, cols, opts)
    fitted = shuffled.map_partitions(_fit_partition, by, cols, opts, meta=meta)
    table = fitted.compute().sort_values(by, kind="stable").reset_index(drop=True)
    b = len(table)
    wide = table[_WIDE[:14]].to_numpy(dtype=np.float64)
    arrays = {
        "offsets": np.ascontiguousarray(wide[:, 0:3]),
        "matrices": np.ascontiguousarray(wide[:, 3:12]).reshape(b, 3, 3),
        "radii": np.ascontiguousarray(wide[:, 12]),
        "rms": np.ascontiguousarray(wide[:, 13]),
        "converged": table["converged"].to_numpy(dtype=bool),
        "iterations": table["iterations"].to_numpy(dtype=np.int64),
    }
    for a in arrays.values():
        a.setflags(write=False)
    errors = tuple(None if (e is None or (isinstance(e, float) and np.isnan(e))) else str(e)
                   for e in table["error"])
    return GroupFit(model=opts.get("model", "full"), errors=errors,
                    ids=tuple(table[by].tolist()), **arrays)


def autocalibrate_many(
    recordings: Sequence[Any],
    rate_hz: float | Sequence[float] | None = None,
    *,
    compute: bool = True,
    **options: Any,
) -> Any:
    """:func:`triaxcal.autocalibrate` over many recordings, one Dask task per recording.

    Parameters
    ----------
    recordings : sequence
        Each one a wearable file path (read with :func:`triaxcal.io.wearables.read_wearable`
        inside the task, so only the path travels), or an ``(N, 3)`` array in g (then
        ``rate_hz`` is needed), or a ``(acc, temp_c)`` pair of arrays.
    rate_hz : float or sequence of float, optional
        Sample rate(s) for array recordings; files carry their own.
    compute : bool
        ``True``: compute now on the current scheduler; ``False``: return the list of
        ``dask.delayed`` objects.
    **options
        Passed on to :func:`triaxcal.autocalibrate` (``window_s``, ``sd_threshold_g``,
        ``min_hours``, ``use_temperature``, ...).

    Returns
    -------
    list of AutoCalibration
        One per recording, in order; a recording that cannot be read or calibrated gives an
        ``AutoCalibration`` with ``accepted=False`` and the reason.
    """
    from ..methods.autocal import autocalibrate_source

    recs = list(recordings)
    rates = (list(rate_hz) if isinstance(rate_hz, (list, tuple, np.ndarray))
             else [rate_hz] * len(recs))
    if len(rates) != len(recs):
        raise CalibrationError(f"{len(rates)} rates for {len(recs)} recordings")
    tasks = [dask.delayed(autocalibrate_source, pure=True)(r, rt, options)
             for r, rt in zip(recs, rates)]
    return list(dask.compute(*tasks)) if compute else tasks
