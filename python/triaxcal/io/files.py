"""Reading and writing files with errors a person can act on.

Every file the library writes goes through :func:`write_file` (a whole file, atomically), and
every file it reads is opened by :func:`open_regular` (or checked by :func:`check_regular`,
when a third-party reader opens it by name): only a regular file is read. A named pipe (FIFO),
a device such as ``/dev/zero``, a socket or a folder is refused with a
:class:`~triaxcal.CalibrationError` before a byte is read -- opening a pipe for reading waits
for a writer, so it would hang -- and the check is made without blocking (the file is opened
with ``O_NONBLOCK`` and checked again by ``fstat``, so a file swapped for a pipe in between is
caught too). :func:`read_bounded` reads a whole small file up to a size limit. An
:class:`OSError` becomes a :class:`~triaxcal.CalibrationError` that names the file and says
what to do (create the folder, free some space, choose another place), never a traceback.
"""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path
from typing import Any, BinaryIO

from ..errors import CalibrationError

__all__ = ["check_output", "check_regular", "open_regular", "os_error_message", "read_bounded",
           "said", "write_file"]


def said(text: Any, limit: int = 200) -> str:
    r"""Text that came from a file or a third-party reader, fit for a message: control and
    other unprintable characters (ESC, BEL, CR...) become ``?`` and it is cut at ``limit``
    characters, so nothing in a damaged file can drive the terminal.

    >>> said("bad\x1b[31m record\r\n")
    'bad?[31m record??'
    """
    text = str(text)
    cut = len(text) > limit
    text = "".join(ch if ch.isprintable() else "?" for ch in text[:limit])
    return text + ("..." if cut else "")


def os_error_message(exc: OSError, path: Any, action: str = "write") -> str:
    """A sentence for ``exc`` raised while trying to ``action`` (read, write, create) ``path``.

    >>> import errno
    >>> msg = os_error_message(OSError(errno.ENOSPC, "No space left"), "/mnt/s.csv")
    >>> msg.split(";")[0]
    'cannot write /mnt/s.csv: no space left on the disk that holds it'
    """
    p = Path(path)
    code = exc.errno
    if code == errno.ENOSPC:
        why = "no space left on the disk that holds it; free some space or choose another place"
    elif code == getattr(errno, "EDQUOT", -1):
        why = "your disk quota is used up; free some space or choose another place"
    elif code == errno.EFBIG:
        why = ("the file has reached the largest size allowed here (a file size limit); free "
               "some space or choose another place")
    elif code == errno.EISDIR:
        why = f"it is a folder; give a file name inside it (e.g. {p / 'name'})"
    elif code == errno.ENOTDIR:
        why = "a part of the path is a file, not a folder"
    elif code == errno.ENOENT:
        if action == "read":
            why = "no such file"
        elif not p.parent.exists():
            why = (f"the folder {p.parent} does not exist; create it first (mkdir -p "
                   f"{p.parent}) or choose another place")
        else:
            why = "that place does not accept new files; choose another place"
    elif code in (errno.EACCES, errno.EPERM):
        why = "permission denied; choose a place you may " + ("read" if action == "read"
                                                               else "write to")
    elif code == errno.EROFS:
        why = "the file system is read-only; choose another place"
    elif code == errno.ENAMETOOLONG:
        why = "the name is too long"
    elif code == errno.ELOOP:
        why = "it is a symbolic link that leads round in a loop (or through too many links)"
    elif code == errno.ENXIO:
        why = "it is a socket or a device with nothing behind it, not a regular file"
    else:
        why = (exc.strerror or str(exc)).rstrip(".")
    return f"cannot {action} {p}: {why}"


def check_output(path: Any, what: str = "output") -> Path:
    """Fail early (before any long work) when ``path`` cannot be written: a folder, or a file
    in a folder that does not exist. Returns ``path`` as a :class:`~pathlib.Path`."""
    p = Path(path)
    if p.is_dir():
        raise CalibrationError(
            f"the {what} {p} is a folder; give a file name inside it (e.g. {p / 'name'})"
        )
    parent = p.parent
    if not parent.is_dir():
        raise CalibrationError(
            f"cannot write the {what} {p}: the folder {parent} does not exist; create it first "
            f"(mkdir -p {parent}) or choose another place"
        )
    return p


def write_file(path: Any, data: str | bytes, *, what: str = "file") -> Path:
    """Write ``data`` (text is UTF-8) as the whole content of ``path``.

    A regular file is replaced atomically (a temporary file in the same folder, ``fsync``,
    then a rename), so a failure leaves the old file as it was; a device or pipe that exists
    (``/dev/stdout``, ``/dev/null``) is written in place and never renamed over.

    Raises
    ------
    CalibrationError
        When the file cannot be written, saying why and what to do.
    """
    p = check_output(path, what)
    raw = data.encode("utf-8") if isinstance(data, str) else bytes(data)
    try:
        st = os.stat(p) if p.exists() else None
        if st is not None and not stat.S_ISREG(st.st_mode):
            with open(p, "wb") as f:
                f.write(raw)
            return p
        tmp = p.with_name(f".{p.name}.{os.getpid()}.tmp")
        try:
            with open(tmp, "xb") as f:
                f.write(raw)
                f.flush()
                os.fsync(f.fileno())
            os.replace(tmp, p)
        except BaseException:
            try:
                tmp.unlink()
            except OSError:
                pass
            raise
    except OSError as exc:
        raise CalibrationError(os_error_message(exc, p, "write") + f" (the {what})") from None
    return p


