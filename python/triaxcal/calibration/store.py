"""Writing one sensor's part into a calibration file: a new file, or an existing one whose other
parts are kept. The calibration a part replaces is not lost: its summary goes into the new
part's ``previous`` list. ``triaxcal fit``, the method commands, ``batch`` and the live page's
Save all write through :func:`store_part`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .._checks.spelling import opt
from ..errors import CalibrationError
from .file import Calibration
from .part import SensorCalibration

__all__ = ["Stored", "existing_calibration", "store_part", "store_parts"]


@dataclass(frozen=True)
class Stored:
    """What :func:`store_part` did: ``verb`` is ``"wrote"`` (a new file) or ``"updated"``."""

    path: Path
    verb: str
    calibration: Calibration


def _check_path(path: Path) -> None:
    if path.is_dir():
        raise CalibrationError(f"{path} is a folder: give a file name, e.g. {path}/cal.json")
    if not path.parent.exists():
        raise CalibrationError(f"cannot write {path}: the folder {path.parent} does not exist")


def existing_calibration(path: str | Path, *, new: bool = False) -> Calibration | None:
    """The calibration already in ``path``, or None (no file, an empty one, or ``new``).

    A file that exists but is not a calibration raises, saying to pass ``--new``
    (``new=True``) to replace it."""
    p = Path(path)
    if new or not p.is_file() or p.stat().st_size == 0:
        return None
    try:
        return Calibration.load(p)
    except CalibrationError as exc:
        raise CalibrationError(
            f"{p} exists but is not a calibration file ({exc}); pass {opt('new', True)} to "
            "replace it"
        ) from None


def store_part(
    path: str | Path,
    sensor: str,
    part: SensorCalibration,
    *,
    new: bool = False,
    sensor_id: str | None = None,
) -> Stored:
    """Write ``part`` as ``sensor`` into the calibration file ``path``.

    An existing calibration file keeps its other parts (``new=True`` starts a new file); the
    part it had for ``sensor`` is summarised in the new part's ``previous``, also with
    ``new=True``, so that ``triaxcal diff`` and the report can say what changed.
    """
    return store_parts(path, {sensor: part}, new=new, sensor_id=sensor_id)


def store_parts(
    path: str | Path,
    parts: Mapping[str, SensorCalibration],
    *,
    new: bool = False,
    sensor_id: str | None = None,
) -> Stored:
    """Write several parts (``{"accel": ..., "gyro": ...}``: a method that calibrates two
    sensors at once) into ``path`` in one write, each as :func:`store_part` writes one."""
    if not parts:
        raise CalibrationError("no part to write")
    p = Path(path)
    _check_path(p)
    cal = existing_calibration(p, new=new)
    old = cal
    if old is None and new and p.is_file():
        try:  # --new over a calibration: it is replaced, but its summary is kept
            old = Calibration.load(p)
        except CalibrationError:
            old = None
    changes: dict[str, Any] = {}
    for sensor, part in parts.items():
        if old is not None and getattr(old, sensor) is not None:
            part = part.with_previous(old.part(sensor), created_utc=old.created_utc)
        changes[sensor] = part
    if cal is None:
        cal = Calibration(**changes, sensor_id=sensor_id or "")
        verb = "wrote"
    else:
        if sensor_id is not None:
            changes["sensor_id"] = sensor_id
        cal = cal.replace(**changes)
        verb = "updated"
    try:
        cal.save(p)
    except OSError as exc:
        raise CalibrationError(f"cannot write {p}: {exc.strerror or exc}") from None
    return Stored(path=p, verb=verb, calibration=cal)
