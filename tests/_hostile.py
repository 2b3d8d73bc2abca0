"""Helpers of the hostile-input tests (test_hostile_io.py, test_hostile_logs.py): the corpus
runner (each case read in a child process) and the builders of mutated files."""

from __future__ import annotations

import bz2
import os
import random
import struct
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
import triaxcal as tc

WEAR = "wearables-ggirread"
ROS = "ros1-imu-tools-madgwick"

needs_skdh = pytest.mark.skipif(
    __import__("importlib").util.find_spec("skdh") is None, reason="needs scikit-digital-health")


# --------------------------------------------------------------------------------------------
# the corpus runner: each case read in a child process


_RUNNER = r"""
import resource, sys, warnings
warnings.simplefilter("ignore")
import triaxcal as tc
from triaxcal.io.tables import read_table
from triaxcal.io.wearables import read_wearable
kind, paths = sys.argv[1], sys.argv[2:]
read = {"wearable": read_wearable, "log": tc.read_log, "table": read_table,
        "calibration": tc.Calibration.load}[kind]
for i, p in enumerate(paths):
    print("START", i, flush=True)
    try:
        read(p)
        out = "ok"
    except tc.CalibrationError:
        out = "refused"
    except BaseException as exc:
        out = "EXCEPTION " + type(exc).__name__ + ": " + repr(str(exc)[:200])
    print("END", i, out, flush=True)
# ru_maxrss of this process would count the test runner it was forked from (Linux keeps the
# high-water mark across exec); VmHWM is this process's own address space since exec.
me = next(int(ln.split()[1]) for ln in open("/proc/self/status") if ln.startswith("VmHWM:"))
kids = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
print("RSS", me, kids, flush=True)
"""


def run_corpus(kind: str, cases: dict[str, Path], *, timeout: float = 120.0,
               max_rss_mb: float = 1500.0) -> dict[str, str]:
    """Read every case in one child process; fail on a crash, a hang, an exception other than
    CalibrationError, or a peak resident memory (of the child or of a reader it started) past
    ``max_rss_mb``. Returns each case's outcome ("ok" or "refused")."""
    names = list(cases)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(Path(tc.__file__).parent.parent), os.environ.get("PYTHONPATH", "")]))
    proc = subprocess.Popen(
        [sys.executable, "-c", _RUNNER, kind, *[str(cases[n]) for n in names]],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, stdin=subprocess.DEVNULL, env=env,
        text=True, errors="replace")
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
        started = [ln for ln in out.splitlines() if ln.startswith("START")]
        last = names[int(started[-1].split()[1])] if started else "?"
        pytest.fail(f"{kind} corpus: hang (killed after {timeout:.0f} s) at case {last!r}")
    finally:
        if proc.poll() is None:  # the test itself timed out: leave no process behind
            proc.kill()
            proc.wait()
    outcome: dict[str, str] = {}
    current = None
    for line in out.splitlines():
        if line.startswith("START"):
            current = names[int(line.split()[1])]
        elif line.startswith("END"):
            _, i, res = line.split(" ", 2)
            outcome[names[int(i)]] = res
            current = None
    if proc.returncode != 0:
        pytest.fail(f"{kind} corpus: the process died (exit status {proc.returncode}) at case "
                    f"{current!r}: {err[-800:]}")
    bad = {n: r for n, r in outcome.items() if r not in ("ok", "refused")}
    assert not bad, f"{kind} corpus: exceptions other than CalibrationError: {bad}"
    assert len(outcome) == len(names)
    rss = [ln for ln in out.splitlines() if ln.startswith("RSS")][-1].split()
    peak_mb = max(int(rss[1]), int(rss[2])) / 1024  # both in KiB
    assert peak_mb < max_rss_mb, f"{kind} corpus: peak memory {peak_mb:.0f} MB"
    return outcome


def cuts(data: bytes, offsets: list[int], name: str, folder: Path, suffix: str,
         seed: int = 0, n_random: int = 6) -> dict[str, Path]:
    """``data`` cut at ``offsets`` and at ``n_random`` more places."""
    rng = random.Random(seed)
    places = sorted({o for o in offsets if 0 <= o < len(data)}
                    | {rng.randrange(len(data)) for _ in range(n_random)})
    out = {}
    for o in places:
        p = folder / f"{name}-cut{o}{suffix}"
        p.write_bytes(data[:o])
        out[p.stem] = p
    return out


def changed(data: bytes, edits: dict[int, int]) -> bytes:
    b = bytearray(data)
    for at, value in edits.items():
        b[at] = value
    return bytes(b)


def flips(data: bytes, offsets: list[int], name: str, folder: Path, suffix: str,
          extremes: bool = True) -> dict[str, Path]:
    """``data`` with the byte at each offset inverted, and (``extremes``) set to 0x00 and to
    0xFF."""
    out = {}
    for o in offsets:
        if o >= len(data):
            continue
        for tag, value in (("x", data[o] ^ 0xFF), ("0", 0x00), ("f", 0xFF))[:3 if extremes else 1]:
            if value == data[o]:
                continue
            p = folder / f"{name}-{tag}{o}{suffix}"
            p.write_bytes(changed(data, {o: value}))
            out[p.stem] = p
    return out


