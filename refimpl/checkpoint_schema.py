"""The schema of a training checkpoint, checked before anything is built from it (spec/robustness.md §9).

:func:`refimpl.checkpoint.load_checkpoint` proves that a file is intact (its SHA-256 matches), not that it is
sensible: the format is public, so a crafted file with a recomputed checksum reaches the caller. This module checks
the *content* of a ``refimpl train`` checkpoint, generically for every registered model:

* the metadata: ``format``, ``model`` (a string), ``model_config`` (a JSON object);
* the model's config: every field present in ``model_config`` has the type its config dataclass declares
  (``int`` — not ``bool``, not ``1.5``; ``float`` — a finite number, not ``bool``; ``bool``; ``str``;
  ``tuple[int, ...]`` — a list of such ints), integers within ``±`` :data:`MAX_CONFIG_INT` and lists of at most
  :data:`MAX_CONFIG_LIST` entries, then the dataclass itself checks the ranges;
* the fields every run stores (:data:`COMMON_FIELDS`): ``fps`` > 0 and finite, ``dtype``
  ``"float32"``/``"float64"``, ``representation`` a string; then the task's schema (its ``CHECKPOINT_SCHEMA``, a
  :class:`refimpl.checkpoint_fields.TaskSchema` kept with its paper's protocol: its fields when present, then
  its checks of the whole stored config — types, ranges, shapes, and that the labels agree with the frame size);
* the parameters: exactly the names and shapes the config implies (the recipe's ``param_shapes(config)``, else
  the config module's ``param_shapes``, else its ``init_params`` on a tiny generator), one floating dtype
  (float32 or float64, the stored ``dtype`` when there is one), all finite and of magnitude at most
  :data:`MAX_PARAM_ABS`;
* optimiser state (``optim.*``) and the sampler permutation, when :func:`validate_training_state` is asked.

Every problem is a ``ValueError`` whose message starts with the file and names the field
(``"ckpt.npz: model_config.gru_layers: expected an integer, got bool (True)"``). This module names no task and no
model: the task's schema comes from the caller (``task_of(spec).CHECKPOINT_SCHEMA``).

Shape legend: parameter shapes as the model's ``param_shapes``.
"""
from __future__ import annotations

import dataclasses
import math
import sys
import types
import typing
from typing import Any, Callable, Mapping

import numpy as np

from refimpl.checkpoint_fields import (TaskSchema, float_dtype_name, is_int, is_number, kind_of, positive_number,
                                       string)

__all__ = ["COMMON_FIELDS", "MAX_CONFIG_INT", "MAX_CONFIG_LIST", "MAX_PARAM_ABS", "validate_model_config",
           "expected_param_shapes", "validate_params", "validate_task_fields", "validate_task_schema",
           "validate_checkpoint_config", "validate_trained", "validate_training_state"]

#: Largest integer any config field (or entry of a size list) may hold, and the longest size list: bounds the
#: work of computing the parameter shapes (``gru_layers = 10**30`` would loop for ever) before the parameters
#: themselves are compared.
MAX_CONFIG_INT = 1_000_000
MAX_CONFIG_LIST = 1_000

#: Largest integer a config field may hold when the parameter shapes have to be found by running the model's
#: ``init_params`` (a recipe without ``param_shapes``): it bounds the memory of that fallback.
MAX_FALLBACK_SIZE = 4096

#: Largest magnitude of a network parameter. Trained networks of this project stay below ~10² (any weight above
#: this comes from a damaged or crafted file); a finite 3e38 bias already overflows float32 in the first product
#: and would surface later as a non-finite output deep inside an evaluation instead of at the file.
MAX_PARAM_ABS = 1e6


