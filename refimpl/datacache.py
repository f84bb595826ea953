"""A checksummed on-disk cache of arrays derived from a folder of data files (spec/data.md §cache).

Reading and preparing a data set can take far longer than training's first step (the Bandai Namco locomotion
set: 830 BVH files, ~95 s). A loader stores what it derived as one ``.npz`` (no pickle) keyed by a fingerprint
of its inputs, and the next command on unchanged files loads it in seconds.

* **Key** (:func:`fingerprint`): sha256 of the loader's name and version, its options, and for every input file
  its resolved path, size and modification time (``st_mtime_ns``). A changed, added or removed file, a new
  loader version or different options give another key; the old entry is simply not found.
* **Entry**: ``<cache dir>/<name>-<key[:24]>.npz`` holding the arrays, ``__meta__`` (a JSON string: key,
  name, version, the caller's metadata) and ``__checksum__`` (CRC-32 of every array's name, dtype, shape and
  bytes). Written atomically (:mod:`refimpl.atomic`); read with the checkpoint reader's bounds
  (:func:`refimpl.npy_files.read_npz`: a regular file, stored members only, every declared size checked against
  the file's before anything is allocated; never unpickled).
* **Trust**: an entry that cannot be read or decoded (damaged zip, a compressed member, a header declaring more
  than the file holds, ``__meta__`` that is not a JSON object, a ``decode`` that raises), whose checksum or key
  does not match, is ignored and noted (the caller rebuilds and overwrites it); nothing in it is used unless it
  verifies. A temporary file left by a writer killed while writing an entry is removed by the next reader
  (:func:`refimpl.atomic.remove_stale_temp_files`).
* **Where** (:func:`cache_dir`): ``$REFIMPL_CACHE`` if set (``off``, ``0`` or empty: no cache), else
  ``$XDG_CACHE_HOME/refimpl``, else ``~/.cache/refimpl``. Entries can be deleted at any time.

Shapes: arrays of any shape and a numeric, boolean or fixed-width string dtype (no object arrays).
"""
from __future__ import annotations

import hashlib
import io
import json
import os
import zlib
from pathlib import Path
from typing import Callable, Iterable, Mapping

import numpy as np

from refimpl._parsing import json_loads_strict
from refimpl.atomic import atomic_write_bytes, remove_stale_temp_files
from refimpl.npy_files import read_npz

__all__ = ["cache_dir", "fingerprint", "entry_path", "save_entry", "load_entry", "cached"]

_META = "__meta__"
_CHECKSUM = "__checksum__"
#: dtype kinds an entry may hold: numbers, booleans and fixed-width text (never objects).
_KINDS = "biufcUS"


def cache_dir() -> Path | None:
    """The cache folder (see the module docstring), or ``None`` when caching is off (``REFIMPL_CACHE=off``)."""
    env = os.environ.get("REFIMPL_CACHE")
    if env is not None:
        return None if env.strip().lower() in ("", "0", "off", "none") else Path(env).expanduser()
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg) if xdg else Path.home() / ".cache") / "refimpl"


def fingerprint(files: Iterable, *, name: str, version: int | str, options: Mapping | None = None) -> str:
    """sha256 (hex) of a loader's inputs: ``name``, ``version``, ``options`` and each file's resolved path,
    size and ``st_mtime_ns`` (in the given order).

    Raises
    ------
    OSError
        A file cannot be stat'ed (missing): the caller reports it as it would when reading.
    """
    h = hashlib.sha256()
    h.update(json.dumps([name, str(version), dict(options or {})], sort_keys=True, default=str).encode())
    for f in files:
        p = Path(f).resolve()
        st = p.stat()
        h.update(json.dumps([str(p), st.st_size, st.st_mtime_ns]).encode())
    return h.hexdigest()


def _checksum(arrays: Mapping[str, np.ndarray]) -> str:
    """CRC-32 (zlib, chained) over every array's name, dtype, shape and bytes: detects a damaged entry at
    ~3x the speed of sha256 (the inputs are identified by the sha256 key, not by this)."""
    crc = 0
    for k in sorted(arrays):
        a = np.ascontiguousarray(arrays[k])
        crc = zlib.crc32(json.dumps([k, a.dtype.str, list(a.shape)]).encode(), crc)
        crc = zlib.crc32(memoryview(a).cast("B") if a.size else b"", crc)
    return f"crc32:{crc:08x}"


def entry_path(name: str, key: str, folder: Path | None = None) -> Path | None:
    """Where the entry of ``(name, key)`` lives (``None`` when caching is off)."""
    folder = cache_dir() if folder is None else Path(folder)
    return None if folder is None else folder / f"{name}-{key[:24]}.npz"


