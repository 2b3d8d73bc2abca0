"""Instruction counts of the fits, with valgrind's callgrind: independent of the machine's load.

``make bench-instructions`` (``python benches/instructions.py``) prints:

- instructions per point of one accumulation pass with JᵀJ (the unit of work), of a polishing
  pass and of the last polishing pass, over 1,000,000 points;
- ``fit_ellipsoid`` of 1e3 .. 1e6 points: instructions per point, and in units of that pass
  (the target for 1e6 points: at most three);
- ``fit_batch`` of 200-point sets: instructions per set (target: at most 90,000), and how the
  work splits between two rayon threads (the bound on the speed-up of two threads).

- a Python ``fit_ellipsoid`` call of 10 points: its instructions, and what it adds to the
  compiled fit inside it (argument checks, the binding, the result object).

- the Allan deviation of 1e6 rows x 3 axes (overlapping and not), and the log readers on a
  simulated flight's ULog and DataFlash log: instructions per term, row or byte.

``--check`` is the regression guard of ``make test``: it counts a fit of 10 points (the fixed
cost of a fit), a fixed 1e5-point fit, a fixed batch of 1,000 sets, what a Python call of
10 points adds to its fit, the Allan deviation of 1e5 rows x 3 axes (overlapping and not) and
the two log readers on a simulated flight (:func:`triaxcal.sim.flight.write_flight`, 600 s at
20 Hz, seed 7), and fails if any grew by more than 10 % over the figures in
``benches/instructions.json`` (``--update`` rewrites them). The fits, the Allan deviation and
the readers are the Rust example ``benches/instructions.rs`` (deterministic data, one
thread); the Python call and the simulated logs come from the installed triaxcal under the
Python running this script. The counts are those of the kernels
this CPU runs (AVX2 + FMA, or the portable build), each with its own figures. Without
valgrind the check is skipped with a message; everything else missing is an error.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
FIGURES = ROOT / "benches" / "instructions.json"
BINARY = ROOT / "target" / "release" / "examples" / "instructions"
TOLERANCE = 0.10


def build() -> None:
    subprocess.run(
        ["cargo", "build", "--release", "--quiet", "--example", "instructions",
         "--no-default-features"],
        cwd=ROOT, check=True,
    )


def kernels() -> str:
    """Which kernels this CPU runs: "avx2" or "portable"."""
    if os.environ.get("TRIAXCAL_PORTABLE"):
        return "portable"
    try:
        flags = Path("/proc/cpuinfo").read_text()
    except OSError:
        return "portable"
    return "avx2" if re.search(r"\bavx2\b", flags) and re.search(r"\bfma\b", flags) else "portable"


def count(case: str, n: int | Path, toggle: str, threads: int = 1) -> list[int]:
    """Instructions executed inside ``toggle`` (and what it calls) for ``instructions case n``,
    one entry per thread that executed any."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "cg.out"
        env = dict(os.environ, RAYON_NUM_THREADS=str(threads))
        cmd = ["valgrind", "--tool=callgrind", f"--callgrind-out-file={out}",
               f"--toggle-collect={toggle}", str(BINARY), case, str(n)]
        if threads > 1:
            # valgrind runs one thread at a time; fair scheduling lets rayon's workers take
            # turns as they would on separate cores
            cmd[2:2] = ["--separate-threads=yes", "--fair-sched=yes"]
        proc = subprocess.run(cmd, env=env, capture_output=True, text=True)
        if proc.returncode != 0:
            raise RuntimeError(f"valgrind failed on {case} {n}:\n{proc.stderr[-2000:]}")
        totals = []
        for f in sorted(Path(tmp).glob("cg.out*")):
            m = re.search(r"^summary:\s+(\d+)", f.read_text(), re.M)
            if m and int(m.group(1)) > 0:
                totals.append(int(m.group(1)))
        return totals


FIT = "triaxcal::ellipsoid::fit_ellipsoid"
PASS = "triaxcal::ellipsoid::bench_one_pass"
ALLAN = "triaxcal::allan::Allan::push"
READERS = {"ulog": "triaxcal::logs::ulog::read", "dataflash": "triaxcal::logs::dataflash::read"}

# the simulated flight whose logs the readers' counts read (deterministic: a fixed seed)
FLIGHT_SCRIPT = """
import sys
from triaxcal.sim.flight import write_flight
write_flight(sys.argv[1], [200.0, 10.0, 420.0], duration_s=600, rate_hz=20.0, seed=7)
"""


