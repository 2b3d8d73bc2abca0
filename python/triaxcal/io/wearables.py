"""Wearable accelerometer files in: Axivity ``.cwa``, GENEActiv ``.bin``, ActiGraph ``.gt3x``.

The readers are the maintained packages' (``pip install 'triaxcal[wearables]'``):

* Axivity AX3 / AX6 ``.cwa`` -- ``scikit-digital-health`` (``skdh.io.ReadCwa``);
* GENEActiv ``.bin`` -- ``skdh.io.ReadBin``; its text header (device, serial, the maker's
  factory calibration) is parsed here, and a file too short or cut off for skdh (it refuses
  fewer than 3600 samples) is decoded page by page here: each page is a text block whose last
  line holds 300 samples of 12 hex digits, x, y, z as 12-bit two's complement counts, then
  10 bits of light, the button and a reserved bit;
* ActiGraph ``.gt3x`` -- ``pygt3x`` (ActiGraph's own reader).

The files are hostile until checked: each is refused unless it is a regular file (see
:func:`triaxcal.io.files.check_regular`), and its structure is checked before a third-party
reader sees it -- an Axivity file's ``MD`` header and 512-byte ``AX`` blocks (sample format,
sample count, checksum, and that each block's sequence number points inside the file), a
GENEActiv file's text header and every page's ten lines, an ActiGraph file's zip directory and
the sizes it declares. skdh's readers are compiled code that trusts the file (a sequence number
past the end makes it write past its arrays; a header without ``Calibration Data`` makes it loop
for ever), so they run in a child process with time and memory limits
(:mod:`triaxcal.io.isolate`): a crash or a time-out is a :class:`~triaxcal.CalibrationError`
that says the file is damaged. A GENEActiv file that is cut short or not laid out exactly as
skdh expects is decoded here, page by page, in Python.

Every reader returns a :class:`WearableRecording` with the acceleration in g as the device's
maker calibrated it (that is the input :func:`triaxcal.autocalibrate` expects), the sample
rate, the time stamps and the temperature when the device records one.

GENEActiv factory calibration (header ``Calibration Data``): ``g = (raw * 100 - offset) /
gain`` per axis, raw in counts. In triaxcal's convention that is ``g = (raw - offset / 100) *
(100 / gain)``: :attr:`WearableRecording.factory` is a :class:`FactoryCalibration` with
``offset = offset / 100`` counts and ``diag = 100 / gain`` g per count (which **multiplies**);
:func:`triaxcal.calibration.parts.part_from_factory` makes it a calibration file's part.
"""

from __future__ import annotations

import contextlib
import importlib.util
import logging
import re
import struct
import sys
import warnings
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from ..errors import CalibrationError
from .files import check_regular, open_regular, os_error_message, said
from .isolate import run_native

__all__ = [
    "FactoryCalibration", "WearableRecording", "geneactiv_header", "read_geneactiv_pages",
    "read_wearable"]

FORMATS = {".cwa": "Axivity", ".bin": "GENEActiv", ".gt3x": "ActiGraph"}
#: Samples per GENEActiv data page.
PAGE_SAMPLES = 300
#: Largest Axivity file read: skdh's reader keeps file positions in 32-bit integers.
MAX_CWA_BYTES = (1 << 31) - 1
#: Most entries in an ActiGraph .gt3x zip (a real one holds two to five).
MAX_GT3X_ENTRIES = 64
#: Largest size a .gt3x entry may declare, and the most it may expand (uncompressed size over
#: compressed size): a "zip bomb" is refused before it is opened.
MAX_GT3X_ENTRY_BYTES = 1 << 32
MAX_GT3X_RATIO = 200
# Longest line of a GENEActiv header read (a real one is under 120 bytes).
_LINE = 4096


@dataclass(frozen=True)
class FactoryCalibration:
    """A maker's calibration read from a file header (GENEActiv's ``Calibration Data``), in
    triaxcal's convention ``g = (counts - offset) * diag`` per axis.

    Attributes
    ----------
    offset : ndarray (3,)
        Counts.
    diag : ndarray (3,)
        g per count; it **multiplies**.
    date, source : str
        The calibration date the header gives, and the file.
    """

    offset: np.ndarray
    diag: np.ndarray
    date: str = ""
    source: str = ""

    def apply(self, counts: Any) -> np.ndarray:
        """Counts (N, 3) to g."""
        return (np.asarray(counts, dtype=np.float64) - self.offset) * self.diag


