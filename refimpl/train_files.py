"""The files of a training run (spec/qtg.md §10, spec/robustness.md §10): the output lock and the atomic writer's
stale temporary files, the training state in a checkpoint (save, load, the resume check) and the CSV loss logs.
The loop that writes them is :func:`refimpl.train.train`.

* The checkpoint is locked (:func:`output_lock`, a ``.<checkpoint name>.lock`` file beside it): a second trainer of
  the same checkpoint stops with :class:`OutputLocked`; a lock left by a dead process is taken over.
* Temporary files of the atomic writer left beside the trainer's files by a killed run
  (``.checkpoint.<12 hex>.tmp.npz``, ``.loss.<12 hex>.tmp.csv``) are removed by :func:`remove_stale_temp_files`
  while the lock is held (no writer of those files is alive).
* A training state (``refimpl.checkpoint``: atomic ``.npz``, no pickle, checksum) holds the parameters
  (``param.<name>``), the Adam state (``optim.<key>``), the sampler's permutation (``sampler.perm``) and the
  metadata (format ``TRAIN_FORMAT``, step, epoch, position, Generator state, ...).
"""
from __future__ import annotations

import contextlib
import csv
import io
import os
from pathlib import Path
from typing import Mapping

import numpy as np

from refimpl.atomic import atomic_write_text
from refimpl.atomic import remove_stale_temp_files as _remove_stale
from refimpl.checkpoint import load_checkpoint, save_checkpoint
from refimpl.checkpoint_schema import validate_training_state

__all__ = ["OutputLocked", "output_lock", "remove_stale_temp_files", "check_resumable"]

#: The ``format`` of a training checkpoint's metadata.
TRAIN_FORMAT = "refimpl.train/1"


class OutputLocked(RuntimeError):
    """Another live process holds the lock of the output (a second trainer writing the same checkpoint)."""


def _pid_alive(pid: int) -> bool:
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True  # it exists (another user's process)
    return True


def _lock_owner(path: Path) -> int:
    try:
        text = path.read_text(encoding="ascii", errors="replace").split()
        return int(text[0]) if text else 0
    except (OSError, ValueError):
        return 0


@contextlib.contextmanager
def output_lock(folder, name: str = ".refimpl-train.lock"):
    """Hold the lock file ``folder/name`` inside the block; :class:`OutputLocked` if a live process holds it.

    POSIX: an exclusive ``fcntl.flock`` on the file (the kernel drops it when its process dies, so the lock of a
    killed run is free at once; the file stays, holding the last owner's PID). Elsewhere: the file is created
    exclusively and holds the PID; a file whose PID is not a live process (a stale lock) is taken over.
    The folder is created if needed.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / name
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX
        fcntl = None
    if fcntl is not None:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
        try:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                owner = _lock_owner(path)
                raise OutputLocked(f"{folder}: another trainer (PID {owner or '?'}) is writing here (lock file "
                                   f"{path}); wait for it, stop it, or choose another output") from None
            os.ftruncate(fd, 0)
            os.write(fd, f"{os.getpid()}\n".encode("ascii"))
            try:
                yield path
            finally:
                with contextlib.suppress(OSError):
                    os.ftruncate(fd, 0)
                fcntl.flock(fd, fcntl.LOCK_UN)
        finally:
            os.close(fd)
        return
    for _ in range(2):  # pragma: no cover - not POSIX
        try:
            fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
            break
        except FileExistsError:
            owner = _lock_owner(path)
            if _pid_alive(owner) and owner != os.getpid():
                raise OutputLocked(f"{folder}: another trainer (PID {owner}) is writing here (lock file {path})")
            with contextlib.suppress(FileNotFoundError):
                os.unlink(path)  # stale: its process is gone
    else:  # pragma: no cover
        raise OutputLocked(f"{folder}: could not take the lock file {path}")
    try:  # pragma: no cover
        os.write(fd, f"{os.getpid()}\n".encode("ascii"))
        os.close(fd)
        yield path
    finally:  # pragma: no cover
        with contextlib.suppress(OSError):
            os.unlink(path)


def remove_stale_temp_files(target) -> list[Path]:
    """Remove the temporary files :mod:`refimpl.atomic` leaves beside ``target`` when its writer is killed
    (:func:`refimpl.atomic.remove_stale_temp_files`; called while holding :func:`output_lock`, which excludes
    other writers of the trainer's files). Returns the removed paths."""
    return _remove_stale(target, assume_no_writer=True)


#: Metadata every training checkpoint carries (checked on resume).
_META_KEYS = ("step", "epoch", "position", "rng_state")


def save_state(path, params, opt_state, perm, meta) -> None:
    arrays = {f"param.{k}": v for k, v in params.items()}
    arrays.update({f"optim.{k}": np.asarray(v) for k, v in opt_state.items()})
    arrays["sampler.perm"] = perm
    save_checkpoint(path, arrays, meta)


def load_state(path):
    arrays, meta = load_checkpoint(path)
    if meta.get("format") != TRAIN_FORMAT:
        raise ValueError(f"checkpoint {path}: expected format {TRAIN_FORMAT!r}, got {meta.get('format')!r}")
    missing = [k for k in _META_KEYS if k not in meta] + [k for k in ("sampler.perm",) if k not in arrays]
    if missing:
        raise ValueError(f"checkpoint {path}: not a complete training state, missing {missing}")
    params = {k[len("param."):]: np.array(v) for k, v in arrays.items() if k.startswith("param.")}
    opt = {k[len("optim."):]: np.array(v) for k, v in arrays.items() if k.startswith("optim.")}
    return params, opt, np.array(arrays["sampler.perm"]), meta


def check_resumable(path) -> None:
    """Raise ``ValueError`` (naming the file and the field) unless ``path`` is a complete, valid training state:
    what :func:`train` checks on resume before the run's data and settings are known (the permutation's length
    is checked against the data then)."""
    params, opt, perm, meta = load_state(path)
    validate_training_state(params, opt, perm, meta, None, where=f"checkpoint {path}")


def truncate_csv(path: Path, max_step: int) -> None:
    """Keep the header and the rows with ``step <= max_step`` (after a resume), rewritten atomically."""
    if not path.is_file():
        return
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    if not rows:
        return
    keep = [rows[0]] + [r for r in rows[1:] if r and int(r[0]) <= max_step]
    buf = io.StringIO()
    csv.writer(buf).writerows(keep)
    atomic_write_text(path, buf.getvalue())


class CsvLog:
    def __init__(self, path: Path | None, fields):
        self.path, self.fields, self.file, self.writer = path, list(fields) if fields else None, None, None

    def write(self, row: Mapping) -> None:
        if self.path is None:
            return
        if self.file is None:
            new = not self.path.is_file() or self.path.stat().st_size == 0
            if self.fields is None:
                self.fields = list(row)
            self.file = open(self.path, "a", newline="")
            self.writer = csv.writer(self.file)
            if new:
                self.writer.writerow(self.fields)
        self.writer.writerow([_fmt(row.get(k)) for k in self.fields])
        self.file.flush()

    def close(self) -> None:
        if self.file is not None:
            self.file.close()
            self.file = None


def _fmt(v) -> str:
    if isinstance(v, float):
        return repr(v)
    return "" if v is None else str(v)


# Kernel tier (spec/architecture.md; not in __all__, imported by refimpl.train under these names):
# TRAIN_FORMAT, CsvLog, load_state, save_state, truncate_csv.
