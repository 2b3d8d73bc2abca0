"""ROS bags checked before ``rosbags`` reads them.

``rosbags`` trusts a bag's framing: it reads a ROS 1 bag's first line without a length limit
(a file of zeros named ``.bag`` is read whole into memory before it is refused), and it unpacks
each compressed chunk with no bound on the output (a chunk of a few kB can unpack to
gigabytes). So before a bag is handed over, :func:`check_bag` walks its records, in bounded
memory, and refuses it unless

* it starts with its format's magic: ``#ROSBAG V2.0\\n`` (ROS 1), ``\\x89MCAP0\\r\\n`` at both
  ends (MCAP), ``SQLite format 3\\0`` (a ROS 2 ``.db3``), and a ROS 2 bag's ``metadata.yaml``
  is a regular file of at most :data:`MAX_METADATA_BYTES`;
* every record's declared lengths lie inside the file (ROS 1: header length, each field, data
  length; MCAP: record length and the lengths inside chunks and chunk indexes);
* every chunk declares at most :data:`MAX_CHUNK_BYTES` unpacked, and unpacks to exactly that
  (checked by unpacking it piece by piece, keeping nothing);
* every chunk the index points at (ROS 1 chunk info, MCAP chunk index) is a chunk found in
  the walk, with the sizes found there.

The formats: ROS bag 2.0 (http://wiki.ros.org/Bags/Format/2.0) and MCAP
(https://mcap.dev/spec).
"""

from __future__ import annotations

import bz2
import struct
from pathlib import Path
from typing import Any, BinaryIO, Callable

from ...errors import CalibrationError
from ..files import check_regular, open_regular

__all__ = ["MAX_CHUNK_BYTES", "MAX_METADATA_BYTES", "check_bag"]

#: Largest chunk accepted, unpacked (rosbag's default is 768 KiB, MCAP writers' a few MiB).
MAX_CHUNK_BYTES = 256 << 20
#: Largest ROS 2 ``metadata.yaml`` accepted.
MAX_METADATA_BYTES = 4 << 20
# Largest ROS 1 record header (a few named fields).
_MAX_HEADER = 1 << 20
_PIECE = 1 << 20

ROS1_MAGIC = b"#ROSBAG V2.0\n"
MCAP_MAGIC = b"\x89MCAP0\r\n"
SQLITE_MAGIC = b"SQLite format 3\x00"


def _decompressor(kind: str) -> Callable[[], Any] | None:
    if kind == "bz2":
        return bz2.BZ2Decompressor
    if kind == "lz4":
        import lz4.frame

        return lz4.frame.LZ4FrameDecompressor  # type: ignore[no-any-return]
    if kind == "zstd":
        try:
            from compression import zstd  # type: ignore[import-not-found]
        except ImportError:
            try:
                from backports import zstd  # type: ignore[import-not-found,no-redef]
            except ImportError:
                return None
        return zstd.ZstdDecompressor  # type: ignore[no-any-return]
    return None


def _unpacks_to(f: BinaryIO, length: int, kind: str, limit: int) -> int:
    """The size ``length`` bytes of ``f`` in ``kind`` compression unpack to, counted piece by
    piece (nothing kept); stops once past ``limit``. bz2 and zstd read every stream in a row
    (as their ``decompress`` functions do), lz4 the first frame (as ``lz4.frame.decompress``)."""
    make = _decompressor(kind)
    if make is None:
        raise CalibrationError(f"{kind}-compressed chunks need the {kind} package")
    dec = make()
    total = 0
    left = length
    pending = b""
    while left > 0 or pending:
        if not pending:
            pending = f.read(min(_PIECE, left))
            if not pending:
                raise ValueError("the file ends inside a chunk")
            left -= len(pending)
        try:
            out = dec.decompress(pending, max_length=_PIECE)
            pending = b""
            total += len(out)
            while not dec.eof and not dec.needs_input and total <= limit:
                out = dec.decompress(b"", max_length=_PIECE)
                total += len(out)
        except Exception as exc:  # noqa: BLE001 - each library raises its own kind
            raise ValueError(f"a {kind} chunk does not unpack ({type(exc).__name__}: "
                             f"{str(exc)[:80]})") from None
        if total > limit:
            return total
        if dec.eof:
            pending = dec.unused_data
            if kind == "lz4":
                return total
            if pending or left:
                dec = make()
    return total


def _u32(b: bytes, at: int = 0) -> int:
    return int(struct.unpack_from("<I", b, at)[0])


def _u64(b: bytes, at: int = 0) -> int:
    return int(struct.unpack_from("<Q", b, at)[0])