@dataclass(frozen=True)
class WearableRecording:
    """A wearable's recording.

    ``acc_g`` (N, 3) acceleration in g (maker-calibrated); ``rate_hz``; ``time_s`` (N,) Unix
    seconds or ``None``; ``temp_c`` (N,) degC or ``None``; ``device`` e.g. ``"GENEActiv 1.1"``;
    ``serial``; ``reader`` the package that decoded the samples; ``factory`` the maker's
    calibration when the file holds it (GENEActiv); ``raw_counts`` (N, 3) when decoded here;
    ``meta`` everything else read from the header.
    """

    path: Path
    acc_g: np.ndarray
    rate_hz: float
    time_s: np.ndarray | None
    temp_c: np.ndarray | None
    device: str
    serial: str | None
    reader: str
    factory: FactoryCalibration | None = None
    raw_counts: np.ndarray | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.acc_g)

    @property
    def hours(self) -> float:
        return len(self.acc_g) / self.rate_hz / 3600.0


def _need(module: str) -> Any:
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError:
        raise CalibrationError(
            f"reading wearable files needs {module.split('.')[0]}: pip install "
            "'triaxcal[wearables]'"
        ) from None


def _installed(module: str) -> bool:
    """Whether ``module`` can be imported, without importing it (skdh takes seconds)."""
    if module in sys.modules:
        return sys.modules[module] is not None
    top = module.split(".")[0]
    if top in sys.modules:
        return sys.modules[top] is not None
    try:
        return importlib.util.find_spec(top) is not None
    except (ImportError, ValueError):
        return False


def _need_installed(module: str) -> None:
    if not _installed(module):
        raise CalibrationError(
            f"reading wearable files needs {module.split('.')[0]}: pip install "
            "'triaxcal[wearables]'"
        )


def read_wearable(path: Any) -> WearableRecording:
    """Read an Axivity ``.cwa``, GENEActiv ``.bin`` or ActiGraph ``.gt3x`` file.

    Examples
    --------
    >>> rec = read_wearable("ax3.cwa")  # doctest: +SKIP
    >>> rec.acc_g.shape, rec.rate_hz, rec.device  # doctest: +SKIP
    ((17400, 3), 100.0, 'Axivity AX3')
    """
    p = Path(path)
    st = check_regular(p, what="wearable file")
    kind = FORMATS.get(p.suffix.lower())
    if kind is None:
        raise CalibrationError(
            f"{p.name}: unknown wearable format {p.suffix!r}; triaxcal reads "
            + ", ".join(f"{v} {k}" for k, v in FORMATS.items()))
    if kind == "Axivity":
        return _read_cwa(p, st.st_size)
    if kind == "GENEActiv":
        return _read_geneactiv(p, st.st_size)
    return _read_gt3x(p, st.st_size)


@contextlib.contextmanager
def _quiet(logger: str = "pygt3x") -> Any:
    """Collect the reader's warnings, what it logs (pygt3x logs a warning per damaged event,
    which Python's last-resort handler would print on the terminal) and what it prints, as a
    bounded list of text."""
    sink = _Sink()
    handler = logging.StreamHandler(sink)
    handler.setLevel(logging.WARNING)
    log = logging.getLogger(logger)
    propagate = log.propagate
    log.addHandler(handler)
    log.propagate = False
    out: list[str] = []
    try:
        with warnings.catch_warnings(record=True) as caught, contextlib.redirect_stdout(sink):
            warnings.simplefilter("always")
            yield out
    finally:
        log.removeHandler(handler)
        log.propagate = propagate
    out += [str(w.message) for w in caught] + sink.summary()


class _Sink:
    """A bounded stand-in for standard output: keeps the first lines and counts the rest."""

    def __init__(self, keep: int = 5) -> None:
        self.lines: list[str] = []
        self.more = 0
        self.keep = keep
        self.part = ""

    def write(self, text: str) -> int:
        self.part = (self.part + text)[-4096:]
        *done, self.part = self.part.split("\n")
        for line in done:
            if not line.strip():
                continue
            if len(self.lines) < self.keep:
                self.lines.append(line.strip()[:200])
            else:
                self.more += 1
        return len(text)

    def flush(self) -> None:
        pass

    def summary(self) -> list[str]:
        return self.lines + ([f"... and {self.more} more lines like these"] if self.more else [])


