"""``triaxcal send CAL.json --port PORT``: write the MotionCal calibration packet to a board.

The board (Adafruit_Sensor_Calibration sketches, the project firmware, ``triaxcal.sim``)
answers a packet with a valid CRC with ``Cal1:`` and ``Cal2:`` lines; ``send`` reads them back
and checks every value against what it sent (4 decimals). Without an answer within
``--timeout`` seconds, or with different values, it fails with a message saying what to check.

A calibration the validity gate refuses is not sent (exit 2) unless ``--force``. The packet is
in the driver's units (m/s^2, rad/s, uT): a part in raw counts needs the board driver's scale,
``--counts-per-unit SENSOR=COUNTS[:UNIT]`` or ``--sensor-model PART``; none is assumed.
"""

from __future__ import annotations

import argparse
import time
from typing import Any

from ..calibration.file import Calibration
from ..errors import CalibrationError
from ..export import echo_matches, motioncal_losses, motioncal_packet, parse_motioncal_echo
from .export import add_scale_options, scale_options


def send_packet(port: str, packet: bytes, *, baud: int = 115200,
                timeout: float = 3.0) -> tuple[list[float], list[float]]:
    """Write ``packet`` to the serial ``port`` and return the board's ``(Cal1, Cal2)`` echo.

    Raises :class:`CalibrationError` when the port cannot be opened, no echo arrives within
    ``timeout`` seconds, or the echoed values differ from the packet's.
    """
    import serial

    try:
        ser = serial.serial_for_url(port, baudrate=baud, timeout=0.05, write_timeout=timeout)
    except (serial.SerialException, OSError, ValueError) as exc:
        raise CalibrationError(
            f"cannot open {port}: {exc}; check the port name (ls /dev/tty*) and that no other "
            "program (serial monitor, MotionCal) holds it"
        ) from None
    with ser:
        ser.reset_input_buffer()
        ser.write(packet)
        ser.flush()
        buf = bytearray()
        deadline = time.monotonic() + timeout
        echo = None
        while time.monotonic() < deadline:
            chunk = ser.read(4096)
            if chunk:
                buf += chunk
                echo = parse_motioncal_echo(bytes(buf))
                if echo is not None:
                    break
                if len(buf) > 1 << 20:
                    del buf[: len(buf) - 4096]
    if echo is None:
        seen = bytes(buf[-80:])
        raise CalibrationError(
            f"no Cal1:/Cal2: echo from {port} within {timeout:g} s (received {len(buf)} bytes"
            + (f", last: {seen!r}" if buf else "")
            + "): check the baud rate (--baud), that the board runs a sketch that accepts "
            "MotionCal packets, and that it has finished booting (try again, or --timeout 10)"
        )
    bad = echo_matches(packet, *echo)
    if bad:
        raise CalibrationError(
            "the board echoed different values: " + "; ".join(bad[:5])
            + " -- the packet may have been garbled; send it again"
        )
    return echo


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "send",
        help="write the MotionCal calibration packet to a board and check its echo",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("calibration", metavar="CAL.json",
                   help="calibration file written by triaxcal fit (or Calibration.save)")
    p.add_argument("--port", required=True,
                   help="serial port (/dev/ttyUSB0, COM3) or a pyserial URL (loop://)")
    p.add_argument("--baud", type=int, default=115200,
                   help="baud rate of the board's serial port (default 115200)")
    p.add_argument("--timeout", type=float, default=3.0,
                   help="seconds to wait for the echo (default 3)")
    add_scale_options(p)
    p.add_argument("--force", action="store_true",
                   help="send a calibration the validity gate refuses (the board cannot be "
                        "told: it applies it like any other)")
    p.add_argument("--offsets-only", action="store_true",
                   help="accept that the packet carries the accelerometer's and gyroscope's "
                        "offsets but not their gains or any temperature terms (without it such "
                        "a calibration is refused, naming what would be lost)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..export._trust import mark_lines, prepare

    cal = Calibration.load(args.calibration)
    scale = scale_options(args)
    prep = prepare(cal, fmt="a MotionCal packet", force=args.force, action="send")
    packet = motioncal_packet(cal, offsets_only=args.offsets_only, force=args.force, **scale)
    for lost in motioncal_losses(cal, **scale):
        print(f"  not in the packet: {lost}")
    for line in mark_lines(prep.invalid):
        print(f"  {line}")
    cal1, cal2 = send_packet(args.port, packet, baud=args.baud, timeout=args.timeout)
    print(f"sent {len(packet)}-byte MotionCal packet to {args.port}; the board confirmed it")
    print("  Cal1: " + ", ".join(f"{v:.4f}" for v in cal1))
    print("  Cal2: " + ", ".join(f"{v:.4f}" for v in cal2))
    return 0
