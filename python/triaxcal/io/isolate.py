"""Third-party native readers, run in a process of their own.

The compiled readers triaxcal hands files to (scikit-digital-health's Axivity and GENEActiv
readers, in C and Fortran) trust the file: a damaged or crafted one can make them write past
their arrays (a segmentation fault or an abort, which would end the Python process that called
them), or loop for ever. triaxcal checks a file's structure before it hands it over (see
:mod:`triaxcal.io.wearables`) and, in case a check misses something, runs the reader in a
child process (a fresh interpreter started with ``subprocess``, so a caller's script is never
re-run) with

* a time limit: :data:`TIMEOUT_S` plus :data:`TIMEOUT_S_PER_MB` per MB of the file;
* a memory limit (its address space): :data:`MEMORY_BASE` plus :data:`MEMORY_PER_BYTE` times
  the file's size;
* its output kept apart (the readers print to standard output).

A crash, a time-out or an error of the reader becomes a :class:`~triaxcal.CalibrationError`
that names the file and says it is damaged or not a file the reader supports. The arrays come
back through ``.npy`` files in a temporary folder, read with ``allow_pickle=False``.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import CalibrationError
from .files import said

__all__ = ["MEMORY_BASE", "MEMORY_PER_BYTE", "TIMEOUT_S", "TIMEOUT_S_PER_MB", "run_native"]

#: Time allowed to any native reader, in s, before the per-MB allowance.
TIMEOUT_S = 60.0
#: Time allowed per MB of the file, in s (the readers manage tens of MB/s).
TIMEOUT_S_PER_MB = 1.0
#: Address space allowed to the child before the per-byte allowance (the interpreter and numpy).
MEMORY_BASE = 1 << 30
#: Address space allowed per byte of the file: the readers' arrays take up to ~10 bytes per
#: byte of an Axivity file (120 samples x 3 axes + time and temperature, in float64, per
#: 512-byte block), and the same again to write them out.
MEMORY_PER_BYTE = 24

_CHILD = Path(__file__).with_name("_native_child.py")
# Started with `python -c`: drop the current folder from sys.path (a numpy.py in the folder
# of the data must not be imported) and run the child script without adding its folder.
_BOOT = ("import sys; del sys.path[0]; sys.argv.pop(0); import runpy; "
         "runpy.run_path(sys.argv[0], run_name='__main__')")


def _tail(path: Path, n: int = 400) -> str:
    try:
        with open(path, "rb") as f:
            f.seek(max(0, os.fstat(f.fileno()).st_size - n))
            return f.read().decode("utf-8", errors="replace").strip()
    except OSError:
        return ""


def run_native(reader: str, path: Any, *, what: str, size: int | None = None,
               timeout: float | None = None) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """Run the native ``reader`` (``"skdh-cwa"``, ``"skdh-bin"``) on ``path`` in a child
    process; returns ``(meta, arrays)``.

    Parameters
    ----------
    reader : str
        Which reader (see ``_native_child.READERS``).
    path : str or Path
        The file, already checked to be a regular file of ``size`` bytes.
    what : str
        The file's kind for messages, with its article ("an Axivity .cwa file").
    size : int, optional
        The file's size in bytes (sets the time and memory limits); ``os.stat`` when None.
    timeout : float, optional
        Seconds before the child is killed (default from :data:`TIMEOUT_S` and
        :data:`TIMEOUT_S_PER_MB`).

    Raises
    ------
    CalibrationError
        When the reader crashes, runs out of time or memory, or raises: the file is damaged or
        not one it supports.
    """
    p = Path(path)
    if not sys.executable:
        raise CalibrationError(
            f"cannot read {p.name}: reading {what} needs a Python interpreter to run the reader "
            "apart, and this one does not say where it is (sys.executable is empty)"
        )
    size = os.stat(p).st_size if size is None else size
    limit = TIMEOUT_S + TIMEOUT_S_PER_MB * size / 1e6 if timeout is None else timeout
    memory = MEMORY_BASE + MEMORY_PER_BYTE * size
    env = dict(os.environ)
    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        env[var] = "1"  # one thread: a small, predictable address space
    damaged = f"{p.name} looks damaged, or is not {what} that triaxcal can read"
    with tempfile.TemporaryDirectory(prefix="triaxcal-") as tmp:
        out = Path(tmp)
        log = out / "output.txt"
        cmd = [sys.executable, "-c", _BOOT, str(_CHILD), reader, str(p.resolve()), str(out),
               str(memory)]
        try:
            with open(log, "wb") as sink:
                proc = subprocess.run(cmd, stdin=subprocess.DEVNULL, stdout=sink, stderr=sink,
                                      env=env, timeout=limit, check=False)
        except subprocess.TimeoutExpired:
            raise CalibrationError(
                f"{damaged}: its reader did not finish within {limit:.0f} s (a damaged file can "
                "make it loop)"
            ) from None
        except OSError as exc:
            raise CalibrationError(f"cannot start the reader of {p.name}: {exc}") from None
        if proc.returncode < 0:
            try:
                name = signal.Signals(-proc.returncode).name
            except ValueError:
                name = f"signal {-proc.returncode}"
            raise CalibrationError(f"{damaged}: its reader crashed on it ({name})")
        meta_path = out / "meta.json"
        if proc.returncode != 0 or not meta_path.is_file():
            printed = _tail(log)
            raise CalibrationError(
                f"{damaged}: its reader stopped (exit status {proc.returncode})"
                + (f": {said(printed, 300)}" if printed else "")
            )
        meta = json.loads(meta_path.read_text(encoding="utf-8"))
        if "error" in meta:
            raise CalibrationError(f"{damaged}: {said(meta['error'], 300)}")
        printed = _tail(log)
        if printed:
            meta.setdefault("warnings", []).append(said(printed, 300))
        arrays = {q.stem: np.load(q, allow_pickle=False) for q in out.glob("*.npy")}
    return meta, arrays