def _u16(b: bytes, at: int) -> int:
    return int(struct.unpack_from("<H", b, at)[0])


def check_cwa(path: Any, size: int | None = None) -> dict[str, Any]:
    """Check an Axivity ``.cwa`` file's structure before skdh's reader sees it.

    The layout (Axivity's ``cwa.h``, as skdh's ``read_axivity.f95`` reads it): a 1024-byte
    header that starts ``MD`` with a packet length of 1020, then 512-byte blocks; a data block
    starts ``AX`` with a packet length of 508; byte 25 holds the number of axes (high
    nibble) and the packing (low nibble: 0 = 3 axes in 4 bytes, 2 = 16-bit values), bytes
    28-29 the sample count, bytes 10-13 the block's sequence number, bytes 510-511 a checksum
    (the 16-bit words of a block add up to 0). skdh reads the axes and the sample count from
    the first block and puts every block whose checksum holds at ``sequence x count``, with
    no bound check, and fills the time stamps around damaged blocks without one either.

    Refused: a file without the header or a first data block; a header of the wrong length;
    a first block that is not ``AX`` or whose axes disagree with the header's sensor set;
    a sample count or packing skdh does not read; a block of another sample format than the
    first; a block that skdh would take (``AX``, checksum good) whose sequence number lies
    outside the file; damaged blocks when the first or the last place in the file is not
    filled by a good block.

    Returns the header's ``device_id``, ``axes``, ``count`` (samples per block), ``blocks``
    (data blocks) and ``bad_blocks``.
    """
    p = Path(path)
    size = check_regular(p, what="wearable file").st_size if size is None else size
    bad = f"{p.name} is not a readable Axivity .cwa file"
    if size > MAX_CWA_BYTES:
        raise CalibrationError(f"{bad}: it is {size / 1e9:.1f} GB; the reader (scikit-digital-"
                               "health) reads Axivity files of less than 2 GiB")
    if size < 1024 + 512:
        raise CalibrationError(f"{bad}: {size} bytes, too short for its 1024-byte header and "
                               "one 512-byte data block")
    nblocks = size // 512 - 2
    with open_regular(p, what="wearable file") as f:
        head = f.read(1024)
        if head[:2] != b"MD":
            raise CalibrationError(f"{bad}: it does not start with the 'MD' header block")
        if _u16(head, 2) != 1020:
            raise CalibrationError(f"{bad}: its header block says it is {_u16(head, 2) + 4} "
                                   "bytes long (1024 in an Axivity file)")
        cfg = head[35]
        axes = 3 if cfg in (0, 0xFF) else (9 if cfg >> 4 else 6)
        first = f.read(512)
        if len(first) < 512 or first[:2] != b"AX" or _u16(first, 2) != 508:
            raise CalibrationError(f"{bad}: its first data block (bytes 1024-1535) is not an "
                                   "'AX' block of 512 bytes")
        fmt = first[25]
        count = struct.unpack_from("<h", first, 28)[0]
        pack = fmt & 0x0F
        if fmt >> 4 != axes:
            raise CalibrationError(f"{bad}: its first block holds {fmt >> 4} axes, its header "
                                   f"{axes}")
        ok_count = {3: (80, 120), 6: (40,), 9: tuple(range(1, 27))}[axes]
        if pack not in (0, 2) or count not in ok_count or (pack == 0 and (axes, count) != (3, 120)):
            raise CalibrationError(f"{bad}: its blocks hold {count} samples of {axes} axes in "
                                   f"packing {pack}, which the reader does not read")
        # the 16-bit words skdh adds up per block: 15 of the header, the samples, the checksum
        ndata = 240 if pack == 0 else axes * min(count, 80)
        words = np.r_[np.arange(15), np.arange(15, 15 + ndata), 255]
        f.seek(1024)
        seen = np.zeros(nblocks, dtype=bool)  # places filled by a good block
        n_bad = 0
        done = 0
        while done < nblocks:
            raw = f.read(512 * min(8192, nblocks - done))
            k = len(raw) // 512
            if k == 0:
                raise CalibrationError(f"{bad}: it became shorter while it was read")
            blk = np.frombuffer(raw[:512 * k], dtype=np.uint8).reshape(k, 512)
            w = blk.view("<u2")
            is_ax = (w[:, 0] == 0x5841) & (w[:, 1] == 508)
            good = is_ax & ((w[:, words].astype(np.int64).sum(axis=1) & 0xFFFF) == 0)
            other = is_ax & (blk[:, 25] != fmt)
            if other.any():
                j = int(np.argmax(other)) + done + 2
                raise CalibrationError(f"{bad}: block {j} holds another sample format than "
                                       "the first (damaged, or written by another device)")
            seq = blk[:, 10:14].copy().view("<i4").ravel()
            out = good & ((seq < 0) | (seq >= nblocks))
            if out.any():
                j = int(np.argmax(out))
                raise CalibrationError(
                    f"{bad}: block {done + j + 2} says it is number {int(seq[j])} of a file of "
                    f"{nblocks} blocks (damaged, or cut from a longer recording)"
                )
            seen[seq[good]] = True
            n_bad += int((~good).sum())
            done += k
    if n_bad and not (seen[0] and seen[-1]):
        raise CalibrationError(
            f"{bad}: {n_bad} of its {nblocks} blocks are damaged and its "
            f"{'first' if not seen[0] else 'last'} block is one of them; the reader cannot "
            "place the good blocks' times around them"
        )
    return {"device_id": _u16(head, 5) | ((0 if _u16(head, 11) == 0xFFFF else _u16(head, 11))
                                          << 16),
            "axes": axes, "count": count, "blocks": nblocks, "bad_blocks": n_bad}