def _kind(mode: int) -> str:
    """What a file of ``mode`` (``st_mode``) is, in words."""
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISFIFO(mode):
        return "a named pipe (FIFO)"
    if stat.S_ISCHR(mode):
        return "a character device"
    if stat.S_ISBLK(mode):
        return "a block device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def _check_mode(p: Path, st: os.stat_result, what: str, limit: int | None) -> None:
    if stat.S_ISDIR(st.st_mode):
        raise CalibrationError(
            f"{p} is a folder, not a regular file: give the {what} inside it"
        )
    if not stat.S_ISREG(st.st_mode):
        raise CalibrationError(
            f"{p} is {_kind(st.st_mode)}, not a regular file: triaxcal reads a {what} only "
            "from a regular file (save the data to a file first)"
        )
    if limit is not None and st.st_size > limit:
        raise CalibrationError(
            f"{p} is {st.st_size / 1e6:.1f} MB, larger than any {what} "
            f"({_size(limit)} at most): is it the right file?"
        )


def _size(n: int) -> str:
    """``n`` bytes in words: ``16 MiB``, ``1.5 MB``."""
    if n >= 1 << 20 and n % (1 << 20) == 0:
        return f"{n >> 20} MiB"
    return f"{n / 1e6:.1f} MB"


def check_regular(path: Any, *, what: str = "file", limit: int | None = None) -> os.stat_result:
    """The ``os.stat`` of ``path`` when it is a regular file (of at most ``limit`` bytes);
    otherwise a :class:`~triaxcal.CalibrationError` naming the path and what it is.

    For readers that open the file by name themselves (third-party packages); a reader of
    triaxcal's own opens it with :func:`open_regular`.

    >>> check_regular("/dev/null", what="log file")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    triaxcal.CalibrationError: /dev/null is a character device, not a regular file: ...
    """
    p = Path(path)
    try:
        st = os.stat(p)
    except FileNotFoundError:
        raise CalibrationError(f"{what} {p} not found") from None
    except OSError as exc:
        raise CalibrationError(os_error_message(exc, p, "read")) from None
    except ValueError:  # a NUL byte in the name
        raise CalibrationError(f"{what} name {str(p)!r} holds a NUL character") from None
    _check_mode(p, st, what, limit)
    return st


_READ_FLAGS = (os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0)
               | getattr(os, "O_CLOEXEC", 0) | getattr(os, "O_BINARY", 0))


def open_regular(path: Any, *, what: str = "file", limit: int | None = None) -> BinaryIO:
    """Open ``path`` for reading (binary) if it is a regular file of at most ``limit`` bytes.

    Anything else -- a missing file, a folder, a named pipe, a device (``/dev/zero``), a
    socket, a symbolic link loop, a file over ``limit`` -- raises
    :class:`~triaxcal.CalibrationError` naming the path and saying what it is, and nothing
    blocks: the file is checked before it is opened, opened with ``O_NONBLOCK`` (a pipe opens
    at once instead of waiting for a writer) and checked again on the open descriptor.

    Parameters
    ----------
    path : str or Path
    what : str
        What the file should be, for the messages ("calibration file", "log file").
    limit : int, optional
        Largest size accepted, in bytes. The caller bounds what it reads beyond that (a file
        may grow while it is read).

    Examples
    --------
    >>> import os, tempfile
    >>> d = tempfile.mkdtemp()
    >>> os.mkfifo(os.path.join(d, "pipe"))
    >>> open_regular(os.path.join(d, "pipe"), what="table")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    triaxcal.CalibrationError: .../pipe is a named pipe (FIFO), not a regular file: ...
    """
    p = Path(path)
    check_regular(p, what=what, limit=limit)  # a device is never opened (that can act)
    try:
        fd = os.open(p, _READ_FLAGS)
    except FileNotFoundError:
        raise CalibrationError(f"{what} {p} not found") from None
    except OSError as exc:
        raise CalibrationError(os_error_message(exc, p, "read")) from None
    try:
        _check_mode(p, os.fstat(fd), what, limit)  # replaced since the first check?
        if _READ_FLAGS & getattr(os, "O_NONBLOCK", 0):
            import fcntl

            flags = fcntl.fcntl(fd, fcntl.F_GETFL)
            fcntl.fcntl(fd, fcntl.F_SETFL, flags & ~os.O_NONBLOCK)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def read_bounded(path: Any, *, limit: int, what: str = "file") -> bytes:
    """The bytes of ``path``, a regular file (see :func:`open_regular`) of at most ``limit``
    bytes (at most ``limit + 1`` bytes are read, so a file that grows cannot exhaust memory)."""
    p = Path(path)
    with open_regular(p, what=what, limit=limit) as f:
        try:
            data = f.read(limit + 1)
        except OSError as exc:
            raise CalibrationError(os_error_message(exc, p, "read")) from None
    if len(data) > limit:
        raise CalibrationError(
            f"{p} holds more than {_size(limit)}, more than any {what}: is it the right file?"
        )
    return data
