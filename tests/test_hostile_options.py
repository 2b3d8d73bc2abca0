"""Hostile values for every option of every command: each option that takes a value, taken from
the command's own parser, set in turn to 0, -1, 1e308, -1e308, 1e-308, the smallest denormal,
nan, inf, -inf, an integer past a double, an empty text and a unicode digit, on a command line
that is otherwise valid (it exits 0 as given).

Every run must end with exit status 0, 1 or 2 (``diff``: 3 or 4) and a message: never an
exception out of ``main`` (a traceback for the user), a hang, raw control characters, or a
file written that holds NaN or infinity or that the command refused (the runner is
_hostile_cli.run). The options that name files (``-o``, ``--data``, ``--cal``...) are left to
test_hostile_cli.py and test_hostile_io.py.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from _hostile_cli import SCALE, calibration, nonfinite_tokens, run, session
from triaxcal.cli import build_parser

#: What each value-taking option is set to.
VALUES = {
    "0": "0", "-1": "-1", "1e308": "1e308", "-1e308": "-1e308", "1e-308": "1e-308",
    "5e-324": "5e-324", "nan": "nan", "inf": "inf", "-inf": "-inf", "huge-int": "9" * 40,
    "empty": "", "arabic-3": "\u0663",
}

#: Options that name a file, a folder, a port or a host: their hostile values are files.
FILE_OPTIONS = {"-o", "--out", "--out-dir", "--output", "--port", "--plot", "--json", "--data",
                "--cal", "--noise", "--limits", "--http-host", "--prefix", "--bias",
                "--sections", "--start"}


def _subparser(path: tuple[str, ...]) -> argparse.ArgumentParser:
    p = build_parser()
    for name in path:
        sub = next(a for a in p._actions if isinstance(a, argparse._SubParsersAction))
        p = sub.choices[name]
    return p


def _options(path: tuple[str, ...]) -> list[str]:
    """The command's options that take a value (not its files)."""
    return [a.option_strings[0] for a in _subparser(path)._actions
            if a.option_strings and a.nargs != 0 and not isinstance(a, argparse._HelpAction)
            and a.option_strings[0] not in FILE_OPTIONS]


def _with(argv: list[str], option: str, value: str) -> list[str]:
    """``argv`` with ``option`` set to ``value`` (replacing its value when given)."""
    out = list(argv)
    if option in out:
        out[out.index(option) + 1] = value
        return out
    return [*out, option, value]


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("options")
    data = session(folder)
    cal = calibration(folder, data)
    rest = folder / "rest.csv"  # a gyroscope at rest with a warming die, for noise/temperature
    rng = np.random.default_rng(3)
    n = 2000
    temp = np.linspace(20.0, 35.0, n)
    g = rng.normal(0, 2.0, (n, 3)) + [30, -12, 5] + np.outer(temp - 20, [1.5, -1.0, 0.5])
    np.savetxt(rest, np.column_stack([np.arange(n) / 50.0, g, temp]), delimiter=",",
               header="t,gx,gy,gz,temp_c", comments="", fmt="%.6f")
    return folder, data, cal, rest


def _real_commands(realdata: Path, out: Path) -> dict[str, tuple[tuple[str, ...], list[str]]]:
    """The method commands on the published recordings (as test_method_commands.py runs
    them), and the commands that open a serial port (none here: exit 1 after the options)."""
    x, g = realdata / "imutk-xsens", realdata / "freeimucal-gearvr"
    return {
        "turntable": (("turntable",), [
            "turntable", str(g / "33RPMgyr.txt"), str(g / "45RPMgyr.txt"), "--rpm", "100/3",
            "--rpm", "45", "--bias", str(g / "0RPMgyr.txt"), "--rate-hz", "100", "--rest", "10",
            "--raw-unit", "rad/s", "-o", f"{out}.tt.json"]),
        "ferraris": (("ferraris",), [
            "ferraris", str(realdata / "imucal-ferraris" / "annotated_session.csv"),
            "--rate-hz", "204.8", "-o", f"{out}.fer.json"]),
        "imu": (("imu",), [
            "imu", str(x / "xsens_acc.mat"), str(x / "xsens_gyro.mat"), "--time-column", "0",
            "--accel-columns", "1,2,3", "--gyro-columns", "1,2,3", "--rate-hz", "100",
            "--gravity", "9.81744", "-o", f"{out}.imu.json"]),
        "board-read": (("board", "read"), ["board", "read", "--port", str(out.parent / "none"),
                                           "-o", f"{out}.board.json"]),
        "capture": (("capture",), ["capture", "--port", str(out.parent / "none"), "--protocol",
                                   "framed", "-o", f"{out}.csv"]),
    }


