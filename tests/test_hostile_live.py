"""Hostile requests to the live page's server, and hostile records into its state.

The server (triaxcal.live.server.LiveServer, Starlette under uvicorn) is sent, over a raw
socket: paths that climb out of /static, percent-encoded NUL and invalid UTF-8, 10,000-character
names, every method on every route, the buttons without and with their header, query values
of every kind, a foreign Host, malformed request lines, a 100 kB header, a body that lies about
its length and a broken chunked body. Each must get an answer below 500 (or a closed
connection for a request that is not HTTP), never a hang, and the server must still serve
``/api/state`` afterwards. The state is fed board records at the edges of their integers, and
its buttons (Save, the C exports, Send, Reset) must answer with a message, not a 500.
"""

from __future__ import annotations

import json
import socket
import time

import numpy as np
import pytest
from triaxcal.capture.run import channel_names
from triaxcal.io.serial import Record
from triaxcal.live import LiveState
from triaxcal.live.server import LiveServer
from triaxcal.sim import SimIMU, globe_script

NAMES = channel_names("framed", 10)

pytest.importorskip("uvicorn")
pytest.importorskip("starlette")


def _raw(port: int, data: bytes, timeout: float = 10.0) -> bytes:
    """Send ``data`` as it is and read the answer until the server closes or ``timeout``."""
    with socket.create_connection(("127.0.0.1", port), timeout=timeout) as s:
        s.sendall(data)
        chunks = []
        t0 = time.monotonic()
        while time.monotonic() - t0 < timeout:
            try:
                b = s.recv(65536)
            except TimeoutError:
                raise AssertionError(f"no answer in {timeout:g} s to {data[:80]!r}") from None
            except ConnectionResetError:
                break
            if not b:
                break
            chunks.append(b)
            if b"\r\n\r\n" in b"".join(chunks) and _complete(b"".join(chunks)):
                break
        return b"".join(chunks)


def _complete(answer: bytes) -> bool:
    head, _, body = answer.partition(b"\r\n\r\n")
    for line in head.split(b"\r\n"):
        if line.lower().startswith(b"content-length:"):
            return len(body) >= int(line.split(b":", 1)[1])
    return b"transfer-encoding: chunked" not in head.lower() or body.endswith(b"0\r\n\r\n")


def _status(answer: bytes) -> int | None:
    """The status code of an answer, or None for a closed connection."""
    if not answer:
        return None
    first = answer.split(b"\r\n", 1)[0].split()
    return int(first[1]) if len(first) > 1 and first[1].isdigit() else -1


def _request(method: str, path: str, *, headers: dict[str, str] | None = None,
             body: bytes = b"", host: str = "127.0.0.1") -> bytes:
    h = {"Host": host, "Connection": "close", **(headers or {})}
    if body and "Content-Length" not in h and "Transfer-Encoding" not in h:
        h["Content-Length"] = str(len(body))
    head = f"{method} {path} HTTP/1.1\r\n" + "".join(f"{k}: {v}\r\n" for k, v in h.items())
    return head.encode("latin-1") + b"\r\n" + body


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    folder = tmp_path_factory.mktemp("live")
    frames = SimIMU(2).record(globe_script(hold_s=1.0, seed=2), 100.0).frames(10)
    st = LiveState(folder / "s.csv", NAMES)
    st.on_records([Record(1.7e9 + 0.01 * j, tuple(int(v) for v in row))
                   for j, row in enumerate(frames[:3000])])
    with LiveServer(st.start(), port=0) as srv:
        yield srv, st


ROUTES = ["/", "/static/app.js", "/static/style.css", "/api/state", "/api/save",
          "/api/export/c", "/api/export/c-fixed", "/api/send", "/api/reset"]