def write(folder: Path, name: str, data: bytes) -> dict[str, Path]:
    p = folder / name
    p.write_bytes(data)
    return {p.stem: p}


def sparse(path: Path, size: int) -> Path:
    """A file of ``size`` zero bytes that takes no disk space."""
    with open(path, "wb") as f:
        f.truncate(size)
    return path


def cwa_fix_checksum(b: bytearray, block: int) -> None:
    """Make the 16-bit words of 512-byte ``block`` add up to 0 again (a valid block)."""
    at = 512 * block
    total = int(np.frombuffer(bytes(b[at:at + 510]), "<u2").astype(np.int64).sum())
    struct.pack_into("<H", b, at + 510, (-total) & 0xFFFF)


def cwa_with(data: bytes, block: int, fmt: str, offset: int, value: int) -> bytes:
    """``data`` with a field of ``block`` set and its checksum made good again (what a
    damaged or crafted file that skdh accepts as valid looks like)."""
    b = bytearray(data)
    struct.pack_into(fmt, b, 512 * block + offset, value)
    cwa_fix_checksum(b, block)
    return bytes(b)


def geneactiv_whole(realdata: Path, pages: int = 16) -> bytes:
    """The real GENEActiv test file (cut at 64 KB, its header says 222,048 pages) made whole:
    its first ``pages`` pages, and a header that says so."""
    raw = (realdata / WEAR / "GENEActiv_testfile.bin").read_bytes()
    i = raw.index(b"Recorded Data")
    body = raw[i:].split(b"Recorded Data")[1:pages + 1]
    return (raw[:i].replace(b"Number of Pages:222048", f"Number of Pages:{pages}".encode())
            + b"".join(b"Recorded Data" + page for page in body))


def zip_of(path: Path, entries: dict[str, bytes], method: int = zipfile.ZIP_DEFLATED) -> Path:
    with zipfile.ZipFile(path, "w", method) as z:
        for name, data in entries.items():
            z.writestr(name, data)
    return path


def ros1_records(data: bytes) -> list[tuple[int, list[tuple[bytes, bytes]], bytes]]:
    """The records of a ROS 1 bag: (position, header fields in order, data)."""
    out = []
    pos = 13
    while pos < len(data):
        hlen = struct.unpack_from("<I", data, pos)[0]
        h = data[pos + 4:pos + 4 + hlen]
        fields, i = [], 0
        while i < len(h):
            n = struct.unpack_from("<I", h, i)[0]
            name, _, value = h[i + 4:i + 4 + n].partition(b"=")
            fields.append((name, value))
            i += 4 + n
        dlen = struct.unpack_from("<I", data, pos + 4 + hlen)[0]
        out.append((pos, fields, data[pos + 8 + hlen:pos + 8 + hlen + dlen]))
        pos += 8 + hlen + dlen
    return out


def ros1_build(records: list[tuple[int, list[tuple[bytes, bytes]], bytes]]) -> bytes:
    """A ROS 1 bag of ``records``, with the bag header's index_pos and the chunk infos'
    chunk_pos moved to where their records are now."""
    def encode(fields):
        return b"".join(struct.pack("<I", len(k) + 1 + len(v)) + k + b"=" + v for k, v in fields)

    moved, pos = {}, 13
    for old, fields, data in records:
        moved.setdefault(old, pos)
        pos += 8 + len(encode(fields)) + len(data)
    out = [b"#ROSBAG V2.0\n"]
    for _, fields, data in records:
        fixed = []
        for k, v in fields:
            if k in (b"index_pos", b"chunk_pos") and len(v) == 8:
                at = struct.unpack("<Q", v)[0]
                v = struct.pack("<Q", moved.get(at, at))
            fixed.append((k, v))
        h = encode(fixed)
        out.append(struct.pack("<I", len(h)) + h + struct.pack("<I", len(data)) + data)
    return b"".join(out)


def ros1_bomb(bag: bytes, extra: int) -> bytes:
    """``bag`` with its first chunk unpacking to ``extra`` zero bytes more than it says."""
    recs = ros1_records(bag)
    k = next(i for i, (_, f, _) in enumerate(recs) if dict(f).get(b"op") == b"\x05")
    pos, fields, data = recs[k]
    assert dict(fields)[b"compression"] == b"bz2"
    recs[k] = (pos, fields, bz2.compress(bz2.decompress(data) + bytes(extra), 1))
    return ros1_build(recs)


def ros1_uncompressed(bag: bytes) -> bytes:
    """``bag`` with its chunks stored unpacked (compression "none")."""
    recs = []
    for pos, fields, data in ros1_records(bag):
        f = dict(fields)
        if f.get(b"op") == b"\x05" and f[b"compression"] == b"bz2":
            data = bz2.decompress(data)
            fields = [(k, b"none" if k == b"compression" else v) for k, v in fields]
        recs.append((pos, fields, data))
    return ros1_build(recs)
