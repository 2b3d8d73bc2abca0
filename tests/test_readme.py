"""The README's quick start runs as written and does what it says."""

from __future__ import annotations

import re

import numpy as np
from conftest import ROOT, readme_section


def test_quickstart_runs_and_recovers_the_offsets(capsys):
    code = re.findall(r"```python\n(.*?)```", readme_section("Quick start"), re.S)[0]
    ns: dict = {}
    exec(compile(code, "README quick start", "exec"), ns)
    fit = ns["fit"]
    np.testing.assert_allclose(fit.offset, [412, -230, 97], atol=10)
    np.testing.assert_allclose(np.diag(fit.matrix) * 16384, [1.03, 0.98, 1.01], atol=2e-3)
    assert "g" in capsys.readouterr().out
    assert len([ln for ln in code.strip().splitlines() if ln.strip()]) <= 12


def test_readme_gives_the_two_fresh_machine_commands():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    assert "pip install '.[plot]' && triaxcal demo" in text
    assert "make test" in text
    ci = (ROOT / ".ci" / "run").read_text()
    assert "make test" in ci