def _check_type(value, hint, name: str) -> Any:
    """``value`` checked against the annotation ``hint`` (JSON lists become tuples); ValueError naming ``name``."""
    origin = typing.get_origin(hint)
    if origin in (typing.Union, types.UnionType):
        args = typing.get_args(hint)
        if value is None and type(None) in args:
            return None
        errors = []
        for a in args:
            if a is type(None):
                continue
            try:
                return _check_type(value, a, name)
            except ValueError as exc:
                errors.append(str(exc))
        raise ValueError(errors[0] if errors else f"{name}: unexpected value {kind_of(value)}")
    if hint is bool:
        if not isinstance(value, (bool, np.bool_)):
            raise ValueError(f"{name}: expected true or false, got {kind_of(value)}")
        return bool(value)
    if hint is int:
        if not is_int(value):
            raise ValueError(f"{name}: expected an integer, got {kind_of(value)}")
        return int(value)
    if hint is float:
        if not is_number(value) or not math.isfinite(float(value)):
            raise ValueError(f"{name}: expected a finite number, got {kind_of(value)}")
        return float(value)
    if hint is str:
        if not isinstance(value, str):
            raise ValueError(f"{name}: expected a string, got {kind_of(value)}")
        return value
    if origin is tuple or hint is tuple:
        if not isinstance(value, (list, tuple)):
            raise ValueError(f"{name}: expected a list, got {kind_of(value)}")
        args = typing.get_args(hint)
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_check_type(v, args[0], f"{name}[{i}]") for i, v in enumerate(value))
        if args and len(args) != len(value):
            raise ValueError(f"{name}: expected a list of {len(args)} values, got {len(value)}")
        return tuple(_check_type(v, a, f"{name}[{i}]") for i, (v, a) in enumerate(zip(value, args))) if args \
            else tuple(value)
    return value  # an annotation we do not know: the dataclass checks it


def validate_model_config(config_type: type, model_config, where: str = "checkpoint"):
    """The config dataclass ``config_type`` built from the JSON object ``model_config`` (unknown keys ignored).

    Raises
    ------
    ValueError
        ``model_config`` is not an object, a field has the wrong type, or the dataclass refuses a value.
    """
    if not isinstance(model_config, Mapping):
        raise ValueError(f"{where}: model_config: expected a JSON object, got {kind_of(model_config)}")
    try:
        hints = typing.get_type_hints(config_type)
    except Exception:  # noqa: BLE001 - unresolvable annotations: leave the checks to the dataclass
        hints = {}
    values = {}
    for f in dataclasses.fields(config_type):
        if f.name not in model_config:
            continue
        name = f"{where}: model_config.{f.name}"
        raw = model_config[f.name]
        if isinstance(raw, (list, tuple)) and len(raw) > MAX_CONFIG_LIST:
            raise ValueError(f"{name}: {len(raw)} entries, more than the limit {MAX_CONFIG_LIST}")
        value = _check_type(raw, hints.get(f.name, Any), name)
        for x in (value if isinstance(value, (list, tuple)) else (value,)):
            if is_int(x) and abs(x) > MAX_CONFIG_INT:
                raise ValueError(f"{name}: {x} is beyond the limit {MAX_CONFIG_INT} for a size")
        values[f.name] = value
    try:
        return config_type(**values)
    except (TypeError, ValueError, OverflowError) as exc:
        raise ValueError(f"{where}: model_config: {exc}") from None


def _config_module(config_type):
    return sys.modules.get(getattr(config_type, "__module__", ""), None)


def expected_param_shapes(owner, config_type: type, config) -> dict[str, tuple[int, ...]]:
    """Name -> shape of every parameter of the model ``config`` describes.

    ``owner``: what may know the shapes — a :class:`~refimpl.registry.ModelSpec` (its ``param_shapes``, the
    recipe's), a model module, or None. Looked up in order: ``owner.param_shapes(config)``, the config module's
    ``param_shapes(config)``, its ``init_params(config, rng, dtype=float32)`` on a tiny generator (only for
    configs whose integers are at most :data:`MAX_FALLBACK_SIZE`, so that a crafted config cannot make it
    allocate without bound).
    """
    module = _config_module(config_type)
    for where in (owner, module):
        fn = getattr(where, "param_shapes", None)
        if callable(fn):
            return {str(k): tuple(int(d) for d in v) for k, v in fn(config).items()}
    for where in (owner, module):
        fn = getattr(where, "init_params", None)
        if callable(fn):
            for f in dataclasses.fields(config):
                v = getattr(config, f.name)
                for x in (v if isinstance(v, tuple) else (v,)):
                    if is_int(x) and x > MAX_FALLBACK_SIZE:
                        raise ValueError(f"model_config.{f.name}: {x} is above {MAX_FALLBACK_SIZE}, the largest "
                                         "size checked without the model's param_shapes")
            params = fn(config, np.random.default_rng(0), dtype=np.float32)
            return {str(k): tuple(np.shape(v)) for k, v in params.items()}
    raise ValueError(f"{config_type.__name__}: no param_shapes or init_params to check parameters against")


