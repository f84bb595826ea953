"""The checks of what a task stores in a checkpoint beside the network, shared by the tasks' schemas
(spec/robustness.md §9.1).

Each task's schema lives with its paper's protocol (``CHECKPOINT_SCHEMA`` of ``refimpl/protocols/<paper>*.py``, a
:class:`TaskSchema`; the task module hands it out as its ``CHECKPOINT_SCHEMA``): the fields it checks when present
(``fields``: name -> ``check(value, name) -> value``, before the network's config) and the checks of the whole
stored config (``check(model_config, config, where)``, after it). This module is the kit those schemas are built
from — types, ranges, shapes, skeletons — and names no task: :func:`refimpl.checkpoint_schema.validate_checkpoint_config`
(every loader of ``refimpl``) and ``deploy``'s loaders apply a schema without asking which task it is.

Every problem is a ``ValueError`` whose message names the file and the field. Every number at most
:data:`MAX_TASK_ABS` in magnitude.

Shape legend: J joints (a stored skeleton).
"""
from __future__ import annotations

import dataclasses
import math
from typing import Callable, Mapping

import numpy as np

__all__ = ["TaskSchema", "MAX_TASK_ABS", "MAX_TASK_JOINTS", "MIN_STD", "kind_of", "is_int", "is_number",
           "positive_number", "vector3", "positive_int", "float_dtype_name", "string", "require_fields",
           "int_field", "number_array", "skeleton_field"]

#: Largest magnitude of a stored statistic, offset or seed value (the data of this project stay below ~10^4).
MAX_TASK_ABS = 1e6
#: Largest skeleton (joints) a task field may describe.
MAX_TASK_JOINTS = 1000
#: Smallest stored standard deviation.
MIN_STD = 1e-6


@dataclasses.dataclass(frozen=True)
class TaskSchema:
    """What one task stores in a checkpoint, and how it is checked.

    Attributes
    ----------
    task : str
        The task's name (messages only).
    fields : mapping name -> ``check(value, name) -> value``
        Fields checked when present, before the network's config is built.
    check : callable ``(model_config, config, where) -> None`` or None
        The checks of the whole stored config against the validated network ``config`` (required fields, labels
        that must agree, shapes), raising ValueError.
    """

    task: str
    fields: Mapping[str, Callable] = dataclasses.field(default_factory=dict)
    check: Callable | None = None


def kind_of(v) -> str:
    """``"type (repr)"`` of a bad value for a message (the type alone when the repr is long)."""
    return f"{type(v).__name__} ({v!r})" if len(repr(v)) <= 40 else type(v).__name__


def is_int(v) -> bool:
    """An integer (Python or NumPy), not a bool."""
    return isinstance(v, (int, np.integer)) and not isinstance(v, (bool, np.bool_))


def is_number(v) -> bool:
    """A real number (Python or NumPy), not a bool."""
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, (bool, np.bool_))


def positive_number(v, name):
    """A field check: a finite number > 0."""
    if not is_number(v) or not math.isfinite(float(v)) or float(v) <= 0:
        raise ValueError(f"{name}: expected a finite number > 0, got {kind_of(v)}")
    return float(v)


def vector3(positive: bool) -> Callable:
    """A field check: a list of 3 finite numbers (each > 0 with ``positive``)."""
    def check(v, name):
        if not isinstance(v, (list, tuple)) or len(v) != 3:
            raise ValueError(f"{name}: expected a list of 3 numbers, got {kind_of(v)}")
        for i, x in enumerate(v):
            if not is_number(x) or not math.isfinite(float(x)) or (positive and float(x) <= 0):
                raise ValueError(f"{name}[{i}]: expected a finite number{' > 0' if positive else ''}, got "
                                 f"{kind_of(x)}")
        return [float(x) for x in v]
    return check


def positive_int(v, name):
    """A field check: an integer >= 1."""
    if not is_int(v) or v < 1:
        raise ValueError(f"{name}: expected a positive integer, got {kind_of(v)}")
    return int(v)


def float_dtype_name(v, name):
    """A field check: ``"float32"`` or ``"float64"``."""
    if v not in ("float32", "float64"):
        raise ValueError(f"{name}: expected 'float32' or 'float64', got {kind_of(v)}")
    return v


