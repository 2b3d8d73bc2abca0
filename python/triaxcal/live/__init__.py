"""The live calibration page: watch the sphere fill and the fit converge while capturing.

``triaxcal capture ... --live`` and ``triaxcal demo --live`` serve a page (default
http://127.0.0.1:8765/) with a rotatable 3D view per sensor, the coverage of the sphere of
directions with a plain-words hint, the running fit with the standard error of every
coefficient, MotionCal's four quality numbers, the stream's health and the buttons Save
calibration, Export C header, Send to board and Reset.

* :mod:`~triaxcal.live.state` -- :class:`LiveState`, the bounded state the capture thread
  feeds and a background thread refits (no web dependency);
* :mod:`~triaxcal.live.quality` -- MotionCal's quality numbers and the buffer of
  well-spread magnetometer samples;
* :mod:`~triaxcal.live.actions` -- the buttons, each the CLI command of the same name;
* :mod:`~triaxcal.live.server` -- :class:`LiveServer` (Starlette + uvicorn, server-sent
  events), which needs the ``live`` extra: ``pip install 'triaxcal[live]'``;
* :mod:`~triaxcal.live.run` -- :class:`LivePage` and :func:`live_capture`, what ``--live``
  runs.
"""

from __future__ import annotations

from typing import Any

from .quality import MOTIONCAL_LIMITS, MotionCalQuality, SpreadBuffer, motioncal_quality
from .state import LiveOptions, LiveState

__all__ = [
    "MOTIONCAL_LIMITS",
    "LiveOptions",
    "LivePage",
    "LiveServer",
    "LiveState",
    "MotionCalQuality",
    "SpreadBuffer",
    "live_capture",
    "motioncal_quality",
]


def __getattr__(name: str) -> Any:
    # the server needs the `live` extra: import it (and say what to install) only when asked
    if name == "LiveServer":
        from .server import LiveServer

        return LiveServer
    if name in ("live_capture", "LivePage"):
        from . import run

        return getattr(run, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
