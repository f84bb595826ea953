"""``refimpl cache [--clear]``: what the data cache holds, and emptying it (spec/cli.md §11, spec/data.md §7).

The cache (:mod:`refimpl.datacache`) keeps prepared data sets, e.g. the Bandai Namco locomotion sequences
(~0.5 GB for the whole set) and QTG's takes of it (85 MiB), so that the next command on unchanged files starts in seconds. ``refimpl cache``
lists its entries (name, size, date) and their total; ``--clear`` deletes them (only files named as entries,
``<name>-<24 hex>.npz``, and the temporary files of an interrupted write), and the next command rebuilds what
it needs.

Shape legend: none (files and their sizes).
"""
from __future__ import annotations

import re
import time
from pathlib import Path

from refimpl.datacache import cache_dir

__all__ = ["add_parser", "cmd_cache", "cache_entries"]

_ENTRY = re.compile(r"^[A-Za-z0-9_.+-]+-[0-9a-f]{24}\.npz$")
_TEMP = re.compile(r"^\..*\.tmp(\.npz)?$")


def cache_entries(folder: Path | None = None) -> list[Path]:
    """The entry files (and leftover temporary files) of the cache folder, sorted by name; [] when there is
    none or the cache is off."""
    folder = cache_dir() if folder is None else Path(folder)
    if folder is None or not folder.is_dir():
        return []
    return sorted(p for p in folder.iterdir() if p.is_file() and (_ENTRY.match(p.name) or _TEMP.match(p.name)))


def _size(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB"):
        if n < 1024 or unit == "GiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} GiB"  # pragma: no cover


def cmd_cache(args) -> int:
    """``refimpl cache``: list the entries and their total size; ``--clear``: delete them."""
    folder = cache_dir()
    if folder is None:
        print("the data cache is off ($REFIMPL_CACHE is 'off', '0' or empty)", flush=True)
        return 0
    entries = cache_entries(folder)
    total = sum(p.stat().st_size for p in entries)
    print(f"data cache {folder}: {len(entries)} entries, {_size(total)}", flush=True)
    for p in entries:
        st = p.stat()
        when = time.strftime("%Y-%m-%d %H:%M", time.localtime(st.st_mtime))
        print(f"  {_size(st.st_size):>10}  {when}  {p.name}", flush=True)
    if args.clear:
        for p in entries:
            p.unlink(missing_ok=True)
        print(f"cleared: {len(entries)} entries, {_size(total)} freed (the next command rebuilds what it needs)",
              flush=True)
    return 0


def add_parser(sub) -> None:
    """The ``cache`` sub-command of ``refimpl``."""
    p = sub.add_parser("cache", help="show the data cache's entries and size; --clear deletes them",
                       description="The data cache ($REFIMPL_CACHE, default ~/.cache/refimpl) keeps prepared data "
                                   "sets (the Bandai Namco locomotion sequences: ~0.5 GB; QTG's takes: 85 MiB) so "
                                   "that the next command on unchanged files starts in seconds. Entries can be "
                                   "deleted at any time.")
    p.add_argument("--clear", action="store_true", help="delete every entry (the next command rebuilds them)")
    p.set_defaults(func=cmd_cache)
