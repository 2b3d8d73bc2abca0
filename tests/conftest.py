"""Shared fixtures: paths to the third-party recordings in ../shared/realdata."""

from __future__ import annotations

import os
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
