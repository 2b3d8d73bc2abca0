"""triaxcal tilt-rig FILE --angle 10: accelerometer offsets and gains from a rig tilted by a
known angle, nose down / nose up and left down / right down (tilt-rig-gravity-calibration.txt).

FILE holds the readings of the four tilts, in either layout:

* the seed's: a line FD (fore down), AD (aft down), LD (left down) or RD (right
  down) -- or fore_down, ... -- followed by that tilt's rows;
* a label in the first column of every row: FD,-0.1429,0.0127,1.0509.

Rows are numbers separated by commas, semicolons, tabs or spaces; --columns picks the
accelerometer's three (by zero-based index, or by name with a header row ax,ay,az).

With the seed's algebra corrected (gain = sin(angle) / |s - s'| * 2, not sin / (s + o)),
the offsets of x and y and the gains of all three axes follow; z's offset cannot be told
from its gain without an upside-down reading (--z-offset, default 0). The tilt the data
imply (equal gains assumed) is printed; when it differs from --angle by more than a degree
the command warns and shows the gains that angle gives.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path
from typing import Any

import numpy as np

from ..calibration.parts import part_from_tilt_rig
from ..errors import CalibrationError
from ..methods.static import TILT_KEYS, tilt_rig
from ._calfile import add_output_options, file_sha256, save_part

HELP = "accelerometer offsets and gains from a rig tilted by a known angle (the seed's rig)"

#: Largest difference (degrees) between the stated tilt and the one the data imply before the
#: command warns.
ANGLE_WARN_DEG = 1.0

LABELS = {"fd": "fore_down", "ad": "aft_down", "ld": "left_down", "rd": "right_down",
          **{k: k for k in TILT_KEYS}, "fore-down": "fore_down", "aft-down": "aft_down",
          "left-down": "left_down", "right-down": "right_down"}

MAX_ROWS = 1_000_000


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "tilt-rig", help=HELP, description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("data", metavar="FILE", help="readings of the four tilts (see above)")
    p.add_argument("--angle", type=float, required=True, metavar="DEG",
                   help="the rig's tilt in degrees (the seed's: 10)")
    p.add_argument("--columns", default=None,
                   help="the accelerometer's three columns, by zero-based index or header "
                        "name (default: ax,ay,az by name, or the only three)")
    p.add_argument("--z-offset", type=float, default=0.0, metavar="Z",
                   help="the vertical axis's offset, raw units (tilts cannot measure it; "
                        "default 0)")
    p.add_argument("--raw-unit", default="counts",
                   help="unit of the readings: counts (default), or g if the board prints g")
    add_output_options(p)
    p.set_defaults(func=run)


def _split(line: str) -> list[str]:
    return [t for t in re.split(r"[,;\t ]+", line.strip()) if t]


def _number(tok: str) -> float | None:
    try:
        return float(tok)
    except ValueError:
        return None


def read_tilts(path: str | Path) -> tuple[tuple[str, ...] | None, dict[str, np.ndarray]]:
    """The header (or None) and the rows of each tilt of a tilt-rig file."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8", errors="replace")
    except FileNotFoundError:
        raise CalibrationError(f"data file {p} not found") from None
    except IsADirectoryError:
        raise CalibrationError(f"{p} is a folder: give the tilt-rig file") from None
    names: tuple[str, ...] | None = None
    groups: dict[str, list[list[float]]] = {}
    current: str | None = None
    width: int | None = None
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        toks = _split(line)
        key = LABELS.get(toks[0].rstrip(":").lower())
        if key is not None and len(toks) == 1:  # a label line: the seed's layout
            current = key
            groups.setdefault(key, [])
            continue
        values = toks[1:] if key is not None else toks
        nums = [_number(t) for t in values]
        if any(v is None for v in nums):
            if names is None and not groups and key is None:
                names = tuple(values)
                continue
            raise CalibrationError(f"{p}, line {lineno}: not all numbers ({line[:60]!r})")
        row_key = key if key is not None else current
        if row_key is None:
            raise CalibrationError(
                f"{p}, line {lineno}: a reading before any tilt label; start each tilt with a "
                "line FD, AD, LD or RD (or put the label first on every row)"
            )
        if width is None:
            width = len(nums)
        if len(nums) != width:
            raise CalibrationError(f"{p}, line {lineno}: {len(nums)} values, expected {width}")
        groups.setdefault(row_key, []).append([float(v) for v in nums])  # type: ignore[arg-type]
        if sum(len(v) for v in groups.values()) > MAX_ROWS:
            raise CalibrationError(f"{p} has more than {MAX_ROWS} readings: is it a tilt-rig file?")
    missing = [k for k in TILT_KEYS if not groups.get(k)]
    if missing:
        raise CalibrationError(
            f"{p}: no readings for {', '.join(missing)} (label them FD, AD, LD, RD: fore down, "
            "aft down, left down, right down)"
        )
    if names is not None and width is not None and len(names) == width + 1:
        names = names[1:]  # the header names the label column too
    if names is not None and width is not None and len(names) != width:
        raise CalibrationError(f"{p}: the header names {len(names)} columns, the rows have {width}")
    return names, {k: np.array(v) for k, v in groups.items()}