def flight_logs(tmp: str) -> dict[str, Path]:
    """The simulated flight's logs, written into ``tmp``: {"ulog": .ulg, "dataflash": .BIN}."""
    subprocess.run([sys.executable, "-c", FLIGHT_SCRIPT, tmp], check=True)
    return {"ulog": Path(tmp) / "flight.ulg", "dataflash": Path(tmp) / "flight.BIN"}


def reader_counts() -> dict[str, tuple[int, int]]:
    """Instructions of each log reader on the simulated flight, with the log's size in bytes."""
    with tempfile.TemporaryDirectory() as tmp:
        return {kind: (sum(count(kind, path, READERS[kind])), path.stat().st_size)
                for kind, path in flight_logs(tmp).items()}

# `calls` Python calls of fit_ellipsoid on 10 points like those of benches/bench_fit.py's
# overhead row, made by triaxcal._core.repeat_call, inside which callgrind counts. One call
# first initialises what is done once per process; the objects made by the imports are frozen
# out of the garbage collector's way, as in a program that has been running for a while.
CALL_SCRIPT = """
import gc
import sys
import numpy as np
import triaxcal as tc
from triaxcal import _core
rng = np.random.default_rng(4)
u = rng.normal(size=(10, 3))
u /= np.linalg.norm(u, axis=1, keepdims=True)
m = np.array([[1.04, 0.01, -0.02], [0.01, 0.97, 0.015], [-0.02, 0.015, 1.01]]) / 16384
raw = u @ np.linalg.inv(m).T + [412.0, -230.5, 97.25] + rng.normal(size=(10, 3)) * 160
tc.fit_ellipsoid(raw, radius=1.0)
gc.collect()
gc.freeze()
_core.repeat_call(lambda: tc.fit_ellipsoid(raw, radius=1.0), int(sys.argv[1]))
"""
REPEAT = "triaxcal::py::bench::__pyfunction_repeat_call"


def python_call(calls: int = 1000) -> tuple[int, int]:
    """Instructions of one Python ``fit_ellipsoid`` call of 10 points, made from a lambda:
    (the whole call, the compiled fit inside it), averaged over ``calls`` calls."""
    from triaxcal import _core

    if not hasattr(_core, "repeat_call"):
        raise SystemExit("the Python-call row needs the benchmark hooks: build with `make "
                         "install` (cargo feature bench-hooks)")
    with tempfile.TemporaryDirectory() as tmp:
        script = Path(tmp) / "calls.py"
        script.write_text(CALL_SCRIPT)
        out = Path(tmp) / "cg.out"
        proc = subprocess.run(
            ["valgrind", "--tool=callgrind", f"--callgrind-out-file={out}",
             f"--toggle-collect={REPEAT}", sys.executable, str(script), str(calls)],
            env=dict(os.environ, PYTHONHASHSEED="0"), capture_output=True, text=True,
        )
        if proc.returncode != 0:
            raise RuntimeError(f"valgrind failed on {calls} Python calls:\n{proc.stderr[-2000:]}")
        whole = int(re.search(r"^summary:\s+(\d+)", out.read_text(), re.M).group(1))
        ann = subprocess.run(["callgrind_annotate", "--inclusive=yes", "--threshold=100",
                              str(out)], capture_output=True, text=True, check=True).stdout
    m = re.search(r"^\s*([\d,]+) .*" + re.escape(FIT) + r" \[", ann, re.M)
    if whole == 0 or m is None:
        raise RuntimeError("callgrind counted nothing in triaxcal._core.repeat_call: is the "
                           "installed triaxcal this checkout's?")
    return round(whole / calls), round(int(m.group(1).replace(",", "")) / calls)


def measure_guard() -> dict[str, int]:
    whole, fit = python_call()
    readers = reader_counts()
    return {
        "fit_10": sum(count("fit", 10, FIT)),
        "fit_1e5": sum(count("fit", 100_000, FIT)),
        "batch_1000": sum(count("batch", 1000, FIT)),
        "python_call_10_beyond_fit": whole - fit,
        "allan_1e5": sum(count("allan", 100_000, ALLAN)),
        "adev_1e5": sum(count("adev", 100_000, ALLAN)),
        "ulog_flight": readers["ulog"][0],
        "dataflash_flight": readers["dataflash"][0],
    }


