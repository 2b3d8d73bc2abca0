"""The real recordings the tests read: find each file, check its SHA-256, download what is missing.

``tests/data/registry.txt`` lists the files (path, SHA-256, licence, URL at a pinned commit).
Each file is taken from the first of: the copy kept in ``tests/data/``; a local copy of the data
folder (``TRIAXCAL_REALDATA``, else ``../shared/realdata`` beside the checkout); the download
cache (``TRIAXCAL_DATA_CACHE``, default ``~/.cache/triaxcal/realdata``), which ``pooch`` fills
from the registry's URLs. A file whose SHA-256 differs is refused.

Run it as a script to download everything ahead of time (``make data``)::

    python tests/fetch_data.py              # download what is missing, check everything
    python tests/fetch_data.py --check      # say where each file comes from; no download
    python tests/fetch_data.py --copy-to D  # also copy every file into folder D (a local copy
                                            # for a machine offline: TRIAXCAL_REALDATA=D)
"""

from __future__ import annotations

import argparse
import hashlib
import os
import re
import shutil
import sys
from dataclasses import dataclass
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
DATA = HERE / "data"
REGISTRY = DATA / "registry.txt"
MIRROR_ENV = "TRIAXCAL_REALDATA"
CACHE_ENV = "TRIAXCAL_DATA_CACHE"

_URL = re.compile(r"^https?://\S+$")


class DataError(Exception):
    """A recording is missing, differs from the registry, or the registry is malformed."""


@dataclass(frozen=True)
class Entry:
    """One line of the registry."""

    path: str
    sha256: str
    licence: str
    url: str


def read_registry(path: Path = REGISTRY) -> list[Entry]:
    """The registry's entries, checked: four fields, a SHA-256, a relative path, a URL (that each
    URL is pinned to a commit is a test of the registry itself)."""
    entries: list[Entry] = []
    for no, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        fields = line.split()
        where = f"{path}:{no}"
        if len(fields) != 4:
            raise DataError(f"{where}: expected path, sha256, licence, url; "
                            f"got {len(fields)} fields")
        rel, digest, licence, url = fields
        if not re.fullmatch(r"[0-9a-f]{64}", digest):
            raise DataError(f"{where}: {digest!r} is not a SHA-256 (64 lowercase hex digits)")
        parts = Path(rel).parts
        if Path(rel).is_absolute() or ".." in parts or not parts:
            raise DataError(f"{where}: {rel!r} is not a relative path inside the data folder")
        if not _URL.match(url):
            raise DataError(f"{where}: {url!r} is not an http(s) URL")
        entries.append(Entry(rel, digest, licence, url))
    seen: set[str] = set()
    for e in entries:
        if e.path in seen:
            raise DataError(f"{path}: {e.path} is listed twice")
        seen.add(e.path)
    return entries


