"""Hostile input for the command line: calibration files with every field mutated (types, NaN
and infinity spelled every way, numbers past a double, denormals, huge integers, deep nesting,
duplicate and unknown keys, terminal escapes and bidi characters in every text, enormous lists)
and files that are valid JSON but describe an impossible calibration, through ``report``,
``diff``, ``export`` (every format), ``send`` and ``board write``; then every numeric option of
every command set to 0, -1, 1e308, 1e-308, nan, inf, a huge integer, an empty string and a
unicode digit.

Each command runs in this process (``triaxcal.cli.main``) under a time limit, and must end with
exit status 0, 1 or 2 (``diff``: 3 or 4 for a change) and a message: never an exception out of
``main`` (what the user sees as a traceback), a hang, raw control characters on the terminal,
or a file written that holds NaN or infinity or that the command refused. The builders and the
runner are in _hostile_cli.py.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import pytest
import triaxcal as tc
from _hostile_cli import SCALE, calibration, mutants, nonfinite_tokens, run, session


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("cli")
    data = session(folder)
    return folder, data, calibration(folder, data)


def _commands(cal: Path, base: Path, out: Path) -> dict[str, list[str]]:
    """Every command that reads a calibration file, with ``cal`` as that file."""
    c = str(cal)
    cmds = {
        "report": ["report", c],
        "diff-previous": ["diff", c],
        "diff-base": ["diff", str(base), c],
        "send": ["send", c, "--port", str(out.parent / "no-port"), "--timeout", "0.1",
                 "--counts-per-unit", SCALE, "--offsets-only"],
        "board-write": ["board", "write", c, "--port", str(out.parent / "no-port"),
                        "--timeout", "0.1", "--counts-per-g", "16384"],
    }
    for fmt in ("c", "c-fixed", "json", "js", "js-espruino"):
        cmds[f"export-{fmt}"] = ["export", c, "--format", fmt, "-o", f"{out}.{fmt}"]
    for fmt in ("ardupilot", "px4", "adafruit"):
        cmds[f"export-{fmt}"] = ["export", c, "--format", fmt, "-o", f"{out}.{fmt}",
                                 "--counts-per-unit", SCALE]
    cmds["export-px4"] += ["--device-id", "gyro=2490378"]
    cmds["export-adafruit"] += ["--sensors", "mag"]
    cmds["export-kalibr"] = ["export", c, "--format", "kalibr", "-o", f"{out}.yaml",
                             "--counts-per-unit", SCALE, "--rate-hz", "200",
                             "--kalibr-model", "calibrated"]
    cmds["export-motioncal"] = ["export", c, "--format", "motioncal", "-o", f"{out}.bin",
                                "--counts-per-unit", SCALE, "--offsets-only",
                                "--no-alignment"]
    cmds["export-forced"] = ["export", c, "--format", "c", "-o", f"{out}.forced.h", "--force"]
    return cmds


def _written(argv: list[str]) -> Path | None:
    return Path(argv[argv.index("-o") + 1]) if "-o" in argv else None


def test_the_valid_file_passes_every_command(files, tmp_path):
    folder, data, cal = files
    for name, argv in _commands(cal, cal, tmp_path / "out").items():
        wrong, code, so, se = run(argv)
        assert wrong is None, (name, wrong)
        expected = 1 if name in ("send", "board-write") else 0  # no board on the port
        assert code == expected, (name, so, se)


@pytest.mark.timeout(300, method="thread")
def test_hostile_calibration_files(files, tmp_path):
    """Every mutant loads or is refused; those that load go through every command, those that
    do not through each command once; no command lets an exception out, hangs, prints raw
    control characters or writes a file with NaN or infinity in it (or after refusing)."""
    folder, data, cal = files
    doc = json.loads(cal.read_text())
    cases = mutants(doc)
    assert len(cases) > 300
    loaded, refused, failures = [], [], {}
    t0 = time.monotonic()
    for name, text in cases.items():
        p = tmp_path / "m.json"
        p.write_text(text, encoding="utf-8", errors="surrogatepass")
        try:
            tc.Calibration.load(p)
            loaded.append(name)
        except tc.CalibrationError:
            refused.append(name)
        except Exception as exc:  # noqa: BLE001
            failures[f"{name}: load"] = f"{type(exc).__name__}: {exc}"
    # what loads meets every command; what is refused is refused by each (on the same load)
    ran = 0
    for i, name in enumerate(loaded + refused[::25]):
        p = tmp_path / f"m{i}.json"
        p.write_text(cases[name], encoding="utf-8", errors="surrogatepass")
        cmds = _commands(p, cal, tmp_path / f"o{i}")
        if name in refused:
            cmds = {k: v for k, v in cmds.items() if k in ("report", "export-c", "send")}
        for cmd, argv in cmds.items():
            wrong, code, so, se = run(argv)
            ran += 1
            out = _written(argv)
            if wrong is None and out is not None and out.exists():
                if code != 0:
                    wrong = f"exit {code} but {out.name} was written"
                elif out.suffix != ".bin":
                    bad = nonfinite_tokens(out.read_text(errors="replace"))
                    if bad:
                        wrong = f"{out.name} holds {bad}"
            if wrong:
                failures[f"{name}: {cmd}"] = f"{wrong} | {se.strip()[-200:]}"
    took = time.monotonic() - t0
    assert not failures, f"{len(failures)} failures of {ran} runs:\n" + "\n".join(
        f"  {k}: {v}" for k, v in list(failures.items())[:60])
    assert loaded and refused, (len(loaded), len(refused))
    print(f"{len(cases)} mutants ({len(loaded)} load), {ran} command runs, {took:.1f} s")