def string(v, name):
    """A field check: a string."""
    if not isinstance(v, str):
        raise ValueError(f"{name}: expected a string, got {kind_of(v)}")
    return v


def require_fields(cfg: Mapping, keys, where: str, task: str) -> None:
    """ValueError naming the keys of ``keys`` that ``cfg`` lacks (a checkpoint not written by ``refimpl train``)."""
    missing = [k for k in keys if k not in cfg]
    if missing:
        raise ValueError(f"{where}: the {task} checkpoint lacks {missing}; train it with `refimpl train`")


def int_field(cfg, key, where, hi=10**7) -> int:
    """``cfg[key]`` checked to be an integer in ``[1, hi]``."""
    v = cfg[key]
    if not is_int(v) or not 1 <= v <= hi:
        raise ValueError(f"{where}: model_config.{key}: expected an integer in [1, {hi}], got {kind_of(v)}")
    return int(v)


def number_array(value, name: str, shape: tuple, lo: float = -MAX_TASK_ABS, hi: float = MAX_TASK_ABS) -> np.ndarray:
    """A nested JSON list of finite numbers in ``[lo, hi]`` of ``shape`` (``None`` = any length) as float64."""
    def ok_leaf(x):
        return isinstance(x, (int, float)) and not isinstance(x, bool)
    try:
        a = np.asarray(value, dtype=object)
    except Exception:  # noqa: BLE001 - ragged lists
        a = None
    if a is None or a.ndim != len(shape) or any(s is not None and s != d for s, d in zip(shape, a.shape)):
        raise ValueError(f"{name}: expected a list of numbers of shape {tuple('*' if s is None else s for s in shape)}"
                         f", got {kind_of(value) if a is None else 'shape ' + str(a.shape)}")
    if not all(ok_leaf(x) for x in a.reshape(-1)):
        raise ValueError(f"{name}: expected numbers, got {kind_of(next(x for x in a.reshape(-1) if not ok_leaf(x)))}")
    f = a.astype(np.float64)
    if not np.all(np.isfinite(f)) or (f.size and (f.min() < lo or f.max() > hi)):
        raise ValueError(f"{name}: expected finite numbers in [{lo:g}, {hi:g}]")
    return f


def skeleton_field(value, where: str, want_sides: bool = False):
    """The stored ``skeleton`` as a :class:`~refimpl.skeleton.Skeleton`: an object with ``parents`` (ints, each
    parent before its child), ``offsets`` (J × 3 finite, at most :data:`MAX_TASK_ABS`), ``names`` (J distinct
    non-empty strings) and optionally (``want_sides``: required) ``joints_left`` / ``joints_right``."""
    from refimpl.skeleton import Skeleton

    name = f"{where}: model_config.skeleton"
    if not isinstance(value, Mapping):
        raise ValueError(f"{name}: expected a JSON object, got {kind_of(value)}")
    require_fields(value, ("parents", "offsets", "names") + (("joints_left", "joints_right") if want_sides else ()),
                   name, "skeleton of the")
    parents = value["parents"]
    if not isinstance(parents, list) or not 1 <= len(parents) <= MAX_TASK_JOINTS or \
            not all(is_int(p) for p in parents):
        raise ValueError(f"{name}.parents: expected a list of 1 to {MAX_TASK_JOINTS} integers, got {kind_of(parents)}")
    J = len(parents)
    offsets = number_array(value["offsets"], f"{name}.offsets", (J, 3))
    names = value["names"]
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        raise ValueError(f"{name}.names: expected a list of {J} strings, got {kind_of(names)}")
    sides = {}
    for k in ("joints_left", "joints_right"):
        if k in value:
            s = value[k]
            if not isinstance(s, list) or not all(is_int(j) and 0 <= j < J for j in s):
                raise ValueError(f"{name}.{k}: expected a list of joint indices in [0, {J}), got {kind_of(s)}")
            sides[k] = s
    try:
        return Skeleton(parents, offsets, names=names, **sides)
    except ValueError as exc:
        raise ValueError(f"{name}: {exc}") from None