def sha256(path: Path) -> str:
    """The SHA-256 of a file, hex."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def mirror_dir() -> Path | None:
    """The local copy of the data folder: ``TRIAXCAL_REALDATA``, else ../shared/realdata."""
    env = os.environ.get(MIRROR_ENV)
    if env:
        p = Path(env).expanduser()
        if not p.is_dir():
            raise DataError(f"{MIRROR_ENV}={env} is not a folder: point it at a copy of the "
                            f"data folder, or unset it to use the download cache")
        return p
    p = ROOT.parent / "shared" / "realdata"
    return p if p.is_dir() else None


def cache_dir() -> Path:
    """Where downloaded recordings are kept (``TRIAXCAL_DATA_CACHE`` moves it)."""
    env = os.environ.get(CACHE_ENV)
    if env:
        return Path(env).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "triaxcal" / "realdata"


def how_to_get(what: str, reason: str) -> str:
    """The one message of a run that cannot get the recordings: what is missing and what to do."""
    return (
        f"{what}\n  {reason}\n"
        "Get them in one of these ways, then run the tests again:\n"
        f"  * with network:    make data   (or: python tests/fetch_data.py) downloads them "
        f"into {cache_dir()} ({CACHE_ENV} moves it)\n"
        "  * without network: on a machine with network run "
        "`python tests/fetch_data.py --copy-to DIR`,\n"
        f"                     carry DIR here and set {MIRROR_ENV}=DIR "
        "(every file is checked against its SHA-256)"
    )


def _unreachable(n: int) -> str:
    return (f"{n} of the real recordings the tests read (tests/data/registry.txt) are not here "
            "and could not be downloaded:")


def _download(entries: list[Entry], cache: Path, progress: bool) -> dict[str, Path]:
    """Fetch into the cache with pooch (a cached file with the right hash is not fetched again)."""
    try:
        import pooch
    except ImportError as exc:  # the `test` extra installs it
        raise DataError(how_to_get(_unreachable(len(entries)), f"pooch is not installed "
                                   f"({exc}); pip install -e '.[test]' installs it")) from exc
    import logging

    pooch.get_logger().setLevel(logging.INFO if progress else logging.WARNING)
    store = pooch.create(path=cache, base_url="",
                         registry={e.path: f"sha256:{e.sha256}" for e in entries},
                         urls={e.path: e.url for e in entries}, retry_if_failed=1)
    downloader = pooch.HTTPDownloader(timeout=60, progressbar=False)
    out = {}
    for e in entries:
        try:
            out[e.path] = Path(store.fetch(e.path, downloader=downloader))
        except Exception as exc:  # no network, HTTP error, or a download that differs
            missing = len(entries) - len(out)
            raise DataError(how_to_get(_unreachable(missing),
                                       f"{e.url}: {type(exc).__name__}: {exc}")) from exc
    return out


def locate(entries: list[Entry] | None = None, *, download: bool = True,
           progress: bool = False) -> dict[str, Path]:
    """Every registry file as ``{path: file}``, each checked against its SHA-256.

    Raises DataError with one message saying what is wrong and what to do: a file that differs
    from the registry (refused), or files that are neither here nor downloadable.
    """
    entries = read_registry() if entries is None else entries
    mirror = mirror_dir()
    cache = cache_dir()
    found: dict[str, Path] = {}
    refused: list[str] = []
    missing: list[Entry] = []
    for e in entries:
        for src in (DATA / e.path, mirror / e.path if mirror else None):
            if src is not None and src.is_file():
                got = sha256(src)
                if got == e.sha256:
                    found[e.path] = src
                else:
                    refused.append(f"{src}: SHA-256 {got}, the registry says {e.sha256}")
                break
        else:
            cached = cache / e.path
            if not download and cached.is_file() and sha256(cached) == e.sha256:
                found[e.path] = cached
            else:
                missing.append(e)
    if refused:
        raise DataError(
            f"refused {len(refused)} recording(s) that differ from the published file "
            f"(tests/data/registry.txt):\n  " + "\n  ".join(refused)
            + f"\nReplace them with the files at the registry's URLs (or unset {MIRROR_ENV} "
            "to use the download cache).")
    if missing:
        if not download:
            names = ", ".join(e.path for e in missing[:3]) + (", ..." if len(missing) > 3 else "")
            raise DataError(how_to_get(
                f"{len(missing)} of the real recordings the tests read (tests/data/registry.txt) "
                "are neither kept here, nor in a local copy, nor in the download cache:", names))
        found.update(_download(missing, cache, progress))
    return found


def make_tree(found: dict[str, Path], dest: Path) -> Path:
    """One folder laid out as the registry says: a symbolic link (or a copy) per file."""
    for rel, src in found.items():
        target = dest / rel
        target.parent.mkdir(parents=True, exist_ok=True)
        if target.is_symlink() or target.exists():
            target.unlink()
        try:
            target.symlink_to(src.resolve())
        except OSError:  # no symbolic links on this file system
            shutil.copyfile(src, target)
    return dest


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--check", action="store_true",
                    help="only say where each file comes from; download nothing")
    ap.add_argument("--copy-to", metavar="DIR", type=Path,
                    help="also copy every file into DIR (a local copy for a machine offline)")
    args = ap.parse_args(argv)
    entries = read_registry()
    try:
        found = locate(entries, download=not args.check, progress=not args.check)
    except DataError as exc:
        print(exc, file=sys.stderr)
        return 1
    mirror = mirror_dir()
    where: dict[str, int] = {}
    for src in found.values():
        if src.is_relative_to(DATA):
            key = f"{DATA.relative_to(ROOT)} (kept in the repository)"
        elif mirror is not None and src.is_relative_to(mirror):
            key = f"{mirror} (local copy)"
        else:
            key = f"{cache_dir()} (download cache)"
        where[key] = where.get(key, 0) + 1
    size = sum(p.stat().st_size for p in found.values())
    print(f"{len(found)} recordings ({size / 1e6:.1f} MB), every SHA-256 as registered:")
    for key, n in where.items():
        print(f"  {n:3d} from {key}")
    if args.copy_to:
        for rel, src in found.items():
            (args.copy_to / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(src, args.copy_to / rel)
        print(f"copied into {args.copy_to}: use it with {MIRROR_ENV}={args.copy_to.resolve()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
