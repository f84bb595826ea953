"""``.safetensors`` files with NumPy alone: a checked reader and an atomic writer (spec/import.md §2).

The format (Hugging Face safetensors, the layout PyTorch users save state dicts in): an unsigned 64-bit
little-endian integer ``N``, then ``N`` bytes of UTF-8 JSON (the header), then the byte buffer. The header is an
object mapping each tensor name to ``{"dtype": D, "shape": [..], "data_offsets": [begin, end]}`` (offsets into the
byte buffer, ``end`` exclusive) plus an optional ``"__metadata__"`` object of string -> string. Tensors are stored
C-order, little-endian. Nothing is ever unpickled: the format has no code in it.

What the reader refuses (``ValueError`` naming the file and the entry; exit 3 on the command line): a file
shorter than 8 bytes, a header length beyond the file or beyond :data:`MAX_HEADER_BYTES`, a header that is not
UTF-8 JSON, not an object, or has a repeated name; an entry that is not an object with exactly ``dtype``,
``shape`` and ``data_offsets``; an unknown dtype name; a shape that is not a list of non-negative integers; offsets
that are not two integers ``0 <= begin <= end``; a byte size other than ``prod(shape) × itemsize``; overlapping
tensors, holes between them, or a buffer whose length differs from the end of the last tensor (the same rules as
the reference implementation's ``validate``); ``__metadata__`` that is not an object of strings.

Dtypes: ``BOOL``, ``U8``, ``I8``, ``U16``, ``I16``, ``U32``, ``I32``, ``U64``, ``I64``, ``F16``, ``F32``,
``F64`` read as the NumPy dtype of the same size; ``BF16`` (which NumPy lacks) is read exactly into ``float32``
(a bfloat16 is the upper half of a float32). Other names (the 8-bit float formats) are refused. The writer stores
bool, integer and float16/32/64 arrays; it pads the header with spaces to a multiple of 8 bytes, as the reference
writer does.

Shape legend: none (arrays of any shape).
"""
from __future__ import annotations

import json
import math
import os
import struct
from typing import Mapping

import numpy as np

from refimpl.atomic import atomic_path
from refimpl.files import open_regular

__all__ = ["MAX_HEADER_BYTES", "DTYPES", "read_safetensors", "write_safetensors", "is_safetensors"]

#: Largest header accepted (the reference implementation's limit, 100 MB).
MAX_HEADER_BYTES = 100_000_000

#: safetensors dtype name -> NumPy dtype (little-endian). ``BF16`` is handled separately (read into float32).
DTYPES: dict[str, np.dtype] = {
    "BOOL": np.dtype("?"), "U8": np.dtype("u1"), "I8": np.dtype("i1"), "U16": np.dtype("<u2"),
    "I16": np.dtype("<i2"), "U32": np.dtype("<u4"), "I32": np.dtype("<i4"), "U64": np.dtype("<u8"),
    "I64": np.dtype("<i8"), "F16": np.dtype("<f2"), "F32": np.dtype("<f4"), "F64": np.dtype("<f8"),
}
_BF16 = "BF16"
_ITEMSIZE = {**{k: v.itemsize for k, v in DTYPES.items()}, _BF16: 2}
_NAME_OF = {(v.kind, v.itemsize): k for k, v in DTYPES.items()}
_METADATA = "__metadata__"
_CHUNK = 1 << 24


def _no_duplicates(pairs):
    out = {}
    for k, v in pairs:
        if k in out:
            raise ValueError(f"the header names {k!r} twice")
        out[k] = v
    return out


def _is_uint(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool) and v >= 0


def _parse_header(raw: bytes, buffer_size: int, where: str) -> tuple[list, dict]:
    """The entries ``(name, dtype name, shape, begin, end)`` sorted by offset, and the metadata."""
    try:
        header = json.loads(raw.decode("utf-8"), object_pairs_hook=_no_duplicates)
    except (UnicodeDecodeError, RecursionError) as exc:
        raise ValueError(f"{where}: the header is not UTF-8 JSON ({type(exc).__name__})") from None
    except ValueError as exc:  # JSONDecodeError and our duplicate check
        raise ValueError(f"{where}: malformed header: {exc}") from None
    if not isinstance(header, dict):
        raise ValueError(f"{where}: the header must be a JSON object, got {type(header).__name__}")
    meta = header.pop(_METADATA, {})
    if not isinstance(meta, dict) or not all(isinstance(v, str) for v in meta.values()):
        raise ValueError(f"{where}: {_METADATA} must be an object of strings")
    entries = []
    for name, e in header.items():
        at = f"{where}: tensor {name!r}"
        if not isinstance(e, dict) or set(e) != {"dtype", "shape", "data_offsets"}:
            raise ValueError(f"{at}: expected an object with exactly dtype, shape and data_offsets")
        dt, shape, offsets = e["dtype"], e["shape"], e["data_offsets"]
        if not isinstance(dt, str) or dt not in _ITEMSIZE:  # a JSON list or object is unhashable: not a dtype
            raise ValueError(f"{at}: unsupported dtype {dt!r}; expected one of {sorted(_ITEMSIZE)}")
        if not isinstance(shape, list) or not all(_is_uint(n) for n in shape):
            raise ValueError(f"{at}: shape must be a list of non-negative integers, got {shape!r}")
        if not isinstance(offsets, list) or len(offsets) != 2 or not all(_is_uint(n) for n in offsets) \
                or offsets[0] > offsets[1]:
            raise ValueError(f"{at}: data_offsets must be [begin, end] with 0 <= begin <= end, got {offsets!r}")
        nbytes = math.prod(shape) * _ITEMSIZE[dt]
        if offsets[1] - offsets[0] != nbytes:
            raise ValueError(f"{at}: shape {shape} of {dt} needs {nbytes} bytes but data_offsets {offsets} "
                             f"span {offsets[1] - offsets[0]}")
        entries.append((name, dt, tuple(shape), offsets[0], offsets[1]))
    entries.sort(key=lambda t: (t[3], t[4]))
    pos = 0
    for name, _, _, begin, end in entries:
        if begin < pos:
            raise ValueError(f"{where}: tensor {name!r} (bytes {begin}..{end}) overlaps the previous tensor "
                             f"(which ends at {pos})")
        if begin > pos:
            raise ValueError(f"{where}: a hole of {begin - pos} bytes before tensor {name!r}")
        pos = end
    if pos != buffer_size:
        raise ValueError(f"{where}: the tensors end at byte {pos} of the data but the file holds {buffer_size} "
                         f"bytes of data (truncated or trailing bytes)")
    return entries, meta


