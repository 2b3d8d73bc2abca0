"""``--live``: run a capture with the live page beside it (``triaxcal capture`` and ``demo``)."""

from __future__ import annotations

import contextlib
import sys
import time
import webbrowser
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, TextIO

from ..capture.run import CaptureResult, capture
from .server import DEFAULT_HOST, DEFAULT_PORT, LiveServer, check_live_extra
from .state import LiveOptions, LiveState

__all__ = ["LivePage", "count_rows", "live_capture"]


def count_rows(path: Any) -> int:
    """Data rows in an existing session CSV (0 when it does not exist)."""
    p = Path(path)
    if not p.exists():
        return 0
    with open(p, "rb") as f:
        return max(sum(1 for _ in f) - 1, 0)


class LivePage:
    """The live page of one capture: a :class:`LiveState` fed by the capture, refitted in a
    background thread and served by a :class:`LiveServer`. Use it as a context manager.

    Parameters
    ----------
    reader : SerialReader
        The reader the capture will use (its events and counters are watched).
    out : str or Path
        The session CSV.
    columns : sequence of str
        Channel names (the session's header without ``t``).
    options : LiveOptions, optional
        Fit options and where Save writes.
    host, port : str, int
        Where the page is served (``--http-host``, ``--http-port``).
    open_browser : bool
        Open the page in the default browser.
    progress : text stream or None
        Where the capture's status line goes.
    notices : text stream or None
        Where to print the page's address and warnings (default: standard error).
    mode : str
        Session file mode (``new``, ``append``, ``overwrite``), as for the capture.
    """

    def __init__(
        self,
        reader: Any,
        out: Any,
        *,
        columns: Sequence[str],
        options: LiveOptions | None = None,
        host: str = DEFAULT_HOST,
        port: int = DEFAULT_PORT,
        open_browser: bool = True,
        progress: TextIO | None = sys.stderr,
        notices: TextIO | None = sys.stderr,
        mode: str = "new",
    ) -> None:
        check_live_extra()
        self.notices = notices
        self.reader = reader
        self.out = out
        self.columns = tuple(columns)
        self.mode = mode
        self.progress = progress
        self.open_browser = open_browser
        existing = count_rows(out) if mode == "append" else 0
        self.state = LiveState(out, self.columns, protocol=reader.protocol,
                               port=reader.port_name, options=options, existing_rows=existing)
        self.server = LiveServer(self.state, host=host, port=port)
        self.result: CaptureResult | None = None

    @property
    def url(self) -> str:
        return self.server.url

    def _say(self, text: str) -> None:
        if self.notices is not None:
            print(text, file=self.notices, flush=True)

    def start(self) -> LivePage:
        """Serve the page (and open it in the browser when asked)."""
        self.state.attach(self.reader)
        self.server.start()
        self.state.start()
        self._say(f"triaxcal: live page at {self.url} (the capture goes on if the browser is "
                  "closed; Ctrl-C stops it)")
        if self.server.public:
            self._say(f"triaxcal: warning: serving on {self.server.host}: anyone on the network "
                      "can see the data and press Save or Send; use --http-host 127.0.0.1 to "
                      "keep the page on this machine")
        if self.open_browser:
            with contextlib.suppress(Exception):
                webbrowser.open(self.url)
        return self

    def capture(self, **capture_kwargs: Any) -> CaptureResult:
        """Run :func:`~triaxcal.capture.run.capture` feeding the page; when it ends by itself
        (not by Ctrl-C), fit the session as ``triaxcal fit`` does and show that."""
        result = capture(self.reader, self.out, on_records=self.state.on_records,
                         columns=self.columns, mode=self.mode, progress=self.progress,
                         **capture_kwargs)
        self.result = result
        if result.stopped_by != "interrupt":
            self.state.finish(result)
        return result

    def linger(self, wait: Callable[[], None] | None = None) -> None:
        """Keep serving until Ctrl-C (or until ``wait`` returns)."""
        self._say(f"triaxcal: capture finished; the page stays up at {self.url} with the "
                  "session's fit: Ctrl-C to quit")
        try:
            if wait is not None:
                wait()
            else:
                while True:
                    time.sleep(0.5)
        except KeyboardInterrupt:
            pass

    def close(self) -> None:
        """Stop the refit thread and the server (idempotent)."""
        self.state.stop()
        self.server.stop()

    def __enter__(self) -> LivePage:  # noqa: PYI034
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()


def live_capture(
    reader: Any,
    out: Any,
    *,
    columns: Sequence[str],
    options: LiveOptions | None = None,
    host: str = DEFAULT_HOST,
    port: int = DEFAULT_PORT,
    open_browser: bool = True,
    linger: bool = True,
    progress: TextIO | None = sys.stderr,
    notices: TextIO | None = sys.stderr,
    mode: str = "new",
    **capture_kwargs: Any,
) -> CaptureResult:
    """:func:`~triaxcal.capture.run.capture` with the live page served beside it.

    The capture runs as it does without the page (in this thread; Ctrl-C stops it with the
    session saved); the page is served from a background thread and refitted in another, so
    closing the browser changes nothing. When the capture ends by itself (``samples``,
    ``poses``, ``duration_s``, ``stop``) the page shows the session's fit and, with
    ``linger``, stays up until Ctrl-C. Other arguments as for :class:`LivePage` and
    :func:`~triaxcal.capture.run.capture`.
    """
    with LivePage(reader, out, columns=columns, options=options, host=host, port=port,
                  open_browser=open_browser, progress=progress, notices=notices,
                  mode=mode) as page:
        result = page.capture(**capture_kwargs)
        if linger and result.stopped_by != "interrupt":
            page.linger()
    return result
