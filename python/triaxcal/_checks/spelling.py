"""How a message names an option: as the command line spells it when a command runs
(``--yaw-only``, ``--sensor mag``), as Python spells it otherwise (``yaw_only=True``,
``sensor="mag"``). The command line sets the context once (:func:`command_line`, in
``triaxcal.cli.main``); every layer below writes its messages with :func:`opt` and never needs
to know which front end called it.

>>> opt("yaw_only")
'yaw_only'
>>> opt("sensor", "mag")
"sensor='mag'"
>>> with command_line():
...     opt("yaw_only"), opt("sensor", "mag"), opt("fixed", "gain_z=1")
('--yaw-only', '--sensor mag', '--fix gain_z=1')
"""

from __future__ import annotations

import contextlib
import contextvars
from collections.abc import Iterator
from typing import Any

__all__ = ["command_line", "in_command_line", "opt"]

_CLI: contextvars.ContextVar[bool] = contextvars.ContextVar("triaxcal_command_line",
                                                             default=False)

#: Python names whose command-line spelling is not the name with dashes.
_FLAGS = {
    "fixed": "--fix",
    "topics": "--topic",
    "max_rounds": "--rounds",
    "lengths": "--reject-on",
    "n_boot": "--bootstrap",
    "accel_threshold_g": "--accel-threshold",
    "hold_windows": "--hold",
    "holdoff_s": "--holdoff",
    "offsets_only": "--offsets-only",
    "counts_per_unit": "--counts-per-unit",
    "angle_deg": "--angle",
    "rest_s": "--rest",
    "offset": "--bias",
    "gyro_offset": "--bias",
    "nominal_counts_per_dps": "--counts-per-unit",
    "require_both_directions": "--both-directions",
    "min_still_s": "--min-still",
    "max_asymmetry_pct": "--max-asymmetry",
}

_MISSING = object()


def in_command_line() -> bool:
    """Whether a command of the command line is running (messages then name flags)."""
    return _CLI.get()


@contextlib.contextmanager
def command_line() -> Iterator[None]:
    """Within this block, :func:`opt` spells options as the command line does."""
    token = _CLI.set(True)
    try:
        yield
    finally:
        _CLI.reset(token)


def opt(name: str, value: Any = _MISSING, *, flag: str | None = None) -> str:
    """The option ``name`` (its Python name), with ``value`` if given, as the user wrote it;
    ``flag`` names its command-line spelling where that is not the name with dashes."""
    if _CLI.get():
        flag = flag or _FLAGS.get(name, "--" + name.replace("_", "-"))
        if value is _MISSING:
            return flag
        if value is True:
            return flag
        return f"{flag} {value}"
    if value is _MISSING:
        return name
    return f"{name}={value!r}"
