"""Checkpoints: atomic, checksummed ``.npz`` files without pickle, and plain PyTorch state dicts as ``.npz``.

File format (a standard NumPy ``.npz``, readable with ``np.load(path, allow_pickle=False)``):

* one ``.npy`` member per array under its own name: parameters under their PyTorch state-dict names
  (``rnn.weight_ih_l0``), optimiser state under a prefix (``optim.step``, ``optim.m.<name>``, ``optim.v.<name>``
  for :func:`refimpl.optim.adam_init` state);
* ``__meta__``: the metadata dict as UTF-8 JSON text in a ``uint8`` array (keys sorted, no NaN/inf);
* ``__checksum__``: ``uint8 (32,)``, SHA-256 over every other member (``__meta__`` included) in sorted name
  order, each contributing ``utf8(name) 0x00 shape 0x00 dtype 0x00 bytes``, where ``shape`` is the decimal
  sizes joined by ``,`` (empty for 0-d), ``dtype`` is NumPy's ``dtype.str`` (e.g. ``<f4``) and ``bytes`` the
  C-order data.

Writing goes to a temporary file in the target directory, which is flushed, fsynced and renamed over the
target with ``os.replace`` (then the directory is fsynced), so a reader sees the old file or the new one, never
a partial one; on any failure the temporary file is removed. Reading never unpickles: each ``.npy`` header is
parsed by NumPy's header reader (``ast.literal_eval``) and only bool/integer/float/complex dtypes are accepted
(object arrays are refused). Every sign of damage (bad zip structure, CRC error, truncation, encrypted members,
a header whose shape does not match its data, checksum mismatch, malformed metadata) becomes ``ValueError``;
memory is bounded by the file size (content declared above 32 × the file size + 8 MiB is refused before
anything is inflated, and no array is allocated from a declared shape before its data size is checked).

Also: :func:`load_state_dict_npz` for converted PyTorch state dicts (no metadata, no checksum),
:func:`check_params` to compare a parameter dict with the expected shapes, and :func:`rng_state_to_json` /
:func:`rng_from_json` to store a ``numpy.random.Generator`` in the metadata so training resumes bit for bit.
"""
from __future__ import annotations

import hashlib
import hmac
import json
import os
import zipfile
from typing import Any, Mapping

import numpy as np

from refimpl._parsing import json_loads_strict
from refimpl.atomic import atomic_path
from refimpl.npy_files import read_npz

__all__ = [
    "save_checkpoint", "load_checkpoint", "load_state_dict_npz", "check_params",
    "rng_state_to_json", "rng_from_json",
]

_META = "__meta__"
_CHECKSUM = "__checksum__"
_RESERVED = (_META, _CHECKSUM)
_ALLOWED_KINDS = "biufc"  # bool, signed/unsigned integers, floats, complex
_BIT_GENERATORS = ("PCG64", "PCG64DXSM", "MT19937", "Philox", "SFC64")

# --------------------------------------------------------------------------------------------------
# internals

def _checksum(entries: Mapping[str, np.ndarray]) -> bytes:
    """SHA-256 over names, shapes, dtypes and C-order bytes of ``entries`` in sorted name order."""
    h = hashlib.sha256()
    for name in sorted(entries):
        a = entries[name]
        h.update(name.encode("utf-8") + b"\0")
        h.update(",".join(str(n) for n in a.shape).encode("ascii") + b"\0")  # the original shape ("" for 0-d)
        h.update(a.dtype.str.encode("ascii") + b"\0")
        if a.size:
            h.update(np.ascontiguousarray(a).reshape(-1).view(np.uint8))  # C-order bytes, no copy if contiguous
    return h.digest()