def validate_params(params: Mapping[str, np.ndarray], shapes: Mapping[str, tuple], where: str = "checkpoint",
                    dtype: str | None = None, prefix: str = "param.") -> np.dtype:
    """Check names, shapes, dtype (one of float32/float64 for all, ``dtype`` if given) and finiteness.

    Returns the dtype. ValueError names the first bad parameter (``param.<name>``).
    """
    missing = [k for k in shapes if k not in params]
    if missing:
        raise ValueError(f"{where}: missing parameter(s) {[prefix + k for k in missing[:5]]}"
                         + (f" and {len(missing) - 5} more" if len(missing) > 5 else "")
                         + " for this model config")
    extra = sorted(k for k in params if k not in shapes)
    if extra:
        raise ValueError(f"{where}: unexpected parameter(s) {[prefix + k for k in extra[:5]]} for this model config")
    found = None
    for name, shape in shapes.items():
        a = params[name]
        if not isinstance(a, np.ndarray) or a.shape != tuple(shape):
            raise ValueError(f"{where}: {prefix}{name}: expected shape {tuple(shape)} (from the model config), "
                             f"got {np.shape(a)}")
        if a.dtype not in (np.dtype(np.float32), np.dtype(np.float64)):
            raise ValueError(f"{where}: {prefix}{name}: expected float32 or float64, got {a.dtype}")
        if found is None:
            found = a.dtype
        elif a.dtype != found:
            raise ValueError(f"{where}: {prefix}{name}: dtype {a.dtype} differs from the other parameters' {found}")
        if not np.isfinite(a).all():
            raise ValueError(f"{where}: {prefix}{name}: contains NaN or inf")
        if a.size and float(np.max(np.abs(a))) > MAX_PARAM_ABS:
            raise ValueError(f"{where}: {prefix}{name}: magnitude {float(np.max(np.abs(a))):.3g} beyond "
                             f"{MAX_PARAM_ABS:g} (a damaged, crafted or diverged checkpoint)")
    if found is not None and dtype is not None and found != np.dtype(dtype):
        raise ValueError(f"{where}: model_config.dtype is {dtype!r} but the parameters are {found}")
    return found


#: What every run stores beside the network's config, checked when present (the task's own fields are its
#: schema's, :class:`refimpl.checkpoint_fields.TaskSchema`).
COMMON_FIELDS: dict[str, Callable] = {
    "fps": positive_number,
    "dtype": float_dtype_name,
    "representation": string,
}


def validate_task_fields(model_config: Mapping, schema: TaskSchema | None = None, where: str = "checkpoint") -> None:
    """Check the fields present in ``model_config``: :data:`COMMON_FIELDS` and the ``fields`` of the task's
    ``schema``."""
    checks = dict(COMMON_FIELDS)
    checks.update(schema.fields if schema is not None else {})
    for key, check in checks.items():
        if key in model_config:
            check(model_config[key], f"{where}: model_config.{key}")


def validate_task_schema(schema: TaskSchema | None, model_config: Mapping, config, where: str = "checkpoint") -> None:
    """The task's checks of the whole stored config (``schema.check``) against the validated network ``config``;
    nothing without a schema."""
    if schema is not None and schema.check is not None:
        schema.check(model_config, config, where)


def validate_checkpoint_config(spec, model_config, where: str = "checkpoint", task_of: Callable | None = None):
    """Everything of a checkpoint but its arrays: ``model_config``'s fields (:data:`COMMON_FIELDS`, the task's
    ``CHECKPOINT_SCHEMA``: ``task_of(spec)``'s) and network config, and the parameter shapes it implies.

    Used by :func:`validate_trained` on a file and by ``refimpl train`` on the checkpoint it is about to write
    (so that training never writes a file its loader refuses).

    Returns
    -------
    config, shapes (name -> shape)
    """
    if not isinstance(model_config, Mapping):
        raise ValueError(f"{where}: model_config: expected a JSON object, got {kind_of(model_config)}")
    schema = task_of(spec).CHECKPOINT_SCHEMA if task_of is not None else None
    validate_task_fields(model_config, schema, where)
    config = validate_model_config(spec.config_type, model_config, where)
    validate_task_schema(schema, model_config, config, where)
    try:
        shapes = expected_param_shapes(spec, spec.config_type, config)
    except ValueError as exc:
        raise ValueError(f"{where}: {exc}") from None
    return config, shapes


