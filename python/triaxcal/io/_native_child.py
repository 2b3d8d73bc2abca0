"""Run one third-party native reader on one file; the child side of :mod:`triaxcal.io.isolate`.

Run as a script (never imported by triaxcal): ``_native_child.py READER FILE OUTDIR
MEMORY_BYTES``. It imports only the standard library, numpy and the reader, bounds its own
address space, writes each array the reader returned to ``OUTDIR/<name>.npy`` and the rest
(numbers, text, the reader's warnings, or its error) to ``OUTDIR/meta.json``. A crash of the
reader kills only this process.

Readers:

* ``skdh-cwa``: scikit-digital-health's Axivity reader (``read_axivity``);
* ``skdh-bin``: scikit-digital-health's GENEActiv reader (``read_geneactiv``).

Both are loaded from skdh's compiled extension without importing the whole package (which
takes seconds); when that extension cannot be found, ``skdh.io.ReadCwa`` / ``ReadBin`` are
used instead.
"""

from __future__ import annotations

import importlib.machinery
import importlib.util
import json
import sys
import warnings
from pathlib import Path
from typing import Any

import numpy as np


def _skdh_extension() -> Any:
    """skdh's compiled readers (``skdh.io._extensions.read``), or None."""
    spec = importlib.util.find_spec("skdh")  # finds the package without running it
    if spec is None or not spec.submodule_search_locations:
        return None
    folder = Path(next(iter(spec.submodule_search_locations))) / "io" / "_extensions"
    for suffix in importlib.machinery.EXTENSION_SUFFIXES:
        f = folder / f"read{suffix}"
        if f.is_file():
            loader = importlib.machinery.ExtensionFileLoader("skdh.io._extensions.read", str(f))
            mspec = importlib.util.spec_from_loader(loader.name, loader)
            if mspec is None:
                return None
            module = importlib.util.module_from_spec(mspec)
            loader.exec_module(module)
            return module
    return None


def _cwa(path: str) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    ext = _skdh_extension()
    if ext is not None and hasattr(ext, "read_axivity"):
        fs, n_bad, imu, ts, temp = ext.read_axivity(path)
        axes = imu.shape[1]
        if axes not in (3, 6, 9):
            raise RuntimeError(f"the reader returned {axes} axes (3, 6 or 9 expected)")
        acc = imu if axes == 3 else imu[:, 3:6]
        arrays = {"accel": np.ascontiguousarray(acc), "time": ts, "temperature": temp}
        if axes > 3:
            arrays["gyro"] = np.ascontiguousarray(imu[:, :3])
        return {"fs": float(fs), "bad_samples": int(n_bad)}, arrays
    from skdh.io import ReadCwa

    r = ReadCwa().predict(file=path)
    arrays = {k: np.asarray(r[k]) for k in ("accel", "time", "temperature", "gyro") if k in r}
    return {"fs": float(r["fs"])}, arrays


def _bin(path: str) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    ext = _skdh_extension()
    if ext is not None and hasattr(ext, "read_geneactiv"):
        n, fs, acc, ts, light, temp = ext.read_geneactiv(path)
        n = int(n)
        return {"fs": float(fs)}, {"accel": acc[:n], "time": ts[:n], "temperature": temp[:n],
                                   "light": light[:n]}
    from skdh.io import ReadBin

    r = ReadBin().predict(file=path)
    arrays = {k: np.asarray(r[k]) for k in ("accel", "time", "temperature") if k in r}
    return {"fs": float(r["fs"])}, arrays


READERS = {"skdh-cwa": _cwa, "skdh-bin": _bin}


def main(argv: list[str]) -> int:
    reader, path, outdir, memory = argv[0], argv[1], Path(argv[2]), int(argv[3])
    try:
        import resource

        _, hard = resource.getrlimit(resource.RLIMIT_AS)
        cap = memory if hard == resource.RLIM_INFINITY else min(memory, hard)
        resource.setrlimit(resource.RLIMIT_AS, (cap, hard))
    except (ImportError, AttributeError, ValueError, OSError):
        pass  # no address-space limit on this system (the time limit still holds)
    meta: dict[str, Any]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            meta, arrays = READERS[reader](path)
        except MemoryError:
            meta, arrays = {"error": "MemoryError: it needs more memory than the file's size "
                                     "allows (a header that declares more data than there is?)"}, {}
        except Exception as exc:  # noqa: BLE001 - the reader raises many kinds; all are reported
            meta, arrays = {"error": f"{type(exc).__name__}: {exc}"}, {}
    meta["warnings"] = [str(w.message) for w in caught]
    for name, arr in arrays.items():
        np.save(outdir / f"{name}.npy", np.asarray(arr), allow_pickle=False)
    (outdir / "meta.json").write_text(json.dumps(meta), encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