def _check_arrays(arrays, allow_reserved: bool = False) -> dict[str, np.ndarray]:
    if not isinstance(arrays, Mapping):
        raise ValueError(f"arrays: expected a dict name -> ndarray, got {type(arrays).__name__}")
    out = {}
    for name, a in arrays.items():
        if not isinstance(name, str) or not name:
            raise ValueError(f"arrays: names must be non-empty strings, got {name!r}")
        if name in _RESERVED and not allow_reserved:
            raise ValueError(f"arrays: the name {name!r} is reserved for the checkpoint format")
        if not isinstance(a, np.ndarray):
            raise ValueError(f"arrays[{name!r}]: expected a numpy array, got {type(a).__name__}")
        if a.dtype.kind not in _ALLOWED_KINDS or a.dtype.hasobject:
            raise ValueError(f"arrays[{name!r}]: dtype {a.dtype} cannot be stored without pickle; "
                             f"expected bool, integer, float or complex")
        out[name] = a
    return out


def _write_npz_atomic(path: str, entries: Mapping[str, np.ndarray]) -> None:
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        with zipfile.ZipFile(f, "w", compression=zipfile.ZIP_STORED, allowZip64=True) as zf:
            for name, a in entries.items():
                with zf.open(name + ".npy", "w", force_zip64=True) as member:
                    np.lib.format.write_array(member, a, allow_pickle=False)


# --------------------------------------------------------------------------------------------------
# checkpoints

def save_checkpoint(path, arrays: Mapping[str, np.ndarray], meta: Mapping[str, Any] | None = None) -> None:
    """Write ``arrays`` and ``meta`` atomically to the ``.npz`` file ``path`` with a SHA-256 checksum.

    Parameters
    ----------
    path : str or os.PathLike
        Target file (conventionally ``*.npz``); its directory must exist. An existing file is replaced
        atomically.
    arrays : dict name -> ndarray
        Numeric arrays (bool/int/float/complex; object and string arrays are refused). Names ``__meta__`` and
        ``__checksum__`` are reserved.
    meta : dict, optional
        JSON-serialisable metadata (epoch, config, ``rng_state_to_json(rng)``, ...); NaN/inf are refused.

    Raises
    ------
    ValueError
        Bad names, dtypes or metadata. Nothing is written then.
    """
    entries = _check_arrays(arrays)
    meta = {} if meta is None else meta
    if not isinstance(meta, Mapping):
        raise ValueError(f"meta: expected a dict, got {type(meta).__name__}")
    try:
        text = json.dumps(meta, sort_keys=True, allow_nan=False)
    except (TypeError, ValueError) as e:
        raise ValueError(f"meta: not JSON-serialisable: {e}") from e
    entries[_META] = np.frombuffer(text.encode("utf-8"), dtype=np.uint8).copy()
    entries[_CHECKSUM] = np.frombuffer(_checksum(entries), dtype=np.uint8).copy()
    _write_npz_atomic(os.fspath(path), entries)