PATHS = [
    "/static/../server.py", "/static/..%2fserver.py", "/static/%2e%2e%2fserver.py",
    "/static/..%5cserver.py", "/static/%00", "/static/app.js%00.txt", "/static/%ff%fe",
    "/static/" + "a" * 10_000, "/" + "%" * 50, "/api/state?points=" + "1" * 10_000,
    "/api/state?points=%00", "/api/state?points=\u00e9".encode().decode("latin-1"),
    "/api/state?points=1&points=0", "//etc/passwd", "/api/../api/state", "*",
    "http://evil.example/api/state", "/static/plotly.min.js?" + "x=1&" * 500,
]
#: Query values of the Send button (offsets_only) and of the state's points.
QUERIES = ["1", "0", "", "%00", "nan", "1e308", "%1b%5b2J", "true", "-1", "x" * 5000]


def _alive(port: int) -> None:
    answer = _raw(port, _request("GET", "/api/state"))
    assert _status(answer) == 200, answer[:200]
    json.loads(answer.partition(b"\r\n\r\n")[2])


def test_paths_methods_and_queries(server):
    srv, _ = server
    port = srv.port
    failures = {}
    cases: dict[str, bytes] = {}
    for path in PATHS:
        cases[f"GET {path[:40]}"] = _request("GET", path)
    for route in ROUTES:
        for method in ("GET", "POST", "PUT", "DELETE", "OPTIONS", "PATCH", "TRACE", "BREW"):
            if route.startswith("/api/") and method == "POST" and route != "/api/state":
                continue  # the buttons without their header: below
            cases[f"{method} {route}"] = _request(method, route)
    for route in ("/api/save", "/api/export/c", "/api/send", "/api/reset"):
        cases[f"POST {route} without X-Triaxcal"] = _request("POST", route)
        # ("1 " is "1": HTTP strips the spaces around a header's value)
        for bad in ("0", "", "\u00ff".encode().decode("latin-1"), "11", "true", "1,1"):
            cases[f"POST {route} X-Triaxcal={bad!r}"] = _request(
                "POST", route, headers={"X-Triaxcal": bad})
    for q in QUERIES:
        cases[f"GET points={q[:20]}"] = _request("GET", f"/api/state?points={q}")
    for host in ("evil.example", "127.0.0.1.evil.example", "", "localhost:1", "[::1]:0",
                 "a" * 5000):
        cases[f"Host {host[:30]}"] = _request("GET", "/api/state", host=host)
    for name, data in cases.items():
        try:
            answer = _raw(port, data)
        except AssertionError as exc:
            failures[name] = str(exc)
            continue
        code = _status(answer)
        if code is None or code >= 500 or code == -1:
            failures[name] = f"answer {answer[:120]!r}"
        elif name.startswith("POST") and "X-Triaxcal" in name and code != 403:
            failures[name] = f"a button pressed without its header answered {code}"
        elif name.startswith("Host ") and not name.startswith("Host localhost") and \
                not name.startswith("Host [::1]") and code != 400:
            failures[name] = f"a foreign Host answered {code}"
        elif b"Traceback" in answer:
            failures[name] = "a traceback in the answer"
    assert not failures, f"{len(failures)} of {len(cases)}:\n" + "\n".join(
        f"  {k}: {v}" for k, v in failures.items())
    _alive(port)
    print(f"{len(cases)} requests")


MALFORMED = {
    "garbage": b"GARBAGE\r\n\r\n",
    "http-0.9": b"GET /\r\n\r\n",
    "no-version": b"GET / \r\n\r\n",
    "bad-version": b"GET / HTTP/9.9\r\nHost: 127.0.0.1\r\n\r\n",
    "nul-in-line": b"GET /api/\x00state HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n",
    "esc-in-path": b"GET /\x1b[2J HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n",
    "high-bytes": b"GET /\xff\xfe HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n",
    "header-no-colon": b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nbroken\r\n\r\n",
    "header-ctl": b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nX-A: a\x07\x1b\r\n\r\n",
    "huge-header": b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Big: " + b"a" * 100_000 +
                   b"\r\n\r\n",
    "many-headers": b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\n" + b"X-A: 1\r\n" * 2000 + b"\r\n",
    "length-lies": b"POST /api/reset HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Triaxcal: 1\r\n"
                   b"Content-Length: 5\r\nConnection: close\r\n\r\nabcdefghij",
    "length-negative": b"POST /api/reset HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Length: -1\r\n"
                       b"\r\n",
    "length-huge": b"POST /api/state HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Length: "
                   b"99999999999999999999999\r\n\r\n",
    "length-twice": b"POST /api/reset HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Length: 1\r\n"
                    b"Content-Length: 2\r\n\r\nab",
    "chunked-broken": b"POST /api/reset HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Triaxcal: 1\r\n"
                      b"Transfer-Encoding: chunked\r\n\r\nzz\r\nabc\r\n",
    "smuggle": b"POST /api/state HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Length: 4\r\n"
               b"Transfer-Encoding: chunked\r\n\r\n0\r\n\r\nGET /api/reset HTTP/1.1\r\n\r\n",
    "two-hosts": b"GET /api/state HTTP/1.1\r\nHost: 127.0.0.1\r\nHost: evil.example\r\n\r\n",
}


