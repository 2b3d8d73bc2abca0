"""The package reads as the pipeline: each layer imports only layers below it, nothing below the
command line sees argparse or the CLI, no module grows past ~800 lines, few modules at the root.

The layers, bottom up (CONTRIBUTING.md draws the same picture)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest
import triaxcal

PKG = Path(triaxcal.__file__).parent

#: Layer of each top-level part of the package; an import may only go to the same or a lower
#: layer. The root modules errors, _core and _checks are the ground.
LAYERS = {
    "_core": 0, "errors": 0, "_checks": 0,
    "conventions": 1,
    "quality": 2,
    "io": 3,
    "sim": 4, "detect": 4,
    "capture": 5,
    "fit": 6,
    "methods": 7,
    "calibration": 8,
    "report": 9,
    "export": 10,
    "fleet": 11, "live": 11, "dask": 12, "demo": 12,
    "cli": 13,
    "__init__": 14,
}


def _modules() -> list[Path]:
    return sorted(p for p in PKG.rglob("*.py"))


def _part(path: Path) -> str:
    rel = path.relative_to(PKG)
    return rel.parts[0] if len(rel.parts) > 1 else rel.stem


def _imports(path: Path) -> list[tuple[str, int]]:
    """Absolute ``triaxcal.<part>`` targets of every import in the file (function-level
    imports too), with their line numbers."""
    rel = path.relative_to(PKG).with_suffix("")
    pkg = ["triaxcal", *rel.parts[:-1]] if rel.name != "__init__" else ["triaxcal", *rel.parts[:-1]]
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = pkg[: len(pkg) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            names = [mod] if node.module or not node.level else [
                f"{mod}.{a.name}" for a in node.names]
            out += [(m, node.lineno) for m in names]
        elif isinstance(node, ast.Import):
            out += [(a.name, node.lineno) for a in node.names]
    return [(m, n) for m, n in out if m == "triaxcal" or m.startswith("triaxcal.")]


def test_every_part_has_a_layer():
    parts = {_part(p) for p in _modules()}
    assert parts <= set(LAYERS), parts - set(LAYERS)


def test_no_upward_import():
    bad = []
    for path in _modules():
        here = _part(path)
        for mod, line in _imports(path):
            there = mod.split(".")[1] if "." in mod else "__init__"
            there = {"rotations": "conventions",  # triaxcal.rotations is conventions.rotations
                     "__version__": "_core"}.get(there, there)
            if LAYERS[there] > LAYERS[here]:
                bad.append(f"{path.relative_to(PKG)}:{line} imports {mod} "
                           f"({here} is below {there})")
    assert not bad, "\n".join(bad)


def test_nothing_below_the_cli_imports_argparse_or_the_cli():
    bad = []
    for path in _modules():
        if _part(path) == "cli":
            continue
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                     [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            for n in names:
                if n == "argparse" or n.startswith("triaxcal.cli") or (
                        isinstance(node, ast.ImportFrom) and node.level and n.startswith("cli")):
                    bad.append(f"{path.relative_to(PKG)}:{node.lineno} imports {n}")
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize("path", _modules(), ids=lambda p: str(p.relative_to(PKG)))
def test_no_module_past_800_lines(path):
    assert len(path.read_text().splitlines()) <= 800


def test_few_modules_at_the_root():
    root = sorted(p.name for p in PKG.glob("*.py"))
    assert len(root) <= 6, root