def validate_trained(arrays: Mapping[str, np.ndarray], meta, models: Mapping, where: str = "checkpoint",
                     task_of: Callable | None = None, expected_format: str = "refimpl.train/1"):
    """The whole schema of a training checkpoint (see the module docstring), for inference.

    Parameters
    ----------
    arrays, meta : what :func:`refimpl.checkpoint.load_checkpoint` returned
    models : dict name -> :class:`~refimpl.registry.ModelSpec`
    task_of : callable spec -> task module, optional (its ``CHECKPOINT_SCHEMA``)

    Returns
    -------
    spec, config, params (name -> ndarray, without the ``param.`` prefix), model_config (dict)
    """
    if not isinstance(meta, Mapping):
        raise ValueError(f"{where}: metadata: expected a JSON object, got {kind_of(meta)}")
    if meta.get("format") != expected_format:
        raise ValueError(f"{where}: not a refimpl training checkpoint (format {meta.get('format')!r})")
    name = meta.get("model")
    if not isinstance(name, str):
        raise ValueError(f"{where}: model: expected a model name, got {kind_of(name)}")
    spec = models.get(name)
    if spec is None:
        raise ValueError(f"{where}: unknown model {name!r}; known: {sorted(models)}")
    cfg = meta.get("model_config")
    config, shapes = validate_checkpoint_config(spec, cfg, where, task_of)
    params = {k[len("param."):]: v for k, v in arrays.items() if k.startswith("param.")}
    validate_params(params, shapes, where, dtype=cfg.get("dtype"))
    return spec, config, params, dict(cfg)


def validate_training_state(params: Mapping[str, np.ndarray], opt_state: Mapping[str, np.ndarray], perm,
                            meta: Mapping, num_examples: int | None = None, where: str = "checkpoint") -> None:
    """What resuming needs beyond the parameters: the trainer's counters, the Adam state and the permutation.

    ``step``, ``epoch``, ``position`` non-negative integers; ``rng_state`` a string; ``optim.step`` an integer
    0-d array; ``optim.m.<name>`` / ``optim.v.<name>`` exactly one per parameter, same shape and dtype, finite,
    ``v >= 0``; ``sampler.perm`` a permutation of ``num_examples`` indices.
    """
    for key in ("step", "epoch", "position"):
        v = meta.get(key)
        if not is_int(v) or v < 0:
            raise ValueError(f"{where}: {key}: expected a non-negative integer, got {kind_of(v)}")
    if not isinstance(meta.get("rng_state"), str):
        raise ValueError(f"{where}: rng_state: expected the generator state as JSON text, got "
                         f"{kind_of(meta.get('rng_state'))}")
    for k, a in params.items():
        if a.dtype.kind != "f" or not np.isfinite(a).all():
            raise ValueError(f"{where}: param.{k}: expected finite floating values")
    expected = {"step"} | {f"{s}.{k}" for k in params for s in ("m", "v")}
    if set(opt_state) != expected:
        bad = sorted(set(opt_state) ^ expected)[:5]
        raise ValueError(f"{where}: optimiser state does not match the parameters (optim.{bad[0]} "
                         f"{'unexpected' if bad[0] in opt_state else 'missing'})")
    s = opt_state["step"]
    if s.shape != () or s.dtype.kind not in "iu" or int(s) < 0:
        raise ValueError(f"{where}: optim.step: expected a non-negative integer scalar, got {s.dtype} {s.shape}")
    for k, p in params.items():
        for part in ("m", "v"):
            a = opt_state[f"{part}.{k}"]
            if a.shape != p.shape or a.dtype != p.dtype:
                raise ValueError(f"{where}: optim.{part}.{k}: expected {p.dtype} {p.shape} like the parameter, "
                                 f"got {a.dtype} {a.shape}")
            if not np.isfinite(a).all() or (part == "v" and (a < 0).any()):
                raise ValueError(f"{where}: optim.{part}.{k}: contains NaN, inf" + (" or negative values"
                                                                                    if part == "v" else ""))
    perm = np.asarray(perm)
    n = num_examples if num_examples is not None else perm.size
    if perm.ndim != 1 or perm.dtype.kind not in "iu" or perm.size != n or \
            not np.array_equal(np.sort(perm), np.arange(n)):
        raise ValueError(f"{where}: sampler.perm: expected a permutation of {n} indices, got {perm.dtype} "
                         f"{perm.shape}")
