"""Shared fixtures: the third-party recordings of tests/data/registry.txt as one folder."""

from __future__ import annotations

import re
import sys
from pathlib import Path

import fetch_data
import pytest

ROOT = Path(__file__).resolve().parent.parent
_FOUND = pytest.StashKey[dict]()


def _locate_or_exit(config: pytest.Config) -> dict[str, Path]:
    """Every registry file, checked; a run that cannot have them stops here with one message."""
    found = config.stash.get(_FOUND, None)
    if found is None:
        try:
            found = fetch_data.locate()
        except fetch_data.DataError as exc:
            tr = config.pluginmanager.get_plugin("terminalreporter")
            if tr is not None:
                tr.write_line("")
                tr.write_line(str(exc), red=True, bold=True)
            else:
                print(exc, file=sys.stderr)
            pytest.exit("the real recordings are missing or differ (see above)",
                        returncode=pytest.ExitCode.USAGE_ERROR)
        config.stash[_FOUND] = found
    return found


def pytest_sessionstart(session: pytest.Session) -> None:
    """With pytest-xdist (``-n``), check in the controller, before any worker starts: a worker
    cannot stop the run cleanly (the controller does not collect, so this is done whether or
    not the chosen tests read the recordings)."""
    config = session.config
    if getattr(config.option, "numprocesses", None) and not hasattr(config, "workerinput"):
        _locate_or_exit(config)


def pytest_collection_modifyitems(session: pytest.Session, config: pytest.Config,
                                  items: list[pytest.Item]) -> None:
    """Find (or download) the recordings once, before the first test, if any test reads them."""
    if not config.option.collectonly and any(
            "realdata" in getattr(item, "fixturenames", ()) for item in items):
        _locate_or_exit(config)


@pytest.fixture(scope="session")
def realdata(pytestconfig: pytest.Config, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The folder of real recordings, laid out as tests/data/registry.txt lists them (each file
    checked against its SHA-256; see tests/data/README.md)."""
    found = _locate_or_exit(pytestconfig)
    return fetch_data.make_tree(found, tmp_path_factory.mktemp("realdata"))


def readme_section(heading: str) -> str:
    """The README text under the level-2 heading that starts with ``heading``, up to the next
    level-2 heading."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    m = re.search(rf"^## {re.escape(heading)}.*?$(.*?)(?=^## |\Z)", text, re.S | re.M)
    assert m, f"README has no section '## {heading}'"
    return m.group(1)


def doc_page(page: str, heading: str | None = None) -> str:
    """The text of a documentation page (``docs/<page>``), or of its section under the heading
    that starts with ``heading`` (any level), up to the next heading of the same or a higher
    level."""
    text = (ROOT / "docs" / page).read_text(encoding="utf-8")
    if heading is None:
        return text
    m = re.search(rf"^(#+) {re.escape(heading)}.*?$", text, re.M)
    assert m, f"docs/{page} has no heading '{heading}'"
    level = len(m.group(1))
    rest = text[m.end():]
    end = re.search(rf"^#{{1,{level}}} ", rest, re.M)
    return rest[: end.start()] if end else rest
