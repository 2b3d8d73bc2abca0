"""The page's buttons, each the CLI command of the same name on the session being captured.

* **Save calibration** = ``triaxcal fit SESSION --sensor accel --poses ... -o calibration.json
  --new`` then ``triaxcal fit SESSION --sensor mag ... -o calibration.json``, into the live
  options' ``out_dir``: the same library call as the command
  (:func:`triaxcal.calibration.session.fit_to_file` with the page's
  :func:`~triaxcal.live.fitting.fit_request`), so every rule of ``fit`` applies (the validity
  gate refuses what is not a calibration, the replaced calibration is kept as ``previous``...).
* **Export C header** = Save, then the C header export (``triaxcal export calibration.json
  --format c`` or ``c-fixed``) to ``<prefix>_calibration.h`` (``<prefix>_calibration_fixed.h``).
* **Send to board** = Save, then ``triaxcal send calibration.json``: the 68-byte MotionCal
  packet goes out over the port being captured (it stays open), and the board's ``Cal1:``
  and ``Cal2:`` echo must repeat every value. The echo lines arrive amid the stream, so the
  decoder drops the frame they interrupt (it is counted like any damaged frame); polled binary
  cannot carry them (the next request clears the input), so Send needs a streaming protocol.

Export and Send refuse a calibration the validity gate refuses (as ``triaxcal export`` and
``send`` do; Save writes only what passes it), and say why, unless ``force``; a forced header
says it is not valid. Send needs the board driver's scale: the live options'
``counts_per_unit`` / ``sensor_model`` (``capture --live --counts-per-unit ...``), or the fixed
scale of MotionCal's ``Raw:`` lines (:data:`triaxcal.io.protocol.RAW_SCALES`); without either
it is refused, naming what is missing.

After a Reset, Save fits only the rows captured since: they are first copied, header and all,
to ``<session>.after-reset-<k>.csv`` next to the session, which is then the file fitted (so
``triaxcal fit`` on that file gives the same calibration).
"""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..errors import CalibrationError
from .fitting import fit_request, session_to_fit

if TYPE_CHECKING:
    from ..calibration.file import Calibration
    from .state import LiveState

__all__ = ["export_header", "reset", "save", "send"]

_ACTION_LOCK = threading.Lock()


def _save(state: LiveState) -> tuple[Calibration, Path, str]:
    """Fit each sensor into calibration.json as ``triaxcal fit`` does; raises with its
    messages when nothing could be saved."""
    from ..calibration.file import Calibration
    from ..calibration.session import fit_to_file
    from ..report.text import fit_lines

    path = state.out_dir / "calibration.json"
    if not state.session.exists():
        raise CalibrationError(f"the session {state.session} does not exist yet: wait for data")
    state.out_dir.mkdir(parents=True, exist_ok=True)
    data = session_to_fit(state)
    lines: list[str] = []
    failed: list[str] = []
    written = False
    for sensor in ("accel", "mag"):
        if sensor not in state.cols:
            continue
        try:
            saved = fit_to_file(data, fit_request(state, sensor), path, new=not written)
        except CalibrationError as exc:
            failed.append(f"{sensor}: not saved: {exc}")
            continue
        written = True
        lines.append(fit_lines(saved)[0])
    if not written:
        raise CalibrationError("nothing saved: " + "; ".join(failed))
    msg = " ".join(lines) + ("" if not failed else " (" + "; ".join(failed) + ")")
    return Calibration.load(path), path, msg


class _NeedsOffsetsOnly(CalibrationError):
    """Send refused because the packet would drop gains (the page then offers offsets only)."""


def _run(state: LiveState, action: str, fn: Any) -> dict[str, Any]:
    if not _ACTION_LOCK.acquire(timeout=0.1):
        return {"action": action, "ok": False, "time": time.time(),
                "message": "another action is still running: wait for it to finish"}
    try:
        try:
            result = {"action": action, "ok": True, **fn()}
        except CalibrationError as exc:
            result = {"action": action, "ok": False, "message": str(exc)}
            if isinstance(exc, _NeedsOffsetsOnly):
                result["needs_offsets_only"] = True
    finally:
        _ACTION_LOCK.release()
    result["time"] = time.time()
    state.last_action = result
    return result


def save(state: LiveState) -> dict[str, Any]:
    """Save calibration: ``triaxcal fit`` of every sensor into ``calibration.json``."""
    def go() -> dict[str, Any]:
        _, path, msg = _save(state)
        return {"message": msg, "path": str(path)}

    return _run(state, "save", go)


def export_header(state: LiveState, fmt: str, *, force: bool = False) -> dict[str, Any]:
    """Export C header: Save, then ``triaxcal export calibration.json --format FMT`` (with
    ``force``: ``--force``)."""
    from ..export import export
    from ..export._cgen import _ident

    if fmt not in ("c", "c-fixed"):
        return {"action": "export", "ok": False, "message": f"unknown header format {fmt!r}: "
                "use 'c' (float) or 'c-fixed' (fixed point)"}

    def go() -> dict[str, Any]:
        cal, cal_path, msg = _save(state)
        prefix = _ident(state.options.prefix)
        name = f"{prefix}_calibration.h" if fmt == "c" else f"{prefix}_calibration_fixed.h"
        out = state.out_dir / name
        try:
            export(cal, fmt, out, prefix=prefix, force=force)
        except CalibrationError as exc:
            raise CalibrationError(f"{msg}; but the export failed: {exc}") from None
        note = "" if not force or not _invalid(cal) else (
            " -- NOT A VALID CALIBRATION, written because forced: " + _invalid(cal))
        return {"message": f"{msg}; wrote {out}{note}", "path": str(out)}

    return _run(state, f"export-{fmt}", go)


