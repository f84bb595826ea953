"""Model metadata: everything a consumer needs to use an exported model without this package.

Stored in ``model.metadata_props`` as key → JSON string (``spec/deploy.md`` §4). Read with ``json.loads``; never
executed. Keys:

====================  ========================================================================================
key                   value (JSON)
====================  ========================================================================================
``format``            ``"refimpl.deploy/1"``: version of this metadata contract
``model``             ``{"name", "role", "config", "transition_length"?}`` (role: ``init``, ``step``, ``rollout``)
``io``                ``{"inputs": [...], "outputs": [...]}``, each ``{"name", "shape", "meaning"}``
``representation``    pose layout: ``{"name", "size", "fields": [{"name", "start", "size", ...}]}``
``normalization``     ``{"mean": [P], "std": [P], "in_graph": bool, "model_io": "raw" | "normalized",
                      "equation"}``: ``pose_normalized = (pose − mean) / std`` per entry of the last axis; with
                      ``in_graph`` the graph does it, so the model takes and returns raw poses
                      (``model_io = "raw"``); else the caller does (``"normalized"``). ``null``: no statistics
                      known, the model's inputs and outputs are whatever it was trained on
``skeleton``          ``{"names", "parents", "offsets", "units"?, "source"?}`` (joint ``j``: name, parent index, −1
                      for the root, offset from the parent in the rest pose) or ``null``
``input_transform``   how to build the inputs from world-space data (``{"summary", "steps": [...], ...}``, any
                      JSON the exporter documents) or ``null``
``output_transform``  how to read the outputs back into world space (same form) or ``null``
``frame_rate``        frames per second (number)
``source_paper``      citation string
``exporter``          ``{"name", "version", "opset", "ir_version", "dtype", "variant"}``
====================  ========================================================================================

Shape legend in ``io``: symbolic dimension names (``"B"`` batch) or integers.
"""
from __future__ import annotations

from typing import Any, Mapping

import numpy as np
import onnx

from refimpl._parsing import json_loads_strict
from refimpl.files import read_bytes

from deploy.graph import IR_VERSION, OPSET, ir_version_for

__all__ = ["EXPORTER_VERSION", "FORMAT", "skeleton_metadata", "normalization_metadata", "read_metadata",
           "io_entries", "build_metadata"]

EXPORTER_VERSION = "0.1.0"
FORMAT = "refimpl.deploy/1"


def skeleton_metadata(skeleton, *, units: str | None = None, source: str | None = None) -> dict | None:
    """``{"names", "parents", "offsets"[, "units", "source"]}`` (plain lists) from a ``refimpl.skeleton.Skeleton``
    (or a dict with those keys, passed through with its lists checked), or ``None``."""
    if skeleton is None:
        return None
    if isinstance(skeleton, Mapping):
        out = {"names": [str(n) for n in skeleton["names"]], "parents": [int(p) for p in skeleton["parents"]],
               "offsets": [[float(v) for v in row] for row in skeleton["offsets"]]}
        for key in ("units", "source"):
            if skeleton.get(key) is not None:
                out[key] = str(skeleton[key])
    else:
        out = {"names": [str(n) for n in skeleton.names],
               "parents": [int(p) for p in skeleton.parents],
               "offsets": [[float(v) for v in row] for row in np.asarray(skeleton.offsets, dtype=np.float64)]}
    if not (len(out["names"]) == len(out["parents"]) == len(out["offsets"])):
        raise ValueError(f"skeleton: expected as many names, parents and offsets, got {len(out['names'])}, "
                         f"{len(out['parents'])} and {len(out['offsets'])}")
    if units is not None:
        out["units"] = units
    if source is not None:
        out["source"] = source
    return out


def normalization_metadata(normalization, in_graph: bool) -> dict | None:
    """The ``normalization`` entry: ``{"mean", "std", "in_graph", "model_io", "equation"}`` or ``None``."""
    if normalization is None:
        return None
    return {"mean": [float(v) for v in normalization[0]], "std": [float(v) for v in normalization[1]],
            "in_graph": bool(in_graph), "model_io": "raw" if in_graph else "normalized",
            "equation": ("normalized = (x - mean) / std and x = normalized * std + mean, per entry of the last "
                         "axis; " + ("the graph applies both: feed raw values, read raw values" if in_graph else
                                     "the graph does not: normalise the inputs and de-normalise the outputs "
                                     "yourself"))}


