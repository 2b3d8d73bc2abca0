"""``triaxcal demo``: capture from a simulated board, fit, and compare with the truth
(:func:`triaxcal.demo.run_demo`, with the pose options of the command line: nothing else)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from ..calibration.flight import write_demo_flight
from ..demo import run_demo
from ..io.protocol import PROTOCOLS
from ._help import renamed
from ._pose_options import add_pose_options, positive_float, settings_from_args
from .capture import add_live_options

HELP = "capture from a simulated board, calibrate it, and compare with the truth"


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "demo",
        help=HELP,
        description=HELP[0].upper() + HELP[1:] + ". Writes session.csv, results.json, "
        "calibration.json, C headers, motioncal.bin and report figures into --out-dir.",
    )
    p.add_argument("--out-dir", default="triaxcal-demo", metavar="DIR",
                   help="folder for the session, the calibration and its reports "
                        "(default ./triaxcal-demo)")
    renamed(p, "--out", "--out-dir")
    p.add_argument("--no-plot", action="store_true",
                   help="skip the report figures (they need matplotlib)")
    p.add_argument("--protocol", default="framed", choices=PROTOCOLS,
                   help="wire protocol between the simulated board and the host, streamed "
                        "(default framed)")
    p.add_argument("--speed", type=positive_float, default=None,
                   help="simulated seconds per real second (default 40; 5 with --live, so "
                        "that the sphere fills in about 40 s)")
    p.add_argument("--seed", type=int, default=1, help="seed of the simulated sensor (default 1)")
    p.add_argument("--quiet", action="store_true", help="print only the summary")
    p.add_argument("--flight", action="store_true",
                   help="instead: write a simulated flight with known compass errors, DIR/"
                        "flight.BIN (ArduPilot), DIR/flight.ulg (PX4) and DIR/flight_truth.json, "
                        "for triaxcal fit DIR/flight.BIN --sensor mag --method attitude")
    add_pose_options(p)
    add_live_options(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    out = Path(args.out_dir)
    if args.flight:  # the simulated flight logs and their truth, nothing else
        for kind, path in write_demo_flight(out).items():
            print(f"{kind}: {path}")
        return 0
    if args.speed is None:
        args.speed = 5.0 if args.live else 40.0
    live = None
    if args.live:
        from ..live.server import check_live_extra

        check_live_extra()
        live = {"host": args.http_host, "port": args.http_port,
                "open_browser": not args.no_browser}
    result = run_demo(out, protocol=args.protocol, speed=args.speed, seed=args.seed,
                      progress=None if args.quiet else sys.stderr, plot=not args.no_plot,
                      detection=settings_from_args(args), live=live)
    page = result.pop("live_page", None)
    try:
        _print_result(args, result)
        if page is not None:
            page.linger()
    finally:
        if page is not None:
            page.close()
    return 0


def _print_result(args: argparse.Namespace, result: dict[str, Any]) -> None:
    print(result["table"])
    print(f"session: {result['session']}\nresults: {result['results']}")
    for kind, path in result["outputs"].items():
        note = (" (offsets and soft iron only: the accelerometer's gains are in the C headers)"
                if kind == "motioncal" else "")
        print(f"{kind}: {path}{note}")
    if not args.no_plot and not any(k.startswith("figure_") for k in result["outputs"]):
        print("report figures skipped: matplotlib is not installed "
              "(pip install 'triaxcal[plot]')")
