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
import math
import time
from pathlib import Path

import numpy as np
import pytest
import triaxcal as tc
import yaml
from _hostile_cli import (
    NUMBERS,
    SCALE,
    TEXTS,
    calibration,
    leaves,
    mutants,
    mutate,
    nonfinite_tokens,
    run,
    session,
)


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


#: The commands every loading mutant of a statistics record meets (the rest of the commands
#: read the coefficients, not the records; the slow run gives them every command).
_STATS_CMDS = ("report", "export-json")
#: The commands a refused mutant meets (each must refuse it, on the same load).
_REFUSED_CMDS = ("report", "export-c", "send")
#: Values of the coefficients whose mutants also meet ``report`` with the session beside the
#: file (0.3 s each: the report refits and searches the sphere; the slow run gives it all).
_WITH_DATA = ("NaN", "1e309", "1e308", "-1e308", "1e-320", "string", "0")


_ALL_CMDS = ("report", "diff-previous", "diff-base", "send", "board-write", "export-c",
             "export-c-fixed", "export-json", "export-js", "export-js-espruino",
             "export-ardupilot", "export-px4", "export-adafruit", "export-kalibr",
             "export-motioncal", "export-forced")


def _in_stats(name: str) -> bool:
    path = name.split("=")[0].split("/")
    return "stats" in path[:-1] or "previous" in path or name.startswith("parts/accel/stats")


def _plan(cases: dict[str, str], loaded: list[str], refused: list[str],
          full: bool) -> list[tuple[str, tuple[str, ...] | None, bool]]:
    """(mutant, the commands it meets (None: all), whether the session lies beside it)."""
    if full:
        return [(n, None, True) for n in loaded] + [(n, _REFUSED_CMDS, True) for n in refused]
    plan: list[tuple[str, tuple[str, ...] | None, bool]] = []
    for i, n in enumerate(loaded):
        if _in_stats(n):
            plan.append((n, _STATS_CMDS, False))
        else:  # every command but the exports, and every other export in turn
            plan.append((n, tuple(k for j, k in enumerate(_ALL_CMDS)
                                  if not k.startswith("export-") or (i + j) % 2 == 0), False))
            if n.startswith("impossible:") or n.split("=")[-1] in _WITH_DATA and any(
                    f"/{k}" in n for k in ("/offset", "/diag", "/offdiag", "/radius")):
                plan.append((n, ("report",), True))
    plan += [(n, _REFUSED_CMDS, False) for n in refused[::40]]
    return plan


def _hostile_files(files, tmp_path, full: bool) -> None:
    folder, data, cal = files
    doc = json.loads(cal.read_text())
    for part in doc["parts"].values():  # found beside the file only (the report's data)
        if part.get("source"):
            part["source"] = Path(part["source"]).name
    cases = mutants(doc)
    assert len(cases) > 300 if full else len(cases) > 200
    if not full:  # by default a share: a sixth of the 300,000-number lists (0.3 s each to
        # parse), a third of the mutants of the statistics records; the slow run takes all
        big = [n for n in cases if n.endswith("=enormous")]
        stats = [n for n in cases if _in_stats(n) and n not in big]
        cases = {n: t for n, t in cases.items()
                 if (n not in big or n in big[::6]) and (n not in stats or n in stats[::3])}
    loaded, refused, failures = [], [], {}
    t0 = time.monotonic()
    alone = tmp_path / "alone"  # no session beside the file: report prints the stored stats
    alone.mkdir()
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
    ran = 0
    for i, (name, keys, beside) in enumerate(_plan(cases, loaded, refused, full)):
        p = (folder if beside else alone) / f"m{i}.json"
        p.write_text(cases[name], encoding="utf-8", errors="surrogatepass")
        cmds = _commands(p, cal, tmp_path / f"o{i}")
        if keys is not None:
            cmds = {k: v for k, v in cmds.items() if k in keys}
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
        p.unlink()
    took = time.monotonic() - t0
    assert not failures, f"{len(failures)} failures of {ran} runs:\n" + "\n".join(
        f"  {k}: {v}" for k, v in list(failures.items())[:80])
    assert loaded and refused, (len(loaded), len(refused))
    print(f"{len(cases)} mutants ({len(loaded)} load), {ran} command runs, {took:.1f} s")


