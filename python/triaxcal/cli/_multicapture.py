"""``triaxcal capture --port A --port B ... --out-dir DIR``: the several-boards branch of
``capture`` (kept apart so that ``cli/capture.py`` stays the one-board command)."""

from __future__ import annotations

import argparse
import sys

from ..capture.multi import capture_many
from ..capture.run import channel_names
from ..errors import CalibrationError


def run_many(args: argparse.Namespace, channels: int | None, poll_interval_s: float) -> int:
    if args.output is not None:
        raise CalibrationError(
            "several --port: give --out-dir DIR (one session file per board), not -o/--output"
        )
    if args.out_dir is None:
        raise CalibrationError("several --port: give --out-dir DIR for the session files")
    names = channel_names(args.protocol, channels)
    mode = "append" if args.append else "overwrite" if args.overwrite else "new"
    out = sys.stderr
    if not args.quiet:
        print(
            f"triaxcal capture: {len(args.port)} boards ({', '.join(args.port)}), "
            f"{args.protocol}, {len(names)} channels -> {args.out_dir}/<board>.csv; Ctrl-C "
            "stops them all",
            file=out,
        )
    boards = capture_many(
        args.port,
        args.out_dir,
        protocol=args.protocol,
        channels=channels,
        query_id=not (args.no_id or args.no_mode_byte),
        reader_options={
            "baud": args.baud,
            "stream": args.stream,
            "request_byte": args.request_byte,
            "switch_mode": not args.no_mode_byte,
            "poll_interval_s": poll_interval_s,
            "board_poses": getattr(args, "board_settings", None),
        },
        samples=args.samples,
        poses=args.poses,
        duration_s=args.seconds,
        mode=mode,
        progress=None if args.quiet else out,
        bell=not args.no_bell,
        columns=names,
        units_per_g=args.counts_per_g,
        window=args.window,
        hold_windows=args.hold,
    )
    failed = 0
    for b in boards:
        if b.result is None:
            failed += 1
            print(f"triaxcal capture: {b.board_id} ({b.port}): FAILED: {b.error}", file=out)
            continue
        r = b.result
        print(
            f"triaxcal capture: {b.board_id} ({b.port}, id from {b.id_source}): {r.samples} "
            f"rows, {len(r.poses)} poses, sphere {100 * r.coverage:.0f}%, reconnects "
            f"{r.stats.reconnects} -> {b.path}",
            file=out,
        )
    return 1 if failed else 0
