"""``triaxcal export CAL.json --format {c,c-fixed,json,motioncal,ardupilot,px4,kalibr,adafruit}
[--prefix NAME] -o FILE``.

``c``: C99 header with float coefficients and ``<prefix>_<sensor>_apply``; ``c-fixed``: the
same with integers only (Q7.24 matrix, ``<prefix>_<sensor>_apply_q``); ``json``: the
calibration file, validated and rewritten; ``motioncal``: the 68-byte PJRC MotionCal packet.
``ardupilot``: a ``.parm`` file (``COMPASS_*``, ``INS_ACC*``, ``INS_GYR*``, ``INS_TCALn_*``);
``px4``: a QGroundControl ``.params`` file (``CAL_*``, ``TC_*``); ``kalibr``: ``imu.yaml``
(``--topic``, ``--rate``, ``--noise``); ``adafruit``: Adafruit_Sensor_Calibration's
``sensor_calib.json``. What a format cannot hold is refused with the reason.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from ..calibration.file import Calibration
from ..errors import CalibrationError
from ..export import DEVICE_COUNTS_PER_UNIT, EXPORT_FORMATS, export, motioncal_losses
from ..io.files import check_output, read_bounded


def _scale(text: str) -> tuple[str, tuple[float, str]]:
    try:
        sensor, rest = text.split("=", 1)
        value, _, unit = rest.partition(":")
        sensor = sensor.strip()
        if sensor not in DEVICE_COUNTS_PER_UNIT:
            raise ValueError
        return sensor, (float(value), unit.strip() or DEVICE_COUNTS_PER_UNIT[sensor][1])
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{text!r}: use SENSOR=COUNTS[:UNIT], e.g. accel=16384:g, gyro=131:deg/s, mag=10:uT"
        ) from None


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "export",
        help="write a calibration as a C header, JSON, MotionCal packet, or ArduPilot / PX4 / "
             "Kalibr / Adafruit parameters",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("calibration", metavar="CAL.json",
                   help="calibration file written by triaxcal fit (or Calibration.save)")
    p.add_argument("--format", required=True, choices=EXPORT_FORMATS, dest="fmt",
                   help="c: C99 header, float; c-fixed: C99 header, integers only (Q7.24); "
                        "json: the calibration file, validated and rewritten; motioncal: the "
                        "68-byte PJRC MotionCal packet")
    p.add_argument("--prefix", default="triaxcal",
                   help="C identifier prefix: imu gives IMU_ACCEL_OFFSET_X, imu_accel_apply")
    p.add_argument("--counts-per-unit", type=_scale, action="append", default=[],
                   metavar="SENSOR=COUNTS[:UNIT]",
                   help="motioncal and the parameter formats, for parts in raw counts: the "
                        "board driver's scale (default accel=16384:g, "
                        "gyro=131:deg/s, mag=10:uT)")
    g = p.add_argument_group("parameter formats (ardupilot, px4, kalibr, adafruit)")
    g.add_argument("--sensors", default=None, metavar="LIST",
                   help="parts to write, e.g. mag or accel,gyro (default: all present)")
    g.add_argument("--instance", type=int, default=None, metavar="N",
                   help="ardupilot: IMU and compass number 0..2 (INS_ACC2OFFS, COMPASS_OFS2 "
                        "for 1); px4: calibration slot CAL_ACCn (0..3)")
    g.add_argument("--device-id", action="append", default=[], metavar="SENSOR=ID",
                   help="px4: device id (the vehicle's CAL_ACC0_ID...), written as CAL_*_ID "
                        "and needed for TC_* thermal terms")
    g.add_argument("--compass-scale", default="auto", metavar="auto|off|S",
                   help="ardupilot: COMPASS_SCALE handling (default auto)")
    g.add_argument("--topic", default="/imu0", help="kalibr: rostopic (default /imu0)")
    g.add_argument("--rate", type=float, default=None, metavar="HZ",
                   help="kalibr: update_rate in Hz (required for kalibr)")
    g.add_argument("--noise", default=None, metavar="NOISE.json",
                   help="kalibr: JSON object with accelerometer_noise_density, "
                        "accelerometer_random_walk, gyroscope_noise_density, "
                        "gyroscope_random_walk")
    g.add_argument("--kalibr-model", default="scale-misalignment",
                   choices=("scale-misalignment", "calibrated"), help="kalibr: IMU model")
    p.add_argument("--offsets-only", action="store_true",
                   help="motioncal: accept that the packet carries the accelerometer's and "
                        "gyroscope's offsets but not their gains or any temperature terms "
                        "(without it such a calibration is refused, naming what would be lost)")
    p.add_argument("--no-alignment", action="store_true",
                   help="leave the magnetometer-to-accelerometer alignment out on purpose (for "
                        "a format that cannot hold it: motioncal, or a non-right-angle one)")
    p.add_argument("-o", "--output", required=True, metavar="FILE",
                   help="file to write (replaced whole; its folder must exist)")
    p.set_defaults(func=run)


def _param_options(args: argparse.Namespace) -> dict[str, Any]:
    """The options of the parameter formats, checked."""

    fmt = args.fmt
    opts: dict[str, Any] = {}
    sensors = [s.strip() for s in args.sensors.split(",") if s.strip()] if args.sensors else None
    if fmt in ("ardupilot", "px4", "adafruit") and sensors:
        opts["sensors"] = sensors
    if fmt == "ardupilot":
        if args.instance is not None:
            opts["imu"] = opts["compass"] = args.instance
        cs = args.compass_scale.strip().lower()
        if cs == "auto":
            opts["compass_scale"] = "auto"
        elif cs in ("off", "none", "0"):
            opts["compass_scale"] = None
        else:
            try:
                opts["compass_scale"] = float(cs)
            except ValueError:
                raise CalibrationError(f"--compass-scale {args.compass_scale!r}: use auto, off "
                                       "or a number") from None
    elif fmt == "px4":
        if args.instance is not None:
            opts["instance"] = args.instance
        ids: dict[str, int] = {}
        for item in args.device_id:
            sensor, _, value = item.partition("=")
            try:
                ids[sensor.strip()] = int(value, 0)
            except ValueError:
                raise CalibrationError(f"--device-id {item!r}: use SENSOR=ID, e.g. "
                                       "accel=2424842") from None
            if sensor.strip() not in ("accel", "gyro", "mag"):
                raise CalibrationError(f"--device-id {item!r}: sensor must be accel, gyro or "
                                       "mag")
        if ids:
            opts["device_ids"] = ids
    elif fmt == "kalibr":
        if args.rate is None:
            raise CalibrationError("kalibr needs the IMU rate: pass --rate HZ")
        opts.update(topic=args.topic, rate_hz=args.rate, model=args.kalibr_model)
        if args.noise:
            from ..calibration.schema import parse_json

            raw = read_bounded(args.noise, limit=1 << 20, what="noise file")
            try:
                opts["noise"] = parse_json(raw.decode("utf-8-sig"))
            except (UnicodeDecodeError, CalibrationError) as exc:
                raise CalibrationError(f"--noise {args.noise}: not a JSON file "
                                       f"({exc})") from None
    used = {"ardupilot": ("sensors", "instance", "compass_scale"),
            "px4": ("sensors", "instance", "device_id"),
            "kalibr": ("topic", "rate", "noise", "kalibr_model"),
            "adafruit": ("sensors",)}.get(fmt, ())
    defaults: dict[str, Any] = {
        "sensors": None, "instance": None, "device_id": [], "compass_scale": "auto",
        "topic": "/imu0", "rate": None, "noise": None, "kalibr_model": "scale-misalignment",
    }
    stray = [k for k, d in defaults.items() if k not in used and getattr(args, k) != d]
    if stray:
        raise CalibrationError(f"--{stray[0].replace('_', '-')} does not apply to --format "
                               f"{fmt}")
    return opts


def run(args: argparse.Namespace) -> int:
    out = check_output(args.output, "export")
    cal = Calibration.load(args.calibration)
    if getattr(args, "no_alignment", False):
        cal = cal.replace(**{s: cal.part(s).replace(alignment=None) for s in cal.sensors})
    if out.resolve() == Path(args.calibration).resolve():
        raise CalibrationError("-o must differ from the calibration file")
    if args.offsets_only and args.fmt != "motioncal":
        raise CalibrationError(f"--offsets-only applies to --format motioncal, not {args.fmt}")
    export(cal, args.fmt, out, prefix=args.prefix,
           counts_per_unit=dict(args.counts_per_unit) or None, offsets_only=args.offsets_only,
           **_param_options(args))
    if args.fmt == "motioncal":
        for lost in motioncal_losses(cal, counts_per_unit=dict(args.counts_per_unit) or None):
            print(f"  not in the packet: {lost}")
    size = out.stat().st_size if out.is_file() else None
    print(f"wrote {out} ({args.fmt}" + (f", {size} bytes" if size is not None else "")
          + f"; sensors: {', '.join(cal.sensors)})")
    return 0
