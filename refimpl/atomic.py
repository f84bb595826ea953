"""Atomic file writes: every file the project writes goes through here (spec/robustness.md).

A reader of the target path sees either the old file or the complete new one, never a partial file:
the data is written to a fresh temporary file in the same folder, flushed, fsynced and renamed over the target
with ``os.replace``; the folder is then fsynced (best effort) so that the rename survives a crash. On any
failure the temporary file is removed and the target is untouched.

The temporary file is created exclusively with mode ``0o666 & ~umask`` (not ``tempfile.mkstemp``'s 0o600),
so the final file gets the usual permissions, and keeps the target's suffix (some writers, such as
matplotlib's ``savefig``, choose the format from it).
"""
from __future__ import annotations

import contextlib
import os
import secrets
from pathlib import Path
from typing import Iterator

__all__ = ["atomic_path", "atomic_write_bytes", "atomic_write_text"]


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


def _create_temp(path: Path) -> Path:
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0)
    for _ in range(100):
        tmp = path.with_name(f".{path.stem}.{secrets.token_hex(6)}.tmp{path.suffix}")
        try:
            os.close(os.open(tmp, flags, 0o666))
            return tmp
        except FileExistsError:
            continue
    raise FileExistsError(f"could not create a temporary file next to {str(path)!r}")


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
    tmp = _create_temp(path)
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
