"""Shared fixtures: paths to the third-party recordings in ../shared/realdata."""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
REALDATA = Path(os.environ.get("TRIAXCAL_REALDATA", ROOT.parent / "shared" / "realdata"))
SEEDS = REALDATA.parent / "seeds"


@pytest.fixture(scope="session")
def realdata() -> Path:
    """The folder of real recordings; the tests that use it fail loudly if it is missing."""
    assert REALDATA.is_dir(), f"real recordings not found at {REALDATA} (set TRIAXCAL_REALDATA)"
    return REALDATA


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