def _fields(h: bytes) -> dict[bytes, bytes]:
    out: dict[bytes, bytes] = {}
    i = 0
    while i < len(h):
        if len(h) - i < 4:
            raise ValueError("a header field is cut short")
        n = _u32(h, i)
        if n > len(h) - i - 4:
            raise ValueError(f"a header field declares {n} bytes, past its header")
        name, eq, value = h[i + 4:i + 4 + n].partition(b"=")
        if not eq:
            raise ValueError("a header field has no '='")
        out[name] = value
        i += 4 + n
    return out


def _check_ros1(p: Path, f: BinaryIO, size: int) -> None:
    head = f.read(len(ROS1_MAGIC))
    if head != ROS1_MAGIC:
        if head.startswith(b"#ROSBAG V"):
            raise CalibrationError(f"{p} is a ROS bag of format {head[9:12]!r}; triaxcal reads "
                                   "bag format 2.0 (ROS 1) and ROS 2 bags")
        raise CalibrationError(f"{p} is not a ROS 1 bag: it does not start with '#ROSBAG "
                               "V2.0' (an empty, damaged or other file named .bag?)")
    pos = len(ROS1_MAGIC)
    chunks: set[int] = set()
    pointed: list[int] = []
    starts_index = False
    index_pos: int | None = None
    while pos < size:
        where = f"the record at byte {pos}"
        try:
            if size - pos < 8:
                raise ValueError("the file ends inside it")
            hlen = _u32(f.read(4))
            if hlen > min(_MAX_HEADER, size - pos - 8):
                raise ValueError(f"its header declares {hlen} bytes")
            fields = _fields(f.read(hlen))
            dlen = _u32(f.read(4))
            end = pos + 8 + hlen + dlen
            if end > size:
                raise ValueError(f"it declares {dlen} bytes of data, past the end of the file")
            op = fields.get(b"op", b"")
            if len(op) != 1:
                raise ValueError("it has no op field")
            kind = op[0]
            if index_pos is None and kind != 0x03:
                raise ValueError("the bag header record (op 3) must come first")
            if kind == 0x03:
                if index_pos is not None:
                    raise ValueError("a second bag header record")
                index_pos = _u64(fields[b"index_pos"])
                if index_pos and not len(ROS1_MAGIC) <= index_pos < size:
                    raise ValueError(f"its index position {index_pos} lies outside the file")
            elif kind == 0x05:
                comp = fields[b"compression"].decode("ascii", errors="replace")
                want = _u32(fields[b"size"])
                if want > MAX_CHUNK_BYTES:
                    raise ValueError(f"a chunk that unpacks to {want / 1e6:.0f} MB (at most "
                                     f"{MAX_CHUNK_BYTES >> 20} MiB are read)")
                if comp == "none":
                    got = dlen
                elif comp in ("bz2", "lz4"):
                    got = _unpacks_to(f, dlen, comp, want)
                else:
                    raise ValueError(f"a chunk in unknown compression {comp[:20]!r}")
                if got != want:
                    raise ValueError(f"a chunk declared as {want} bytes unpacks to "
                                     f"{'more' if got > want else got}")
                chunks.add(pos)
            elif kind == 0x06:
                pointed.append(_u64(fields[b"chunk_pos"]))
            elif kind not in (0x02, 0x04, 0x07):
                raise ValueError(f"an unknown op {kind}")
            starts_index |= pos == index_pos
        except (ValueError, KeyError, struct.error, OSError, EOFError) as exc:
            why = f"no field {exc.args[0]!r}" if isinstance(exc, KeyError) else str(exc)
            raise CalibrationError(
                f"{p} is a damaged ROS 1 bag: {where}: {why} (a bag cut short can be repaired "
                "with `rosbag reindex`)"
            ) from None
        pos = end
        f.seek(pos)
    if index_pos is None:
        raise CalibrationError(f"{p} is a damaged ROS 1 bag: it holds no bag header record")
    if index_pos and not starts_index:
        raise CalibrationError(f"{p} is a damaged ROS 1 bag: its index position {index_pos} "
                               "is not the start of a record")
    stray = [c for c in pointed if c not in chunks]
    if stray:
        raise CalibrationError(f"{p} is a damaged ROS 1 bag: its index points at byte "
                               f"{stray[0]}, where no chunk starts")


def _string(b: bytes, at: int) -> tuple[str, int]:
    n = _u32(b, at)
    if n > len(b) - at - 4:
        raise ValueError("a string runs past its record")
    return b[at + 4:at + 4 + n].decode("utf-8", errors="replace"), at + 4 + n