def _read_cwa(p: Path, size: int) -> WearableRecording:
    _need_installed("skdh.io")
    info = check_cwa(p, size)
    meta, r = run_native("skdh-cwa", p, what="an Axivity .cwa file", size=size)
    acc = np.asarray(r.get("accel"), dtype=np.float64)
    if acc.ndim != 2 or acc.shape[1] != 3 or len(acc) == 0:
        raise CalibrationError(f"{p.name}: no acceleration samples in the file")
    temp = r.get("temperature")
    return WearableRecording(
        path=p, acc_g=acc, rate_hz=float(meta["fs"]),
        time_s=np.asarray(r["time"], np.float64),
        temp_c=None if temp is None else np.asarray(temp, np.float64),
        device="Axivity AX6" if "gyro" in r else "Axivity AX3",
        serial=str(info["device_id"]), reader="scikit-digital-health ReadCwa",
        meta={"warnings": meta.get("warnings", []), "has_gyro": "gyro" in r,
              "bad_blocks": info["bad_blocks"]})


def _lines(f: BinaryIO, limit: int = _LINE) -> Any:
    """Lines of ``f`` as text (latin-1, line break and surrounding blanks dropped), each read
    with at most ``limit`` bytes (a longer line comes in pieces: memory stays bounded)."""
    while True:
        raw = f.readline(limit)
        if not raw:
            return
        yield raw.decode("latin-1").strip()


def geneactiv_header(path: Any) -> dict[str, str]:
    """The text header of a GENEActiv ``.bin`` file (up to ``Recorded Data``) as key: value.

    The file must start with the line ``Device Identity`` and name a ``GENEActiv`` device
    type; at most 200 lines of at most 4096 bytes are read."""
    p = Path(path)
    out: dict[str, str] = {}
    with open_regular(p, what="wearable file") as f:
        for n, line in enumerate(_lines(f)):
            if n == 0 and line != "Device Identity":
                raise CalibrationError(f"{p.name} is not a GENEActiv .bin file (it does not "
                                       "start with the line 'Device Identity')")
            if line == "Recorded Data" or n > 200:
                break
            key, sep, value = line.partition(":")
            if sep and key.strip():
                out.setdefault(key.strip(), value.strip())
    if "Device Type" not in out or not out["Device Type"].startswith("GENEActiv"):
        raise CalibrationError(f"{p.name} is not a GENEActiv .bin file (no GENEActiv header)")
    return out