#: Method commands of 0.9 to 5 s a run (ferraris, imu) and capture (which waits 1 s for its
#: port): in the slow run only.
REAL_FAST = ["turntable", "board-read"]
REAL_SLOW = ["ferraris", "imu", "capture"]


def _commands(files, out: Path) -> dict[str, tuple[tuple[str, ...], list[str]]]:
    """Command -> (its parser's path, a valid command line)."""
    folder, data, cal, rest = files
    d, c = str(data), str(cal)
    return {
        "fit": (("fit",), ["fit", d, "--sensor", "accel", "--poses", "--model", "axis",
                           "--radius", "1g", "-o", f"{out}.json", "--new"]),
        "fit-mag": (("fit",), ["fit", d, "--sensor", "mag", "--model", "axis", "--radius",
                               "48uT", "-o", f"{out}.mag.json", "--new"]),
        "report": (("report",), ["report", c, "--data", d, "--sensor", "accel"]),
        "export-kalibr": (("export",), ["export", c, "--format", "kalibr", "-o", f"{out}.yaml",
                                        "--counts-per-unit", SCALE, "--rate-hz", "200",
                                        "--kalibr-model", "calibrated"]),
        "export-ardupilot": (("export",), ["export", c, "--format", "ardupilot", "-o",
                                           f"{out}.parm", "--counts-per-unit", SCALE,
                                           "--instance", "1"]),
        "diff": (("diff",), ["diff", c, c]),
        "send": (("send",), ["send", c, "--port", str(folder / "no-port"), "--timeout", "0.1",
                             "--counts-per-unit", SCALE, "--offsets-only"]),
        "board-write": (("board", "write"), ["board", "write", c, "--port",
                                             str(folder / "no-port"), "--timeout", "0.1",
                                             "--counts-per-g", "16384"]),
        "sphere-center": (("sphere-center",), ["sphere-center", d, "--sensor", "accel",
                                               "--radius", "16384", "-o", f"{out}.sc.json"]),
        "noise": (("noise",), ["noise", str(rest), "--sensor", "gyro", "--unit", "counts",
                               "-o", f"{out}.noise.json", "--format", "json"]),
        "temperature": (("temperature",), ["temperature", str(rest), "--sensor", "gyro",
                                           "--temp-column", "temp_c", "--degree", "1",
                                           "--all-rows", "-o", f"{out}.t.json"]),
    }


#: Commands that refit a session on every run (0.1 to 0.3 s each): a share of the values by
#: default, every value in the slow run.
HEAVY = {"fit", "fit-mag", "report", "sphere-center"}
_SHARE = ("1e308", "5e-324", "nan", "huge-int")

_NAMES = ["fit", "fit-mag", "report", "export-kalibr", "export-ardupilot", "diff", "send",
          "board-write", "sphere-center", "noise", "temperature"]


def _yaml_values(node: object) -> list[object]:
    if isinstance(node, dict):
        return [v for x in node.values() for v in _yaml_values(x)]
    if isinstance(node, list):
        return [v for x in node for v in _yaml_values(x)]
    return [node]


def _refuse(token: str) -> float:
    raise ValueError(f"{token} written as a number")


#: Commands that open a serial port: no board here, so they end with exit 1 after the options.
PORTS = {"send", "board-write", "board-read", "capture"}


