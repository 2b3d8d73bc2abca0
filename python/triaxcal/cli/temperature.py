"""triaxcal temperature SESSION --sensor gyro --degree 1: the gyroscope's bias as a
polynomial in the temperature change (the turn-integration method).

Cool the board down, then record it lying still while it comes back to room temperature (or
warm it up). The bias of every axis is fitted by least squares as
offset(T) = offset + sum_k c_k (T - T_ref)^k, degree 1 being the turn-integration method's linear
tempcomp: calibrated = (raw - (tempcomp * dT + offset)) / gain. Only the samples of still
poses are used (the pose detection of triaxcal fit --poses), so a bump does not spoil it.

If CAL.json has a gyro part already (from triaxcal gyro-gains), its gains are kept and the
temperature terms are added to it; otherwise the part is counts in, counts out.

The temperature column: temp is read as the MPU-6050's raw counts (T = raw / 340 +
36.53, as triaxcal capture records it); temp_c / temperature as deg C; or give
--temp-column with --temp-scale and --temp-offset (deg C = raw * scale + offset).
"""

from __future__ import annotations

import argparse
import math
import sys
from typing import Any

import numpy as np

from ..calibration.parts import part_from_temperature
from ..detect.session import session_poses
from ..errors import CalibrationError
from ..io.tables import pick_columns, read_table
from ..methods.temperature import fit_temperature
from ._calfile import add_output_options, existing_part, file_sha256, save_part
from ._pose_options import add_pose_options, settings_from_args

HELP = ("gyro bias against temperature (the turn-integration method's linear trend; degree "
        "1 to 3)")

#: The MPU-6050's temperature sensor: deg C = raw / 340 + 36.53 (register map, TEMP_OUT).
MPU6050_TEMP = (1.0 / 340.0, 36.53)


def _fraction(text: str) -> float:
    try:
        if "/" in text:
            a, b = text.split("/", 1)
            v = float(a) / float(b)
        else:
            v = float(text)
    except (ValueError, ZeroDivisionError):
        raise argparse.ArgumentTypeError(f"expected a number such as 0.00294 or 1/340, got "
                                         f"{text!r}") from None
    if not math.isfinite(v) or v == 0:
        raise argparse.ArgumentTypeError(f"expected a finite non-zero number, got {text!r}")
    return v


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "temperature", help=HELP, description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("data", metavar="SESSION.csv", help="a session of the board lying still while "
                   "its temperature changes")
    p.add_argument("--sensor", choices=("gyro",), default="gyro",
                   help="the sensor whose bias drifts (gyro: its true reading at rest is zero)")
    p.add_argument("--degree", type=int, choices=(1, 2, 3), default=1,
                   help="polynomial degree (1: the linear trend of the turn-integration method, "
                        "default)")
    p.add_argument("--reference", type=float, default=None, metavar="DEGC",
                   help="reference temperature T_ref, deg C (default: the first reading's, the "
                        "original method's 'since start')")
    p.add_argument("--columns", default=None,
                   help="the sensor's three columns (default gx,gy,gz by name)")
    p.add_argument("--temp-column", default=None, metavar="NAME",
                   help="the temperature column (default: temp, temp_c or temperature)")
    p.add_argument("--temp-scale", type=_fraction, default=None, metavar="K",
                   help="deg C per raw unit of the temperature column (default 1/340 for temp, "
                        "the MPU-6050's; 1 for temp_c)")
    p.add_argument("--temp-offset", type=float, default=None, metavar="DEGC",
                   help="deg C at a raw reading of 0 (default 36.53 for temp; 0 for temp_c)")
    p.add_argument("--all-rows", action="store_true",
                   help="use every row, not only the still poses")
    p.add_argument("--raw-unit", default="counts", help="unit of the readings (counts)")
    add_pose_options(p)
    add_output_options(p)
    p.set_defaults(func=run)


