"""Instruction counts of the fits, with valgrind's callgrind: independent of the machine's load.

``make bench-instructions`` (``python benches/instructions.py``) prints:

- instructions per point of one accumulation pass with JᵀJ (the unit of work), of a polishing
  pass and of the last polishing pass, over 1,000,000 points;
- ``fit_ellipsoid`` of 1e3 .. 1e6 points: instructions per point, and in units of that pass
  (the target for 1e6 points: at most three);
- ``fit_batch`` of 200-point sets: instructions per set (target: at most 90,000), and how the
  work splits between two rayon threads (the bound on the speed-up of two threads).

``--check`` is the regression guard of ``make test``: it counts a fit of 10 points (the fixed
cost of a call), a fixed 1e5-point fit and a fixed batch of 1,000 sets and fails if any grew
by more than 10 % over the figures in ``benches/instructions.json`` (``--update`` rewrites
them). The workloads are the Rust example ``benches/instructions.rs`` (deterministic data, one
thread); the counts are those of the kernels this CPU runs (AVX2 + FMA, or the portable
build), each with its own figures. Without valgrind the check is skipped with a message;
everything else missing is an error.
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


def count(case: str, n: int, toggle: str, threads: int = 1) -> list[int]:
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


def measure_guard() -> dict[str, int]:
    return {
        "fit_10": sum(count("fit", 10, FIT)),
        "fit_1e5": sum(count("fit", 100_000, FIT)),
        "batch_1000": sum(count("batch", 1000, FIT)),
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
    if want is None:
        print(f"no committed instruction figures for the {kind} kernels in "
              f"{FIGURES.relative_to(ROOT)}: run `python benches/instructions.py --update`")
        return 1
    bad = 0
    for key, value in got.items():
        ratio = value / want[key]
        status = "ok" if ratio <= 1 + TOLERANCE else "REGRESSION"
        bad += status != "ok"
        print(f"{key:<12} {value:>14,} instructions, committed {want[key]:>14,} "
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
