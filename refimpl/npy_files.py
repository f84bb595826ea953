"""Bounded readers of ``.npy`` and ``.npz`` files (spec/robustness.md §13): nothing is allocated beyond what the
file's real size allows, nothing is unpickled.

* :func:`read_npy_stream` — one ``.npy`` stream holding ``available`` bytes: NumPy parses the header
  (``ast.literal_eval``, never pickle), only the allowed dtype kinds pass, and the size the header declares must
  equal the bytes present before the array is allocated; the data is read in chunks straight into the array;
* :func:`read_npy` — a ``.npy`` file (a regular file, :func:`refimpl.files.open_regular`) through it;
* :func:`read_npz` — every member of an ``.npz``: the total size the zip directory declares must be within
  ``INFLATE_RATIO`` × the file size + ``INFLATE_ALLOWANCE`` (a zip bomb is refused before inflating), encrypted
  or patched members are refused, and compressed members only where the caller allows them (the data cache
  never writes any). Every sign of damage is ``ValueError`` naming the file.

Shapes: arrays of any shape.
"""
from __future__ import annotations

import math
import os
import struct
import tokenize
import zipfile
import zlib

import numpy as np

from refimpl.files import open_regular

__all__ = ["INFLATE_RATIO", "INFLATE_ALLOWANCE", "read_npy_stream", "read_npy", "read_npz"]

#: The members of an archive may inflate to at most ``INFLATE_RATIO`` × the file size + ``INFLATE_ALLOWANCE`` bytes
#: in total (checked on the sizes the zip directory declares, before anything is read; zipfile never produces
#: more than a member's declared size). Stored members have ratio 1; ``np.savez_compressed`` float weights ~1.1.
INFLATE_RATIO = 32
INFLATE_ALLOWANCE = 8 * 2**20
_READ_CHUNK = 2**20
_NUMERIC_KINDS = "biufc"  # bool, signed/unsigned integers, floats, complex
_ZIP_UNSUPPORTED_FLAGS = 0x1 | 0x20 | 0x40  # encrypted, compressed patched data, strong encryption
# what NumPy's .npy header parser (ast.literal_eval after a tokenize-based filter) may raise on a bad header
_NPY_HEADER_ERRORS = (ValueError, SyntaxError, tokenize.TokenError, RecursionError, MemoryError, TypeError,
                      OverflowError, struct.error, EOFError)
# what zipfile / zlib may raise on a damaged archive
_ZIP_ERRORS = (zipfile.BadZipFile, zlib.error, EOFError, KeyError, NotImplementedError, RuntimeError,
               OverflowError, struct.error, ValueError, MemoryError)


def read_npy_stream(f, available: int, where: str, kinds: str = _NUMERIC_KINDS) -> np.ndarray:
    """The array of the ``.npy`` stream ``f`` (positioned at its magic), which holds ``available`` bytes.

    Raises
    ------
    ValueError
        A malformed header, a dtype kind outside ``kinds`` (object arrays always), a negative size, a declared
        size other than the bytes present, truncated data.
    """
    start = f.tell()
    try:
        version = np.lib.format.read_magic(f)
        if version == (1, 0):
            shape, fortran_order, dtype = np.lib.format.read_array_header_1_0(f)
        elif version == (2, 0):
            shape, fortran_order, dtype = np.lib.format.read_array_header_2_0(f)
        else:
            raise ValueError(f"unsupported .npy format version {version}")
    except _NPY_HEADER_ERRORS as e:
        raise ValueError(f"{where}: malformed .npy header: {type(e).__name__}: {e}") from e
    if dtype.kind not in kinds or dtype.hasobject or dtype.subdtype is not None:
        raise ValueError(f"{where}: dtype {dtype} is not accepted here (kinds {kinds!r} only; never pickled "
                         f"objects)")
    if any(n < 0 for n in shape):
        raise ValueError(f"{where}: negative size in the declared shape {shape}")
    declared = math.prod(shape) * dtype.itemsize
    present = available - (f.tell() - start)
    if declared != present:
        raise ValueError(f"{where}: the header declares shape {shape} of {dtype} ({declared} bytes) but the "
                         f"file holds {present} bytes of data")
    array = np.empty(math.prod(shape), dtype=dtype)
    buf = memoryview(array.view(np.uint8)) if array.size else memoryview(b"")
    pos = 0
    while pos < declared:
        n = f.readinto(buf[pos:pos + _READ_CHUNK])
        if not n:
            raise ValueError(f"{where}: truncated data ({pos} of {declared} bytes)")
        pos += n
    return array.reshape(shape[::-1]).T if fortran_order else array.reshape(shape)


