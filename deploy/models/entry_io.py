"""What the exporter table's entry modules (``deploy/models/*_io.py``) share: reading ``refimpl train``
checkpoints (the arrays and metadata, the parameters ``param.<name>``, a config dataclass from
``meta["model_config"]``) and writing a folder of exported models.

* :func:`read_checkpoint` — ``(arrays, meta)``; with ``state_dict_ok`` a plain state-dict ``.npz`` is accepted too
  (``meta`` then ``{}``);
* :func:`checkpoint_params` — the ``param.<name>`` arrays without the prefix (with ``state_dict_ok``: all arrays
  when there is none);
* :func:`config_from_meta` — ``config_type(**fields)`` from ``meta["model_config"]`` (unknown keys ignored), checked
  against the checkpoint schema and the task's fields (``ValueError`` only);
* :func:`checked_params` — the parameters checked against the shapes the config implies;
* :func:`write_models` — validate each model and write it as ``<name>_<role>.onnx``;
* :func:`write_npy` — an array written atomically as ``.npy`` (no pickle).
"""
from __future__ import annotations

import dataclasses
import io
from pathlib import Path

import numpy as np

from refimpl.atomic import atomic_write_bytes
from refimpl.checkpoint import load_checkpoint, load_state_dict_npz
from refimpl.checkpoint_schema import expected_param_shapes, validate_model_config, validate_params
from refimpl.checkpoint_schema import validate_task_schema

from deploy.graph import save_model
from deploy.validate import validate_model

__all__ = ["read_checkpoint", "checkpoint_params", "config_from_meta", "checked_params", "write_models",
           "write_npy"]

PARAM_PREFIX = "param."


def read_checkpoint(path, *, state_dict_ok: bool = False) -> tuple[dict, dict]:
    """``(arrays, meta)`` of a ``refimpl.checkpoint`` file; with ``state_dict_ok``, a file that is not one is read
    as a plain state-dict ``.npz`` (``meta = {}``)."""
    try:
        return load_checkpoint(path)
    except ValueError as exc:
        if not state_dict_ok or "not a refimpl checkpoint" not in str(exc):
            raise
        return load_state_dict_npz(path), {}


def checkpoint_params(arrays, *, state_dict_ok: bool = False) -> dict:
    """The arrays named ``param.<name>``, keyed ``<name>``; with ``state_dict_ok``, all arrays when none is."""
    params = {k[len(PARAM_PREFIX):]: v for k, v in arrays.items() if k.startswith(PARAM_PREFIX)}
    return (params or dict(arrays)) if state_dict_ok else params


def config_from_meta(config_type, meta, convert=None, *, schema=None, where: str = "checkpoint"):
    """``config_type`` built from the fields of ``meta["model_config"]`` it has (others ignored); ``convert``, if
    given, maps that dict first.

    The fields are checked against the checkpoint schema first (``refimpl.checkpoint_schema``: types, integer
    limits; with ``schema``, the task's checks of its stored fields: the ``CHECKPOINT_SCHEMA`` of its protocol,
    ``refimpl.checkpoint_fields.TaskSchema``), so that every problem is a
    ``ValueError`` naming ``where`` and the field — never a ``TypeError`` or ``KeyError`` from the dataclass.
    """
    model_config = meta.get("model_config") if isinstance(meta, dict) else None
    if model_config is None:
        model_config = {}
    if not isinstance(model_config, dict):
        raise ValueError(f"{where}: model_config: expected a JSON object, got {type(model_config).__name__}")
    names = {f.name for f in dataclasses.fields(config_type)}
    cfg = {k: v for k, v in model_config.items() if k in names}
    try:
        if convert:
            cfg = convert(cfg)
        config = validate_model_config(config_type, cfg, where)
    except (TypeError, KeyError, AttributeError, IndexError) as exc:
        raise ValueError(f"{where}: model_config: {type(exc).__name__} ({exc})") from None
    if schema is not None:
        validate_task_schema(schema, model_config, config, where)
    return config


def checked_params(params, config, where: str = "checkpoint", dtype=None) -> dict:
    """``params`` after :func:`refimpl.checkpoint_schema.validate_params` against the shapes ``config`` implies
    (names, shapes, one float dtype, finite, magnitude at most ``MAX_PARAM_ABS``); ``ValueError`` otherwise."""
    validate_params(params, expected_param_shapes(None, type(config), config), where, dtype=dtype)
    return params


def write_models(models: dict, out_dir, name: str) -> dict:
    """Validate every ``role -> ModelProto`` of ``models`` and write it atomically to ``out_dir/<name>_<role>.onnx``
    (``out_dir`` created if needed); returns ``role -> Path``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {}
    for role, m in models.items():
        validate_model(m)
        paths[role] = out / f"{name}_{role}.onnx"
        save_model(m, paths[role])
    return paths


def write_npy(path, array) -> Path:
    """``array`` written atomically to ``path`` as ``.npy`` (``allow_pickle=False``); returns the Path."""
    buf = io.BytesIO()
    np.save(buf, np.ascontiguousarray(array), allow_pickle=False)
    atomic_write_bytes(Path(path), buf.getvalue())
    return Path(path)
