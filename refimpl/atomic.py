"""Atomic file writes: every file the project writes goes through here (spec/robustness.md).

A reader of the target path sees either the old file or the complete new one, never a partial file:
the data is written to a fresh temporary file in the same folder, flushed, fsynced and renamed over the target
with ``os.replace``; the folder is then fsynced (best effort) so that the rename survives a crash. On any
failure the temporary file is removed and the target is untouched.

The temporary file is created exclusively with mode ``0o666 & ~umask`` (not ``tempfile.mkstemp``'s 0o600),
so the final file gets the usual permissions, and keeps the target's suffix (some writers, such as
matplotlib's ``savefig``, choose the format from it). Its name is ``.<stem>.<12 hex digits>.tmp<suffix>``.

A writer killed with ``kill -9`` cannot remove its temporary file. While it writes, the writer holds an
exclusive ``fcntl.flock`` on the file (POSIX; the kernel drops it when the process dies), so that
:func:`remove_stale_temp_files` — called by the next reader or writer of the target (the trainer, the data
cache, ``refimpl import``, ``export-weights``) — removes exactly the temporary files whose writer is gone and
never the one of a live writer.
"""
from __future__ import annotations

import contextlib
import os
import re
import secrets
from pathlib import Path
from typing import Iterator

try:
    import fcntl
except ImportError:  # pragma: no cover - not POSIX
    fcntl = None

__all__ = ["atomic_path", "atomic_write_bytes", "atomic_write_text", "remove_stale_temp_files"]


def _fsync_dir(directory: Path) -> None:
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _create_temp(path: Path) -> tuple[Path, int]:
    """A new temporary file beside ``path`` and a descriptor holding its writer's lock (closing it drops it)."""
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0) | getattr(os, "O_CLOEXEC", 0)
    for _ in range(100):
        tmp = path.with_name(f".{path.stem}.{secrets.token_hex(6)}.tmp{path.suffix}")
        try:
            fd = os.open(tmp, flags, 0o666)
        except FileExistsError:
            continue
        if fcntl is None:  # pragma: no cover - not POSIX: no lock, no cleaning by others
            return tmp, fd
        fcntl.flock(fd, fcntl.LOCK_EX)  # a cleaner may hold it for an instant: wait, then check it kept the file
        try:
            same = os.stat(tmp).st_ino == os.fstat(fd).st_ino
        except FileNotFoundError:
            same = False
        if same:
            return tmp, fd
        os.close(fd)
    raise FileExistsError(f"could not create a temporary file next to {str(path)!r}")


def _temp_pattern(target: Path) -> re.Pattern:
    return re.compile(r"\." + re.escape(target.stem) + r"\.[0-9a-f]{12}\.tmp" + re.escape(target.suffix) + r"\Z")


def _remove_if_unlocked(path: str, assume_no_writer: bool) -> bool:
    if fcntl is None:  # pragma: no cover - not POSIX: only a caller that excludes other writers removes
        if assume_no_writer:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(path)
                return True
        return False
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:  # a live writer holds it
        os.close(fd)
        return False
    try:
        os.unlink(path)
        return True
    except FileNotFoundError:
        return False
    finally:
        os.close(fd)


def remove_stale_temp_files(target, *, assume_no_writer: bool = False) -> list[Path]:
    """Remove the temporary files :func:`atomic_path` left beside ``target`` when their writer was killed.

    Only regular files of the writer's exact pattern for this target (``.<stem>.<12 hex digits>.tmp<suffix>``)
    whose writer's lock is free (no live writer) are removed. Without ``fcntl`` (not POSIX) nothing is removed
    unless ``assume_no_writer`` (the caller holds a lock that excludes other writers of ``target``). Returns the
    removed paths; never raises for a folder that cannot be listed.
    """
    target = Path(target)
    pattern = _temp_pattern(target)
    removed = []
    try:
        entries = list(os.scandir(target.parent))
    except OSError:
        return removed
    for e in entries:
        if pattern.match(e.name) and e.is_file(follow_symlinks=False) and _remove_if_unlocked(e.path,
                                                                                              assume_no_writer):
            removed.append(Path(e.path))
    return removed


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, *, make_parents: bool = False) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on normal exit it is fsynced and renamed over ``path``.

    Parameters
    ----------
    path : path-like
        The final file.
    make_parents : bool
        Create missing parent folders first (default: a missing folder is an ``OSError``, as for ``open``).

    Examples
    --------
    >>> with atomic_path("out/figure.png") as tmp:    # doctest: +SKIP
    ...     fig.savefig(tmp)
    """
    path = Path(path)
    if make_parents:
        path.parent.mkdir(parents=True, exist_ok=True)
    tmp, lock = _create_temp(path)
    try:
        yield tmp
        with open(tmp, "rb+") as f:
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise
    finally:
        os.close(lock)  # drops the writer's lock
    _fsync_dir(path.parent)


def atomic_write_bytes(path: str | os.PathLike, data: bytes, *, make_parents: bool = False) -> None:
    """Write ``data`` to ``path`` atomically."""
    with atomic_path(path, make_parents=make_parents) as tmp, open(tmp, "wb") as f:
        f.write(data)


def atomic_write_text(path: str | os.PathLike, text: str, encoding: str = "utf-8", *,
                      make_parents: bool = False) -> None:
    """Write ``text`` to ``path`` atomically, exactly as given (no newline translation)."""
    with atomic_path(path, make_parents=make_parents) as tmp, open(tmp, "w", encoding=encoding, newline="") as f:
        f.write(text)