def _check_mcap(p: Path, f: BinaryIO, size: int) -> None:
    head = f.read(8)
    if head != MCAP_MAGIC:
        raise CalibrationError(f"{p} is not an MCAP file: it does not start with the MCAP "
                               "magic bytes")
    if size < 16:
        raise CalibrationError(f"{p} is a damaged MCAP file: {size} bytes")
    f.seek(size - 8)
    if f.read(8) != MCAP_MAGIC:
        raise CalibrationError(f"{p} is a damaged MCAP file: it does not end with the MCAP magic "
                               "bytes (cut short? `mcap recover` can repair it)")
    chunks: dict[int, tuple[int, int, str]] = {}
    indexes: list[tuple[int, int, int, str]] = []
    pos = 8
    f.seek(pos)
    while pos < size - 8:
        try:
            rec = f.read(9)
            if len(rec) < 9:
                raise ValueError("the file ends inside it")
            op, length = rec[0], _u64(rec, 1)
            if length > size - 8 - pos - 9:
                raise ValueError(f"it declares {length} bytes, past the end of the file")
            if op == 0x02:  # footer: the summary follows no more
                break
            if op == 0x06:  # chunk: 3 x u64, u32 crc, compression, u64 records length, records
                fixed = f.read(min(length, 28 + 4 + 255))
                want = _u64(fixed, 16)
                comp, at = _string(fixed, 28)
                if at + 8 > len(fixed):
                    raise ValueError("the chunk's header is cut short")
                rlen = _u64(fixed, at)
                if at + 8 + rlen != length:
                    raise ValueError("the chunk's records length disagrees with its length")
                if want > MAX_CHUNK_BYTES:
                    raise ValueError(f"a chunk that unpacks to {want / 1e6:.0f} MB (at most "
                                     f"{MAX_CHUNK_BYTES >> 20} MiB are read)")
                f.seek(pos + 9 + at + 8)
                if comp == "":
                    got = rlen
                elif comp in ("lz4", "zstd"):
                    got = _unpacks_to(f, rlen, comp, want)
                else:
                    raise ValueError(f"a chunk in unknown compression {comp[:20]!r}")
                if got != want:
                    raise ValueError(f"a chunk declared as {want} bytes unpacks to "
                                     f"{'more' if got > want else got}")
                chunks[pos] = (rlen, want, comp)
            elif op == 0x08:  # chunk index
                if length > 1 << 24:
                    raise ValueError(f"a chunk index of {length} bytes")
                b = f.read(length)
                start = _u64(b, 16)
                n = _u32(b, 32)
                at = 36 + n + 8
                comp, at = _string(b, at)
                indexes.append((start, _u64(b, at), _u64(b, at + 8), comp))
        except (ValueError, struct.error, OSError, EOFError) as exc:
            raise CalibrationError(f"{p} is a damaged MCAP file: the record at byte {pos}: "
                                   f"{exc}") from None
        pos += 9 + length
        f.seek(pos)
    for start, csize, usize, comp in indexes:
        if chunks.get(start) != (csize, usize, comp):
            raise CalibrationError(f"{p} is a damaged MCAP file: its summary points at a chunk "
                                   f"at byte {start} that is not there as described")


def _check_file(p: Path, kind: str) -> None:
    st = check_regular(p, what="log file")
    with open_regular(p, what="log file") as f:
        if kind == "ros1":
            _check_ros1(p, f, st.st_size)
        elif kind == "mcap":
            _check_mcap(p, f, st.st_size)
        elif f.read(len(SQLITE_MAGIC)) != SQLITE_MAGIC:
            raise CalibrationError(f"{p} is not a ROS 2 bag's SQLite file: it does not start "
                                   "with 'SQLite format 3'")


def check_bag(path: str | Path, fmt: str) -> None:
    """Refuse a bag that ``rosbags`` should not be given (see the module docstring).

    ``path`` is a ROS 1 ``.bag`` (``fmt == "ros1-bag"``), or a ROS 2 bag folder or lone
    ``.mcap`` file (``"ros2-bag"``): a folder's ``metadata.yaml`` and every ``.db3`` and
    ``.mcap`` file in it are checked.
    """
    p = Path(path)
    if fmt == "ros1-bag":
        _check_file(p, "ros1")
        return
    if not p.is_dir():
        _check_file(p, "mcap" if p.suffix.lower() == ".mcap" else "db3")
        return
    check_regular(p / "metadata.yaml", what="bag's metadata.yaml", limit=MAX_METADATA_BYTES)
    for q in sorted(p.iterdir()):
        if q.suffix.lower() in (".db3", ".mcap"):
            _check_file(q, "mcap" if q.suffix.lower() == ".mcap" else "db3")