@pytest.mark.timeout(120)
def test_malformed_requests(server):
    """Requests that are not well-formed HTTP: an answer below 500 or a closed connection,
    quickly; the server keeps serving."""
    srv, _ = server
    failures = {}
    for name, data in MALFORMED.items():
        try:
            answer = _raw(srv.port, data, timeout=8.0)
        except AssertionError as exc:
            failures[name] = str(exc)
            continue
        code = _status(answer)
        if code is not None and (code >= 500 or code == -1):
            failures[name] = f"answer {answer[:120]!r}"
        if name == "two-hosts" and code == 200:
            failures[name] = "a request naming a foreign Host as well was served"
    assert not failures, "\n".join(f"  {k}: {v}" for k, v in failures.items())
    _alive(srv.port)


#: Board records at the edges of what a frame can carry (the framed protocol's 16-bit
#: channels, and what a damaged reader could hand over).
RECORDS = {
    "int16-extremes": [(-32768,) * 10, (32767,) * 10],
    "zeros": [(0,) * 10],
    "int64-extremes": [(2**63 - 1,) * 10, (-(2**63),) * 10],
    "huge-int": [(10**30,) * 10],
}


@pytest.mark.timeout(300)
@pytest.mark.parametrize("kind", sorted(RECORDS))
def test_hostile_records_then_every_button(kind, tmp_path):
    """Records at the edges fed among good ones: the state either takes them or refuses them
    with a CalibrationError; every button then answers with a message (HTTP 200 or 409),
    never 500, and the document stays strict JSON."""
    from triaxcal import CalibrationError

    frames = SimIMU(2).record(globe_script(hold_s=1.0, seed=2), 100.0).frames(10)
    st = LiveState(tmp_path / "s.csv", NAMES)
    rows = [tuple(int(v) for v in r) for r in frames[:2000]]
    rng = np.random.default_rng(0)
    for at in sorted(rng.integers(0, len(rows), 20).tolist(), reverse=True):
        rows[at:at] = RECORDS[kind]
    records = [Record(1.7e9 + 0.01 * j, row) for j, row in enumerate(rows)]
    refused = 0
    for i in range(0, len(records), 50):  # the reader hands records over in batches
        try:
            st.on_records(records[i:i + 50])
        except CalibrationError as exc:  # a batch with a reading past any sensor's
            assert "beyond" in str(exc) and "row" in str(exc), exc
            refused += 1
    assert refused < len(records) / 50, "every batch was refused"
    with LiveServer(st.start(), port=0) as srv:
        _alive(srv.port)
        for route in ("/api/save", "/api/export/c", "/api/export/c-fixed",
                      "/api/send?offsets_only=1", "/api/send", "/api/reset"):
            answer = _raw(srv.port, _request("POST", route, headers={"X-Triaxcal": "1"}),
                          timeout=60.0)
            code = _status(answer)
            assert code in (200, 409), (route, answer[:300])
            body = json.loads(answer.partition(b"\r\n\r\n")[2],
                              parse_constant=lambda c, r=route: pytest.fail(f"{c} in {r}"))
            assert isinstance(body.get("message", ""), str), body
        _alive(srv.port)
