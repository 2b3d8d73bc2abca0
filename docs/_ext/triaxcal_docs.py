"""The parts of the triaxcal documentation that are generated at build time.

* **API reference**: one page per pipeline stage (``reference/api/<stage>.rst``) with an
  autosummary table of every name of ``triaxcal.__all__`` that the stage's package lists in its
  own ``__all__``; autosummary then writes one page per name. A public name that no stage claims
  is a build warning (an error under ``-W``), so a name added anywhere gets its page or fails
  the build.
* **Command-line reference**: one page per command of ``triaxcal.cli.build_parser()``
  (``reference/cli/<command>.rst``): the usage line, the description, every option with its
  help, default and choices, and the old spellings a command still accepts. Help texts are
  written in reST (the terminal shows them as plain text), so here their roles link to the API.
* **Benchmarks**: the results table the benchmarks write (``docs/benchmarks/results.md``), when
  present, at the top of the benchmarks page.
* **Offline check**: after the build, no page may load a script, stylesheet or font from the
  network.

The generated folders are not kept in git; ``make docs`` writes them again on every build.
"""

from __future__ import annotations

import argparse
import importlib
import re
import textwrap
from pathlib import Path
from typing import Any

from sphinx.application import Sphinx
from sphinx.util import logging

logger = logging.getLogger(__name__)

#: The pipeline stages, in order: (package, title, what the stage does).
STAGES: list[tuple[str, str, str]] = [
    ("io", "Reading data",
     "Tables of numbers, flight logs (PX4 ULog, ArduPilot DataFlash, ROS bags) and their "
     "streams: everything that brings readings in."),
    ("detect", "Still poses",
     "Finding the moments the board was held still, and the pose settings the command line "
     "shares with the library."),
    ("fit", "Fits",
     "The ellipsoid and sphere fits of the Rust core, model choice and outlier rejection."),
    ("methods", "Calibration methods",
     "Gyroscope bias and gains, multi-position IMU calibration, tilt rig, six-position, "
     "Ferraris, temperature, the magnetometer in its surroundings, yaw-only, noise and Allan "
     "deviation, bootstrap intervals, free-living auto-calibration."),
    ("calibration", "Calibrations and the validity gate",
     "The calibration file and its parts, the typed fit requests, the validity gate every "
     "writer and exporter calls, and comparisons between calibrations."),
    ("report", "Quality report", "Numbers, warnings, tables and figures of a calibration."),
    ("export", "Exports",
     "Every target a calibration is written for: C headers, MotionCal, JavaScript, ArduPilot, "
     "PX4, Kalibr, Adafruit."),
    ("errors", "Errors",
     "Every error is a :class:`triaxcal.CalibrationError`, a :class:`ValueError` that says "
     "what was wrong and what to do."),
]

#: Names of ``triaxcal.__all__`` documented as modules (with their own members).
MODULES = {"sim": "triaxcal.sim", "rotations": "triaxcal.conventions.rotations"}


def _write(path: Path, text: str) -> None:
    """Write only when the text changed, so that an unchanged page is not read again."""
    path.parent.mkdir(parents=True, exist_ok=True)
    if not path.exists() or path.read_text(encoding="utf-8") != text:
        path.write_text(text, encoding="utf-8")


def _heading(text: str, char: str = "=") -> str:
    return f"{text}\n{char * len(text)}\n"


def stage_names() -> tuple[dict[str, list[str]], list[str]]:
    """The public names per stage, in ``triaxcal.__all__``'s order, and the names no stage
    claims."""
    import triaxcal

    public = [n for n in triaxcal.__all__ if n not in MODULES and n != "__version__"]
    claimed: dict[str, list[str]] = {}
    taken: set[str] = set()
    for pkg, _, _ in STAGES:
        mod = importlib.import_module(f"triaxcal.{pkg}")
        listed = set(getattr(mod, "__all__", ()))
        names = [n for n in public if n in listed and n not in taken]
        if not names:  # a stage whose names triaxcal re-exports under its own list
            names = [n for n in public if n not in taken
                     and getattr(getattr(triaxcal, n), "__module__", "").startswith(
                         f"triaxcal.{pkg}.")]
        claimed[pkg] = names
        taken.update(names)
    return claimed, [n for n in public if n not in taken]


