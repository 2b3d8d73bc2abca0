"""How ``triaxcal report`` treats parts made by the seed-method commands.

A tilt-rig part is judged on its readings like a fitted part (their calibrated lengths should
be 1 g); its file is a tilt-rig file, read here. Gyro gains, temperature terms and a bias are
not spheres: their report is the numbers the command stored.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from ..calibration.part import SensorCalibration

#: Parts whose readings do not lie on a sphere: reported by their stored numbers.
SUMMARY_METHODS = ("gyro-gains", "temperature")
SUMMARY_MODELS = ("bias",)


def summary_only(part: SensorCalibration) -> bool:
    """Whether ``part`` is reported by its stored numbers rather than on its readings."""
    return part.stats.get("method") in SUMMARY_METHODS or part.model in SUMMARY_MODELS


def _num(v: Any, fmt: str = ".4g") -> str:
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else format(v, fmt)


def summary_text(sensor: str, part: SensorCalibration) -> str:
    """The report of a gyro-gains, temperature or bias part."""
    s = part.stats
    method = s.get("method") or part.model
    lines = [f"{sensor} calibration ({part.raw_unit} -> {part.unit}, {method}): the numbers "
             "stored when it was made"]
    lines.append("  offset          " + "  ".join(f"{a} {v:.6g}" for a, v in
                                               zip("xyz", part.offset)) + f" {part.raw_unit}")
    d = np.diag(part.matrix)
    lines.append("  scale           " + "  ".join(f"{a} {v:.6g}" for a, v in zip("xyz", d))
                 + f" {part.unit} per {part.raw_unit} (multiplies)")
    if "gain_counts_per_dps" in s:
        cw, ccw = s.get("gain_cw_counts_per_dps", [None] * 3), s.get("gain_ccw_counts_per_dps",
                                                                     [None] * 3)
        for i, a in enumerate("xyz"):
            lines.append(f"  gain {a}          {_num(s['gain_counts_per_dps'][i])} counts per "
                         f"deg/s (clockwise {_num(cw[i])}, counter-clockwise {_num(ccw[i])})")
    if part.temperature is not None:
        t = part.temperature
        lines.append(f"  temperature     degree {len(t.offset_poly) - 1} about {t.temp_ref_c:.2f} "
                     f"deg C, fitted over {t.temp_range_c[0]:.2f} .. {t.temp_range_c[1]:.2f}")
        lines.append("  drift           " + "  ".join(
            f"{a} {v:.4g}" for a, v in zip("xyz", t.offset_poly[1])) + f" {part.raw_unit} per "
            "deg C")
    if "n_samples" in s:
        lines.append(f"  samples         {s['n_samples']}")
    if s.get("warnings"):
        lines.append("  warnings")
        lines += [f"    - {w}" for w in s["warnings"]]
    return "\n".join(lines)


def tilt_points(src: Path, part: SensorCalibration) -> np.ndarray:
    """The readings of a tilt-rig part's file (all four tilts, its columns)."""
    from ..methods.static import TILT_KEYS
    from .tilt_rig import read_tilts

    _, groups = read_tilts(src)
    cols = [int(c) for c in part.stats.get("columns", [0, 1, 2])]
    return np.vstack([groups[k][:, cols] for k in TILT_KEYS])