def test_hostile_calibration_files(files, tmp_path):
    """Every mutant loads or is refused; a mutant of a coefficient that loads goes through
    every command but the exports and half of the exports (each export meets every other
    such mutant), one of a statistics record through the commands that print or copy the
    records, a share of the refused through three commands; no command lets an exception out,
    hangs, prints raw control characters or writes a file with NaN or infinity in it (or after
    refusing)."""
    _hostile_files(files, tmp_path, full=False)


@pytest.mark.slow
@pytest.mark.timeout(3600, method="thread")
def test_hostile_calibration_files_every_command(files, tmp_path):
    """The same with every loading mutant through every command, the session beside it."""
    _hostile_files(files, tmp_path, full=True)


def test_hostile_noise_files_for_the_kalibr_export(files, tmp_path):
    """The noise file ``noise --format kalibr`` writes, with every value mutated (and files
    that are not such a file at all), given to ``export --format kalibr --noise``: refused
    with a message or exported with finite numbers only, never a traceback."""
    folder, _, cal = files
    rng = np.random.default_rng(3)
    n = 3000
    rest = tmp_path / "rest.csv"
    np.savetxt(rest, np.column_stack([np.arange(n) / 100.0,
                                      rng.normal(0, 20.0, (n, 3)) + [0, 0, 16384],
                                      rng.normal(0, 2.0, (n, 3)) + [30, -12, 5]]),
               delimiter=",", header="t,ax,ay,az,gx,gy,gz", comments="", fmt="%.6f")
    noise = tmp_path / "noise.json"
    wrong, code, _, se = run(["noise", str(rest), "--sensor", "both", "--cal", str(cal),
                              "--format", "kalibr", "-o", str(noise)])
    assert wrong is None and code == 0, (wrong, se)
    doc = json.loads(noise.read_text())
    cases = {"as-written": noise.read_text()}
    for path, value in leaves(doc):
        kinds = NUMBERS if isinstance(value, (int, float)) else TEXTS
        for k, v in kinds.items():
            cases[f"{'/'.join(map(str, path))}={k}"] = mutate(doc, path, v)
    cases.update({"empty": "", "list": "[]", "null": "null", "nested": '{"a": {"b": 1}}',
                  "calibration": cal.read_text(), "unknown-key": json.dumps({**doc, "x": 1}),
                  "missing-key": json.dumps(dict(list(doc.items())[1:]))})
    failures = {}
    for name, text in cases.items():
        bad = tmp_path / "bad.json"
        bad.write_text(text, encoding="utf-8", errors="surrogatepass")
        out = tmp_path / "k.yaml"
        argv = ["export", str(cal), "--format", "kalibr", "--noise", str(bad), "-o", str(out),
                "--counts-per-unit", SCALE, "--rate-hz", "100", "--kalibr-model", "calibrated"]
        wrong, code, _, se = run(argv)
        if wrong is None and out.exists():
            if code != 0:
                wrong = f"exit {code} but {out.name} was written"
            else:
                y = yaml.safe_load(out.read_text())
                nums = [v for k, v in y.items() if "noise" in k or "walk" in k]
                if not all(isinstance(v, float) and math.isfinite(v) and v > 0 for v in nums):
                    wrong = f"noise values written: {nums}"
            out.unlink()
        if name == "as-written" and (wrong or code != 0):
            wrong = f"the noise file as written is not exported (exit {code})"
        if wrong:
            failures[name] = f"{wrong} | {se.strip()[-200:]}"
    assert not failures, f"{len(failures)} of {len(cases)}:\n" + "\n".join(
        f"  {k}: {v}" for k, v in failures.items())
