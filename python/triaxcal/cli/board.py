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

import numpy as np

from ..calibration import Calibration, SensorCalibration
from ..calibration.gate import check_part, judged, require_valid
from ..conventions.units import DEVICE_COUNTS_PER_UNIT, unit_factor
from ..errors import CalibrationError
from ..io.board_store import (
    COMMAND_APPLY,
    COMMAND_REPORT,
    BoardRecord,
    BoardStoreDecoder,
    RecordReport,
    write_packet,
)

_COUNTS_PER_G = DEVICE_COUNTS_PER_UNIT["accel"][0]


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


def record_to_calibration(rec: BoardRecord, *, counts_per_g: float = _COUNTS_PER_G,
                          source: str | None = None) -> Calibration:
    """A board's record as a calibration file: the accelerometer part in g.

    The board's calibrated counts are at ``counts_per_g``: the part's matrix (g per count)
    is the record's divided by it, and so are the radius and the RMS.

    Examples
    --------
    >>> r = BoardRecord(offset=(180, -240, 350), matrix=((0.985, 0, 0), (0, 1.016, 0),
    ...                 (0, 0, 0.996)), radius=16384, model="axis", origin="board", n=60)
    >>> part = record_to_calibration(r).accel
    >>> part.unit, part.radius, round(float(1 / part.matrix[0, 0]))  # counts per g, x axis
    ('g', 1.0, 16634)
    """
    m = np.asarray(rec.matrix, dtype=float) / counts_per_g
    radius = rec.radius / counts_per_g
    stats: dict[str, Any] = {
        "origin": rec.origin,
        "converged": not rec.warnings & 0x02,
        "n_poses": rec.n,
        "rms": rec.rms / counts_per_g,
        "rms_pct_of_radius": 100.0 * rec.rms / rec.radius,
        "spread": rec.spread,
        "warnings": rec.warning_texts,
        "board_counts_per_g": counts_per_g,
    }
    part = SensorCalibration(offset=np.asarray(rec.offset, dtype=float), matrix=m,
                             raw_unit="counts", unit="g", radius=radius, model=rec.model,
                             stats=stats, source=source)
    return Calibration(accel=part, extra={"board_record": "fitted on the board"
                                          if rec.origin == "board" else "written by the host"})


def calibration_to_record(cal: Calibration, *,
                          counts_per_g: float = _COUNTS_PER_G) -> BoardRecord:
    """The accelerometer part of a host calibration as the record a board stores.

    The part must be in raw counts, calibrated in an acceleration unit (g, m/s^2) and have
    no temperature terms (the board applies none). The board's calibrated counts are at
    ``counts_per_g``: its matrix is the part's in g per count times that.
    """
    part = cal.part("accel")
    if part.raw_unit != "counts":
        raise CalibrationError(
            f"the accelerometer part's raw unit is {part.raw_unit!r}: a board applies its "
            "calibration to raw counts, so the part must be fitted on counts")
    if part.temperature is not None:
        raise CalibrationError(
            "the accelerometer part has temperature terms, which the board does not apply: "
            "export it as a C header instead (triaxcal export --format c)")
    to_g = unit_factor(part.unit, "g")
    m = np.asarray(part.matrix, dtype=float) * to_g * counts_per_g
    rms = part.stats.get("rms")
    rms_counts = float(rms) * to_g * counts_per_g if isinstance(rms, (int, float)) and \
        math.isfinite(rms) else 0.0
    n = part.stats.get("n")
    return BoardRecord(offset=tuple(part.offset), matrix=tuple(tuple(r) for r in m),
                       radius=counts_per_g, model=part.model if part.model in ("axis", "full")
                       else None, origin="host", n=n if isinstance(n, int) and 0 <= n < 65536
                       else 0, rms=rms_counts)


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
    sub = p.add_subparsers(dest="action", metavar="ACTION", required=True)
    r = sub.add_parser("read", help="the board's stored calibration into a calibration file")
    r.add_argument("-o", "--out", metavar="CAL.json",
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
        q.add_argument("--counts-per-g", type=_positive, default=_COUNTS_PER_G,
                       help="the board's nominal scale: its calibrated counts per g (default "
                            "16384, an MPU-6050 at +-2 g)")
    p.set_defaults(func=run)


def _show(rec: BoardRecord, counts_per_g: float) -> None:
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
        if args.out:
            cal = record_to_calibration(rec, counts_per_g=cpg, source=args.port)
            part = cal.part("accel")
            part = judged(part, check_part(part, "accel"), force=args.force)  # the gate
            path = cal.replace(accel=part).save(args.out)
            print(f"wrote {path}")
        return 0
    cal = Calibration.load(args.calibration)
    require_valid(cal.part("accel"), "accel", force=args.force, action="store on the board")
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