def _check(argv: list[str], expect: int | None = None) -> str | None:
    wrong, code, _, se = run(argv, limit_s=15.0)
    if wrong is None and expect is not None and code != expect:
        wrong = f"exit {code}, expected {expect}"
    out = Path(argv[argv.index("-o") + 1]) if "-o" in argv else None
    if wrong is None and out is not None and out.exists():
        if code not in (0,):
            wrong = f"exit {code} but {out.name} was written"
        elif out.suffix == ".json":  # NaN or Infinity as a number (a text "nan" is a label)
            try:
                json.loads(out.read_text(), parse_constant=_refuse)
            except ValueError as exc:
                wrong = f"{out.name} is not strict JSON: {exc}"
        elif out.suffix == ".yaml":  # a text such as the topic "nan" is a name, not a number
            bad = [v for v in _yaml_values(yaml.safe_load(out.read_text()))
                   if isinstance(v, float) and not math.isfinite(v)]
            if bad:
                wrong = f"{out.name} holds {bad}"
        elif out.suffix in (".parm", ".h"):
            bad = nonfinite_tokens(out.read_text(errors="replace"))
            if bad:
                wrong = f"{out.name} holds {bad}"
        out.unlink()
    return None if wrong is None else f"{wrong} | {se.strip()[-200:]}"


def _edges(name: str, files, tmp_path: Path, every: bool, realdata: Path | None = None) -> None:
    out = tmp_path / "out"
    path, argv = (_real_commands(realdata, out) if realdata else _commands(files, out))[name]
    wrong = _check(argv, expect=1 if name in PORTS else 0)
    assert wrong is None, f"the valid command line fails: {wrong}"
    options = _options(path)
    assert options, name
    failures = {}
    for option in options:
        for label, value in VALUES.items():
            if not every and name in HEAVY and label not in _SHARE:
                continue
            got = _check(_with(argv, option, value))
            if got is not None:
                failures[f"{option} {label}"] = got
    assert not failures, f"{name}: {len(failures)} failures:\n" + "\n".join(
        f"  {k}: {v}" for k, v in failures.items())


@pytest.mark.timeout(600, method="thread")
@pytest.mark.parametrize("name", _NAMES)
def test_every_option_at_its_edges(name, files, tmp_path):
    _edges(name, files, tmp_path, every=False)


@pytest.mark.slow
@pytest.mark.timeout(1800, method="thread")
@pytest.mark.parametrize("name", sorted(HEAVY))
def test_every_option_of_the_fitting_commands_at_every_edge(name, files, tmp_path):
    _edges(name, files, tmp_path, every=True)


@pytest.mark.timeout(600, method="thread")
@pytest.mark.parametrize("name", REAL_FAST)
def test_every_option_of_the_method_and_port_commands(name, realdata, tmp_path):
    _edges(name, None, tmp_path, every=True, realdata=realdata)


@pytest.mark.slow
@pytest.mark.timeout(3600, method="thread")
@pytest.mark.parametrize("name", REAL_SLOW)
def test_every_option_of_the_slow_method_and_port_commands(name, realdata, tmp_path):
    _edges(name, None, tmp_path, every=True, realdata=realdata)


def test_holdoff_near_the_edge_of_a_double_is_refused_by_name(files, tmp_path):
    """--holdoff 1e308 overflowed converting seconds to samples (OverflowError)."""
    _, data, _, _ = files
    out = tmp_path / "c.json"
    wrong, code, _, se = run(["fit", str(data), "--sensor", "accel", "--poses", "--holdoff",
                              "1e308", "-o", str(out)])
    assert wrong is None and code == 1, (wrong, code, se)
    assert "--holdoff" in se and "Traceback" not in se and not out.exists(), se


def test_a_calibration_file_with_a_huge_holdoff_is_refused(files, tmp_path):
    """holdoff_s in a file's pose settings overflowed the same way when report re-read it."""
    _, data, cal, _ = files
    doc = json.loads(Path(cal).read_text())
    doc["parts"]["accel"]["stats"]["pose_detection"]["holdoff_s"] = 1e308
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc))
    wrong, code, _, se = run(["report", str(bad), "--data", str(data)])
    assert wrong is None and code == 1, (wrong, code, se)
    assert "holdoff" in se, se

