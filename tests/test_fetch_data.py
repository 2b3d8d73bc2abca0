"""The real recordings' registry and how the tests get the files: checked copies, refused
differences, and one message (not an error per test) when the files cannot be had."""

from __future__ import annotations

import importlib.util
import os
import re
import shutil
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import fetch_data
import pytest
from fetch_data import DataError, Entry, locate, read_registry

HERE = Path(__file__).resolve().parent
PERMISSIVE = {"MIT", "BSD-3-Clause", "Apache-2.0"}


def test_registry_pins_every_file_to_a_commit_with_its_hash_and_licence():
    entries = read_registry()
    assert len(entries) >= 70
    raw = re.compile(r"https://raw\.githubusercontent\.com/[\w.-]+/[\w.-]+/([0-9a-f]{40})/\S+")
    for e in entries:
        assert raw.fullmatch(e.url), e.url  # the raw file at a commit, not at a branch
        assert e.licence in PERMISSIVE | {"BSD", "EUPL-1.2", "GPL-3.0-or-later", "none-stated"}
    # the files kept in the repository: permissive licences only, each folder with its licence
    kept = [e for e in entries if (fetch_data.DATA / e.path).is_file()]
    assert {e.path.split("/")[0] for e in kept} == {"imucal-ferraris", "wearables-ggirread"}
    for e in kept:
        assert e.licence in PERMISSIVE
        assert (fetch_data.DATA / e.path).parent.joinpath("LICENSE").is_file()
        assert fetch_data.sha256(fetch_data.DATA / e.path) == e.sha256


@pytest.mark.parametrize("line, complaint", [
    ("a/b.csv 1234 MIT https://raw.githubusercontent.com/o/r/" + "0" * 40 + "/b.csv",
     "not a SHA-256"),
    ("../b.csv " + "0" * 64 + " MIT https://raw.githubusercontent.com/o/r/" + "0" * 40 + "/b",
     "not a relative path"),
    ("a/b.csv " + "0" * 64 + " MIT raw.githubusercontent.com/o/r/main/b.csv",
     "not an http"),
    ("a/b.csv " + "0" * 64 + " https://raw.githubusercontent.com/o/r/" + "0" * 40 + "/b",
     "got 3 fields"),
])
def test_malformed_registry_lines_are_refused(tmp_path, line, complaint):
    reg = tmp_path / "registry.txt"
    reg.write_text("# comment\n\n" + line + "\n")
    with pytest.raises(DataError, match=complaint):
        read_registry(reg)


def _small_registry(tmp_path: Path) -> tuple[list[Entry], Path]:
    """Three real entries (not kept in tests/data) and a local copy holding them."""
    entries = [e for e in read_registry() if e.path.startswith("icm20948-magneto/")]
    assert len(entries) == 3
    mirror = tmp_path / "mirror"
    for e in entries:
        (mirror / e.path).parent.mkdir(parents=True, exist_ok=True)
        (mirror / e.path).write_bytes(_published(e))
    return entries, mirror


def _published(e: Entry) -> bytes:
    """The bytes of a registry file, from wherever this run finds it."""
    return locate([e], download=False)[e.path].read_bytes()


def test_a_local_copy_is_used_after_its_hashes_are_checked(tmp_path, monkeypatch):
    entries, mirror = _small_registry(tmp_path)
    monkeypatch.setenv("TRIAXCAL_REALDATA", str(mirror))
    monkeypatch.setenv("TRIAXCAL_DATA_CACHE", str(tmp_path / "cache"))
    found = locate(entries)
    assert found == {e.path: mirror / e.path for e in entries}
    tree = fetch_data.make_tree(found, tmp_path / "tree")
    for e in entries:
        assert (tree / e.path).read_bytes() == (mirror / e.path).read_bytes()


def test_a_local_copy_that_differs_is_refused(tmp_path, monkeypatch):
    entries, mirror = _small_registry(tmp_path)
    bad = mirror / entries[1].path
    bad.write_bytes(bad.read_bytes().replace(b"1", b"2", 1))  # one digit changed
    monkeypatch.setenv("TRIAXCAL_REALDATA", str(mirror))
    monkeypatch.setenv("TRIAXCAL_DATA_CACHE", str(tmp_path / "cache"))
    with pytest.raises(DataError) as info:
        locate(entries)
    msg = str(info.value)
    assert "refused 1 recording" in msg and str(bad) in msg and entries[1].sha256 in msg
    assert fetch_data.sha256(bad) in msg


def test_a_missing_local_copy_named_by_the_variable_is_an_error(tmp_path, monkeypatch):
    monkeypatch.setenv("TRIAXCAL_REALDATA", str(tmp_path / "nowhere"))
    with pytest.raises(DataError, match="TRIAXCAL_REALDATA=.*nowhere is not a folder"):
        locate(read_registry()[:1])