def _factory(header: dict[str, str], source: str) -> FactoryCalibration:
    try:
        gain = np.array([float(header[f"{a} gain"]) for a in "xyz"])
        off = np.array([float(header[f"{a} offset"]) for a in "xyz"])
    except (KeyError, ValueError):
        raise CalibrationError("the GENEActiv header has no usable Calibration Data") from None
    ok = np.isfinite(gain) & np.isfinite(off) & (np.abs(off) < 1e12)
    with np.errstate(divide="ignore", over="ignore"):
        ok &= (gain > 0) & np.isfinite(100.0 / gain) & (100.0 / gain > 0)
    if not ok.all():
        raise CalibrationError(f"implausible GENEActiv calibration: gains {gain}, offsets {off}")
    return FactoryCalibration(offset=off / 100.0, diag=100.0 / gain,
                              date=header.get("Calibration Date", ""), source=source)


# Hex digit values (255: not a hex digit), for decoding a page's 3600 characters at once.
_HEX = np.full(256, 255, dtype=np.uint8)
_HEX[np.frombuffer(b"0123456789", np.uint8)] = np.arange(10)
_HEX[np.frombuffer(b"ABCDEF", np.uint8)] = np.arange(10, 16)
_HEX[np.frombuffer(b"abcdef", np.uint8)] = np.arange(10, 16)


def _number(text: str, low: float, high: float) -> float | None:
    """``text`` as a float in [low, high], else None."""
    try:
        x = float(text)
    except ValueError:
        return None
    return x if low <= x <= high else None


def read_geneactiv_pages(path: Any) -> tuple[np.ndarray, np.ndarray, float, int]:
    """Decode the data pages of a GENEActiv ``.bin``: ``(counts (N, 3) int, temp_c (N,),
    rate_hz, pages)``.

    Each page is ``Recorded Data``, eight lines of ``key:value`` (``Temperature``,
    ``Measurement Frequency``, ...) and a line of 300 samples of 12 hex digits. The file is
    read line by line with bounded lines; a page cut short or malformed (a truncated file, a
    temperature or rate that is not a number in range, a rate that differs from the first
    page's) ends the reading, and everything after it is left out."""
    counts, temps, rate, pages, _ = _decode_pages(Path(path))
    return counts, temps, rate, pages


def _decode_pages(p: Path) -> tuple[np.ndarray, np.ndarray, float, int, str | None]:
    """:func:`read_geneactiv_pages`, and why the reading stopped before the end (or None)."""
    hexes = bytearray()
    temps: list[float] = []
    rate = 0.0
    stop: str | None = None
    with open_regular(p, what="wearable file") as f:
        lines = _lines(f, 2 * 12 * PAGE_SAMPLES)
        for line in lines:
            if line == "Recorded Data":
                break
        while True:
            k = len(temps)
            block = [ln for _, ln in zip(range(9), lines)]
            if len(block) < 9:
                stop = f"the file ends inside page {k} (cut short)"
                break
            meta = {k.strip(): v.strip() for k, _, v in (ln.partition(":") for ln in block[:8])}
            t = _number(meta.get("Temperature", ""), -100.0, 200.0)
            r = _number(meta.get("Measurement Frequency", ""), 1e-3, 1e5)
            data = block[8].encode("latin-1")
            if t is None:
                stop = (f"page {k}: Temperature {said(meta.get('Temperature'), 40)!r} is not a "
                        "temperature in deg C")
            elif r is None:
                stop = (f"page {k}: Measurement Frequency "
                        f"{said(meta.get('Measurement Frequency'), 40)!r} is not a rate in Hz")
            elif rate and r != rate:
                stop = f"page {k}: Measurement Frequency {r:g} differs from page 0's {rate:g}"
            elif (len(data) != 12 * PAGE_SAMPLES
                  or (_HEX[np.frombuffer(data, np.uint8)] == 255).any()):
                stop = f"page {k}: its data line is not {12 * PAGE_SAMPLES} hex digits"
            if stop is not None:
                break
            assert r is not None and t is not None
            rate = r
            hexes += data
            temps.append(t)
            following = next(lines, None)
            if following != "Recorded Data":
                if following is not None:
                    stop = f"after page {k}: a line that is not 'Recorded Data'"
                break
    if not temps:
        raise CalibrationError(f"{p.name}: no complete data page ({stop})")
    nib = _HEX[np.frombuffer(bytes(hexes), np.uint8)].reshape(-1, 12).astype(np.int64)
    xyz = np.stack([nib[:, 3 * a] * 256 + nib[:, 3 * a + 1] * 16 + nib[:, 3 * a + 2]
                    for a in range(3)], axis=1)
    xyz = np.where(xyz >= 2048, xyz - 4096, xyz)
    return xyz, np.repeat(np.asarray(temps), PAGE_SAMPLES), rate, len(temps), stop


