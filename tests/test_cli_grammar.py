"""One grammar for every command: ``-o/--output FILE``, ``--out-dir DIR``, ``--rate-hz``,
``--topic`` for inputs, ``--format`` for what is printed; the old spellings still work for one
release and say so; nothing below the command line imports it."""

from __future__ import annotations

import argparse
import ast
from pathlib import Path

import pytest
from triaxcal.cli import build_parser, main

PACKAGE = Path(__file__).resolve().parent.parent / "python" / "triaxcal"


def _commands() -> dict[str, argparse.ArgumentParser]:
    p = build_parser()
    sub = next(a for a in p._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


def _visible(parser: argparse.ArgumentParser) -> dict[str, argparse.Action]:
    return {s: a for a in parser._actions if a.help != argparse.SUPPRESS
            for s in a.option_strings}


# (command, argv with the old spelling, argv with the new, the namespace field they set)
RENAMED = [
    ("capture", ["--out", "s.csv"], ["-o", "s.csv"], "output"),
    ("capture", ["--poll-hz", "50"], ["--rate-hz", "50"], "rate_hz"),
    ("capture", ["--units-per-g", "8192"], ["--counts-per-g", "8192"], "counts_per_g"),
    ("demo", ["--out", "d"], ["--out-dir", "d"], "out_dir"),
    ("report", ["--json", "r.json"], ["-o", "r.json"], "json_out"),
    ("batch", ["-o", "o"], ["--out-dir", "o"], "out_dir"),
    ("batch", ["--output", "o"], ["--out-dir", "o"], "out_dir"),
    ("diff", ["--json"], ["--format", "json"], "format"),
    ("gyro-gains", ["--nominal", "16.4"], ["--counts-per-unit", "16.4"], "counts_per_unit"),
]

BASE = {"capture": ["--port", "p", "--protocol", "framed"], "demo": [], "report": ["x.csv"],
        "batch": ["sessions"], "diff": ["a.json"], "gyro-gains": ["s.csv", "-o", "c.json"]}


@pytest.mark.parametrize(("command", "old", "new", "field"), RENAMED)
def test_old_spellings_still_work_and_say_so(command, old, new, field, capsys):
    parser = build_parser()
    want = getattr(parser.parse_args([command, *BASE[command], *new]), field)
    assert capsys.readouterr().err == ""
    got = getattr(parser.parse_args([command, *BASE[command], *old]), field)
    assert got == want
    err = capsys.readouterr().err
    assert f"{old[0]} is now " in err and "next release" in err
    assert "/".join(new[:1]) in err.split(" is now ")[1]
    # the old spelling is not shown in the help any more
    assert old[0] not in _visible(_commands()[command])


def test_a_required_option_is_satisfied_by_either_spelling(tmp_path, capsys):
    (tmp_path / "s").mkdir()
    assert main(["batch", str(tmp_path / "s"), "-o", str(tmp_path / "o"), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert "-o is now --out-dir" in err and "no session files" in err
    with pytest.raises(SystemExit):
        main(["batch", str(tmp_path / "s")])
    assert "required: --out-dir" in capsys.readouterr().err


def test_the_grammar_of_every_command():
    commands = _commands()
    assert {"ferraris", "imu", "turntable"} <= set(commands)
    for name, parser in commands.items():
        opts = _visible(parser)
        # a file to write is -o/--output, a folder --out-dir; no other spelling
        assert "--out" not in opts and "--json" not in opts, name
        if "-o" in opts or "--output" in opts:
            assert opts["-o"] is opts["--output"], name
            assert "DIR" not in (opts["-o"].metavar or ""), name
        # a sample rate is --rate-hz (noise's is its own developer's to rename); --topic is an
        # input topic (the Kalibr export's output topic is --ros-topic)
        if name != "noise":
            assert "--rate" not in opts and "--poll-hz" not in opts, name
        assert "--topic" not in opts or "NAME" == opts["--topic"].metavar, name
    # the commands that write a calibration name it CAL.json
    for name in ("fit", "sphere-center", "tilt-rig", "gyro-gains", "temperature", "ferraris",
                 "imu", "turntable"):
        assert _visible(commands[name])["-o"].metavar == "CAL.json", name
    assert _visible(commands["batch"])["--out-dir"].metavar == "DIR"
    assert _visible(commands["capture"])["--out-dir"].metavar == "DIR"


def test_nothing_below_the_command_line_imports_it():
    offenders = []
    for path in PACKAGE.rglob("*.py"):
        rel = path.relative_to(PACKAGE)
        if rel.parts[0] == "cli":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                mod = node.module or ""
                names = [("." * node.level) + mod]
            for n in names:
                if n == "argparse" or n.startswith("argparse.") or "cli" in n.split(".")[-2:] \
                        and (n.startswith(".") or n.startswith("triaxcal")):
                    offenders.append(f"{rel}: {n}")
    assert offenders == []
    # and the root holds at most six modules
    assert len([p for p in PACKAGE.glob("*.py")]) <= 6
