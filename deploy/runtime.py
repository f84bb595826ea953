"""Running exported models with onnxruntime: validated loading and metadata (:class:`DeployedModel`), the
generic runtime every model's ``Runtime`` (``deploy/models/``) is built on.

Sessions come from :mod:`deploy.session` (the project's settings, ``spec/deploy.md`` §7).

Every model is validated before use (``deploy.validate.validate_model``: checker, strict shape inference, IR
version) and its metadata decoded with ``json.loads`` (never executed).

Shape legend: B batch, T frames, P pose size, Z latent size, H hidden size, L layers.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Mapping

import numpy as np
import onnx

from refimpl.bounds import check_number
from refimpl.files import read_bytes

from deploy.metadata import read_metadata
from deploy.session import check_model_size, make_session
from deploy.session import make_session_options  # noqa: F401  (its home before deploy.session)
from deploy.validate import validate_model

__all__ = ["DeployedModel", "load_model", "MAX_INPUT_ELEMENTS"]

#: Largest input tensor :meth:`DeployedModel.run` passes to onnxruntime (elements; 2^26 = 256 MiB of float32).
MAX_INPUT_ELEMENTS = 2 ** 26

#: Array kinds accepted for each declared input type (anything else is refused, not cast): a float input takes
#: floating and integer arrays; an int64 input integers; a bool input booleans.
_ACCEPTED_KINDS = {np.float32: "fiu", np.float64: "fiu", np.int64: "iu", np.bool_: "b"}

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
    try:
        data = read_bytes(path)  # a regular file (not a FIFO or a device), read to its real size
    except FileNotFoundError:
        raise ValueError(f"model: no such file {str(path)!r}") from None
    except (OSError, ValueError) as exc:
        raise ValueError(f"model: {exc}") from None
    try:
        return onnx.load_model_from_string(data)
    except Exception as exc:  # onnx raises DecodeError and others on garbage
        raise ValueError(f"model: {str(path)!r} is not a readable ONNX model ({type(exc).__name__})") from exc


_METADATA_TYPES = {"model": dict, "io": dict, "representation": dict, "normalization": (dict, type(None)),
                   "skeleton": (dict, type(None)), "exporter": dict, "frame_rate": (int, float), "format": str,
                   "source_paper": str}
#: Keys written by ``build_metadata`` since the contract gained them (type-checked when present, not required,
#: so models exported before them still load).
_OPTIONAL_METADATA_TYPES = {"input_transform": (dict, type(None)), "output_transform": (dict, type(None))}


def _check_metadata_types(meta: dict) -> None:
    """The keys this package writes must have the documented JSON types (``deploy/metadata.py``); a model that
    carries any of them (``format``, ``exporter``, ...) must carry all of them — ``metadata_props`` are serialized
    last, so a file cut at an entry boundary would otherwise load with keys silently missing."""
    for key, types in {**_METADATA_TYPES, **_OPTIONAL_METADATA_TYPES}.items():
        if key in meta and (not isinstance(meta[key], types) or isinstance(meta[key], bool)):
            raise ValueError(f"metadata[{key!r}]: expected a JSON {getattr(types, '__name__', 'object or null')}, "
                             f"got {type(meta[key]).__name__}")
    present = [k for k in _METADATA_TYPES if k in meta]
    if present and len(present) != len(_METADATA_TYPES):
        missing = [k for k in _METADATA_TYPES if k not in meta]
        raise ValueError(f"metadata: keys {missing} are missing (truncated file?); a refimpl.deploy model has "
                         f"{sorted(_METADATA_TYPES)}")


def _is_number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def _want(ok: bool, key: str, expected: str, value) -> None:
    if not ok:
        raise ValueError(f"metadata[{key}]: expected {expected}, got {type(value).__name__} {str(value)[:40]}")


def _check_numbers(value, key: str) -> None:
    _want(isinstance(value, list) and all(_is_number(v) for v in value), key, "a list of finite numbers", value)


def _check_metadata_contents(meta: dict) -> None:
    """The fields inside the documented keys that the runners and ``python -m deploy info`` read (the same JSON
    types ``deploy/metadata.py`` writes), so that a damaged or hand-edited model is refused when it is opened
    (one line naming the field) rather than failing later with a ``KeyError`` or ``TypeError``."""
    model = meta.get("model")
    if isinstance(model, dict):
        _want(isinstance(model.get("name"), str), "'model']['name'", "a string", model.get("name"))
        if "config" in model:
            _want(isinstance(model["config"], dict), "'model']['config'", "a JSON object", model["config"])
    rep = meta.get("representation")
    if isinstance(rep, dict) and "name" in rep:
        _want(isinstance(rep["name"], str), "'representation']['name'", "a string", rep["name"])
    skel = meta.get("skeleton")
    if isinstance(skel, dict):
        names, parents, offsets = skel.get("names"), skel.get("parents"), skel.get("offsets")
        _want(isinstance(names, list) and all(isinstance(n, str) for n in names), "'skeleton']['names'",
              "a list of strings", names)
        _want(isinstance(parents, list) and all(isinstance(p, int) and not isinstance(p, bool) for p in parents),
              "'skeleton']['parents'", "a list of integers", parents)
        _want(isinstance(offsets, list) and all(isinstance(o, list) and len(o) == 3 and all(map(_is_number, o))
                                                for o in offsets), "'skeleton']['offsets'",
              "a list of [x, y, z] numbers", offsets)
        _want(len(names) == len(parents) == len(offsets), "'skeleton'", "as many names, parents and offsets",
              f"{len(names)}, {len(parents)}, {len(offsets)}")
        if skel.get("units") is not None:
            _want(isinstance(skel["units"], str), "'skeleton']['units'", "a string", skel["units"])
    norm = meta.get("normalization")
    if isinstance(norm, dict):
        _check_numbers(norm.get("mean"), "'normalization']['mean'")
        _check_numbers(norm.get("std"), "'normalization']['std'")
        _want(len(norm["mean"]) == len(norm["std"]) >= 1, "'normalization'", "mean and std of one length >= 1",
              f"{len(norm['mean'])} and {len(norm['std'])}")
        _want(isinstance(norm.get("in_graph"), bool), "'normalization']['in_graph'", "true or false",
              norm.get("in_graph"))
    for key in ("input_transform", "output_transform"):
        t = meta.get(key)
        if isinstance(t, dict):
            if "summary" in t:
                _want(isinstance(t["summary"], str), f"{key!r}]['summary'", "a string", t["summary"])
            if "steps" in t:
                _want(isinstance(t["steps"], list), f"{key!r}]['steps'", "a list", t["steps"])
    if "frame_rate" in meta:
        check_number(meta["frame_rate"], "metadata['frame_rate']", "fps")


class DeployedModel:
    """An exported model loaded for inference: validated proto, decoded metadata, onnxruntime session.

    Attributes
    ----------
    metadata : dict
        ``metadata_props`` decoded with ``json.loads`` (``deploy/metadata.py`` lists the keys).
    inputs, outputs : list of (name, shape, dtype)
        Declared graph inputs/outputs; ``shape`` entries are ints or symbolic names.
    """

    def __init__(self, model, *, intra_op_threads: int = 1, validate: bool = True, spinning: bool = False):
        proto = _load_proto(model)
        check_model_size(proto)   # before the checker too: a declared 10 GB constant is refused without reading it
        if validate:
            validate_model(proto)
        self.metadata = read_metadata(proto)
        _check_metadata_types(self.metadata)
        _check_metadata_contents(self.metadata)
        self.session = make_session(proto, intra_op_threads=intra_op_threads, check_size=False, spinning=spinning)
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

        Every input is checked before onnxruntime sees it (``spec/deploy.md`` §7): names; array kind (numeric,
        not object, string or complex; see ``_ACCEPTED_KINDS``); rank and fixed dimensions; symbolic dimensions
        (``"B"``) equal across all inputs and at least 1 (a batch of 0 crashes onnxruntime's GRU kernel and kills
        the process); at most :data:`MAX_INPUT_ELEMENTS` elements; finite values after the conversion to the
        declared dtype (float64 → float32 for a float32 model; ``1e300`` would become ``inf``).

        Outputs are checked too: a non-finite output (damaged weights, absurd inputs) is a ``ValueError``.

        A portable graph (batch fixed at 1, ``deploy/portable.py``) given a batch of B > 1 along the axes its
        metadata names (``target.batch_axes``) runs once per sample and the outputs are concatenated, as a host
        with several sequences does.

        Raises
        ------
        ValueError
            Naming the input, what was expected and what was given (or the non-finite output).
        """
        if feeds is not None and not isinstance(feeds, Mapping):
            raise ValueError(f"feeds: expected a mapping name -> array, got {type(feeds).__name__}")
        given = dict(feeds or {})
        given.update(kw)
        names = [n for n, _, _ in self.inputs]
        unknown = sorted(map(str, set(given) - set(names)))
        missing = [n for n in names if n not in given]
        if unknown or missing:
            raise ValueError(f"feeds: expected inputs {names}; missing {missing}, unknown {unknown}")
        batch = self._portable_batch(given)
        if batch > 1:
            return self._run_per_sample(given, batch)
        ready = {}
        symbols: dict[str, tuple[str, int]] = {}
        for name, shape, dtype in self.inputs:
            ready[name] = self._check_input(name, shape, dtype, given[name], symbols)
        outs = self.session.run(None, ready)
        result = {name: out for (name, _, _), out in zip(self.outputs, outs)}
        for name, out in result.items():
            if out.dtype.kind == "f" and not np.all(np.isfinite(out)):
                raise ValueError(f"{name}: the model produced NaN or infinite values from finite inputs (weights "
                                 "damaged, or inputs far outside the training range)")
        return result

    def _batch_axes(self) -> dict:
        from deploy.portable import is_portable

        if not is_portable(self.metadata):
            return {}
        axes = self.metadata["target"].get("batch_axes")
        return axes if isinstance(axes, dict) else {}

    def _portable_batch(self, given) -> int:
        """The batch B > 1 given to a portable graph along its batch axes (1 otherwise, and for other graphs)."""
        sizes = set()
        for name, axis in self._batch_axes().items():
            a = given.get(name)
            if isinstance(a, np.ndarray) and isinstance(axis, int) and 0 <= axis < a.ndim:
                sizes.add(int(a.shape[axis]))
        if len(sizes) > 1:
            raise ValueError(f"feeds: the batch axes of the inputs ({self._batch_axes()}) have different sizes "
                             f"{sorted(sizes)}")
        return sizes.pop() if sizes else 1

    def _run_per_sample(self, given, batch: int) -> dict[str, np.ndarray]:
        axes = self._batch_axes()
        runs = []
        for b in range(batch):
            feeds = {k: (np.take(v, [b], axis=axes[k]) if k in axes else v) for k, v in given.items()}
            runs.append(self.run(feeds))
        return {k: np.concatenate([r[k] for r in runs], axis=axes[k]) if k in axes else runs[0][k]
                for k in runs[0]}

    @staticmethod
    def _check_input(name, shape, dtype, value, symbols) -> np.ndarray:
        if isinstance(value, (str, bytes, Mapping)) or value is None:
            raise ValueError(f"{name}: expected a numeric array of shape {shape}, got {type(value).__name__}")
        try:
            a = np.asarray(value)
        except Exception as exc:  # ragged nested lists, objects whose __array__ raises, ...
            raise ValueError(f"{name}: expected a numeric array of shape {shape}, got {type(value).__name__} "
                             f"that is not one ({exc})") from None
        kinds = _ACCEPTED_KINDS.get(dtype, "fiub")
        if a.dtype.kind not in kinds:
            expected = {"fiu": "floating or integer", "iu": "integer", "b": "boolean"}.get(kinds, "numeric")
            raise ValueError(f"{name}: expected a {expected} array for a tensor of "
                             f"{np.dtype(dtype).name if dtype is not None else 'unknown type'}, got dtype "
                             f"{a.dtype} (object, string and complex arrays are refused, not cast)")
        if a.ndim != len(shape):
            raise ValueError(f"{name}: expected shape {shape} (rank {len(shape)}), got {a.shape} (rank {a.ndim})")
        for axis, (d, s) in enumerate(zip(shape, a.shape)):
            if isinstance(d, int) and d > 0 and d != s:
                raise ValueError(f"{name}: expected shape {shape}, got {a.shape} (axis {axis})")
            if s == 0:
                raise ValueError(f"{name}: expected shape {shape} with every dimension >= 1, got {a.shape} "
                                 f"(an empty {'batch' if d == 'B' else 'axis'} is refused: onnxruntime's GRU "
                                 "kernel crashes the process on a batch of 0)")
            if isinstance(d, str) and d:
                if d in symbols and symbols[d][1] != s:
                    other, size = symbols[d]
                    raise ValueError(f"{name}: dimension {d!r} (axis {axis}) must equal the one of {other!r}, "
                                     f"{size}; got shape {a.shape}")
                symbols.setdefault(d, (name, int(s)))
        if a.size > MAX_INPUT_ELEMENTS:
            raise ValueError(f"{name}: expected at most MAX_INPUT_ELEMENTS = {MAX_INPUT_ELEMENTS} elements, got "
                             f"shape {a.shape} ({a.size})")
        if dtype is not None:
            with np.errstate(over="ignore", invalid="ignore"):
                a = np.ascontiguousarray(a, dtype=dtype)
        if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
            raise ValueError(f"{name}: expected finite values, got NaN or infinite values (or values that "
                             f"overflow {a.dtype})")
        return a


def load_model(path, *, intra_op_threads: int = 1, validate: bool = True, spinning: bool = False) -> DeployedModel:
    """Load ``path`` (or a ModelProto / bytes) as a :class:`DeployedModel` (validated unless ``validate=False``;
    ``intra_op_threads`` and ``spinning`` as :func:`deploy.session.make_session_options`)."""
    return DeployedModel(path, intra_op_threads=intra_op_threads, validate=validate, spinning=spinning)
