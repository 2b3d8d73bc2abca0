"""``triaxcal capture``: record a session CSV from a board on a serial port."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from ..capture.run import capture, channel_names
from ..detect.session import POSE_N_COLUMN
from ..errors import CalibrationError
from ..io.board_poses import BoardPoseSettings
from ..io.protocol import PROTOCOLS
from ..io.serial import SerialReader, parse_request_byte
from ._help import renamed
from ._pose_options import add_pose_options, positive_int, settings_from_args

HELP = "record a session CSV from a sensor board on a serial port"

EPILOG = """\
Turn the board slowly through many orientations and hold each one still for a second: every
still pose rings the bell, and the status line says which way to turn next. Ctrl-C stops
with everything saved. The session CSV has a header 't,<channels>' and one row per record:
host time in seconds, then the values as received (counts).

With --board-poses the board finds the poses itself (the triaxcal firmware's mode S: the
sphere-centre note's window method, run on the board, with the gyro watching for turns) and sends
one mean per pose; each becomes a row of the session, with a last column pose_n (samples averaged),
and beeps its buzzer. The pose-detection options below are sent to the board (in its
counts: --counts-per-g, default 16384, turns --accel-threshold into counts; --gyro-threshold
auto is the firmware's 393 counts = 3 deg/s; --rate-hz sets its sample rate, default 100).
triaxcal fit takes such rows as the poses they are.

With --live, a page in the browser (http://127.0.0.1:8765 by default) shows the readings
filling the sphere in 3D, the running fit with its standard errors, MotionCal's four quality
numbers and the stream's health, with buttons to save, export and send the calibration.

examples:
  triaxcal capture --port /dev/ttyUSB0 --protocol framed --poses 30 -o s.csv
  triaxcal capture --port /dev/ttyACM0 --protocol framed --live -o s.csv
  triaxcal capture --port /dev/ttyACM0 --protocol framed --channels 7 --board-poses \
      --holdoff 2 --poses 84 -o globe.csv
  triaxcal capture --port /dev/ttyACM0 --protocol binary --channels 7 -o s.csv
  triaxcal capture --port COM3 --protocol raw --samples 5000 -o s.csv

several boards at once (a production rig): one session file per board in --out-dir, named by
the serial number each board reports (command 'I', answer 'ID:<serial>'), else by its port;
one status line per board; an unplugged board is waited for while the others go on:
  triaxcal capture --port /dev/ttyUSB0 --port /dev/ttyUSB1 --protocol framed --poses 30 \
                   --out-dir sessions/
"""


def _request_byte(text: str) -> bytes:
    try:
        return parse_request_byte(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _http_port(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a port number, got {text!r}") from None
    if not 0 <= v <= 65535:
        raise argparse.ArgumentTypeError(f"expected a port number 0..65535, got {v}")
    return v


def add_live_options(p: argparse.ArgumentParser) -> None:
    """``--live``, ``--http-host``, ``--http-port``, ``--no-browser`` (capture and demo)."""
    g = p.add_argument_group("live page (needs: pip install 'triaxcal[live]')")
    g.add_argument("--live", action="store_true",
                   help="serve a live page while capturing: the readings in 3D, coverage, the "
                        "running fit, quality numbers, stream health, Save/Export/Send buttons")
    g.add_argument("--http-host", default="127.0.0.1", metavar="HOST",
                   help="address of the live page (default 127.0.0.1: this machine only; "
                        "0.0.0.0 shows the data to the whole network)")
    g.add_argument("--http-port", type=_http_port, default=8765, metavar="PORT",
                   help="port of the live page (default 8765; the next free one if taken)")
    g.add_argument("--no-browser", action="store_true",
                   help="do not open the live page in the default browser")


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "capture",
        help=HELP,
        description=HELP[0].upper() + HELP[1:] + ".",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--port", required=True, action="append",
                   help="serial port: /dev/ttyUSB0, /dev/ttyACM0, COM3; repeat it to capture "
                        "several boards at once (with --out-dir)")
    p.add_argument("--baud", type=positive_int, default=115200, help="baud rate (default 115200)")
    p.add_argument("--protocol", required=True, choices=PROTOCOLS,
                   help="wire protocol: binary (legacy, polled unless --stream), framed "
                        "(COBS + CRC-16, recommended), text (numbers per line), raw "
                        "(MotionCal Raw: lines)")
    p.add_argument("--channels", type=positive_int, default=None, metavar="K",
                   help="values per record (default 10: ax ay az gx gy gz mx my mz temp; "
                        "7 for the AVR firmware, the default with --board-poses; raw is "
                        "always 9)")
    p.add_argument("--request-byte", type=_request_byte, default=b"!", metavar="BYTE",
                   help="request byte of polled binary (default 0x21, '!')")
    p.add_argument("--stream", action="store_true",
                   help="binary: the board streams by itself (mode byte B) instead of being "
                        "polled")
    stop = p.add_mutually_exclusive_group()
    stop.add_argument("--samples", type=positive_int, metavar="N",
                      help="stop after N records")
    stop.add_argument("--poses", type=positive_int, metavar="N",
                      help="stop after N still poses")
    p.add_argument("--seconds", type=float, default=None, metavar="S",
                   help="stop after S seconds")
    p.add_argument("-o", "--output", metavar="SESSION.csv",
                   help="session CSV to write (one port)")
    p.add_argument("--out-dir", metavar="DIR",
                   help="folder for one session CSV per board, <serial number>.csv (several "
                        "ports)")
    p.add_argument("--no-id", action="store_true",
                   help="with --out-dir: do not ask the boards for their serial number; name "
                        "the files after the ports")
    exist = p.add_mutually_exclusive_group()
    exist.add_argument("--append", action="store_true",
                       help="add to an existing session CSV with the same columns")
    exist.add_argument("--overwrite", action="store_true", help="replace an existing file")
    p.add_argument("--no-mode-byte", action="store_true",
                   help="do not send the mode byte (P/B/F/T/R) that switches the firmware to "
                        "the protocol; for boards that stream by themselves")
    p.add_argument("--board-poses", action="store_true",
                   help="framed: the board detects the still poses itself and sends one mean "
                        "per pose (firmware mode S); the session gets one row per pose")
    p.add_argument("--beep-ms", type=int, default=100, metavar="MS",
                   help="--board-poses: length of the board's beep on each pose, 0..250 ms "
                        "(default 100; 0: silent)")
    p.add_argument("--no-bell", action="store_true", help="do not ring the bell on each pose")
    p.add_argument("--quiet", action="store_true", help="no status line")
    add_pose_options(p)
    rate = next(a for a in p._actions if "--rate-hz" in a.option_strings)
    rate.help = ("the board's sample rate: polled binary asks at most HZ times a second (set "
                 "it to the sensor's output rate to avoid repeated samples; default: as fast "
                 "as the board answers); --board-poses sets the board's rate to it (default "
                 "100); the pose detection turns --holdoff into samples with it (default: from "
                 "the arrival times)")
    renamed(p, "--poll-hz", "--rate-hz")
    renamed(p, "--out", "--output")
    add_live_options(p)
    from .export import add_scale_options

    add_scale_options(p.add_argument_group(
        "live page's Send: the board driver's scale (the MotionCal packet is in m/s^2, rad/s, "
        "uT)"))
    p.set_defaults(func=run)


def board_settings(args: argparse.Namespace) -> BoardPoseSettings:
    """The board's pose settings from the pose-detection options, in the board's units."""
    if args.hold is None:
        raise CalibrationError("--board-poses needs --hold W: the board registers a pose after "
                               "W steady windows")
    if args.mag_threshold not in ("auto", "off"):
        raise CalibrationError("--board-poses: the board's pose mode has no magnetometer; drop "
                               "--mag-threshold")
    per_g = 16384.0 if args.counts_per_g is None else float(args.counts_per_g)
    rate = 100.0 if args.rate_hz is None else float(args.rate_hz)
    period = 1000.0 / rate
    if abs(period - round(period)) > 1e-9 or not 1 <= round(period) <= 250:
        raise CalibrationError(f"--board-poses: --rate-hz {rate:g} is not 1000 / a whole number "
                               "of milliseconds from 1 to 250 (e.g. 100, 200, 500, 1000)")
    thr = args.gyro_threshold
    gyro = 393 if thr == "auto" else 0 if thr == "off" else int(round(float(thr)))
    return BoardPoseSettings(
        period_ms=int(round(period)),
        window=args.window,
        hold_windows=args.hold,
        holdoff_ms=int(round(args.holdoff * 1000.0)),
        accel_threshold=max(1, int(round(args.accel_threshold * per_g))),
        gyro_threshold=gyro,
        beep_ms=args.beep_ms,
    )


def poll_interval_s(args: argparse.Namespace) -> float:
    """Seconds between the requests of polled binary: one sample period at ``--rate-hz`` (0:
    as fast as the board answers). One rate, whatever the protocol: the board's."""
    return 1.0 / args.rate_hz if args.rate_hz else 0.0


def run(args: argparse.Namespace) -> int:
    if args.live:
        from ..live.server import check_live_extra

        check_live_extra()  # before the port is opened: say what to install first
    channels = args.channels
    board = None
    if args.board_poses:
        if args.protocol != "framed":
            raise CalibrationError("--board-poses comes in the framed protocol: use "
                                   "--protocol framed")
        board = board_settings(args)
        channels = 7 if channels is None else channels
    elif channels is None and args.protocol != "raw":
        channels = 10
    args.board_settings = board
    if args.live and board is not None:
        raise CalibrationError(
            "--live shows the readings as they stream; with --board-poses the board sends only "
            "its pose means: drop one of the two")
    if args.live and (args.out_dir is not None or len(args.port) > 1):
        raise CalibrationError(
            "--live shows one board: capture one --port into -o SESSION.csv with it, or "
            "drop --live for a capture of several boards")
    if args.out_dir is not None or len(args.port) > 1:
        from ._multicapture import run_many

        return run_many(args, channels, poll_interval_s(args))
    if args.output is None:
        raise CalibrationError("give -o SESSION.csv (or --out-dir DIR)")
    port = args.port[0]
    reader = SerialReader(
        port,
        protocol=args.protocol,
        channels=channels,
        baud=args.baud,
        stream=args.stream,
        request_byte=args.request_byte,
        switch_mode=not args.no_mode_byte,
        poll_interval_s=poll_interval_s(args),
        board_poses=board,
    )
    names = channel_names(args.protocol, channels)
    if board is not None:
        names = (*names, POSE_N_COLUMN)
    mode = "append" if args.append else "overwrite" if args.overwrite else "new"
    out = sys.stderr
    if not args.quiet:
        how = "polled" if reader.polled else "streaming"
        if board is not None:
            how = (f"poses found on the board: {board.period_ms} ms per sample, windows of "
                   f"{board.window}, {board.hold_windows} averaged, hold-off "
                   f"{board.holdoff_ms} ms, thresholds accel {board.accel_threshold} gyro "
                   f"{board.gyro_threshold or 'off'} counts")
        print(
            f"triaxcal capture: {port} at {args.baud} baud, {args.protocol} ({how}), "
            f"{len(names)} channels ({' '.join(names)}) -> {args.output}; Ctrl-C stops",
            file=out,
        )
    kwargs: dict[str, Any] = {"samples": args.samples, "poses": args.poses,
                              "duration_s": args.seconds, "bell": not args.no_bell}
    detection = settings_from_args(args)
    if args.live:
        from ..live import LiveOptions
        from ..live.run import live_capture

        result = live_capture(
            reader, args.output, columns=names, mode=mode, detection=detection,
            options=LiveOptions(detection=detection, **_live_scale(args)),
            host=args.http_host, port=args.http_port, open_browser=not args.no_browser,
            progress=None if args.quiet else out, notices=out, **kwargs)
    else:
        result = capture(reader, args.output, mode=mode, columns=names, detection=detection,
                         progress=None if args.quiet else out, **kwargs)
    st = result.stats
    d = st.decoder
    why = {"interrupt": "stopped by Ctrl-C", "samples": "sample count reached",
           "poses": "pose count reached", "duration": "time is up", "stop": "stopped"}
    print(
        f"triaxcal capture: {why[result.stopped_by]}: {result.samples} rows, "
        f"{len(result.poses)} poses, coverage {100 * result.coverage:.0f} %, saved to "
        f"{result.path} ({result.elapsed_s:.1f} s; dropped frames {d.dropped_frames}, "
        f"skipped lines {d.lines_skipped}, lost by sequence {d.lost_frames}, "
        f"reconnects {st.reconnects})",
        file=out,
    )
    return 0


def _live_scale(args: argparse.Namespace) -> dict[str, Any]:
    from .export import scale_options

    d = scale_options(args)
    if "sensor_model" in d:
        d["sensor_model"] = tuple(d["sensor_model"])
    return d
