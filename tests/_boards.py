"""Simulated production runs: session CSVs of good boards and of boards with known faults,
made offline with SimIMU (no pseudo-terminals), fast enough for a thousand boards."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from triaxcal import sim

#: The faults a bad board can have, with the fail reason the batch must give.
FAULTS = {
    "dead_axis": "dead_axis",
    "saturation": "saturation",
    "coverage": "coverage",
    "cross_axis": "cross_axis",
    "stuck": "stuck",
    "noise": "noise",
    "offset": "offset",
}
RATE_HZ = 50.0
WINDOW = 10  # pose detection window (samples): 0.2 s at 50 Hz


_SCRIPTS: dict[tuple[int, bool], sim.Script] = {}


def _script(seed: int, fault: str | None) -> sim.Script:
    key = (seed % 8, fault == "coverage")  # eight hand-placement variants of each
    if key not in _SCRIPTS:
        rng = np.random.default_rng(key[0])
        if key[1]:
            # only a cap around +Z up: tilted poses of the same face
            poses = [sim.rotvec_to_matrix(np.r_[rng.normal(0, 0.3, 2), rng.uniform(0, 6.28)])
                     for _ in range(16)]
            _SCRIPTS[key] = sim.Script.from_poses(np.array(poses), hold_s=0.7, settle_s=0.5)
        else:
            _SCRIPTS[key] = sim.globe_script(latitudes=5, turns=5, hold_s=0.7, settle_s=0.5,
                                             seed=key[0])
    return _SCRIPTS[key]


def make_board(seed: int, fault: str | None = None) -> tuple[np.ndarray, sim.SimIMU]:
    """Accelerometer counts (N, 3) of one board's session, with ``fault`` injected."""
    accel: dict = {}
    if fault == "saturation":
        accel["scale"] = [0.48, 1.0, 1.0]  # x reads 2.1x too much: 1 g clips at int16
    elif fault == "cross_axis":
        accel["scale"] = [[1.0, 0.08, 0.0], [0.08, 1.0, 0.0], [0.0, 0.0, 1.0]]
    elif fault == "noise":
        accel["noise"] = 600.0  # 37 mg rms
    elif fault == "offset":
        accel["offset"] = [3500.0, -200.0, 300.0]  # 0.21 g on x
    imu = sim.SimIMU(seed, accel=accel)
    rec = imu.record(_script(seed, fault), RATE_HZ)
    a = rec.accel.copy()
    rng = np.random.default_rng(seed + 1)
    if fault == "dead_axis":
        ax = int(rng.integers(3))
        a[:, ax] = np.rint(rng.normal(imu.truth.accel.offset[ax], 30.0, len(a))).astype(a.dtype)
    elif fault == "stuck":
        k = len(a) // 3
        a[k:] = a[k]  # the sensor froze a third of the way in
    return a, imu


def write_session(path: Path, t0: float, counts: np.ndarray) -> None:
    t = t0 + np.arange(len(counts)) / RATE_HZ
    lines = ["t,ax,ay,az"]
    lines += [f"{ti:.6f},{x},{y},{z}" for ti, (x, y, z) in zip(t, counts.tolist())]
    path.write_text("\n".join(lines) + "\n")


def _write_one(job: tuple[Path, str, int, float, str | None]) -> None:
    path, _, seed, t0, fault = job
    counts, _ = make_board(seed, fault)
    write_session(path, t0, counts)


def production_run(folder: Path, n: int = 1000, n_bad: int = 50, seed: int = 0,
                   jobs: int = 2) -> dict[str, str | None]:
    """Write ``n`` session files into ``folder`` (``n_bad`` of them with a fault, the kinds
    taking turns); returns board id -> injected fault (``None`` for a good board)."""
    from concurrent.futures import ProcessPoolExecutor

    rng = np.random.default_rng(seed)
    kinds = list(FAULTS)
    bad = sorted(rng.choice(n, n_bad, replace=False).tolist())
    folder.mkdir(parents=True, exist_ok=True)
    work = []
    for i in range(n):
        fault = kinds[bad.index(i) % len(kinds)] if i in bad else None
        work.append((folder / f"SN{100000 + i}.csv", f"SN{100000 + i}", seed * 100000 + i,
                     1.7e9 + i * 60.0, fault))
    with ProcessPoolExecutor(max_workers=jobs) as pool:
        list(pool.map(_write_one, work, chunksize=25))
    return {w[1]: w[4] for w in work}