# skdh's GENEActiv reader (read_geneactiv.c) reads the header and each page with fgets into
# 255-byte (data: 3610-byte) buffers at fixed line numbers, and takes values from fixed columns
# with strtok/strtol, with no check: a missing ':' is a NULL pointer, a missing "Calibration
# Data" line a loop that never ends, a sequence number past the header's page count a write
# past its arrays. So a file goes to skdh only if it is laid out exactly as it expects.
_PAGE = (
    re.compile(rb"Recorded Data\r?\n"),
    re.compile(rb"Device Unique Serial Code:[^\x00]*\r?\n"),
    re.compile(rb"Sequence Number:(\d{1,9})\r?\n"),
    re.compile(rb"Page Time:\d{4}-\d{2}-\d{2} \d{2}:\d{2}:\d{2}:\d{3}\r?\n"),
    re.compile(rb"Unassigned:[^\x00]*\r?\n"),
    re.compile(rb"Temperature:-?\d{1,3}(\.\d+)?\r?\n"),
    re.compile(rb"Battery voltage:[^\x00]*\r?\n"),
    re.compile(rb"Device Status:[^\x00]*\r?\n"),
    re.compile(rb"Measurement Frequency:\d{1,4}(\.\d+)?\r?\n"),
    re.compile(rb"[0-9A-Fa-f]{3600}\r?\n"),
)
_KEY_VALUE = re.compile(rb"[^:\x00]+:+[^:\x00]")  # what strtok(buf, ":") needs twice


def skdh_geneactiv_problem(path: Any, size: int | None = None) -> str | None:
    """Why skdh's GENEActiv reader must not be given ``path``, or None when the file is laid
    out exactly as that reader expects: the header's 59 lines with ``key:value`` where it
    reads values and a ``Calibration Data`` line, a page count the file can hold, and then
    exactly that many pages of ten lines, numbered 0, 1, 2, ..."""
    p = Path(path)
    size = check_regular(p, what="wearable file").st_size if size is None else size
    with open_regular(p, what="wearable file") as f:
        head = [f.readline(254) for _ in range(20)]
        if not head[-1] or not _KEY_VALUE.match(head[19]):
            return "line 20 of the header is not 'Measurement Frequency:...'"
        line, n = head[19], 20
        while not line.startswith(b"Calibration Data"):
            line, n = f.readline(254), n + 1
            if not line or n > 200:
                return "the header has no 'Calibration Data' line"
        for _ in range(6):
            if not _KEY_VALUE.match(f.readline(254)):
                return "the six lines after 'Calibration Data' are not 'x gain:...' etc."
        rest = [f.readline(254) for _ in range(6)]
        m = re.match(rb"Number of Pages:(\d{1,9})\r?\n", rest[4])
        if not m or not rest[5].endswith(b"\n"):
            return "line 58 of the header is not 'Number of Pages:N'"
        pages = int(m.group(1))
        if not 0 < pages <= size // 3600:
            return (f"the header says it holds {pages} pages; a file of {size} bytes holds at "
                    f"most {size // 3600}")
        for k in range(pages):
            for j, rule in enumerate(_PAGE):
                line = f.readline(3609 if j == 9 else 254)
                m = rule.fullmatch(line)
                if m is None:
                    if not line and j == 0:
                        return f"the file holds {k} of the {pages} pages its header says"
                    return f"page {k} (line {j + 1} of it) is cut short or malformed"
                if j == 2 and int(m.group(1)) != k:
                    return f"page {k} is numbered {int(m.group(1))}"
    return None