def save_entry(name: str, key: str, arrays: Mapping[str, np.ndarray], meta: Mapping | None = None, *,
               folder: Path | None = None) -> Path | None:
    """Write ``arrays`` (and JSON-able ``meta``) as the entry of ``(name, key)``, atomically.

    Returns the path, or ``None`` when caching is off or the folder is not writable (a cache is an
    optimisation: failing to write it is not an error of the command).
    """
    path = entry_path(name, key, folder)
    if path is None:
        return None
    for k, a in arrays.items():
        if k.startswith("__") or np.asarray(a).dtype == object:
            raise ValueError(f"{k}: cache arrays need a name without '__' and a non-object dtype")
    arrays = {k: np.asarray(a) for k, a in arrays.items()}
    payload = dict(arrays)
    payload[_META] = np.array(json.dumps(dict(key=key, name=name, meta=dict(meta or {})), default=str))
    payload[_CHECKSUM] = np.array(_checksum(arrays))
    buf = io.BytesIO()
    np.savez(buf, **payload)
    try:
        atomic_write_bytes(path, buf.getvalue(), make_parents=True)
    except OSError:
        return None
    return path


def load_entry(name: str, key: str, *, folder: Path | None = None) -> tuple[dict, dict, str]:
    """``(arrays, meta, status)`` of the entry of ``(name, key)``.

    ``status`` is ``"hit"`` (verified), ``"miss"`` (no entry, or caching off) or ``"corrupt: <reason>"``
    (unreadable, wrong checksum or key); arrays and meta are empty unless it is a hit.
    """
    path = entry_path(name, key, folder)
    if path is None:
        return {}, {}, "miss"
    remove_stale_temp_files(path)  # of a writer killed while writing this entry (refimpl.atomic)
    if not os.path.lexists(path):
        return {}, {}, "miss"
    try:
        # the checkpoint reader's bounds: a regular file, stored members only, every declared size checked
        # against the file's before anything is allocated (refimpl.npy_files)
        arrays = read_npz(path, kinds=_KINDS, allow_compressed=False)
        meta_raw, stored_raw = arrays.pop(_META), arrays.pop(_CHECKSUM)
        if meta_raw.ndim or meta_raw.dtype.kind != "U" or stored_raw.ndim or stored_raw.dtype.kind != "U":
            raise ValueError("__meta__ / __checksum__: expected 0-d text entries")
        head = json_loads_strict(str(meta_raw))
        stored = str(stored_raw)
        if not isinstance(head, dict) or not isinstance(head.get("meta", {}), dict):
            raise ValueError(f"__meta__: expected a JSON object with an object 'meta', got {type(head).__name__}")
    except (OSError, ValueError, KeyError, RecursionError, MemoryError) as exc:
        return {}, {}, f"corrupt: {type(exc).__name__}: {str(exc)[:300]}"
    if head.get("key") != key or head.get("name") != name:
        return {}, {}, "corrupt: the entry belongs to other inputs"
    if _checksum(arrays) != stored:
        return {}, {}, "corrupt: checksum mismatch"
    return arrays, dict(head.get("meta") or {}), "hit"


def cached(name: str, key: str, build: Callable[[], object], encode: Callable[[object], tuple[dict, dict]],
           decode: Callable[[dict, dict], object], *, folder: Path | None = None,
           progress: Callable[[str], None] | None = None):
    """``decode`` of the verified entry of ``(name, key)``; else ``build()``, stored through ``encode``.

    ``encode(value) -> (arrays, meta)`` and ``decode(arrays, meta) -> value`` must be inverse. A corrupt entry
    is reported through ``progress`` and rebuilt; a ``decode`` that raises (an entry of an older layout under the
    same key, a field of the wrong type) counts as corrupt too.
    """
    arrays, meta, status = load_entry(name, key, folder=folder)
    if status == "hit":
        try:
            value = decode(arrays, meta)
        except Exception as exc:  # noqa: BLE001 - any decode failure of a verified entry: ignored, rebuilt
            status = f"corrupt: {type(exc).__name__}: {exc}"
        else:
            if progress is not None:
                progress(f"  {name}: loaded from the cache ({entry_path(name, key, folder)})")
            return value
    if progress is not None and status.startswith("corrupt"):
        progress(f"  {name}: cache entry ignored ({status[9:]}); rebuilding")
    value = build()
    arrays, meta = encode(value)
    path = save_entry(name, key, arrays, meta, folder=folder)
    if progress is not None and path is not None:
        progress(f"  {name}: cached as {path} (the next command on these files reads it)")
    return value
