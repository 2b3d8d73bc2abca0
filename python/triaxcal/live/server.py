"""The HTTP side of the live page: Starlette routes served by uvicorn in a background thread.

Routes (all under the one origin the server listens on; nothing is fetched from elsewhere):

* ``GET /``: the page; ``GET /static/app.js``, ``/static/style.css``: its code; ``GET
  /static/plotly.min.js``: plotly.js from the installed ``plotly`` wheel (MIT licence,
  4.8 MB, sent gzip-compressed: 1.5 MB);
* ``GET /api/state``: the live document as JSON (see the README for its fields);
  ``?points=1`` adds the thinned point sets;
* ``GET /api/events``: server-sent events, one ``data:`` message per published document,
  ``{"state": ..., "points": {...}}`` where ``points`` holds only the sets that changed since
  the previous message to this client;
* ``POST /api/save``, ``/api/export/c``, ``/api/export/c-fixed``, ``/api/send`` (with
  ``?offsets_only=1`` as ``triaxcal send --offsets-only``), ``/api/reset``: the buttons
  (:mod:`triaxcal.live.actions`). They need the header ``X-Triaxcal: 1``, which a page of
  another origin cannot send without a CORS pre-flight that this server never grants, so
  other web sites cannot press the buttons.

Bound to a loopback address (the default), the server also refuses requests whose ``Host``
header is not that address or ``localhost`` (no DNS rebinding).
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import gzip
import importlib.util
import ipaddress
import socket
import threading
import time
from pathlib import Path
from typing import Any

from ..errors import CalibrationError
from .state import LiveState

__all__ = ["DEFAULT_HOST", "DEFAULT_PORT", "LiveServer", "check_live_extra", "plotly_js_path"]

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8765
STATIC = Path(__file__).resolve().parent / "static"
_INSTALL = "pip install 'triaxcal[live]'"


def plotly_js_path() -> Path:
    """Path of ``plotly.min.js`` inside the installed ``plotly`` package (not imported)."""
    spec = importlib.util.find_spec("plotly")
    if spec is None or not spec.submodule_search_locations:
        raise CalibrationError(f"the live page needs plotly for its 3D views: {_INSTALL}")
    path = Path(list(spec.submodule_search_locations)[0]) / "package_data" / "plotly.min.js"
    if not path.is_file():
        raise CalibrationError(
            f"the installed plotly has no offline bundle at {path}: reinstall it ({_INSTALL})")
    return path


def check_live_extra() -> None:
    """Raise :class:`CalibrationError` naming the ``live`` extra if a part of it is missing."""
    missing = [m for m in ("starlette", "uvicorn") if importlib.util.find_spec(m) is None]
    if missing:
        raise CalibrationError(
            f"the live page needs {' and '.join(missing)}: {_INSTALL}")
    plotly_js_path()


def _is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def bind_socket(host: str, port: int, tries: int = 20) -> socket.socket:
    """A listening TCP socket on ``host``: ``port``, or the next free one of ``tries`` ports
    (``port=0``: any free port)."""
    if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535:
        raise CalibrationError(f"--http-port must be a number 0..65535, got {port!r}")
    try:
        infos = socket.getaddrinfo(host, None, type=socket.SOCK_STREAM)
    except socket.gaierror as exc:
        raise CalibrationError(f"--http-host {host!r} is not an address of this machine: {exc}"
                               ) from None
    family = infos[0][0]
    last: OSError | None = None
    for p in ([0] if port == 0 else range(port, min(port + tries, 65536))):
        sock = socket.socket(family, socket.SOCK_STREAM)
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            sock.bind((host, p))
            sock.listen(64)
            sock.set_inheritable(True)
            return sock
        except OSError as exc:
            sock.close()
            last = exc
            if exc.errno not in (errno.EADDRINUSE, errno.EACCES):
                break
    raise CalibrationError(
        f"cannot listen on {host}:{port} (nor the next {tries - 1} ports): {last}; pass "
        "another --http-port")


def create_app(state: LiveState, *, host: str = DEFAULT_HOST,
               closed: threading.Event | None = None) -> Any:
    """The Starlette application of the live page for ``state`` (``closed``: set it to end
    the event streams, e.g. before shutting the server down)."""
    check_live_extra()
    from starlette.applications import Starlette
    from starlette.middleware import Middleware
    from starlette.middleware.trustedhost import TrustedHostMiddleware
    from starlette.requests import Request
    from starlette.responses import FileResponse, JSONResponse, Response, StreamingResponse
    from starlette.routing import Route

    from . import actions

    plotly_js = plotly_js_path()
    gz_cache: dict[str, bytes] = {}
    gz_lock = threading.Lock()
    closed = closed if closed is not None else threading.Event()

    def index(request: Request) -> Response:
        return FileResponse(STATIC / "index.html", media_type="text/html; charset=utf-8",
                            headers={"Cache-Control": "no-cache"})

    def static(request: Request) -> Response:
        name = request.path_params["name"]
        if name == "plotly.min.js":
            if "gzip" in request.headers.get("accept-encoding", ""):
                with gz_lock:
                    if "plotly" not in gz_cache:
                        gz_cache["plotly"] = gzip.compress(plotly_js.read_bytes(), 6)
                return Response(gz_cache["plotly"], media_type="text/javascript",
                                headers={"Content-Encoding": "gzip", "Vary": "Accept-Encoding",
                                         "Cache-Control": "max-age=86400"})
            return FileResponse(plotly_js, media_type="text/javascript",
                                headers={"Cache-Control": "max-age=86400"})
        kinds = {"app.js": "text/javascript", "style.css": "text/css"}
        if name not in kinds:
            return Response("not found", status_code=404, media_type="text/plain")
        return FileResponse(STATIC / name, media_type=kinds[name] + "; charset=utf-8",
                            headers={"Cache-Control": "no-cache"})

    def api_state(request: Request) -> Response:
        _, text = state.document_json()
        if request.query_params.get("points") in ("1", "true", "yes"):
            pts = ",".join(f'"{k}":{js}' for k, (_, js) in state.points_json().items())
            text = '{"state":' + text + ',"points":{' + pts + "}}"
        return Response(text, media_type="application/json", headers={"Cache-Control": "no-store"})

    async def api_events(request: Request) -> Response:
        async def messages() -> Any:
            sent: dict[str, int] = {}
            last = -1
            quiet = time.monotonic()
            yield "retry: 1000\n\n"
            while not closed.is_set():
                version, text = state.document_json()
                if version != last:
                    last = version
                    pts = state.points_json()
                    changed = [f'"{k}":{js}' for k, (v, js) in pts.items() if sent.get(k) != v]
                    sent.update({k: v for k, (v, _) in pts.items()})
                    yield ('data: {"state":' + text + ',"points":{' + ",".join(changed)
                           + "}}\n\n")
                    quiet = time.monotonic()
                elif time.monotonic() - quiet > 15.0:
                    yield ": keep-alive\n\n"
                    quiet = time.monotonic()
                await asyncio.sleep(0.04)

        return StreamingResponse(messages(), media_type="text/event-stream",
                                 headers={"Cache-Control": "no-store", "X-Accel-Buffering": "no"})

    def button(fn: Any) -> Any:
        async def endpoint(request: Request) -> Response:
            if request.headers.get("x-triaxcal") != "1":
                return JSONResponse({"ok": False, "message": "missing header X-Triaxcal: 1"},
                                    status_code=403)
            from starlette.concurrency import run_in_threadpool

            result = await run_in_threadpool(fn, request)
            return JSONResponse(result, status_code=200 if result.get("ok") else 409)

        return endpoint

    routes = [
        Route("/", index),
        Route("/static/{name}", static),
        Route("/api/state", api_state),
        Route("/api/events", api_events),
        Route("/api/save", button(lambda r: actions.save(state)), methods=["POST"]),
        Route("/api/export/c", button(lambda r: actions.export_header(state, "c")),
              methods=["POST"]),
        Route("/api/export/c-fixed", button(lambda r: actions.export_header(state, "c-fixed")),
              methods=["POST"]),
        Route("/api/send", button(lambda r: actions.send(
            state, offsets_only=r.query_params.get("offsets_only") == "1")), methods=["POST"]),
        Route("/api/reset", button(lambda r: actions.reset(state)), methods=["POST"]),
    ]
    middleware = []
    if _is_loopback(host):
        hosts = ["127.0.0.1", "localhost", "[::1]", "::1"]
        if host not in hosts:
            hosts.append(host)
        middleware.append(Middleware(TrustedHostMiddleware, allowed_hosts=hosts,
                                     www_redirect=False))
    return Starlette(routes=routes, middleware=middleware)


class LiveServer:
    """Serve the live page of ``state`` from a background thread (uvicorn).

    Parameters
    ----------
    state : LiveState
    host : str
        Address to listen on (default ``127.0.0.1``: this machine only). Another address
        makes the data and the buttons reachable from the network.
    port : int
        TCP port (default 8765; the next free one if it is taken; 0: any free port).

    Examples
    --------
    >>> import tempfile, os, json, urllib.request
    >>> st = LiveState(os.path.join(tempfile.mkdtemp(), "s.csv"), ("ax", "ay", "az"))
    >>> with LiveServer(st.start(), port=0) as srv:
    ...     doc = json.load(urllib.request.urlopen(srv.url + "api/state"))
    >>> st.stop(); doc["samples"], doc["status"]
    (0, 'waiting')
    """

    def __init__(self, state: LiveState, *, host: str = DEFAULT_HOST,
                 port: int = DEFAULT_PORT) -> None:
        check_live_extra()
        self.state = state
        self.host = host
        self._sock = bind_socket(host, port)
        self.port = int(self._sock.getsockname()[1])
        self._closed = threading.Event()
        self._app = create_app(state, host=host, closed=self._closed)
        self._server: Any = None
        self._thread: threading.Thread | None = None

    @property
    def url(self) -> str:
        """The page's address (for ``0.0.0.0``/``::``: this machine's name)."""
        h = self.host
        if h in ("0.0.0.0", "::", ""):
            h = socket.gethostname()
        if ":" in h:
            h = f"[{h}]"
        return f"http://{h}:{self.port}/"

    @property
    def public(self) -> bool:
        """Whether the server listens on a non-loopback address."""
        return not _is_loopback(self.host)

    def start(self) -> LiveServer:
        """Start serving (returns once the server accepts connections)."""
        import uvicorn

        if self._thread is not None:
            return self
        config = uvicorn.Config(self._app, log_level="warning", access_log=False,
                                lifespan="off", ws="none", http="h11",
                                timeout_graceful_shutdown=2)
        self._server = server = uvicorn.Server(config)
        sock = self._sock
        self._thread = threading.Thread(target=lambda: server.run(sockets=[sock]),
                                        name="triaxcal-live-http", daemon=True)
        self._thread.start()
        deadline = time.monotonic() + 20.0
        while not server.started:
            if not self._thread.is_alive() or time.monotonic() > deadline:
                raise CalibrationError(f"the live page's server did not start on {self.url}")
            time.sleep(0.01)
        return self

    def stop(self) -> None:
        """Stop serving and close the socket (idempotent)."""
        self._closed.set()  # ends the event streams, so the shutdown is quick
        if self._server is not None:
            self._server.should_exit = True
        if self._thread is not None:
            self._thread.join(timeout=10.0)
            self._thread = None
        with contextlib.suppress(OSError):
            self._sock.close()

    def __enter__(self) -> LiveServer:  # noqa: PYI034
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