def read_npy(path, kinds: str = _NUMERIC_KINDS) -> np.ndarray:
    """The array of the ``.npy`` file ``path``, bounded by the file's size (:func:`read_npy_stream`).

    Raises
    ------
    ValueError
        Not a regular file, or any damage :func:`read_npy_stream` refuses.
    OSError
        As ``open``.
    """
    where = os.fspath(path)
    with open_regular(path) as f:
        size = os.fstat(f.fileno()).st_size
        array = read_npy_stream(f, size, where, kinds)
        if f.read(1):
            raise ValueError(f"{where}: bytes after the array's data (not a .npy file)")
    return array


def _check_member(info: zipfile.ZipInfo, where: str, allow_compressed: bool) -> None:
    name = info.filename
    if not name.endswith(".npy"):
        raise ValueError(f"{where}: member {name!r} is not a .npy array")
    if info.flag_bits & _ZIP_UNSUPPORTED_FLAGS:
        raise ValueError(f"{where}: member {name!r} is encrypted or patched (zip flags {info.flag_bits:#x})")
    allowed = (zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED) if allow_compressed else (zipfile.ZIP_STORED,)
    if info.compress_type not in allowed:
        raise ValueError(f"{where}: member {name!r} uses compression {info.compress_type} (accepted: "
                         f"{', '.join(map(str, allowed))}{'' if allow_compressed else ', stored only'})")


def read_npz(path, *, kinds: str = _NUMERIC_KINDS, allow_compressed: bool = True) -> dict[str, np.ndarray]:
    """Every member of the ``.npz`` file ``path`` as a dict name -> array (member names without ``.npy``).

    Raises
    ------
    ValueError
        Not a regular file; bad zip structure, CRC error, truncation; a member that is not ``.npy``, appears
        twice, is encrypted, or is compressed when ``allow_compressed`` is false; content declared beyond
        ``INFLATE_RATIO`` × the file size + ``INFLATE_ALLOWANCE``; any :func:`read_npy_stream` refusal.
    OSError
        As ``open`` (no such file, a directory, unreadable).
    """
    where = os.fspath(path)
    with open_regular(path) as fh:
        size = os.fstat(fh.fileno()).st_size
        try:
            with zipfile.ZipFile(fh) as zf:
                infos = zf.infolist()
                total = sum(i.file_size for i in infos)
                limit = INFLATE_RATIO * size + INFLATE_ALLOWANCE
                if total > limit:
                    raise ValueError(f"{where}: the archive declares {total} bytes of content, more than the "
                                     f"{limit} allowed for a {size}-byte file ({INFLATE_RATIO} × its size + "
                                     f"{INFLATE_ALLOWANCE} bytes): refusing a possible zip bomb")
                out = {}
                for info in infos:
                    _check_member(info, where, allow_compressed)
                    key = info.filename[:-len(".npy")]
                    if key in out:
                        raise ValueError(f"{where}: member {info.filename!r} appears twice")
                    with zf.open(info) as f:
                        out[key] = read_npy_stream(f, info.file_size, f"{where}: member {info.filename!r}", kinds)
        except (*_ZIP_ERRORS, OSError) as e:  # damage inside the file: ValueError
            if isinstance(e, ValueError) and str(e).startswith(where):
                raise  # our own message already names the file
            raise ValueError(f"{where}: unreadable .npz (corrupted, truncated or not an npz): "
                             f"{type(e).__name__}: {e}") from e
    return out
