"""Writing one sensor's part into a calibration file, as ``triaxcal fit`` does: a new file, or
an existing one whose other parts are kept. Shared by the seed-method commands."""

from __future__ import annotations

import argparse
import hashlib
from pathlib import Path
from typing import Any

from ..calibration.file import Calibration, SensorCalibration
from ..errors import CalibrationError


def add_output_options(p: argparse.ArgumentParser) -> None:
    """``-o CAL.json`` (required), ``--new`` and ``--sensor-id``."""
    p.add_argument("-o", "--output", required=True, metavar="CAL.json",
                   help="calibration file to write; an existing one keeps its other sensors")
    p.add_argument("--new", action="store_true",
                   help="overwrite CAL.json instead of adding this sensor to it")
    p.add_argument("--sensor-id", default=None, help="board / sensor id to record")


def existing_part(path: str | Path, sensor: str, new: bool) -> SensorCalibration | None:
    """The sensor's part already in ``path`` (None if there is none, or with ``new``)."""
    cal = _load(Path(path), new)
    return None if cal is None else getattr(cal, sensor)


def _load(path: Path, new: bool) -> Calibration | None:
    if new or not path.exists():
        return None
    try:
        return Calibration.load(path)
    except CalibrationError as exc:
        raise CalibrationError(
            f"{path} exists but is not a calibration file ({exc}); pass --new to replace it"
        ) from None


def save_part(args: Any, sensor: str, part: SensorCalibration) -> str:
    """Write ``part`` as ``sensor`` into ``args.output``; returns "wrote" or "updated"."""
    path = Path(args.output)
    if path.is_dir():
        raise CalibrationError(f"-o {path} is a folder: give a file name, e.g. {path}/cal.json")
    if not path.parent.exists():
        raise CalibrationError(f"-o {path}: the folder {path.parent} does not exist")
    cal = _load(path, args.new)
    if cal is None:
        parts: dict[str, Any] = {sensor: part}
        cal = Calibration(**parts, sensor_id=args.sensor_id or "")
        verb = "wrote"
    else:
        changes: dict[str, Any] = {sensor: part}
        if args.sensor_id is not None:
            changes["sensor_id"] = args.sensor_id
        cal = cal.replace(**changes)
        verb = "updated"
    try:
        cal.save(path)
    except OSError as exc:
        raise CalibrationError(f"cannot write {path}: {exc.strerror or exc}") from None
    return verb


def file_sha256(path: str | Path) -> str:
    """SHA-256 of a file's bytes (``sha256sum FILE``)."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()
