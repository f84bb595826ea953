"""What the exporter table's entry modules (``deploy/models/*_io.py``) share: reading ``refimpl train``
checkpoints (the arrays and metadata, the parameters ``param.<name>``, a config dataclass from
``meta["model_config"]``) and writing a folder of exported models.

* :func:`read_checkpoint` — ``(arrays, meta)``; with ``state_dict_ok`` a plain state-dict ``.npz`` is accepted too
  (``meta`` then ``{}``);
* :func:`checkpoint_params` — the ``param.<name>`` arrays without the prefix (with ``state_dict_ok``: all arrays
  when there is none);
* :func:`config_from_meta` — ``config_type(**fields)`` from ``meta["model_config"]`` (unknown keys ignored);
* :func:`write_models` — validate each model and write it as ``<name>_<role>.onnx``.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

from refimpl.checkpoint import load_checkpoint, load_state_dict_npz

from deploy.graph import save_model
from deploy.validate import validate_model

__all__ = ["read_checkpoint", "checkpoint_params", "config_from_meta", "write_models"]

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


def config_from_meta(config_type, meta, convert=None):
    """``config_type`` built from the fields of ``meta["model_config"]`` it has (others ignored); ``convert``, if
    given, maps that dict first."""
    names = {f.name for f in dataclasses.fields(config_type)}
    cfg = {k: v for k, v in (meta.get("model_config") or {}).items() if k in names}
    if convert:
        cfg = convert(cfg)
    return config_type(**cfg)


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
