"""Reading ``refimpl train`` checkpoints for the exporter table's entry modules (``deploy/models/*_io.py``):
the arrays and metadata, the parameters (``param.<name>`` arrays), and a config dataclass from
``meta["model_config"]``.

* :func:`read_checkpoint` — ``(arrays, meta)``; with ``state_dict_ok`` a plain state-dict ``.npz`` is accepted too
  (``meta`` then ``{}``);
* :func:`checkpoint_params` — the ``param.<name>`` arrays without the prefix (with ``state_dict_ok``: all arrays
  when there is none);
* :func:`config_from_meta` — ``config_type(**fields)`` from ``meta["model_config"]`` (unknown keys ignored).
"""
from __future__ import annotations

import dataclasses

from refimpl.checkpoint import load_checkpoint, load_state_dict_npz

__all__ = ["read_checkpoint", "checkpoint_params", "config_from_meta"]

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
