"""The one rule for every path a command reads (spec/robustness.md §13): a regular file, opened without blocking,
read no further than its real size.

A FIFO blocks ``open`` until a writer comes and then streams without end; ``/dev/zero`` (or a symlink to it) has
``st_size`` 0 and never ends; other devices and sockets are no better. Every reader of a file a user names goes
through :func:`open_regular` (or :func:`read_bytes` / :func:`read_text` on top of it):

* :func:`check_regular` — ``os.stat`` (following symlinks, never opening): ``ValueError`` unless it is a regular
  file; ``FileNotFoundError`` / ``IsADirectoryError`` as ``open`` would raise them;
* :func:`open_regular` — ``os.open`` with ``O_NONBLOCK`` (a FIFO without writer opens at once instead of
  hanging), ``fstat`` of the descriptor, refused unless regular (so a path swapped after the check is caught too),
  then a blocking binary file object;
* :func:`read_bytes` — at most the file's ``st_size`` bytes (a file that grows while it is read is refused);
* :func:`read_text` — :func:`read_bytes` decoded (``UnicodeDecodeError`` is a ``ValueError``).

Shapes: none (bytes and text).
"""
from __future__ import annotations

import os
import stat
from typing import BinaryIO

__all__ = ["check_regular", "open_regular", "read_bytes", "read_text", "kind_of"]

_READ_CHUNK = 1 << 20


def kind_of(mode: int) -> str:
    """What a ``st_mode`` is, in words (for messages): ``"a FIFO (named pipe)"``, ``"a character device"``, ..."""
    for test, what in ((stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"), (stat.S_ISDIR, "a directory"),
                       (stat.S_ISREG, "a regular file")):
        if test(mode):
            return what
    return "not a regular file"


def _refuse(path, mode: int):
    where = os.fspath(path)
    if stat.S_ISDIR(mode):
        return IsADirectoryError(21, "Is a directory", where)
    return ValueError(f"{where}: {kind_of(mode)}, not a regular file (refused: it could block or never end)")


def check_regular(path) -> os.stat_result:
    """``os.stat(path)`` when ``path`` (after symlinks) is a regular file; never opens it.

    Raises
    ------
    FileNotFoundError, PermissionError, OSError
        As ``os.stat`` (no such file, a dangling symlink, ...).
    IsADirectoryError
        A folder.
    ValueError
        A FIFO, a device, a socket: ``"<path>: a FIFO (named pipe), not a regular file ..."``.
    """
    st = os.stat(path)
    if not stat.S_ISREG(st.st_mode):
        raise _refuse(path, st.st_mode)
    return st


def open_regular(path) -> BinaryIO:
    """A binary file object of ``path`` for reading, after checking that the opened descriptor is a regular file.

    The open is non-blocking (``O_NONBLOCK`` where the system has it) so that a FIFO without a writer is refused
    at once, not waited for; the returned file is blocking. Raises as :func:`check_regular`.
    """
    check_regular(path)
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_BINARY", 0) | getattr(os, "O_CLOEXEC", 0)
    fd = os.open(path, flags)
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise _refuse(path, st.st_mode)
        if hasattr(os, "set_blocking"):
            os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def read_bytes(path, limit: int | None = None) -> bytes:
    """The content of the regular file ``path``: at most its ``st_size`` bytes (and at most ``limit``).

    Raises
    ------
    ValueError
        Not a regular file (:func:`check_regular`), larger than ``limit``, or grown while being read.
    OSError
        As ``open``.
    """
    with open_regular(path) as f:
        size = os.fstat(f.fileno()).st_size
        if limit is not None and size > limit:
            raise ValueError(f"{os.fspath(path)}: {size} bytes, more than the {limit} this reader accepts")
        parts, left = [], size
        while left > 0:
            block = f.read(min(left, _READ_CHUNK))
            if not block:
                break  # shrank while read: what is there
            parts.append(block)
            left -= len(block)
        if f.read(1):
            raise ValueError(f"{os.fspath(path)}: the file grew while it was read (more than its {size} bytes)")
    return b"".join(parts)


def read_text(path, encoding: str = "utf-8-sig", limit: int | None = None) -> str:
    """:func:`read_bytes` decoded with ``encoding`` (``UnicodeDecodeError``, a ``ValueError``, on other bytes)."""
    return read_bytes(path, limit).decode(encoding)