def load_checkpoint(path) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Read a checkpoint written by :func:`save_checkpoint` and verify its checksum.

    Returns
    -------
    arrays : dict name -> ndarray
    meta : dict

    Raises
    ------
    ValueError
        Corrupted, truncated or foreign file: bad zip structure or CRC, encrypted or oddly compressed members,
        missing ``__meta__``/``__checksum__``, checksum mismatch, malformed metadata (not UTF-8 JSON, not an
        object, NaN/inf, nesting too deep), a ``.npy`` header whose shape does not match its data, a dtype
        other than bool/int/float/complex, or content declared larger than ``32 ×`` the file size + 8 MiB.
        Memory stays bounded by that size.
    OSError
        No file at ``path`` (``FileNotFoundError``), a directory, unreadable.
    """
    entries = read_npz(path)
    missing = [k for k in _RESERVED if k not in entries]
    if missing:
        raise ValueError(f"{os.fspath(path)}: not a refimpl checkpoint (missing {missing}); "
                         f"use load_state_dict_npz for a plain state dict")
    stored = entries.pop(_CHECKSUM)
    if stored.dtype != np.uint8 or stored.shape != (32,):
        raise ValueError(f"{os.fspath(path)}: malformed checksum entry (dtype {stored.dtype}, shape {stored.shape})")
    if not hmac.compare_digest(stored.tobytes(), _checksum(entries)):
        raise ValueError(f"{os.fspath(path)}: checksum mismatch, the file is corrupted")
    meta_raw = entries.pop(_META)
    if meta_raw.dtype != np.uint8 or meta_raw.ndim != 1:
        raise ValueError(f"{os.fspath(path)}: malformed metadata entry (dtype {meta_raw.dtype}, shape "
                         f"{meta_raw.shape}); expected UTF-8 JSON text as uint8 (n,)")
    try:
        meta = json_loads_strict(meta_raw.tobytes().decode("utf-8"))
    except (ValueError, RecursionError) as e:  # UnicodeDecodeError and JSONDecodeError are ValueErrors
        raise ValueError(f"{os.fspath(path)}: malformed metadata: {type(e).__name__}: {str(e)[:200]}") from e
    if not isinstance(meta, dict):
        raise ValueError(f"{os.fspath(path)}: malformed metadata: expected a JSON object, got {type(meta).__name__}")
    return entries, meta


def load_state_dict_npz(path) -> dict[str, np.ndarray]:
    """Read a PyTorch state dict saved as ``.npz`` (``np.savez(path, **{k: v.numpy() ...})``): name -> array.

    No metadata or checksum is expected. If the file is a refimpl checkpoint, its checksum is verified and its
    arrays are returned without the metadata.

    Raises
    ------
    ValueError
        Unreadable/corrupted file, or a member that would need pickle (object arrays).
    """
    entries = read_npz(path)
    if _CHECKSUM in entries or _META in entries:
        return load_checkpoint(path)[0]
    return entries


def check_params(params: Mapping[str, np.ndarray], expected_shapes: Mapping[str, tuple]) -> None:
    """Check that ``params`` has exactly the expected names and shapes, with finite floating values.

    Parameters
    ----------
    params : dict name -> ndarray
    expected_shapes : dict name -> tuple of int

    Raises
    ------
    ValueError
        One message listing every missing, unexpected, mis-shaped, non-floating or non-finite entry.
    """
    if not isinstance(params, Mapping):
        raise ValueError(f"params: expected a dict name -> ndarray, got {type(params).__name__}")
    problems = []
    missing = sorted(set(expected_shapes) - set(params))
    unexpected = sorted(set(params) - set(expected_shapes))
    if missing:
        problems.append(f"missing keys {missing}")
    if unexpected:
        problems.append(f"unexpected keys {unexpected}")
    for name in sorted(set(params) & set(expected_shapes)):
        a, want = params[name], tuple(expected_shapes[name])
        shape = getattr(a, "shape", None)
        if shape != want:
            problems.append(f"{name!r}: expected shape {want}, got {shape}")
        elif not np.issubdtype(a.dtype, np.floating):
            problems.append(f"{name!r}: expected a floating dtype, got {a.dtype}")
        elif not np.all(np.isfinite(a)):
            problems.append(f"{name!r}: contains NaN or inf")
    if problems:
        raise ValueError("params do not match the expected layout: " + "; ".join(problems))


# --------------------------------------------------------------------------------------------------
# random generator state

def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.floating):
        return float(x)
    return x


def rng_state_to_json(rng: np.random.Generator) -> str:
    """The state of ``rng`` (``rng.bit_generator.state``) as JSON text, e.g. for ``meta["rng"]``.

    Python's ``json`` keeps 128-bit integers exactly; arrays (MT19937, Philox) become lists.
    """
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng: expected a numpy.random.Generator, got {type(rng).__name__}")
    return json.dumps(_jsonable(rng.bit_generator.state), sort_keys=True)


def rng_from_json(text: str) -> np.random.Generator:
    """A new ``numpy.random.Generator`` in the state recorded by :func:`rng_state_to_json`.

    Raises
    ------
    ValueError
        Malformed text or an unknown bit generator.
    """
    try:
        state = json.loads(text)
        name = state["bit_generator"]
    except (TypeError, ValueError, KeyError) as e:
        raise ValueError(f"text: not a generator state recorded by rng_state_to_json: {e}") from e
    if name not in _BIT_GENERATORS:
        raise ValueError(f"text: unknown bit generator {name!r}; expected one of {_BIT_GENERATORS}")
    bit_generator = getattr(np.random, name)()
    try:
        bit_generator.state = state
    except (TypeError, ValueError, KeyError) as e:
        raise ValueError(f"text: invalid {name} state: {e}") from e
    return np.random.Generator(bit_generator)
