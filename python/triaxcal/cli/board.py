"""``triaxcal board``: the calibration a board keeps itself (the project firmware, mode S).

``triaxcal board read --port PORT -o cal.json`` asks the board for its stored record (command
``K``) and writes it as a calibration file: the accelerometer part in g (the board works in
counts at its nominal scale, ``--counts-per-g``, 16384 for an MPU-6050 at +-2 g). A board with
no record, or with a damaged one (its CRC does not match), is an error that says so.

``triaxcal board write CAL.json --port PORT`` stores a host calibration's accelerometer part
on the board (a 74-byte write packet, the record with its own CRC) and checks the board's
answer: it must hold exactly the record sent. The board applies it to its streams after
``A`` (``--apply``).

Both pass the validity gate (:mod:`triaxcal.calibration.gate`): a part it refuses is neither
written nor stored unless ``--force`` (then marked as not valid, with the reasons).

The record's layout and the frames are in :mod:`triaxcal.io.board_store`.
"""

from __future__ import annotations

import argparse
import math
import time
from typing import Any

from ..calibration import Calibration
from ..calibration.board import calibration_to_record, record_to_calibration
from ..calibration.gate import check_part, judged, require_valid
from ..errors import CalibrationError
from ..io.board_store import (
    COMMAND_APPLY,
    COMMAND_REPORT,
    BoardRecord,
    BoardStoreDecoder,
    RecordReport,
    write_packet,
)


def _open(port: str, baud: int, timeout: float) -> Any:
    import serial

    try:
        return serial.serial_for_url(port, baudrate=baud, timeout=0.05, write_timeout=timeout)
    except (serial.SerialException, OSError, ValueError) as exc:
        raise CalibrationError(
            f"cannot open {port}: {exc}; check the port name (ls /dev/tty*) and that no other "
            "program (serial monitor, a capture) holds it"
        ) from None


def exchange(port: str, data: bytes, *, want: tuple[str, ...], baud: int = 115200,
             timeout: float = 5.0) -> RecordReport:
    """Write ``data`` to the board and return the first ``K`` frame whose reason is in
    ``want`` (``"report"``, ``"written"``, ``"write refused"``, ``"fitted"``).

    Raises :class:`CalibrationError` when the port cannot be opened or no such frame arrives
    within ``timeout`` seconds.
    """
    dec = BoardStoreDecoder()
    with _open(port, baud, timeout) as ser:
        ser.reset_input_buffer()
        ser.write(data)
        ser.flush()
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for rec in dec.feed(ser.read(4096)):
                if isinstance(rec, RecordReport) and rec.reason in want:
                    return rec
    raise CalibrationError(
        f"no answer from {port} within {timeout:g} s ({dec.stats.bytes_in} bytes received, "
        f"{dec.stats.dropped_frames} damaged frames): check the baud rate (--baud), that the "
        "board runs the triaxcal firmware with its own calibration (firmware/README.md), and "
        "that it has finished booting or fitting (try again, or --timeout 20)"
    )


def _positive(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"{text!r}: give a number greater than zero")
    return v


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "board",
        help="read the calibration a board stored itself, or store a host calibration on it",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sub = p.add_subparsers(dest="action", metavar="ACTION", required=True,
                           help="read: the stored calibration into a file; write: store one")
    r = sub.add_parser("read", help="the board's stored calibration into a calibration file")
    r.add_argument("-o", "--output", metavar="CAL.json",
                   help="write the calibration file here (otherwise only print it)")
    w = sub.add_parser("write", help="store a host calibration's accelerometer part")
    w.add_argument("calibration", metavar="CAL.json",
                   help="calibration file written by triaxcal fit (or Calibration.save)")
    w.add_argument("--apply", action="store_true",
                   help="then switch the board's streams to calibrated counts ('A')")
    for q in (r, w):
        q.add_argument("--force", action="store_true",
                       help="write (read) or store (write) a calibration the validity gate "
                            "refuses, marked as not valid (read) with the reasons")
        q.add_argument("--port", required=True,
                       help="serial port (/dev/ttyUSB0, COM3) or a pyserial URL")
        q.add_argument("--baud", type=int, default=115200,
                       help="baud rate of the board's serial port (default 115200)")
        q.add_argument("--timeout", type=_positive, default=5.0,
                       help="seconds to wait for the board's answer (default 5)")
        q.add_argument("--counts-per-g", type=_positive, default=None,
                       help="the board's calibrated counts per g (read: default the stored "
                            "record's radius; write: default the radius of the record the "
                            "board holds, else required -- 16384 for an MPU-6050 at +-2 g)")
    p.set_defaults(func=run)


def _show(rec: BoardRecord, counts_per_g: float | None) -> None:
    counts_per_g = counts_per_g or float(rec.radius)
    gains = [rec.matrix[i][i] for i in range(3)]
    origin = "fitted on the board" if rec.origin == "board" else "written by the host"
    print(f"  model {rec.model or 'other'}, {origin}, {rec.n} poses")
    print("  offset (counts): " + ", ".join(f"{v:.3f}" for v in rec.offset))
    print("  gains (x, multiply, calibrated counts per count): "
          + ", ".join(f"{g:.6f}" for g in gains))
    print(f"  RMS {rec.rms:.3f} counts ({rec.rms / counts_per_g * 1000:.4f} mg), "
          f"spread {rec.spread:.3f}")
    for text in rec.warning_texts:
        print(f"  warning: {text}")


def run(args: argparse.Namespace) -> int:
    cpg = args.counts_per_g
    if args.action == "read":
        rep = exchange(args.port, COMMAND_REPORT, want=("report",), baud=args.baud,
                       timeout=args.timeout)
        rec = rep.record()
        print(f"{args.port}: stored calibration "
              f"({'applied to the streams' if rep.applied else 'streams raw'})")
        _show(rec, cpg)
        if args.output:
            cal = record_to_calibration(rec, counts_per_g=cpg, source=args.port)
            part = cal.part("accel")
            part = judged(part, check_part(part, "accel"), force=args.force)  # the gate
            path = cal.replace(accel=part).save(args.output)
            print(f"wrote {path}")
        return 0
    cal = Calibration.load(args.calibration)
    require_valid(cal.part("accel"), "accel", force=args.force, action="store on the board")
    if cpg is None:  # the scale of the record the board holds, if it holds one
        try:
            held = exchange(args.port, COMMAND_REPORT, want=("report",), baud=args.baud,
                            timeout=args.timeout).record()
            cpg = float(held.radius)
        except CalibrationError:
            raise CalibrationError(
                "the board holds no calibration to take its scale from: give its calibrated "
                "counts per g with --counts-per-g (16384 for an MPU-6050 at +-2 g)") from None
    rec = calibration_to_record(cal, counts_per_g=cpg)
    rep = exchange(args.port, write_packet(rec), want=("written", "write refused"),
                   baud=args.baud, timeout=args.timeout)
    stored = rep.record()
    if stored != rec:
        raise CalibrationError("the board holds another record than the one sent: the packet "
                               "may have been garbled; write it again")
    print(f"{args.port}: stored the accelerometer calibration of {args.calibration}")
    _show(stored, cpg)
    if args.apply:
        rep = exchange(args.port, COMMAND_APPLY, want=("report",), baud=args.baud,
                       timeout=args.timeout)
        if not rep.applied:
            raise CalibrationError("the board did not switch its streams to calibrated counts")
        print("  the board's streams are calibrated now ('a' switches them back to raw)")
    return 0