def _header_of(f, size: int, where: str) -> tuple[list, dict, int]:
    if size < 8:
        raise ValueError(f"{where}: {size} bytes, too short for a safetensors file (8-byte header length)")
    (n,) = struct.unpack("<Q", f.read(8))
    if n > MAX_HEADER_BYTES:
        raise ValueError(f"{where}: header length {n} is beyond the limit {MAX_HEADER_BYTES}")
    if 8 + n > size:
        raise ValueError(f"{where}: header length {n} is beyond the end of the {size}-byte file")
    raw = f.read(n)
    if not raw.lstrip().startswith(b"{"):
        raise ValueError(f"{where}: not a safetensors file (the header does not start with '{{')")
    entries, meta = _parse_header(raw, size - 8 - n, where)
    return entries, meta, 8 + n


def is_safetensors(path) -> bool:
    """Whether ``path`` looks like a safetensors file (a plausible header length, then ``{``); no validation."""
    try:
        with open_regular(path) as f:
            head = f.read(9)
            size = os.fstat(f.fileno()).st_size
    except (OSError, ValueError):
        return False
    if len(head) < 9:
        return False
    n = struct.unpack("<Q", head[:8])[0]
    return 0 < n <= min(MAX_HEADER_BYTES, size - 8) and head[8:9] == b"{"


def read_safetensors(path) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    """Read every tensor of a ``.safetensors`` file, checking the whole header first.

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    tensors : dict name -> ndarray
        Native-endian arrays of the stored shapes (``BF16`` as ``float32``), in the file's offset order.
    metadata : dict str -> str
        The ``__metadata__`` object (empty when absent).

    Raises
    ------
    ValueError
        A malformed file (module docstring); nothing is allocated from a declared shape before the offsets and
        the file size agree with it.
    OSError
        No file, a directory, unreadable.
    """
    where = os.fspath(path)
    with open_regular(path) as f:
        size = os.fstat(f.fileno()).st_size
        entries, meta, start = _header_of(f, size, where)
        out = {}
        for name, dt, shape, begin, end in entries:
            f.seek(start + begin)
            raw = np.empty(end - begin, dtype=np.uint8)
            view = memoryview(raw)
            pos = 0
            while pos < raw.size:
                got = f.readinto(view[pos:pos + _CHUNK])
                if not got:
                    raise ValueError(f"{where}: tensor {name!r} truncated ({pos} of {raw.size} bytes)")
                pos += got
            if dt == _BF16:
                bits = raw.view("<u2").astype(np.uint32) << 16
                a = bits.view(np.float32)
            else:
                a = raw.view(DTYPES[dt]).astype(DTYPES[dt].newbyteorder("="), copy=False)
            out[name] = a.reshape(shape)
    return out, dict(meta)


def write_safetensors(path, tensors: Mapping[str, np.ndarray], metadata: Mapping[str, str] | None = None) -> None:
    """Write ``tensors`` (bool, integer, float16/32/64 arrays) atomically as a ``.safetensors`` file.

    Tensors are stored in sorted name order, C-order, little-endian; the header is padded with spaces to a multiple
    of 8 bytes. ``metadata`` (string -> string) becomes ``__metadata__``.

    Raises
    ------
    ValueError
        A name that is empty, not a string or ``__metadata__``; an array of another dtype (complex, object,
        strings); metadata that is not string -> string. Nothing is written then.
    """
    entries = {}
    for name, a in tensors.items():
        if not isinstance(name, str) or not name or name == _METADATA:
            raise ValueError(f"tensors: bad name {name!r}")
        a = np.asarray(a)
        dt = _NAME_OF.get((a.dtype.kind, a.dtype.itemsize))
        if dt is None or a.dtype.hasobject:
            raise ValueError(f"tensors[{name!r}]: dtype {a.dtype} has no safetensors name this writer uses "
                             f"(bool, integers, float16/32/64)")
        entries[name] = (dt, np.ascontiguousarray(a, dtype=DTYPES[dt]).reshape(a.shape))  # keeps 0-d
    header, pos = {}, 0
    if metadata:
        if not all(isinstance(k, str) and isinstance(v, str) for k, v in metadata.items()):
            raise ValueError("metadata: expected a dict of strings")
        header[_METADATA] = dict(metadata)
    for name in sorted(entries):
        dt, a = entries[name]
        header[name] = {"dtype": dt, "shape": list(a.shape), "data_offsets": [pos, pos + a.nbytes]}
        pos += a.nbytes
    raw = json.dumps(header, separators=(",", ":")).encode("utf-8")
    raw += b" " * (-len(raw) % 8)
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        f.write(struct.pack("<Q", len(raw)))
        f.write(raw)
        for name in sorted(entries):
            a = entries[name][1]
            if a.size:
                f.write(a.reshape(-1).view(np.uint8).data)
