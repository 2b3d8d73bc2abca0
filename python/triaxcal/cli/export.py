"""``triaxcal export CAL.json --format FORMAT -o FILE``: a calibration for firmware and autopilots.

``c``: C99 header with float coefficients and ``<prefix>_<sensor>_apply``; ``c-fixed``: the
same with integers only (Q7.24 matrix, ``<prefix>_<sensor>_apply_q``); ``json``: the
calibration file, validated and rewritten; ``motioncal``: the 68-byte PJRC MotionCal packet;
``js`` / ``js-espruino``: a JavaScript module (ES module / ECMAScript 5.1 for Espruino).
``ardupilot``: a ``.parm`` file (``COMPASS_*``, ``INS_ACC*``, ``INS_GYR*``, ``INS_TCALn_*``);
``px4``: a QGroundControl ``.params`` file (``CAL_*``, ``TC_*``); ``kalibr``: ``imu.yaml``
(``--ros-topic``, ``--rate-hz``, ``--noise``); ``adafruit``: Adafruit_Sensor_Calibration's
``sensor_calib.json``. What a format cannot hold is refused with the reason.

Nothing is written on trust: a part the validity gate refuses (marked ``"valid": false`` by
``fit --force``, or judged now) is not exported (exit 2) unless ``--force``, and then the file
says so. A part in raw counts exported to a format in physical units (motioncal, ardupilot,
px4, kalibr, adafruit) needs the driver's scale: ``--counts-per-unit SENSOR=COUNTS[:UNIT]`` or
``--sensor-model PART`` (its datasheet value); none is assumed. A part fitted on readings an
autopilot had already corrected is exported as the composed absolute calibration.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from ..calibration.file import Calibration
from ..errors import CalibrationError
from ..export import (
    EXPORT_FORMATS,
    adafruit_left_out,
    export,
    exported_sensors,
    motioncal_losses,
    parse_counts_per_unit,
    px4_omitted,
)
from ..io.files import check_output, read_bounded
from ._help import renamed

#: One line per format for ``--format``'s help (every one of EXPORT_FORMATS).
FORMAT_HELP = {
    "c": "C99 header, float",
    "c-fixed": "C99 header, integers only (Q7.24)",
    "json": "the calibration file, validated and rewritten",
    "motioncal": "the 68-byte PJRC MotionCal packet",
    "ardupilot": "ArduPilot .parm (COMPASS_*, INS_ACC*, INS_GYR*, INS_TCALn_*)",
    "px4": "PX4 / QGroundControl .params (CAL_*, TC_*)",
    "kalibr": "Kalibr imu.yaml",
    "adafruit": "Adafruit_Sensor_Calibration sensor_calib.json",
    "js": "JavaScript ES module",
    "js-espruino": "JavaScript (ECMAScript 5.1) for Espruino",
}


def _scale(text: str) -> dict[str, tuple[float, str]]:
    try:
        return parse_counts_per_unit(text)
    except CalibrationError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def add_scale_options(p: Any) -> None:
    """``--counts-per-unit`` and ``--sensor-model``, the same for export and send."""
    p.add_argument("--counts-per-unit", type=_scale, action="append", default=[],
                   metavar="SENSOR=COUNTS[:UNIT]",
                   help="the board driver's scale of a part in raw counts, e.g. accel=16384:g, "
                        "gyro=131:deg/s, mag=6.6667:uT (UNIT defaults to g, deg/s, uT; "
                        "several comma-separated or repeated); needed by the formats in "
                        "physical units, wins over --sensor-model. No scale is ever assumed")
    p.add_argument("--sensor-model", action="append", default=[], metavar="[SENSOR=]PART[:SET]",
                   help="take the driver's scale from the part's datasheet: ICM-20948, "
                        "MPU-6050:2g,250dps, mag=HMC5883L:1.3gauss, ... (SET names the "
                        "full-scale setting when the part has several)")


def scale_options(args: argparse.Namespace) -> dict[str, Any]:
    """``counts_per_unit`` and ``sensor_model`` for the library, from the parsed options."""
    cpu: dict[str, tuple[float, str]] = {}
    for d in args.counts_per_unit:
        cpu.update(d)
    out: dict[str, Any] = {}
    if cpu:
        out["counts_per_unit"] = cpu
    if args.sensor_model:
        out["sensor_model"] = list(args.sensor_model)
    return out


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "export",
        help="write a calibration as a C header, JSON, JavaScript, MotionCal packet, or "
             "ArduPilot / PX4 / Kalibr / Adafruit parameters",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("calibration", metavar="CAL.json",
                   help="calibration file written by triaxcal fit (or Calibration.save)")
    p.add_argument("--format", required=True, choices=EXPORT_FORMATS, dest="fmt",
                   metavar="FORMAT",
                   help="; ".join(f"{f}: {FORMAT_HELP.get(f, f)}" for f in EXPORT_FORMATS))
    p.add_argument("-o", "--output", required=True, metavar="FILE",
                   help="file to write (replaced whole; its folder must exist)")
    p.add_argument("--prefix", default="triaxcal",
                   help="C / JavaScript identifier prefix: imu gives IMU_ACCEL_OFFSET_X, "
                        "imu_accel_apply")
    p.add_argument("--force", action="store_true",
                   help="export parts the validity gate refuses (marked \"valid\": false, or "
                        "judged now); the file then says they are not a valid calibration, "
                        "and why")
    add_scale_options(p)
    g = p.add_argument_group("parameter formats (ardupilot, px4, kalibr, adafruit)")
    g.add_argument("--sensors", default=None, metavar="LIST",
                   help="parts to write, e.g. mag or accel,gyro (default: all present)")
    g.add_argument("--instance", type=int, default=None, metavar="N",
                   help="ardupilot: IMU and compass number 0..2 (INS_ACC2OFFS, COMPASS_OFS2 "
                        "for 1); px4: calibration slot CAL_ACCn (0..3)")
    g.add_argument("--device-id", action="append", default=[], metavar="SENSOR=ID",
                   help="px4: device id (the vehicle's CAL_ACC0_ID...), written as CAL_*_ID "
                        "and needed for TC_* thermal terms (default: the id the log recorded)")
    g.add_argument("--compass-scale", default="auto", metavar="auto|off|S",
                   help="ardupilot: COMPASS_SCALE handling (default auto)")
    g.add_argument("--ros-topic", default="/imu0", metavar="TOPIC",
                   help="kalibr: rostopic (default /imu0)")
    g.add_argument("--rate-hz", type=float, default=None, metavar="HZ",
                   help="kalibr: update_rate in Hz (required for kalibr)")
    g.add_argument("--noise", default=None, metavar="NOISE.json",
                   help="kalibr: JSON object with accelerometer_noise_density, "
                        "accelerometer_random_walk, gyroscope_noise_density, "
                        "gyroscope_random_walk")
    g.add_argument("--kalibr-model", default="scale-misalignment",
                   choices=("scale-misalignment", "calibrated"), help="kalibr: IMU model")
    g.add_argument("--mag-field", default=None, metavar="FIELD",
                   help="adafruit: mag_field, the local field (e.g. 48uT) when the "
                        "magnetometer part was not fitted to one (--radius)")
    renamed(g, "--topic", "--ros-topic")
    renamed(g, "--rate", "--rate-hz")
    p.add_argument("--offsets-only", action="store_true",
                   help="motioncal: accept that the packet carries the accelerometer's and "
                        "gyroscope's offsets but not their gains or any temperature terms "
                        "(without it such a calibration is refused, naming what would be lost)")
    p.add_argument("--no-alignment", action="store_true",
                   help="leave the magnetometer-to-accelerometer alignment out on purpose (for "
                        "a format that cannot hold it: motioncal, or a non-right-angle one)")
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
        if args.rate_hz is None:
            raise CalibrationError("kalibr needs the IMU rate: pass --rate-hz HZ")
        opts.update(topic=args.ros_topic, rate_hz=args.rate_hz, model=args.kalibr_model)
        if args.noise:
            from ..calibration.schema import parse_json

            raw = read_bounded(args.noise, limit=1 << 20, what="noise file")
            try:
                opts["noise"] = parse_json(raw.decode("utf-8-sig"))
            except (UnicodeDecodeError, CalibrationError) as exc:
                raise CalibrationError(f"--noise {args.noise}: not a JSON file "
                                       f"({exc})") from None
    elif fmt == "adafruit" and args.mag_field is not None:
        opts["mag_field"] = args.mag_field
    used = {"ardupilot": ("sensors", "instance", "compass_scale"),
            "px4": ("sensors", "instance", "device_id"),
            "kalibr": ("ros_topic", "rate_hz", "noise", "kalibr_model"),
            "adafruit": ("sensors", "mag_field")}.get(fmt, ())
    defaults: dict[str, Any] = {
        "sensors": None, "instance": None, "device_id": [], "compass_scale": "auto",
        "ros_topic": "/imu0", "rate_hz": None, "noise": None,
        "kalibr_model": "scale-misalignment", "mag_field": None,
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
    opts = _param_options(args)
    scale = scale_options(args)
    if scale and args.fmt not in ("motioncal", "ardupilot", "px4", "kalibr", "adafruit"):
        raise CalibrationError(f"--counts-per-unit / --sensor-model apply to the formats in "
                               f"physical units; --format {args.fmt} writes each part in its "
                               "own units")
    written = exported_sensors(cal, args.fmt, **opts)
    export(cal, args.fmt, out, prefix=args.prefix, offsets_only=args.offsets_only,
           force=args.force, **scale, **opts)
    if args.fmt == "motioncal":
        for lost in motioncal_losses(cal, **scale):
            print(f"  not in the packet: {lost}")
    size = out.stat().st_size if out.is_file() else None
    what = ", ".join(written) if written else "none (noise figures and topic only)"
    print(f"wrote {out} ({args.fmt}" + (f", {size} bytes" if size is not None else "")
          + f"; sensors: {what})")
    refused = [s for s in written if _reasons(cal.part(s), s)]  # written: so forced
    for sensor in refused:
        print(f"  NOT A VALID CALIBRATION (written with --force): the {sensor} part: "
              + "; ".join(_reasons(cal.part(sensor), sensor)))
    if args.fmt == "motioncal" and refused:
        print("  the MotionCal packet cannot carry a mark: keep this file away from boards "
              "that should not have it")
    if args.fmt == "adafruit":
        left = adafruit_left_out(written)
        if left:
            print(f"  not written: {', '.join(left)}; Adafruit_Sensor_Calibration reads a "
                  "missing key as 0 (the identity for mag_softiron) when it loads this file, "
                  "so the board's stored values for them are replaced")
    if args.fmt == "px4":
        for line in px4_omitted(cal, **{k: v for k, v in opts.items()}, **scale,
                                force=args.force):
            print(f"  {line}")
    for sensor in written:
        log = cal.part(sensor).stats.get("log")
        if isinstance(log, dict) and log.get("calibrated_by_autopilot") and \
                args.fmt not in ("json",):
            print(f"  {sensor}: fitted on readings the autopilot had already corrected: "
                  "written as the composed absolute calibration (stored, then the correction)")
    return 0


def _reasons(part: Any, sensor: str) -> tuple[str, ...]:
    from ..calibration.gate import require_valid

    return require_valid(part, sensor, force=True).reasons