def test_files_neither_here_nor_downloadable_give_one_message(tmp_path, monkeypatch):
    entries, _ = _small_registry(tmp_path)
    # no local copy, an empty cache, and URLs that refuse at once (a closed port on loopback)
    monkeypatch.setenv("TRIAXCAL_REALDATA", str(tmp_path / "empty"))
    (tmp_path / "empty").mkdir()
    monkeypatch.setenv("TRIAXCAL_DATA_CACHE", str(tmp_path / "cache"))
    offline = [Entry(e.path, e.sha256, e.licence, "http://127.0.0.1:9/" + e.path) for e in entries]
    with pytest.raises(DataError) as info:
        locate(offline)
    msg = str(info.value)
    assert msg.startswith("3 of the real recordings")
    assert "make data" in msg and "TRIAXCAL_REALDATA=DIR" in msg and "--copy-to DIR" in msg
    assert not (tmp_path / "cache" / entries[0].path).exists()
    # --check downloads nothing and says the same
    with pytest.raises(DataError, match="neither kept here, nor in a local copy"):
        locate(offline, download=False)


def test_a_cached_download_that_differs_is_fetched_again(tmp_path, monkeypatch):
    """pooch re-fetches a cached file whose hash is wrong; here from a local HTTP server."""
    pytest.importorskip("pooch")
    import http.server
    import threading

    entries, mirror = _small_registry(tmp_path)

    class Quiet(http.server.SimpleHTTPRequestHandler):
        def __init__(self, *a, **k):
            super().__init__(*a, directory=str(mirror), **k)

        def log_message(self, *a):
            pass

    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Quiet)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        url = f"http://127.0.0.1:{server.server_address[1]}/"
        served = [Entry(e.path, e.sha256, e.licence, url + e.path) for e in entries]
        empty = tmp_path / "empty"
        empty.mkdir()
        monkeypatch.setenv("TRIAXCAL_REALDATA", str(empty))
        cache = tmp_path / "cache"
        monkeypatch.setenv("TRIAXCAL_DATA_CACHE", str(cache))
        (cache / entries[0].path).parent.mkdir(parents=True)
        (cache / entries[0].path).write_bytes(b"1,2,3\n")  # a damaged earlier download
        found = locate(served)
        for e in entries:
            assert found[e.path] == cache / e.path
            assert fetch_data.sha256(found[e.path]) == e.sha256
        # a server that sends something else: refused, nothing kept
        (mirror / entries[2].path).write_bytes(b"not the file\n")
        (cache / entries[2].path).unlink()
        with pytest.raises(DataError, match="does not match the known hash|hash"):
            locate(served)
        assert not (cache / entries[2].path).exists()
    finally:
        server.shutdown()
        server.server_close()


@pytest.mark.slow
def test_a_run_without_the_files_stops_at_once_with_one_message(tmp_path):
    """A checkout with no local copy and no network: pytest stops before the first test with
    one message, however many tests need the files; tests that need none still run alone."""
    clone = tmp_path / "clone"
    (clone / "tests" / "data").mkdir(parents=True)
    for name in ("conftest.py", "fetch_data.py"):
        shutil.copy(HERE / name, clone / "tests" / name)
    e = next(e for e in read_registry() if e.path.startswith("icm20948-magneto/"))
    (clone / "tests" / "data" / "registry.txt").write_text(
        f"{e.path} {e.sha256} {e.licence} http://127.0.0.1:9/{e.path}\n")
    for k in range(3):
        (clone / "tests" / f"test_needs_{k}.py").write_text(textwrap.dedent(f"""
            def test_a(realdata):
                assert (realdata / "{e.path}").is_file()

            def test_b(realdata):
                assert (realdata / "{e.path}").is_file()
            """))
    (clone / "tests" / "test_plain.py").write_text("def test_c():\n    assert True\n")
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTEST")}
    env.pop("TRIAXCAL_REALDATA", None)
    env["TRIAXCAL_DATA_CACHE"] = str(tmp_path / "cache")
    run = lambda *args: subprocess.run(  # noqa: E731
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *args],
        cwd=clone, env=env, capture_output=True, text=True, timeout=120)
    t0 = time.monotonic()
    proc = run("tests")
    elapsed = time.monotonic() - t0
    out = proc.stdout + proc.stderr
    assert proc.returncode == pytest.ExitCode.USAGE_ERROR, out
    assert out.count("could not be downloaded") == 1, out
    assert "make data" in out and "TRIAXCAL_REALDATA" in out
    assert " passed" not in out and " error" not in out.lower().replace("connectionerror", "")
    assert elapsed < 60
    if importlib.util.find_spec("xdist") is not None:  # with workers: the same one message
        par = run("-n", "2", "tests")
        out = par.stdout + par.stderr
        assert par.returncode == pytest.ExitCode.USAGE_ERROR, out
        assert out.count("could not be downloaded") == 1 and "INTERNALERROR" not in out, out
    # the tests that need no recordings run without them
    plain = run("tests/test_plain.py")
    assert plain.returncode == 0 and "1 passed" in plain.stdout, plain.stdout + plain.stderr
    # and with a local copy holding the file, all run
    mirror = tmp_path / "mirror"
    (mirror / e.path).parent.mkdir(parents=True)
    (mirror / e.path).write_bytes(_published(e))
    env["TRIAXCAL_REALDATA"] = str(mirror)
    full = run("tests")
    assert full.returncode == 0 and "7 passed" in full.stdout, full.stdout + full.stderr
