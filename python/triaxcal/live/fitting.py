"""The fits the live page runs on the saved session, as ``triaxcal fit`` runs them: the command
arguments that carry the page's options (:func:`fit_argv`), the rows to fit after a Reset
(:func:`session_to_fit`), and the fit itself (:func:`fit_session`).

These need only what :class:`FitSource` names (a :class:`~triaxcal.live.state.LiveState` has
it all), so the page's state can call them without this module knowing the state.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from ..errors import CalibrationError

if TYPE_CHECKING:
    from ..calibration.session import FitOutcome
    from ..detect.session import PoseSettings
    from .options import LiveOptions

__all__ = ["FitSource", "fit_argv", "fit_session", "pose_argv", "session_to_fit"]


class FitSource(Protocol):
    """What the fits of the saved session need to know of the live page."""

    session: Path
    out_dir: Path
    cols: Any
    options: LiveOptions
    detection: PoseSettings
    existing_rows: int
    reset_row: int
    resets: int
    last_fit_errors: list[str]


def pose_argv(settings: PoseSettings) -> list[str]:
    """The pose options (``--window``, ``--accel-threshold``...) that describe ``settings``,
    those that differ from the defaults (the inverse of the CLI's ``settings_from_args``)."""
    from ..detect.options import default_settings

    d = default_settings()
    out: list[str] = []
    if settings.window != d.window:
        out += ["--window", str(settings.window)]
    if settings.accel_threshold_g != d.accel_threshold_g:
        out += ["--accel-threshold", repr(float(settings.accel_threshold_g))]
    if settings.counts_per_g is not None:
        out += ["--counts-per-g", repr(float(settings.counts_per_g))]
    for name, use, thr in (("gyro", settings.use_gyro, settings.gyro_threshold),
                           ("mag", settings.use_mag, settings.mag_threshold)):
        text = "off" if not use else "auto" if thr is None else repr(float(thr))
        if text != "auto":
            out += [f"--{name}-threshold", text]
    if settings.hold_windows != d.hold_windows:
        out += ["--hold", "off" if settings.hold_windows is None else str(settings.hold_windows)]
    if settings.holdoff_s != d.holdoff_s:
        out += ["--holdoff", repr(float(settings.holdoff_s))]
    if settings.rate_hz is not None:
        out += ["--rate-hz", repr(float(settings.rate_hz))]
    return out


def fit_argv(state: FitSource, sensor: str, session: str, output: str, *, new: bool) -> list[str]:
    """The ``triaxcal fit`` arguments (without ``triaxcal``) that fit ``sensor`` of
    ``session`` with the live page's options."""
    o = state.options
    argv = ["fit", session, "--sensor", sensor]
    if o.model != "auto":
        argv += ["--model", o.model]
    if o.sigma != 2.0:
        argv += ["--sigma", repr(float(o.sigma))]
    if o.rounds != 10:
        argv += ["--rounds", str(o.rounds)]
    if sensor == "accel":
        argv += ["--poses", *pose_argv(state.detection), "--radius", o.accel_radius]
    elif o.mag_radius is not None:
        argv += ["--radius", o.mag_radius]
    argv += ["-o", output]
    if new:
        argv.append("--new")
    return argv


def session_to_fit(state: FitSource) -> Path:
    """The session file, or after a Reset a copy of the rows captured since."""
    skip = state.existing_rows + state.reset_row
    if state.reset_row == 0:
        return state.session
    out = state.session.with_name(f"{state.session.stem}.after-reset-{state.resets}.csv")
    with open(state.session, encoding="ascii", errors="replace") as src, \
            open(out, "w", encoding="ascii", newline="") as dst:
        dst.write(src.readline())
        for i, line in enumerate(src):
            if i >= skip:
                dst.write(line if line.endswith("\n") else line + "\n")
    return out


def fit_session(state: FitSource, output: str | None = None) -> dict[str, FitOutcome]:
    """Fit every sensor of the session as ``triaxcal fit`` does; ``{sensor: FitOutcome}``.

    Raises :class:`CalibrationError` when no sensor could be fitted (the messages of each)."""
    from ..calibration.session import fit_file
    from ..cli import build_parser

    if not state.session.exists():
        raise CalibrationError(f"the session {state.session} does not exist yet: wait for data")
    data = str(session_to_fit(state))
    out = output or str(state.out_dir / "calibration.json")
    parser = build_parser()
    outcomes: dict[str, FitOutcome] = {}
    errors: list[str] = []
    for sensor in ("accel", "mag"):
        if sensor not in state.cols:
            continue
        args = parser.parse_args(fit_argv(state, sensor, data, out, new=not outcomes))
        try:
            outcomes[sensor] = fit_file(args)
        except CalibrationError as exc:
            errors.append(f"{sensor}: {exc}")
    if not outcomes:
        raise CalibrationError("; ".join(errors) or "no sensor to fit in this session")
    state.last_fit_errors = errors
    return outcomes