def report() -> None:
    n = 1_000_000
    per_pass = {}
    for kind in ("pass", "polish", "last"):
        per_pass[kind] = sum(count(kind, n, PASS)) / n
    unit = per_pass["pass"]
    print(f"kernels: {kernels()}")
    print(f"one pass with J^T J:            {unit:6.1f} instructions per point")
    print(f"a polishing pass (J^T r only):  {per_pass['polish']:6.1f}")
    print(f"the last pass (+ noise sums):   {per_pass['last']:6.1f} (with coverage)")
    small = sum(count("fit", 10, FIT))
    print(f"fit_ellipsoid, N=10: {small:,} instructions (the fixed cost of a fit)")
    whole, fit = python_call()
    print(f"a Python fit_ellipsoid call of 10 points: {whole:,} instructions, of which the "
          f"compiled fit {fit:,}: the call adds {whole - fit:,}")
    for size in (1_000, 10_000, 100_000, 1_000_000):
        total = sum(count("fit", size, FIT))
        print(f"fit_ellipsoid, N={size:>9,}: {total / size:8.1f} instructions per point = "
              f"{total / size / unit:5.2f} passes with J^T J")
    sets = 1000
    one = sum(count("batch", sets, FIT)) / sets
    print(f"fit_batch, 200 points per set: {one:,.0f} instructions per set")
    split = count("batch", sets, FIT, threads=2)
    if len(split) >= 2:
        share = max(split) / sum(split)
        print(f"  with 2 threads: {sum(split) / sets:,.0f} per set, the busier thread does "
              f"{share:.1%} of the work: speed-up bound {1 / share:.2f}x")
    rows = 1_000_000
    ms = len([m for m in (1 << k for k in range(64)) if m <= (rows - 1) // 2])
    terms = sum(3 * (rows - 2 * (1 << k)) for k in range(ms))
    over = sum(count("allan", rows, ALLAN))
    print(f"Allan deviation, 1e6 rows x 3 axes, {ms} octave taus, overlapping: {over / 1e6:.1f} M "
          f"instructions, {over / terms:.2f} per term ({terms / 1e6:.1f} M terms)")
    non = sum(count("adev", rows, ALLAN))
    print(f"  non-overlapping: {non / 1e6:.1f} M instructions, {non / (3 * rows):.1f} per row "
          "and axis")
    for kind, (n, size) in reader_counts().items():
        print(f"{kind} reader, simulated flight ({size / 1e6:.2f} MB): {n / 1e6:.1f} M "
              f"instructions, {n / size:.1f} per byte")


def check(update: bool) -> int:
    kind = kernels()
    got = measure_guard()
    figures = json.loads(FIGURES.read_text()) if FIGURES.exists() else {}
    if update:
        figures[kind] = got
        FIGURES.write_text(json.dumps(figures, indent=2, sort_keys=True) + "\n")
        print(f"wrote {FIGURES.relative_to(ROOT)} [{kind}]: {got}")
        return 0
    want = figures.get(kind)
    if want is not None and not set(got) <= set(want):
        print(f"no committed figures for {sorted(set(got) - set(want))} [{kind}] in "
              f"{FIGURES.relative_to(ROOT)}: run `python benches/instructions.py --update`")
        return 1
    if want is None:
        print(f"no committed instruction figures for the {kind} kernels in "
              f"{FIGURES.relative_to(ROOT)}: run `python benches/instructions.py --update`")
        return 1
    bad = 0
    for key, value in got.items():
        ratio = value / want[key]
        status = "ok" if ratio <= 1 + TOLERANCE else "REGRESSION"
        bad += status != "ok"
        print(f"{key:<26} {value:>14,} instructions, committed {want[key]:>14,} "
              f"({ratio - 1:+.1%}, limit +{TOLERANCE:.0%}) {status}")
    return 1 if bad else 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--check", action="store_true", help="the regression guard of `make test`")
    ap.add_argument("--update", action="store_true", help="rewrite the committed figures")
    args = ap.parse_args()
    if shutil.which("valgrind") is None:
        print("valgrind not found: instruction counts skipped (make deps installs it)")
        return 0
    build()
    if args.check or args.update:
        return check(args.update)
    report()
    return 0


if __name__ == "__main__":
    sys.exit(main())