def _temperature(table: Any, args: argparse.Namespace) -> tuple[np.ndarray, str]:
    names = table.names or ()
    col = args.temp_column
    if col is None:
        col = next((c for c in ("temp", "temp_c", "temperature") if c in names), None)
        if col is None:
            raise CalibrationError(
                f"{table.path} has no temperature column (temp, temp_c or temperature): name "
                "it with --temp-column"
            )
    elif col not in names:
        raise CalibrationError(f"--temp-column {col!r}: no such column in {table.path}")
    scale, offset = (MPU6050_TEMP if col == "temp" else (1.0, 0.0))
    if args.temp_scale is not None:
        scale = args.temp_scale
    if args.temp_offset is not None:
        offset = args.temp_offset
    if not math.isfinite(offset):
        raise CalibrationError(f"--temp-offset must be finite, got {offset}")
    with np.errstate(over="ignore", invalid="ignore"):
        t = table.data[:, names.index(col)] * scale + offset
    if not np.isfinite(t[np.isfinite(table.data[:, names.index(col)])]).all():
        raise CalibrationError(
            f"--temp-scale {scale:g} and --temp-offset {offset:g} turn {col} into temperatures "
            "beyond any number: give the column's scale in deg C per raw unit (1/340 for an "
            "MPU-6050)")
    how = (f"{col} (deg C = raw / {1 / scale:.6g} + {offset:g})" if scale != 1.0 or offset
           else f"{col} (deg C)")
    return t, how


def run(args: argparse.Namespace) -> int:
    table = read_table(args.data)
    cols = pick_columns(table, args.columns, args.sensor)
    temp, how = _temperature(table, args)
    rows = np.arange(len(table.data))
    used = "every row"
    if not args.all_rows:
        det, _ = session_poses(table.names, table.data, settings_from_args(args))
        if det.poses:
            rows = np.concatenate([np.arange(p.start, p.end) for p in det.poses])
            used = f"the {len(rows)} rows of {len(det.poses)} still pose(s)"
        else:
            raise CalibrationError(
                f"no still pose found in {table.path}: the board must lie still while the "
                "temperature changes (or pass --all-rows)"
            )
    raw = table.data[rows][:, cols]
    model = fit_temperature(raw, temp[rows], degree=args.degree, reference_degC=args.reference)
    base = existing_part(args.output, args.sensor, args.new)
    part = part_from_temperature(model, base, raw_unit=args.raw_unit,
                                 stats={"temperature_column": how, "rows_used": len(rows)},
                                 source=str(table.path), input_sha256=file_sha256(table.path),
                                force=args.force)
    u = args.raw_unit
    out = sys.stdout
    print(f"{args.sensor} bias against temperature, degree {model.degree}, from {used}; "
          f"temperature from {how}, {model.t_min_degC:.2f} .. {model.t_max_degC:.2f} deg C",
          file=out)
    print(f"  T_ref {model.reference_degC:.2f} deg C; offset(T) = offset + sum_k c_k dT^k",
          file=out)
    names = ["offset"] + [f"c{k} per degC^{k}" if k > 1 else "c1 per degC"
                          for k in range(1, model.degree + 1)]
    for k, name in enumerate(names):
        row = model.offset_coef[k]
        print(f"  {name:<16} x {row[0]:10.4f}  y {row[1]:10.4f}  z {row[2]:10.4f} {u}", file=out)
    print(f"  residual RMS     x {model.rms[0]:10.4f}  y {model.rms[1]:10.4f}  z "
          f"{model.rms[2]:10.4f} {u}", file=out)
    if base is not None and part.unit != u:
        slope = model.offset_coef[1] * np.diag(part.matrix)
        print(f"  drift            x {slope[0]:10.5f}  y {slope[1]:10.5f}  z "
              f"{slope[2]:10.5f} {part.unit} per degC (with the part's gains)", file=out)
    verb = save_part(args, args.sensor, part)
    kept = " (gains of the existing part kept)" if base is not None else ""
    print(f"{verb} {args.output}: {args.sensor} temperature terms, degree {model.degree}{kept}",
          file=out)
    return 0
