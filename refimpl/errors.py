"""Errors of the application layer (spec/cli.md §exit codes) and the helpers that raise them.

The command line maps them to exit codes: :class:`BadInputError` 3 (a file named by the user is missing,
unreadable or malformed), :class:`UsageError` 2 (options that parse but do not fit together),
:class:`MissingDependency` 1 (an optional extra is not installed). The library below the application layer
raises ``ValueError`` / ``OSError``; :func:`reading` turns those into :class:`BadInputError` naming the file.
"""
from __future__ import annotations

import contextlib
from pathlib import Path

from refimpl.files import check_regular

__all__ = ["BadInputError", "UsageError", "MissingDependency", "DEPLOY_HINT", "file_error", "reading",
           "existing_file"]

#: How to install what the ONNX paths need (appended to :class:`MissingDependency` messages).
DEPLOY_HINT = "needs the deploy extra: pip install 'refimpl[deploy]' (onnx and onnxruntime)"


class BadInputError(Exception):
    """A file named on the command line is missing, unreadable or malformed (exit code 3)."""


class UsageError(Exception):
    """Options that parse but do not make sense together (exit code 2)."""


class MissingDependency(Exception):
    """An optional dependency is not installed (exit code 1)."""


def file_error(path, exc: BaseException) -> BadInputError:
    """A :class:`BadInputError` for ``path`` from the reader's exception (its message already names the file)."""
    msg = str(exc)
    if isinstance(exc, FileNotFoundError):
        msg = f"{path}: no such file"
    elif isinstance(exc, IsADirectoryError):
        msg = f"{path}: is a directory, expected a file"
    elif isinstance(exc, PermissionError):
        msg = f"{path}: permission denied"
    elif isinstance(exc, UnicodeDecodeError):
        msg = f"{path}: not a text file ({exc.reason})"
    elif str(path) not in msg:
        msg = f"{path}: {msg}"
    return BadInputError(msg)


@contextlib.contextmanager
def reading(path):
    """Turn the readers' errors about ``path`` into :class:`BadInputError`."""
    try:
        yield
    except (OSError, ValueError, UnicodeDecodeError, EOFError, KeyError) as exc:
        raise file_error(path, exc) from exc


def existing_file(path) -> Path:
    """``Path(path)`` when it names a regular file (after symlinks), else :class:`BadInputError` (exit 3).

    Checked with ``os.stat``, before anything is opened: a FIFO, a device (``/dev/zero`` or a symlink to it) or
    a socket is refused as a folder is (spec/robustness.md §13), since a reader of one could block or never end.
    """
    p = Path(path)
    try:
        check_regular(p)
    except FileNotFoundError:
        raise BadInputError(f"{p}: no such file") from None
    except IsADirectoryError:
        raise BadInputError(f"{p}: is a directory, expected a file") from None
    except (OSError, ValueError) as exc:
        raise file_error(p, exc) from None
    return p
