"""Running exported models with onnxruntime: validated loading and metadata (:class:`DeployedModel`), the
generic runtime every model's ``Runtime`` (``deploy/models/``) is built on.

Sessions come from :mod:`deploy.session` (the project's settings, ``spec/deploy.md`` §7).

Every model is validated before use (``deploy.validate.validate_model``: checker, strict shape inference, IR
version) and its metadata decoded with ``json.loads`` (never executed).

Shape legend: B batch, T frames, P pose size, Z latent size, H hidden size, L layers.
"""
from __future__ import annotations

from pathlib import Path
from typing import Mapping

import numpy as np
import onnx

from deploy.metadata import read_metadata
from deploy.session import make_session, make_session_options  # noqa: F401  (their home before deploy.session)
from deploy.validate import validate_model

__all__ = ["DeployedModel", "load_model"]

_NP_FROM_ORT = {"tensor(float)": np.float32, "tensor(double)": np.float64, "tensor(int64)": np.int64,
                "tensor(bool)": np.bool_}


def _load_proto(model) -> onnx.ModelProto:
    if isinstance(model, onnx.ModelProto):
        return model
    if isinstance(model, bytes):
        try:
            return onnx.load_model_from_string(model)
        except Exception as exc:
            raise ValueError(f"model: the bytes are not a readable ONNX model ({type(exc).__name__})") from exc
    path = Path(model)
    if not path.is_file():
        raise ValueError(f"model: no such file {str(path)!r}")
    try:
        return onnx.load(str(path))
    except Exception as exc:  # onnx raises DecodeError and others on garbage
        raise ValueError(f"model: {str(path)!r} is not a readable ONNX model ({type(exc).__name__})") from exc


_METADATA_TYPES = {"model": dict, "io": dict, "representation": dict, "normalization": (dict, type(None)),
                   "skeleton": (dict, type(None)), "exporter": dict, "frame_rate": (int, float), "format": str,
                   "source_paper": str}


def _check_metadata_types(meta: dict) -> None:
    """The keys this package writes must have the documented JSON types (``deploy/metadata.py``); a model that
    carries any of them (``format``, ``exporter``, ...) must carry all of them — ``metadata_props`` are serialized
    last, so a file cut at an entry boundary would otherwise load with keys silently missing."""
    for key, types in _METADATA_TYPES.items():
        if key in meta and (not isinstance(meta[key], types) or isinstance(meta[key], bool)):
            raise ValueError(f"metadata[{key!r}]: expected a JSON {getattr(types, '__name__', 'object or null')}, "
                             f"got {type(meta[key]).__name__}")
    present = [k for k in _METADATA_TYPES if k in meta]
    if present and len(present) != len(_METADATA_TYPES):
        missing = [k for k in _METADATA_TYPES if k not in meta]
        raise ValueError(f"metadata: keys {missing} are missing (truncated file?); a refimpl.deploy model has "
                         f"{sorted(_METADATA_TYPES)}")


class DeployedModel:
    """An exported model loaded for inference: validated proto, decoded metadata, onnxruntime session.

    Attributes
    ----------
    metadata : dict
        ``metadata_props`` decoded with ``json.loads`` (``deploy/metadata.py`` lists the keys).
    inputs, outputs : list of (name, shape, dtype)
        Declared graph inputs/outputs; ``shape`` entries are ints or symbolic names.
    """

    def __init__(self, model, *, intra_op_threads: int = 1, validate: bool = True):
        proto = _load_proto(model)
        if validate:
            validate_model(proto)
        self.metadata = read_metadata(proto)
        _check_metadata_types(self.metadata)
        self.session = make_session(proto, intra_op_threads=intra_op_threads)
        self.inputs = [(i.name, list(i.shape), _NP_FROM_ORT.get(i.type, None)) for i in self.session.get_inputs()]
        self.outputs = [(o.name, list(o.shape), _NP_FROM_ORT.get(o.type, None))
                        for o in self.session.get_outputs()]

    @property
    def role(self) -> str | None:
        """``metadata["model"]["role"]`` (``init``, ``step``, ``rollout``) when present, else ``None``."""
        model = self.metadata.get("model")
        role = model.get("role") if isinstance(model, dict) else None
        return role if isinstance(role, str) else None

    def run(self, feeds: Mapping[str, np.ndarray] | None = None, **kw) -> dict[str, np.ndarray]:
        """Run once; inputs by name (``feeds`` dict and/or keywords), outputs as a dict by name.

        Inputs are converted to the declared dtype (float64 → float32 for a float32 model) after checking the
        names, ranks, fixed dimensions and finiteness.

        Raises
        ------
        ValueError
            Missing or unknown input name, wrong rank or fixed dimension, non-finite values.
        """
        given = dict(feeds or {})
        given.update(kw)
        names = [n for n, _, _ in self.inputs]
        unknown = sorted(set(given) - set(names))
        missing = [n for n in names if n not in given]
        if unknown or missing:
            raise ValueError(f"feeds: expected inputs {names}; missing {missing}, unknown {unknown}")
        ready = {}
        for name, shape, dtype in self.inputs:
            a = np.asarray(given[name])
            if a.ndim != len(shape) or any(isinstance(d, int) and d != s for d, s in zip(shape, a.shape)):
                raise ValueError(f"{name}: expected shape {shape}, got {a.shape}")
            if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
                raise ValueError(f"{name}: contains NaN or infinite values")
            ready[name] = np.ascontiguousarray(a, dtype=dtype) if dtype is not None else a
        outs = self.session.run(None, ready)
        return {name: out for (name, _, _), out in zip(self.outputs, outs)}


def load_model(path, *, intra_op_threads: int = 1, validate: bool = True) -> DeployedModel:
    """Load ``path`` (or a ModelProto / bytes) as a :class:`DeployedModel` (validated unless ``validate=False``)."""
    return DeployedModel(path, intra_op_threads=intra_op_threads, validate=validate)