def read_metadata(model: onnx.ModelProto | str | bytes) -> dict[str, Any]:
    """All ``metadata_props`` of ``model`` (a ModelProto, a path, or serialized bytes) decoded with ``json.loads``.

    Strict JSON: ``NaN``/``Infinity`` and numbers that overflow a float (``1e999``) are refused, and so is nesting
    deeper than Python's recursion limit.

    Raises
    ------
    ValueError
        When a value is not valid JSON (the message names the key), or the file is not a readable ONNX model
        (protobuf's ``DecodeError`` is not let through).
    """
    if isinstance(model, (str, bytes)) and not isinstance(model, onnx.ModelProto):
        try:
            model = onnx.load_model_from_string(model if isinstance(model, bytes) else read_bytes(model))
        except OSError:
            raise
        except ValueError as exc:  # not a regular file (a FIFO, a device): refimpl.files
            if isinstance(model, str) and model in str(exc):
                raise
            raise ValueError(f"model: not a readable ONNX model ({type(exc).__name__})") from None
        except Exception as exc:  # noqa: BLE001 - protobuf's DecodeError and friends on a damaged file
            where = "model" if isinstance(model, bytes) else repr(str(model))
            raise ValueError(f"{where}: not a readable ONNX model ({type(exc).__name__})") from None
    out = {}
    for prop in model.metadata_props:
        try:
            out[prop.key] = json_loads_strict(prop.value)
        except (ValueError, RecursionError) as exc:  # JSONDecodeError is a ValueError
            raise ValueError(f"metadata[{prop.key!r}]: expected a JSON value, got {prop.value[:60]!r} "
                             f"({type(exc).__name__})") from exc
    return out


def io_entries(*entries) -> list[dict]:
    """``[(name, shape, meaning), ...]`` -> the ``io`` metadata list ``[{"name", "shape", "meaning"}, ...]``."""
    return [{"name": n, "shape": list(shape), "meaning": m} for n, shape, m in entries]


def build_metadata(g, *, name: str, role: str, config: Mapping[str, Any], io: Mapping[str, Any],
                   representation: Mapping[str, Any], normalization=None, in_graph: bool = False, skeleton=None,
                   frame_rate: float = 30.0, source_paper: str = "", variant: str = "float",
                   extra: Mapping[str, Any] | None = None, T: int | None = None,
                   input_transform: Mapping[str, Any] | None = None,
                   output_transform: Mapping[str, Any] | None = None) -> dict:
    """The metadata of an exported model (every key of the module docstring, in that order, then ``extra``).

    Parameters
    ----------
    g : GraphBuilder
        The graph's builder (opset and dtype go to ``exporter``).
    name, role : str
        ``model.name`` (the exporter's key, ``deploy.models.EXPORTERS``) and ``model.role``.
    config : dict
        The network's config (JSON-friendly).
    io : dict ``{"inputs": [...], "outputs": [...]}`` (:func:`io_entries`)
    representation : dict
        The pose layout.
    normalization : (mean (P,), std (P,)) or None
    in_graph : bool
        Whether the graph standardises inside (raw poses in and out).
    skeleton : Skeleton, dict or None
        Joint names, parents and offsets naming the slots of the pose (:func:`skeleton_metadata`).
    frame_rate : float
    source_paper : str
    variant : str
        ``exporter.variant`` (``"float"``, ``"float.scan"``, ``"compact.int8"``, ...).
    extra : dict, optional
        More keys (they replace the standard ones of the same name).
    T : int, optional
        ``model.transition_length``, for models with a fixed number of frames.
    input_transform, output_transform : dict, optional
        How a consumer builds the inputs from world-space data and maps the outputs back, stated in words and
        equations (``{"summary": str, "steps": [str, ...], ...}``), so that nothing but the metadata and
        ``deploy/README.md`` is needed. ``null`` when not given.
    """
    model = {"name": name, "role": role, "config": dict(config)}
    if T is not None:
        model["transition_length"] = int(T)
    meta = {
        "format": FORMAT,
        "model": model,
        "io": io,
        "representation": representation,
        "normalization": normalization_metadata(normalization, in_graph),
        "skeleton": skeleton_metadata(skeleton),
        "input_transform": None if input_transform is None else dict(input_transform),
        "output_transform": None if output_transform is None else dict(output_transform),
        "frame_rate": float(frame_rate),
        "source_paper": source_paper,
        "exporter": {"name": "refimpl.deploy", "version": EXPORTER_VERSION, "opset": g.opset,
                     "ir_version": IR_VERSION if g.opset == OPSET else ir_version_for(g.opset),
                     "dtype": g.dtype.name, "variant": variant},
    }
    for k, v in (extra or {}).items():
        meta[k] = v
    return meta
