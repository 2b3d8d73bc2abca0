"""triaxcal tilt-rig FILE --angle 10: accelerometer offsets and gains from a rig tilted by a
known angle, nose down / nose up and left down / right down (the two-tilt method).

FILE holds the readings of the four tilts, in either layout:

* the original method's: a line FD (fore down), AD (aft down), LD (left down) or RD (right
  down) -- or fore_down, ... -- followed by that tilt's rows;
* a label in the first column of every row: FD,-0.1429,0.0127,1.0509.

Rows are numbers separated by commas, semicolons, tabs or spaces; --columns picks the
accelerometer's three (by zero-based index, or by name with a header row ax,ay,az).

With the original method's algebra corrected (gain = sin(angle) / |s - s'| * 2, not sin / (s + o)),
the offsets of x and y and the gains of all three axes follow; z's offset cannot be told
from its gain without an upside-down reading (--z-offset, default 0). The tilt the data
imply (equal gains assumed) is printed; when it differs from --angle by more than a degree
the command warns and shows the gains that angle gives.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

import numpy as np

from ..calibration.parts import part_from_tilt_rig
from ..io.sections import TILT_SECTIONS, read_tilts
from ..io.tables import pick_columns
from ..methods.static import tilt_rig
from ._calfile import add_output_options, save_part

HELP = "accelerometer offsets and gains from a rig tilted by a known angle (the two-tilt rig)"

#: Largest difference (degrees) between the stated tilt and the one the data imply before the
#: command warns.
ANGLE_WARN_DEG = 1.0


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "tilt-rig", help=HELP, description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("data", metavar="FILE", help="readings of the four tilts (see above)")
    p.add_argument("--angle", type=float, required=True, metavar="DEG",
                   help="the rig's tilt in degrees (the original method's: 10)")
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


def run(args: argparse.Namespace) -> int:
    tilts = read_tilts(args.data)
    cols = pick_columns(tilts.table(), args.columns, "accel")
    readings = {k: tilts.groups[k][:, cols] for k in TILT_SECTIONS}
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
                              source=str(args.data), input_sha256=tilts.sha256, force=args.force)
    everything = np.vstack(list(readings.values()))
    norms = np.linalg.norm(part.apply(everything), axis=1)
    print(f"  check: calibrated |a| of the {n} readings {norms.min():.5f} .. {norms.max():.5f} g",
          file=out)
    verb = save_part(args, "accel", part)
    print(f"{verb} {args.output}: accel ({u} -> g, tilt rig at {rig.angle_deg:g} deg)", file=out)
    return 0
