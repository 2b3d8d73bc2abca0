"""Reading and writing files with errors a person can act on.

Every file the library writes goes through :func:`write_file` (a whole file, atomically) and
every bounded read through :func:`read_bounded`; an :class:`OSError` becomes a
:class:`~triaxcal.CalibrationError` that names the file and says what to do (create the
folder, free some space, choose another place), never a traceback.
"""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path
from typing import Any

from ..errors import CalibrationError

__all__ = ["check_output", "os_error_message", "read_bounded", "write_file"]


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


def read_bounded(path: Any, *, limit: int, what: str = "file") -> bytes:
    """The bytes of ``path``, refusing folders, missing files and anything over ``limit``
    bytes (read at most ``limit + 1`` bytes, so ``/dev/zero`` cannot exhaust memory)."""
    p = Path(path)
    try:
        if p.is_dir():
            raise CalibrationError(
                f"{p} is a folder, not a {what}; give the file inside it"
            )
        with open(p, "rb") as f:
            st = os.fstat(f.fileno())
            if stat.S_ISREG(st.st_mode) and st.st_size > limit:
                raise CalibrationError(
                    f"{p} is {st.st_size / 1e6:.1f} MB, larger than any {what} "
                    f"({limit / 1e6:.0f} MB at most): is it the right file?"
                )
            data = f.read(limit + 1)
    except FileNotFoundError:
        raise CalibrationError(f"{what} {p} not found") from None
    except OSError as exc:
        raise CalibrationError(os_error_message(exc, p, "read")) from None
    if len(data) > limit:
        raise CalibrationError(
            f"{p} holds more than {limit / 1e6:.0f} MB, more than any {what}: is it the right "
            "file?"
        )
    return data
