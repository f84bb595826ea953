"""Argument checks shared by the models' onnxruntime wrappers (``deploy/models/*_io.py``): what
:meth:`deploy.runtime.DeployedModel.run` promises for its inputs, applied to the wrappers' own arguments before
any of them is converted, so that a wrapper refuses (``ValueError``) what it cannot use instead of coercing it.

* :func:`frames_array` — a numeric array of one of the allowed ranks (strings, bytes, booleans, complex and
  object arrays, ``None``, mappings and ragged lists refused; finite; every axis >= 1; at most
  :data:`deploy.runtime.MAX_INPUT_ELEMENTS` elements) as float32;
* :func:`count` — a frame count or batch size: an integer (``bool``, ``3.0``, ``"3"`` refused) within
  :data:`refimpl.bounds.BOUNDS` (the same bounds as ``refimpl``'s options);
* :func:`metadata_int` — an integer read from a model's metadata (a model whose metadata lacks it is refused);
* :func:`check_graph_inputs` — a loaded model of a role has exactly the graph inputs its runtime feeds (a folder
  holding another graph under the role's file name is refused when opened, not at the first call).

Shape legend: B batch, T frames, F features.
"""
from __future__ import annotations

from typing import Mapping

import numpy as np

from refimpl.bounds import check_count

from deploy.runtime import MAX_INPUT_ELEMENTS

__all__ = ["frames_array", "count", "metadata_int", "check_graph_inputs"]


def frames_array(value, name: str, ranks=(3,)) -> np.ndarray:
    """``value`` as a float32 array whose rank is one of ``ranks``; ``ValueError`` naming ``name`` otherwise.

    Integer and floating arrays (and nested lists of numbers) are accepted; everything else is refused, not cast.
    """
    if value is None or isinstance(value, (str, bytes, Mapping, bool, np.bool_)):
        raise ValueError(f"{name}: expected a numeric array of rank {' or '.join(map(str, ranks))}, got "
                         f"{type(value).__name__}")
    try:
        a = np.asarray(value)
    except Exception as exc:  # ragged nested lists, objects whose __array__ raises
        raise ValueError(f"{name}: expected a numeric array, got {type(value).__name__} that is not one "
                         f"({type(exc).__name__})") from None
    if a.dtype.kind not in "fiu":
        raise ValueError(f"{name}: expected a floating or integer array, got dtype {a.dtype} (boolean, object, "
                         "string and complex arrays are refused, not cast)")
    if a.ndim not in ranks:
        raise ValueError(f"{name}: expected rank {' or '.join(map(str, ranks))}, got shape {a.shape}")
    if 0 in a.shape:
        raise ValueError(f"{name}: expected every dimension >= 1, got shape {a.shape}")
    if a.size > MAX_INPUT_ELEMENTS:
        raise ValueError(f"{name}: expected at most MAX_INPUT_ELEMENTS = {MAX_INPUT_ELEMENTS} elements, got shape "
                         f"{a.shape}")
    with np.errstate(over="ignore", invalid="ignore"):
        a = np.ascontiguousarray(a, dtype=np.float32)
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: expected finite values, got NaN or infinite values (or values that overflow "
                         "float32)")
    return a


def count(value, name: str, bound: str = "frames") -> int:
    """An integer argument within ``refimpl.bounds.BOUNDS[bound]`` (:func:`refimpl.bounds.check_count`)."""
    return check_count(value, name, bound)


def metadata_int(model, key: str, bound: str = "frames") -> int:
    """``model.metadata[key]`` (a :class:`~deploy.runtime.DeployedModel`) as a bounded integer; ``ValueError``
    naming the key when it is missing or not an integer in range."""
    meta = getattr(model, "metadata", None) or {}
    return check_count(meta.get(key), f"metadata[{key!r}]", bound)


def check_graph_inputs(model, role: str, names) -> None:
    """``ValueError`` unless the :class:`~deploy.runtime.DeployedModel` ``model`` of ``role`` takes exactly the
    inputs ``names`` (its runtime feeds those, by name), the first of them frames of the size the metadata states
    (``representation.size``, when it is an integer): a graph of another layout is refused when it is opened, not at
    its first run."""
    got = [n for n, _, _ in model.inputs]
    if sorted(got) != sorted(names):
        raise ValueError(f"{role}: expected a graph with inputs {list(names)}, got {got} (another model's graph "
                         "under this role's file name?)")
    rep = model.metadata.get("representation")
    size = rep.get("size") if isinstance(rep, dict) else None
    shape = next(s for n, s, _ in model.inputs if n == names[0])
    if isinstance(size, int) and not isinstance(size, bool) and shape and isinstance(shape[-1], int) \
            and shape[-1] != size:
        raise ValueError(f"{role}: metadata['representation']['size'] is {size}, but the graph's input "
                         f"{names[0]!r} takes frames of {shape[-1]} (shape {shape}): metadata and graph of "
                         "different layouts")
