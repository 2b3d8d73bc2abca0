"""The fits the live page runs on the saved session, as ``triaxcal fit`` runs them: the
:class:`~triaxcal.calibration.request.FitRequest` of each sensor built from the page's options
(:func:`fit_request`), the equivalent command line shown on the page (:func:`fit_argv`), the
rows to fit after a Reset (:func:`session_to_fit`), and the fit itself
(:func:`fit_saved_session`).

These need only what :class:`FitSource` names (a :class:`~triaxcal.live.state.LiveState` has
it all), so the page's state can call them without this module knowing the state.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from ..calibration.request import FitRequest, SourceOptions
from ..detect.session import PoseSettings
from ..errors import CalibrationError

if TYPE_CHECKING:
    from ..calibration.session import FitOutcome
    from .options import LiveOptions

__all__ = ["FitSource", "fit_argv", "fit_request", "fit_saved_session", "pose_argv",
           "session_to_fit"]


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


def fit_request(state: FitSource, sensor: str) -> FitRequest:
    """The request Save fits ``sensor`` with: the accelerometer's still poses to the page's
    accelerometer radius, the magnetometer on every row (to its radius, or its own scale)."""
    o = state.options
    common: dict[str, Any] = {"model": o.model, "outliers": o.outliers, "sigma": o.sigma,
                              "rounds": o.rounds}
    if sensor == "accel":
        return FitRequest(sensor="accel", radius=o.accel_radius, **common,
                          source=SourceOptions(poses=True, detection=state.detection))
    return FitRequest(sensor=sensor, radius=o.mag_radius, **common)


def pose_argv(settings: PoseSettings) -> list[str]:
    """The pose options (``--window``, ``--accel-threshold``...) that describe ``settings``,
    those that differ from the defaults."""
    d = PoseSettings()
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


def fit_argv(request: FitRequest, session: str, output: str, *, new: bool) -> list[str]:
    """The ``triaxcal fit`` arguments (without ``triaxcal``) that make the same fit as
    ``request`` -- shown on the page, so that a user can repeat Save from a terminal."""
    d = FitRequest()
    argv = ["fit", session, "--sensor", request.sensor]
    if request.model != d.model:
        argv += ["--model", request.model]
    if request.outliers != d.outliers:
        argv += ["--outliers", request.outliers]
    if request.sigma != d.sigma:
        argv += ["--sigma", repr(float(request.sigma))]
    if request.rounds != d.rounds:
        argv += ["--rounds", str(request.rounds)]
    if request.source.poses:
        argv += ["--poses", *pose_argv(request.source.detection)]
    if request.radius is not None:
        argv += ["--radius", str(request.radius)]
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


def fit_saved_session(state: FitSource) -> dict[str, FitOutcome]:
    """Fit every sensor of the session as ``triaxcal fit`` does; ``{sensor: FitOutcome}``.

    Raises :class:`CalibrationError` when no sensor could be fitted (the messages of each)."""
    from ..calibration.session import fit_session

    if not state.session.exists():
        raise CalibrationError(f"the session {state.session} does not exist yet: wait for data")
    data = session_to_fit(state)
    outcomes: dict[str, FitOutcome] = {}
    errors: list[str] = []
    for sensor in ("accel", "mag"):
        if sensor not in state.cols:
            continue
        try:
            outcomes[sensor] = fit_session(data, fit_request(state, sensor))
        except CalibrationError as exc:
            errors.append(f"{sensor}: {exc}")
    if not outcomes:
        raise CalibrationError("; ".join(errors) or "no sensor to fit in this session")
    state.last_fit_errors = errors
    return outcomes
