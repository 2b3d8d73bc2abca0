"""Writing one sensor's part into a calibration file from a method command, as ``triaxcal fit``
does (:func:`triaxcal.calibration.store.store_part`, after the validity gate)."""

from __future__ import annotations

import argparse
import hashlib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from ..calibration.part import SensorCalibration
from ..calibration.store import existing_calibration, store_part, store_parts


def add_output_options(p: argparse.ArgumentParser) -> None:
    """``-o CAL.json`` (required), ``--new``, ``--sensor-id`` and ``--force``."""
    p.add_argument("-o", "--output", required=True, metavar="CAL.json",
                   help="calibration file to write; an existing one keeps its other sensors")
    p.add_argument("--new", action="store_true",
                   help="overwrite CAL.json instead of adding to it")
    p.add_argument("--sensor-id", default=None, help="board / sensor id to record")
    p.add_argument("--force", action="store_true",
                   help="write the part even when the validity gate refuses it (marked "
                        "\"valid\": false with the reasons)")


def existing_part(path: str | Path, sensor: str, new: bool) -> SensorCalibration | None:
    """The sensor's part already in ``path`` (None if there is none, or with ``new``)."""
    cal = existing_calibration(path, new=new)
    return None if cal is None else getattr(cal, sensor)


def save_part(args: Any, sensor: str, part: SensorCalibration) -> str:
    """Write ``part`` (already through the gate) as ``sensor`` into ``args.output``; returns
    "wrote" or "updated"."""
    return store_part(args.output, sensor, part, new=args.new, sensor_id=args.sensor_id).verb


def save_parts(args: Any, parts: Mapping[str, SensorCalibration]) -> str:
    """Write several parts (already through the gate) into ``args.output`` in one write."""
    return store_parts(args.output, parts, new=args.new, sensor_id=args.sensor_id).verb


def file_sha256(path: str | Path) -> str:
    """SHA-256 of a file's bytes (``sha256sum FILE``)."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()
