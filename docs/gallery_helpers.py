"""What the gallery's examples share: where the real recordings are, and showing a figure.

The recordings are the third-party files the tests read. :func:`recording` is the one place
that finds them, so that pointing the gallery at another store (a download cache, a registry)
changes this function only. Today it looks, in order, at ``TRIAXCAL_REALDATA`` and at
``../shared/realdata`` beside the checkout; a checkout whose tests have a registry
(``tests/fetch_data.py``) takes the file from there instead, checked against its SHA-256.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def recording(path: str) -> Path:
    """The real recording ``path`` (relative to the data folder, e.g.
    ``"icm20948-magneto/icm_20948_cal_mag.csv"``)."""
    tests = ROOT / "tests"
    if (tests / "fetch_data.py").is_file():  # the tests' registry: local copy, cache, download
        sys.path.insert(0, str(tests))
        try:
            import fetch_data  # type: ignore[import-not-found]

            entries = [e for e in fetch_data.read_registry() if e.path == path]
            if entries:
                return Path(fetch_data.locate(entries)[path])
        finally:
            sys.path.remove(str(tests))
    env = os.environ.get("TRIAXCAL_REALDATA")
    base = Path(env) if env else ROOT.parent / "shared" / "realdata"
    found = base / path
    if not found.is_file():
        raise FileNotFoundError(
            f"real recording {path} not found under {base}: set TRIAXCAL_REALDATA to the "
            "folder of the tests' recordings")
    return found


def show(fig):
    """Hand a :class:`matplotlib.figure.Figure` made outside pyplot (as triaxcal's report
    figures are) to pyplot, so that the gallery shows it."""
    import matplotlib.pyplot as plt

    holder = plt.figure(figsize=fig.get_size_inches(), dpi=fig.dpi)
    manager = holder.canvas.manager
    manager.canvas.figure = fig
    fig.set_canvas(manager.canvas)
    return fig
