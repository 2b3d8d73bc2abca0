"""The pose-detection options shared by ``capture``, ``fit --poses``, ``report`` and ``demo``.

One argument group, one conversion to :class:`triaxcal.detect.session.PoseSettings`: the commands
cannot drift apart, and the demo uses nothing a user cannot pass.
"""

from __future__ import annotations

import argparse
import math
from typing import Any

from .session import HEAD_ROWS, PoseSettings


def _positive_float(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"expected a number > 0, got {text!r}")
    return v


def _nonnegative_float(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (math.isfinite(v) and v >= 0):
        raise argparse.ArgumentTypeError(f"expected a number >= 0, got {text!r}")
    return v


def positive_int(text: str) -> int:
    """An argparse type: a whole number >= 1."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected a number >= 1, got {v}")
    return v


def _threshold(text: str) -> float | str:
    t = text.strip().lower()
    if t in ("auto", "off"):
        return t
    return _positive_float(text)


def _hold(text: str) -> int | None:
    if text.strip().lower() == "off":
        return None
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected a whole number or 'off', got {text!r}") from None
    if v < 2:
        raise argparse.ArgumentTypeError(
            f"expected a number >= 2 (two windows to compare), got {v}")
    return v


def add_pose_options(p: argparse.ArgumentParser) -> None:
    """Add the pose-detection group to a command's parser."""
    g = p.add_argument_group(
        "pose detection",
        "A pose ends when any sensor says the board moved. The same options give the same poses "
        "in capture, fit --poses, report and demo.",
    )
    g.add_argument("--window", type=positive_int, default=25, metavar="N",
                   help="samples per averaging window (default 25: 0.25 s at 100 Hz)")
    g.add_argument("--accel-threshold", type=_positive_float, default=0.07, metavar="G",
                   help="accelerometer: largest change of a window mean from the previous "
                        "window, in g (default 0.07, the seed's rule)")
    g.add_argument("--counts-per-g", "--units-per-g", dest="counts_per_g",
                   type=_positive_float, default=None, metavar="C",
                   help="accelerometer units per g (16384 at +-2 g; 1 for a board that prints "
                        f"g). Default: the median length of the first {HEAD_ROWS} readings, "
                        "taken while the board lies still")
    g.add_argument("--gyro-threshold", type=_threshold, default="auto", metavar="COUNTS",
                   help="gyroscope: largest rate away from its bias at rest, in the gyro's raw "
                        "units (counts; 131 counts = 1 deg/s at +-250 deg/s). 'auto' (default): "
                        "8 standard deviations of its noise, learnt at the start; 'off': the "
                        "gyro does not take part")
    g.add_argument("--mag-threshold", type=_threshold, default="auto", metavar="COUNTS",
                   help="magnetometer: largest change of a window mean from the previous "
                        "window, in its raw units (counts). 'auto' (default): learnt from its "
                        "noise; 'off': it does not take part")
    g.add_argument("--hold", type=_hold, default=4, metavar="W",
                   help="register a pose once it has been still for W windows (the capture's "
                        "bell, the seed's beep), then average it until the board moves; 'off': "
                        "decide when the board moves (default 4)")
    g.add_argument("--holdoff", type=_nonnegative_float, default=0.0, metavar="S",
                   help="seconds ignored after each registered pose, to let go of the board "
                        "(the seed waits 2 s after its beep: --holdoff 2). Default 0")
    g.add_argument("--rate-hz", type=_positive_float, default=None, metavar="HZ",
                   help="samples per second, to turn --holdoff into samples (default: from the "
                        "arrival times, the session's t column)")


def settings_from_args(args: Any) -> PoseSettings:
    """The :class:`PoseSettings` that the options in ``args`` describe."""

    def thr(v: Any) -> float | None:
        return None if v in ("auto", "off", None) else float(v)

    return PoseSettings(
        window=int(args.window),
        accel_threshold_g=float(args.accel_threshold),
        counts_per_g=args.counts_per_g,
        use_gyro=args.gyro_threshold != "off",
        use_mag=args.mag_threshold != "off",
        gyro_threshold=thr(args.gyro_threshold),
        mag_threshold=thr(args.mag_threshold),
        hold_windows=args.hold,
        holdoff_s=float(args.holdoff),
        rate_hz=args.rate_hz,
    )


def default_settings() -> PoseSettings:
    """The settings a user gets by passing none of the options."""
    p = argparse.ArgumentParser(add_help=False)
    add_pose_options(p)
    return settings_from_args(p.parse_args([]))


def stored_settings(stats: Any) -> PoseSettings:
    """The pose settings a calibration part was fitted with (``stats["pose_detection"]``).

    Parts written before the detector used every sensor stored only ``pose_window`` and
    ``units_per_g``: they replay with the accelerometer alone, as they were made.
    """
    d = stats.get("pose_detection") if hasattr(stats, "get") else None
    if d is not None:
        return PoseSettings.from_dict(d)
    return PoseSettings(window=int(stats.get("pose_window", 25)),
                        counts_per_g=float(stats.get("units_per_g", 16384.0)),
                        use_gyro=False, use_mag=False, hold_windows=None)


def apply_settings(args: Any, settings: PoseSettings) -> None:
    """Set the pose options of ``args`` (an argparse namespace) to ``settings``: the inverse of
    :func:`settings_from_args`."""
    args.window = settings.window
    args.accel_threshold = settings.accel_threshold_g
    args.counts_per_g = settings.counts_per_g
    args.gyro_threshold = ("off" if not settings.use_gyro else
                           "auto" if settings.gyro_threshold is None else settings.gyro_threshold)
    args.mag_threshold = ("off" if not settings.use_mag else
                          "auto" if settings.mag_threshold is None else settings.mag_threshold)
    args.hold = settings.hold_windows
    args.holdoff = settings.holdoff_s
    args.rate_hz = settings.rate_hz