def _invalid(cal: Calibration) -> str:
    """The gate's reasons against the parts of ``cal``, in words ("" when all pass)."""
    from ..calibration.gate import require_valid

    out = []
    for s in cal.sensors:
        v = require_valid(cal.part(s), s, force=True)
        if not v.valid:
            out.append(f"{s}: " + "; ".join(v.reasons))
    return " | ".join(out)


def _scales(state: LiveState) -> dict[str, Any]:
    """The driver's scale for Send: the live options', else the ``Raw:`` format's own."""
    opts = state.options
    cpu = getattr(opts, "counts_per_unit", None)
    models = tuple(getattr(opts, "sensor_model", ()) or ())
    if cpu or models:
        return {"counts_per_unit": cpu, "sensor_model": list(models) or None}
    if state.protocol == "raw":
        from ..io.protocol import RAW_SCALES

        return {"counts_per_unit": {"accel": (RAW_SCALES["accel"], "g"),
                                    "gyro": (RAW_SCALES["gyro"], "deg/s"),
                                    "mag": (RAW_SCALES["mag"], "uT")}}
    return {}


def send(state: LiveState, *, offsets_only: bool = False,
         force: bool = False) -> dict[str, Any]:
    """Send to board: Save, then the MotionCal packet over the open port, with the echo check
    of ``triaxcal send``. The packet carries the accelerometer's and gyroscope's offsets but
    not their gains: as ``triaxcal send`` does, such a calibration is refused (the answer has
    ``needs_offsets_only``) unless ``offsets_only`` (``--offsets-only``) accepts the loss."""
    from ..export import echo_matches, motioncal_losses, motioncal_packet, parse_motioncal_echo

    def go() -> dict[str, Any]:
        reader = state._reader
        if reader is None or state.status in ("fitting", "finished"):
            raise CalibrationError(
                "the capture has ended, so the port is closed: send the saved calibration with "
                "`triaxcal send calibration.json --port PORT`")
        if getattr(reader, "polled", False):
            raise CalibrationError(
                "polled binary cannot carry the board's echo while capturing: stop the capture "
                "(Ctrl-C), then `triaxcal send calibration.json --port PORT`")
        cal, cal_path, msg = _save(state)
        from ..export._trust import prepare

        try:
            prepare(cal, fmt="a MotionCal packet", force=force, action="send")
            scales = _scales(state)
            losses = motioncal_losses(cal, **scales)
        except CalibrationError as exc:
            raise CalibrationError(
                f"{msg}; not sent: {exc}"
                + (" (start the capture with --counts-per-unit or --sensor-model; "
                   "LiveOptions(counts_per_unit=...))" if "guess the driver" in str(exc)
                   else "")) from None
        if losses and not offsets_only:
            raise _NeedsOffsetsOnly(
                f"{msg}; not sent: the MotionCal packet cannot carry " + "; ".join(losses)
                + ". Send the offsets only (as `triaxcal send --offsets-only`), or export a C "
                "header, which carries everything")
        packet = motioncal_packet(cal, offsets_only=offsets_only, force=force, **scales)
        state._echo = bytearray()
        try:
            reader.write(packet)
            deadline = time.monotonic() + state.options.send_timeout_s
            echo = None
            while time.monotonic() < deadline:
                echo = parse_motioncal_echo(bytes(state._echo))
                if echo is not None:
                    break
                time.sleep(0.02)
        finally:
            seen = len(state._echo or b"")
            state._echo = None
        if echo is None:
            raise CalibrationError(
                f"{msg}; but no Cal1:/Cal2: echo from {state.port} within "
                f"{state.options.send_timeout_s:g} s ({seen} bytes received meanwhile): check "
                "that the board runs a sketch that accepts MotionCal packets")
        bad = echo_matches(packet, *echo)
        if bad:
            raise CalibrationError(
                f"{msg}; but the board echoed different values: " + "; ".join(bad[:5])
                + " -- the packet may have been garbled; send it again")
        cal1, cal2 = echo
        lost = ("" if not losses else " -- not in the packet: " + "; ".join(losses))
        return {"message": f"{msg}; sent {len(packet)}-byte MotionCal packet to {state.port}; "
                           f"the board confirmed it{lost} (Cal1: "
                           + ", ".join(f"{v:.4f}" for v in cal1) + "; Cal2: "
                           + ", ".join(f"{v:.4f}" for v in cal2) + ")",
                "path": str(cal_path)}

    return _run(state, "send", go)


def reset(state: LiveState) -> dict[str, Any]:
    """Reset: forget the live poses, buffer and fits (the session file keeps every row)."""
    return _run(state, "reset", lambda: {k: v for k, v in state.reset().items()
                                         if k not in ("action", "ok")})