def _read_geneactiv(p: Path, size: int) -> WearableRecording:
    header = geneactiv_header(p)
    factory = _factory(header, str(p))
    device = f"GENEActiv {header.get('Device Model', '')}".strip()
    serial = header.get("Device Unique Serial Code") or None
    why = skdh_geneactiv_problem(p, size)
    if why is None and not _installed("skdh.io"):
        why = "scikit-digital-health is not installed (pip install 'triaxcal[wearables]')"
    if why is None:
        try:
            meta, r = run_native("skdh-bin", p, what="a GENEActiv .bin file", size=size)
            acc = np.asarray(r["accel"], dtype=np.float64)
            if acc.ndim != 2 or acc.shape[1] != 3 or not len(acc):
                raise CalibrationError(f"{p.name}: no acceleration samples in the file")
            temp = r.get("temperature")
            return WearableRecording(
                path=p, acc_g=acc, rate_hz=float(meta["fs"]),
                time_s=np.asarray(r["time"], np.float64),
                temp_c=None if temp is None else np.asarray(temp, np.float64),
                device=device, serial=serial, reader="scikit-digital-health ReadBin",
                factory=factory, meta={"header": header, "warnings": meta.get("warnings", [])})
        except CalibrationError as exc:  # decoded page by page below
            why = str(exc)
    counts, temp, rate, pages, stop = _decode_pages(p)
    acc = factory.apply(counts.astype(np.float64))
    return WearableRecording(
        path=p, acc_g=acc, rate_hz=rate, time_s=None, temp_c=temp, device=device,
        serial=serial, reader="triaxcal GENEActiv page decoder", factory=factory,
        raw_counts=counts, meta={"header": header, "pages": pages, "skdh_refused": why,
                                 "pages_left_out": stop})


def check_gt3x(path: Any, size: int | None = None) -> None:
    """Check an ActiGraph ``.gt3x`` file (a zip) before pygt3x opens it: a zip of at most
    :data:`MAX_GT3X_ENTRIES` entries holding ``info.txt`` and ``log.bin`` (or the older
    ``log.txt`` and ``activity.bin``), each declaring at most :data:`MAX_GT3X_ENTRY_BYTES`
    and at most :data:`MAX_GT3X_RATIO` times its compressed size (zip reads never return more
    than an entry declares, so this bounds what pygt3x can unpack)."""
    p = Path(path)
    bad = f"{p.name} is not a readable ActiGraph .gt3x file"
    with open_regular(p, what="wearable file") as f:
        try:
            with zipfile.ZipFile(f) as z:
                entries = z.infolist()
        except (zipfile.BadZipFile, zipfile.LargeZipFile, ValueError, EOFError) as exc:
            raise CalibrationError(f"{bad}: not a zip archive ({said(exc)})") from None
        except OSError as exc:
            raise CalibrationError(os_error_message(exc, p, "read")) from None
    if len(entries) > MAX_GT3X_ENTRIES:
        raise CalibrationError(f"{bad}: its zip holds {len(entries)} entries")
    names = {e.filename for e in entries}
    if "info.txt" not in names or not ({"log.bin"} <= names or {"log.txt", "activity.bin"}
                                       <= names):
        raise CalibrationError(f"{bad}: its zip lacks info.txt and log.bin "
                               f"(it holds {said(', '.join(sorted(names)[:8])) or 'nothing'})")
    for e in entries:
        if e.file_size > MAX_GT3X_ENTRY_BYTES or e.file_size > MAX_GT3X_RATIO * max(
                e.compress_size, 1 << 16):
            raise CalibrationError(
                f"{bad}: its entry {said(e.filename, 60)!r} would unpack to "
                f"{e.file_size / 1e6:.0f} MB from {e.compress_size / 1e6:.1f} MB (a damaged or "
                "hostile zip)"
            )


def _read_gt3x(p: Path, size: int) -> WearableRecording:
    reader = _need("pygt3x.reader")
    check_gt3x(p, size)
    with _quiet() as caught:
        try:
            with reader.FileReader(str(p)) as f:
                info = f.info
                df = f.to_pandas()
        except Exception as exc:  # noqa: BLE001 - the reader raises many kinds
            raise CalibrationError(f"{p.name} is not a readable ActiGraph .gt3x file: "
                                   f"{type(exc).__name__}: {said(exc)}") from None
    acc = df[["X", "Y", "Z"]].to_numpy(dtype=np.float64)
    meta = {"idle_sleep_rows": int(df["IdleSleepMode"].sum()) if "IdleSleepMode" in df else 0,
            "range_g": (info.acceleration_min, info.acceleration_max),
            "scale": info.acceleration_scale, "firmware": info.firmware,
            "warnings": caught}
    return WearableRecording(
        path=p, acc_g=acc, rate_hz=float(info.sample_rate),
        time_s=np.asarray(df.index, dtype=np.float64), temp_c=None,
        device=f"ActiGraph {info.device_type}", serial=info.serial_number,
        reader="pygt3x FileReader", meta=meta)
