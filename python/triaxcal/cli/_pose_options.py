"""The pose-detection options shared by ``capture``, ``fit --poses``, ``report``, ``demo``,
``temperature``, ``sphere-center`` and ``batch``.

One argument group, one conversion to :class:`triaxcal.detect.session.PoseSettings` (whose
defaults the options take): the commands cannot drift apart, and the demo uses nothing a user
cannot pass.
"""

from __future__ import annotations

import argparse
import math
from typing import Any

from ..detect.session import HEAD_ROWS, PoseSettings
from ._help import renamed

#: The defaults every option takes from (one place: the settings object itself).
_D = PoseSettings()


def positive_float(text: str) -> float:
    """An argparse type: a finite number > 0."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"expected a number > 0, got {text!r}")
    return v


def nonnegative_float(text: str) -> float:
    """An argparse type: a finite number >= 0."""
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
    return positive_float(text)


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
    g.add_argument("--window", type=positive_int, default=_D.window, metavar="N",
                   help=f"samples per averaging window (default {_D.window}: "
                        f"{_D.window / 100:g} s at 100 Hz)")
    g.add_argument("--accel-threshold", type=positive_float, default=_D.accel_threshold_g,
                   metavar="G",
                   help="accelerometer: largest change of a window mean from the previous "
                        "window, in g (default %(default)s, the sphere-centre method's rule)")
    g.add_argument("--counts-per-g", dest="counts_per_g",
                   type=positive_float, default=None, metavar="C",
                   help="accelerometer units per g (16384 at +-2 g; 1 for a board that prints "
                        f"g). Default: the median length of the first {HEAD_ROWS} readings, "
                        "taken while the board lies still")
    renamed(g, "--units-per-g", "--counts-per-g")
    g.add_argument("--gyro-threshold", type=_threshold, default="auto", metavar="COUNTS",
                   help="gyroscope: largest rate away from its bias at rest, in the gyro's raw "
                        "units (counts; 131 counts = 1 deg/s at +-250 deg/s). 'auto' (default): "
                        "8 standard deviations of its noise, learnt at the start; 'off': the "
                        "gyro does not take part")
    g.add_argument("--mag-threshold", type=_threshold, default="auto", metavar="COUNTS",
                   help="magnetometer: largest change of a window mean from the previous "
                        "window, in its raw units (counts). 'auto' (default): learnt from its "
                        "noise; 'off': it does not take part")
    g.add_argument("--hold", type=_hold, default=_D.hold_windows, metavar="W",
                   help="register a pose once it has been still for W windows (the capture's "
                        "bell, the sphere-centre note's beep), then average it until the board "
                        "moves; 'off': "
                        "decide when the board moves (default %(default)s)")
    g.add_argument("--holdoff", type=nonnegative_float, default=_D.holdoff_s, metavar="S",
                   help="seconds ignored after each registered pose, to let go of the board "
                        "(the sphere-centre note waits 2 s after its beep: --holdoff 2). Default 0")
    g.add_argument("--rate-hz", type=positive_float, default=None, metavar="HZ",
                   help="samples per second, to turn --holdoff into samples (default: from the "
                        "arrival times, the session's t column)")


def settings_from_args(args: Any) -> PoseSettings:
    """The :class:`~triaxcal.detect.session.PoseSettings` that the options in ``args`` describe
    (validated by the settings object)."""

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