def write_api_pages(app: Sphinx) -> None:
    out = Path(app.srcdir) / "reference" / "api"
    claimed, orphans = stage_names()
    for name in orphans:
        logger.warning("triaxcal.%s is public (triaxcal.__all__) but no pipeline stage lists it "
                       "in its __all__: it has no API page", name, type="triaxcal", subtype="api")
    toc = []
    for pkg, title, what in STAGES:
        names = claimed[pkg]
        if not names:
            continue
        toc.append(pkg)
        body = [
            f".. _api-{pkg}:\n",
            _heading(title),
            f"{what}\n",
            f"The names below are importable from ``triaxcal`` (they live in "
            f":mod:`triaxcal.{pkg}`).\n",
            ".. currentmodule:: triaxcal\n",
            ".. autosummary::\n   :toctree: generated/\n   :nosignatures:\n",
        ]
        body += [f"   {n}" for n in names]
        _write(out / f"{pkg}.rst", "\n".join(body) + "\n")
    # the modules: the simulator and the mounting rotations
    body = [".. _api-sim:\n", _heading("Simulator and conventions"),
            "The simulator (:mod:`triaxcal.sim`) makes readings of known truth: a simulated IMU, "
            "the scripts a person would follow, noise of known size, and a serial device on a "
            "pseudo-terminal. :mod:`triaxcal.conventions.rotations` (``triaxcal.rotations``) "
            "holds the 24 right-angle mountings as ArduPilot and PX4 number them.\n",
            ".. currentmodule:: triaxcal.sim\n",
            ".. autosummary::\n   :toctree: generated/\n   :nosignatures:\n"]
    import triaxcal.sim as sim

    body += [f"   {n}" for n in sim.__all__]
    body += ["", ".. automodule:: triaxcal.conventions.rotations", "   :members:"]
    _write(out / "sim.rst", "\n".join(body) + "\n")
    toc.append("sim")
    index = [".. _api:\n", _heading("API reference"),
             "Every public name of triaxcal (``triaxcal.__all__``), grouped by the stage of the "
             "pipeline it belongs to, in the order a reading travels: read, find still poses, "
             "fit, apply a method, keep a calibration, report, export. ``import triaxcal as "
             "tc`` gives them all (``tc.fit_ellipsoid``, ``tc.Calibration``, ...). "
             "``triaxcal.__version__`` is the version of the package and its compiled core.\n",
             ".. toctree::\n   :maxdepth: 1\n"]
    index += [f"   {p}" for p in toc]
    _write(out / "index.rst", "\n".join(index) + "\n")


# -- the command line --------------------------------------------------------------------------

def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _help_of(parser: argparse.ArgumentParser, name: str) -> str:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for choice in action._choices_actions:
                if choice.dest == name:
                    return choice.help or ""
    return ""


_LITERAL_SPAN = re.compile(r"(``.+?``)", re.S)


def _escape_bars(text: str) -> str:
    """``|x|`` (an absolute value in a help text) is a substitution in reST: escape the bars
    outside literals."""
    parts = _LITERAL_SPAN.split(text)
    return "".join(p if i % 2 else p.replace("|", "\\|") for i, p in enumerate(parts))


def _expand(action: argparse.Action, parser: argparse.ArgumentParser) -> str:
    """The help text with ``%(default)s`` and friends filled in, as argparse does, but kept in
    reST (not the terminal's plain text)."""
    text = action.help or ""
    params: dict[str, Any] = dict(vars(action), prog=parser.prog)
    for key in list(params):
        if params[key] is argparse.SUPPRESS:
            del params[key]
    for key in list(params):
        if hasattr(params[key], "__name__"):
            params[key] = params[key].__name__
    if params.get("choices") is not None:
        params["choices"] = ", ".join(str(c) for c in params["choices"])
    try:
        text = text % params
    except (KeyError, TypeError, ValueError):
        pass
    return _escape_bars(text)


def _invocation(action: argparse.Action) -> str:
    if not action.option_strings:
        return action.metavar or action.dest
    if action.nargs == 0:
        return ", ".join(action.option_strings)
    metavar = action.metavar
    if metavar is None:
        metavar = action.dest.upper() if action.choices is None else \
            "{" + ",".join(str(c) for c in action.choices) + "}"
    if isinstance(metavar, tuple):
        metavar = " ".join(metavar)
    if action.nargs in ("*", "+"):
        metavar = f"{metavar} [...]"
    elif action.nargs == "?":
        metavar = f"[{metavar}]"
    return ", ".join(f"{o} {metavar}" for o in action.option_strings)


