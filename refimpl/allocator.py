"""The C allocator's settings for a training process: keep freed memory for the next step (spec/cli.md §1).

Every training step of a NumPy network allocates its caches afresh (a QTG step at batch 32: ≈ 20 MB in arrays of
0.1-4 MB) and frees them at the end of the step. glibc's ``malloc`` serves blocks above its *mmap threshold*
(128 KiB at start, raised dynamically up to 32 MiB) with fresh ``mmap`` pages and returns the free top of its heap
to the system once it exceeds the *trim threshold*. Either way the next step's arrays land on pages the kernel
must fault in and zero again: measured on the 2-vCPU development VM, 4,800-8,800 page faults per QTG training
step, up to 1.3× the step's time (``benchmarks/bench_allocator.py``; glibc's dynamic threshold is path dependent,
and some processes happen to settle where a step faults nothing).

:func:`retain_freed_memory` sets both thresholds once for the process (``mallopt``): blocks up to
``mmap_threshold`` come from the heap, and up to ``trim_threshold`` bytes of freed heap stay with the process, so
the next step reuses the same pages. The cost is resident memory that is not given back between steps (at most
the step's own peak plus ``trim_threshold``). It changes no result: only where the bytes live.

The command line and the demo call it at start (``refimpl --malloc system`` leaves glibc's defaults). Library
functions never call it: a process setting is the application's choice. Other C libraries (musl, macOS,
Windows) have no ``mallopt``; there the function does nothing and returns ``False``.
"""
from __future__ import annotations

import ctypes
import ctypes.util
import sys

__all__ = ["MMAP_THRESHOLD_MAX", "retain_freed_memory"]

#: glibc's largest accepted mmap threshold on 64-bit systems (``DEFAULT_MMAP_THRESHOLD_MAX``: 4 MiB · sizeof(long)).
MMAP_THRESHOLD_MAX = 32 * 1024 * 1024

_M_TRIM_THRESHOLD = -1  # <malloc.h>
_M_MMAP_THRESHOLD = -3


def _glibc():
    """The process's C library if it is glibc (it has ``mallopt`` and ``gnu_get_libc_version``), else None."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(None)
        libc.gnu_get_libc_version  # noqa: B018  (glibc only)
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return None
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    mallopt.restype = ctypes.c_int
    return libc


def retain_freed_memory(mmap_threshold: int = MMAP_THRESHOLD_MAX, trim_threshold: int = 256 * 1024 * 1024) -> bool:
    """Keep freed memory in the process for reuse (glibc ``mallopt``); returns whether the settings took effect.

    Parameters
    ----------
    mmap_threshold : int
        Bytes; allocations below it come from the heap instead of fresh ``mmap`` pages. At most
        :data:`MMAP_THRESHOLD_MAX` (glibc refuses more), at least 0.
    trim_threshold : int
        Bytes of free memory at the top of the heap that ``free`` keeps instead of returning them to the system;
        at least 0, at most ``2**31 - 1``.

    Returns
    -------
    bool
        True when both settings were accepted; False on a C library without ``mallopt`` (nothing changed).

    Raises
    ------
    ValueError
        A threshold outside the ranges above.
    """
    for name, value, high in (("mmap_threshold", mmap_threshold, MMAP_THRESHOLD_MAX),
                              ("trim_threshold", trim_threshold, 2 ** 31 - 1)):
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= high:
            raise ValueError(f"{name}: expected an int in [0, {high}] bytes, got {value!r}")
    libc = _glibc()
    if libc is None:
        return False
    ok_trim = libc.mallopt(_M_TRIM_THRESHOLD, trim_threshold)
    ok_mmap = libc.mallopt(_M_MMAP_THRESHOLD, mmap_threshold)
    return bool(ok_trim) and bool(ok_mmap)