def _pick(names: tuple[str, ...] | None, width: int, spec: str | None) -> list[int]:
    if spec is None:
        if names is not None and all(c in names for c in ("ax", "ay", "az")):
            return [names.index(c) for c in ("ax", "ay", "az")]
        if width == 3:
            return [0, 1, 2]
        raise CalibrationError(
            f"the rows have {width} values: say which three are the accelerometer with "
            "--columns (zero-based, e.g. --columns 2,3,4 for the seed's rows)"
        )
    parts = [s.strip() for s in spec.split(",") if s.strip()]
    if len(parts) != 3:
        raise CalibrationError(f"--columns needs three columns (x,y,z), got {spec!r}")
    out = []
    for s in parts:
        if s.lstrip("-").isdigit():
            i = int(s)
            if not 0 <= i < width:
                raise CalibrationError(f"--columns: index {i} is out of range (0..{width - 1})")
            out.append(i)
        elif names is not None and s in names:
            out.append(names.index(s))
        else:
            raise CalibrationError(f"--columns: no column {s!r}")
    return out


def run(args: argparse.Namespace) -> int:
    names, groups = read_tilts(args.data)
    width = next(iter(groups.values())).shape[1]
    cols = _pick(names, width, args.columns)
    readings = {k: groups[k][:, cols] for k in TILT_KEYS}
    rig = tilt_rig(readings, angle_deg=args.angle, z_offset=args.z_offset)
    u = args.raw_unit
    out = sys.stdout
    n = sum(len(v) for v in readings.values())
    print(f"tilt rig at {rig.angle_deg:g} deg, {n} readings ({u}); calibrated = (raw - offset) "
          "* gain, in g", file=out)
    print(f"  offset  x {rig.offset[0]:.6g}  y {rig.offset[1]:.6g}  z {rig.offset[2]:.6g} "
          f"(z given, not measured) {u}", file=out)
    print(f"  gain    x {rig.gain[0]:.6g}  y {rig.gain[1]:.6g}  z {rig.gain[2]:.6g} g per {u} "
          "(multiplies)", file=out)
    print(f"  z gain from fore/aft {rig.gain_z_pairs[0]:.6g}, from left/right "
          f"{rig.gain_z_pairs[1]:.6g}", file=out)
    imp = rig.implied_angle_deg
    print(f"  the data imply a tilt of {imp[0]:.2f} deg (fore/aft) and {imp[1]:.2f} deg "
          "(left/right), with equal gains on every axis", file=out)
    off = float(np.max(np.abs(rig.angle_error_deg)))
    extra: dict[str, Any] = {}
    if off > ANGLE_WARN_DEG:
        mean_imp = float(np.mean(imp))
        alt = tilt_rig(readings, angle_deg=mean_imp, z_offset=args.z_offset)
        extra["gain_at_implied_angle"] = [float(v) for v in alt.gain]
        print(f"warning: the data imply a tilt of {mean_imp:.2f} deg, not {rig.angle_deg:g} "
              f"(off by {off:.2f} deg): with {mean_imp:.2f} deg the gains would be x "
              f"{alt.gain[0]:.6g}  y {alt.gain[1]:.6g}  z {alt.gain[2]:.6g} g per {u}. Measure "
              f"the rig's angle (or pass --angle {mean_imp:.2f} if the gains are known to be "
              "equal)", file=out)
    part = part_from_tilt_rig(rig, raw_unit=u, stats={"n": n, "columns": cols, **extra},
                              source=str(args.data), input_sha256=file_sha256(args.data),
                                force=args.force)
    everything = np.vstack(list(readings.values()))
    norms = np.linalg.norm(part.apply(everything), axis=1)
    print(f"  check: calibrated |a| of the {n} readings {norms.min():.5f} .. {norms.max():.5f} g",
          file=out)
    verb = save_part(args, "accel", part)
    print(f"{verb} {args.output}: accel ({u} -> g, tilt rig at {rig.angle_deg:g} deg)", file=out)
    return 0