def _is_renamed(action: argparse.Action) -> bool:
    return type(action).__name__ == "_Renamed"


def _literal(value: Any) -> str:
    text = str(value)
    return f"``{text}``" if text and "`" not in text else repr(text)


def command_page(name: str, parser: argparse.ArgumentParser, summary: str) -> str:
    lines = [f".. _cli-{name}:\n", _heading(f"triaxcal {name}")]
    if summary:
        lines.append(f"{summary.strip()}\n")
    usage = parser.format_usage().strip()
    usage = re.sub(r"^usage:\s*", "", usage)
    formatter = argparse.HelpFormatter(parser.prog, width=88)
    formatter.add_usage(parser.usage, parser._actions, parser._mutually_exclusive_groups,
                        prefix="")
    usage = formatter.format_help().strip()
    lines += [".. code-block:: text\n", textwrap.indent(usage, "   ") + "\n"]
    if parser.description:
        text = _escape_bars(textwrap.dedent(parser.description).strip())
        # the terminal's "examples:" paragraph of indented command lines: a literal block here
        text = re.sub(r"(?m)^examples:\n(?=  )", "Examples::\n\n", text)
        lines.append(text + "\n")
    renamed: list[tuple[str, str]] = []
    for group in parser._action_groups:
        actions = [a for a in group._group_actions
                   if not isinstance(a, argparse._HelpAction)]
        shown = []
        for a in actions:
            if _is_renamed(a):
                renamed.append((", ".join(a.option_strings), getattr(a, "new", "")))
            elif a.help is not argparse.SUPPRESS:
                shown.append(a)
        if not shown:
            continue
        title = group.title or "options"
        title = {"positional arguments": "Arguments", "options": "Options",
                 "optional arguments": "Options"}.get(title, title[:1].upper() + title[1:])
        lines.append(_heading(title, "-"))
        if group.description:
            lines.append(textwrap.dedent(group.description).strip() + "\n")
        for a in shown:
            lines.append(f"``{_invocation(a)}``")
            body = _expand(a, parser).strip() or "(no description)"
            extra = []
            if a.choices is not None and "%(choices)" not in (a.help or ""):
                extra.append("Choices: " + ", ".join(_literal(c) for c in a.choices) + ".")
            default = a.default
            if (a.option_strings and a.nargs != 0 and default not in (None, [], "")
                    and default is not argparse.SUPPRESS
                    and "default" not in (a.help or "").lower()):
                extra.append(f"Default: {_literal(default)}.")
            if a.required and a.option_strings:
                extra.append("Required.")
            text = body + ("\n\n" + " ".join(extra) if extra else "")
            lines.append(textwrap.indent(text, "   ") + "\n")
    if renamed:
        lines.append(_heading("Old spellings", "-"))
        lines.append("Accepted for one release; each says on standard error what it is called "
                     "now.\n")
        for old, new in renamed:
            lines.append(f"* ``{old}``: now ``{new}``" if new else f"* ``{old}``")
        lines.append("")
    return "\n".join(lines) + "\n"


def write_cli_pages(app: Sphinx) -> None:
    from triaxcal.cli import build_parser

    out = Path(app.srcdir) / "reference" / "cli"
    parser = build_parser()
    commands = _subparsers(parser)
    for name, sub in commands.items():
        _write(out / f"{name}.rst", command_page(name, sub, _help_of(parser, name)))
    for old in out.glob("*.rst"):  # a command that went away
        if old.stem not in commands and old.stem != "index":
            old.unlink()
    rows = [f"   * - :ref:`triaxcal {n} <cli-{n}>`\n     - {_help_of(parser, n).strip()}"
            for n in commands]
    index = [".. _cli:\n", _heading("Command-line reference"),
             "Generated from the command line's own parser (``triaxcal.cli.build_parser()``), so "
             "it lists exactly what ``triaxcal COMMAND --help`` does. Every command takes "
             "``-h``/``--help``; ``triaxcal --version`` prints the version.\n",
             "Exit status: ``0`` done; ``1`` an error, with a message saying what was wrong and "
             "what to do (never a traceback); ``2`` a usage error, or a calibration the validity "
             "gate refused (nothing was written; see :doc:`/guide/trust`); ``130`` interrupted "
             "with Ctrl-C (what was captured is saved).\n",
             ".. list-table::\n   :header-rows: 1\n   :widths: 25 75\n",
             "   * - command\n     - what it does"]
    index += rows
    index += ["", ".. toctree::\n   :hidden:\n"] + [f"   {n}" for n in commands]
    _write(out / "index.rst", "\n".join(index) + "\n")


