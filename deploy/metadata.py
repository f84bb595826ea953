"""Model metadata: everything a consumer needs to use an exported model without this package.

Stored in ``model.metadata_props`` as key → JSON string (``spec/deploy.md`` §4). Read with ``json.loads``; never
executed. Keys:

==================  ========================================================================================
key                 value (JSON)
==================  ========================================================================================
``format``          ``"refimpl.deploy/1"``: version of this metadata contract
``model``           ``{"name", "role", "config", "transition_length"?}`` (role: ``init``, ``step``, ``rollout``)
``io``              ``{"inputs": [...], "outputs": [...]}``, each ``{"name", "shape", "meaning"}``
``representation``  pose layout: ``{"name", "size", "fields": [{"name", "start", "size", ...}]}``
``normalization``   ``{"mean": [P], "std": [P], "in_graph": bool}``: ``pose_normalized = (pose − mean) / std``;
                    with ``in_graph`` the model takes and returns raw poses; ``null`` when unknown
``skeleton``        ``{"names", "parents", "offsets"}`` or ``null``
``frame_rate``      frames per second (number)
``source_paper``    citation string
``exporter``        ``{"name", "version", "opset", "ir_version", "dtype", "variant"}``
==================  ========================================================================================

Shape legend in ``io``: symbolic dimension names (``"B"`` batch) or integers.
"""
from __future__ import annotations

import json
import math
from typing import Any, Mapping

import numpy as np
import onnx

from refimpl._parsing import json_loads_strict

__all__ = ["EXPORTER_VERSION", "FORMAT", "QTG_PAPER", "skeleton_metadata", "read_metadata",
           "qtg_representation"]

EXPORTER_VERSION = "0.1.0"
FORMAT = "refimpl.deploy/1"
QTG_PAPER = ("Geleijn, Radziszewski, van Straaten, Galvan Debarba: Lightweight Quaternion Transition Generation "
             "with Neural Networks. IEEE VR 2021 (abstracts and workshops)")


def skeleton_metadata(skeleton) -> dict | None:
    """``{"names", "parents", "offsets"}`` (plain lists) from a ``refimpl.skeleton.Skeleton``, or ``None``."""
    if skeleton is None:
        return None
    return {"names": [str(n) for n in skeleton.names],
            "parents": [int(p) for p in skeleton.parents],
            "offsets": [[float(v) for v in row] for row in np.asarray(skeleton.offsets, dtype=np.float64)]}


def qtg_representation(pose_size: int) -> dict:
    """Layout of a QTG pose vector: root translation (3) then ``(P − 3) / 4`` local joint quaternions (w, x, y, z)."""
    joints = (pose_size - 3) // 4
    return {"name": "qtg_pose", "size": int(pose_size),
            "fields": [{"name": "root_translation", "start": 0, "size": 3,
                        "meaning": "root translation relative to the window's first pose, z-normalised"},
                       {"name": "joint_rotations", "start": 3, "size": 4 * joints, "joints": joints,
                        "quaternion": "(w, x, y, z), Hamilton, local to the parent joint, not normalised"}]}



def _finite_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(f"{text} overflows a float")
    return value


def read_metadata(model: onnx.ModelProto | str | bytes) -> dict[str, Any]:
    """All ``metadata_props`` of ``model`` (a ModelProto, a path, or serialized bytes) decoded with ``json.loads``.

    Strict JSON: ``NaN``/``Infinity`` and numbers that overflow a float (``1e999``) are refused, and so is nesting
    deeper than Python's recursion limit.

    Raises
    ------
    ValueError
        When a value is not valid JSON (the message names the key).
    """
    if isinstance(model, (str, bytes)) and not isinstance(model, onnx.ModelProto):
        model = onnx.load_model_from_string(model) if isinstance(model, bytes) else onnx.load(model)
    out = {}
    for prop in model.metadata_props:
        try:
            out[prop.key] = json_loads_strict(prop.value)
        except (ValueError, RecursionError) as exc:  # JSONDecodeError is a ValueError
            raise ValueError(f"metadata[{prop.key!r}]: expected a JSON value, got {prop.value[:60]!r} "
                             f"({type(exc).__name__})") from exc
    return out


def _io_entry(name: str, shape, meaning: str) -> dict:
    return {"name": name, "shape": list(shape), "meaning": meaning}


def _merge(base: dict, extra: Mapping[str, Any] | None) -> dict:
    out = dict(base)
    for k, v in (extra or {}).items():
        out[k] = v
    json.dumps(out, allow_nan=False)  # fail early on non-JSON values
    return out