# -- the gallery's order ------------------------------------------------------------------------

#: The gallery in the order of the pipeline: fit, report, gate, the methods, noise, export.
#: Examples not listed follow, by file name.
GALLERY_ORDER = [
    "plot_fit_tumble.py", "plot_report_figure.py", "plot_validity_gate.py",
    "plot_sphere_centre_descent.py", "plot_tilt_rig.py", "plot_gyro_turns.py",
    "plot_temperature_drift.py", "plot_turntable.py", "plot_imu_tedaldi.py",
    "plot_yaw_only.py", "plot_allan_deviation.py", "plot_export_c_header.py",
]


class GalleryOrder:
    """sphinx-gallery's ``within_subsection_order``: :data:`GALLERY_ORDER`, then by name."""

    def __init__(self, src_dir: str) -> None:
        self.src_dir = src_dir

    def __call__(self, filename: str) -> tuple[int, str]:
        name = Path(filename).name
        rank = GALLERY_ORDER.index(name) if name in GALLERY_ORDER else len(GALLERY_ORDER)
        return rank, name

    def __repr__(self) -> str:
        return "GalleryOrder"


# -- benchmarks -------------------------------------------------------------------------------

def write_benchmark_results(app: Sphinx) -> None:
    """``benchmarks/_results.inc``, included by the benchmarks page: the table the benchmarks
    write into ``docs/benchmarks/results.md`` when they run (its headings one level down), or
    nothing when they have not run in this checkout."""
    src = Path(app.srcdir) / "benchmarks" / "results.md"
    text = ""
    if src.is_file():
        body = re.sub(r"^(#{1,5}) ", r"#\1 ", src.read_text(encoding="utf-8"), flags=re.M)
        text = "## Latest results (`make bench`)\n\n" + body.strip() + "\n"
    _write(Path(app.srcdir) / "benchmarks" / "_results.inc", text)


def generate(app: Sphinx, config: Any = None) -> None:
    write_api_pages(app)
    write_cli_pages(app)
    write_benchmark_results(app)


# -- offline ------------------------------------------------------------------------------------

_REMOTE = re.compile(
    r"""<(?:script|link|img|iframe|source)\b[^>]*?\b(?:src|href)\s*=\s*["']((?:https?:)?//[^"']+)""",
    re.I)
_CSS_REMOTE = re.compile(r"""(?:@import|url\()\s*["']?((?:https?:)?//[^"')]+)""", re.I)


def remote_assets(outdir: Path, pages: list[Path] | None = None) -> list[tuple[str, str]]:
    """(file, URL) of every script, stylesheet, font, image or frame a built page (all of
    ``outdir``'s, or ``pages``) or stylesheet would load from the network (links to other sites
    are fine: they are not loaded)."""
    found = []
    for page in sorted(outdir.rglob("*.html") if pages is None else pages):
        for url in _REMOTE.findall(page.read_text(encoding="utf-8", errors="replace")):
            tag = page.read_text(encoding="utf-8", errors="replace")
            # <link rel="..."> to a page (not a stylesheet or icon) is a link, not an asset
            m = re.search(r"<link\b[^>]*" + re.escape(url) + r"[^>]*>", tag)
            if m and not re.search(r"rel=[\"'](?:stylesheet|icon|preload|modulepreload)",
                                   m.group(0)):
                continue
            found.append((str(page.relative_to(outdir)), url))
    for css in sorted(outdir.rglob("*.css")):
        for url in _CSS_REMOTE.findall(css.read_text(encoding="utf-8", errors="replace")):
            found.append((str(css.relative_to(outdir)), url))
    return found


def check_offline(app: Sphinx, exception: Exception | None) -> None:
    if exception is not None or app.builder.format != "html":
        return
    outdir = Path(app.outdir)
    pages = [outdir / app.builder.get_target_uri(doc) for doc in sorted(app.env.found_docs)]
    for page, url in remote_assets(outdir, [p for p in pages if p.is_file()]):
        logger.warning("%s loads %s from the network: the pages must open offline", page, url,
                       type="triaxcal", subtype="offline")


def setup(app: Sphinx) -> dict[str, Any]:
    app.connect("config-inited", generate)  # before the sources are listed
    app.connect("build-finished", check_offline)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
