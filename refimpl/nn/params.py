"""Parameter dictionaries: names, sub-dicts, gradient merging, counting, PyTorch-default initialisers, checks.

Conventions (spec/architecture.md "Parameters and checkpoints", spec/layers.md §1)
-------------------------------------------------------------------------------
- A model's parameters are ONE flat ``dict[str, np.ndarray]`` with PyTorch state-dict names and layouts.
- A layer reads its parameters under a ``prefix``: ``param_name("rnn", "weight_ih_l0") == "rnn.weight_ih_l0"``;
  the empty prefix means no dot (``param_name("", "weight") == "weight"``).
- A layer's backward returns gradients under the same full names, so a model's gradient is the union of its
  layers' gradient dicts, summed where a parameter is used twice (:func:`merge_grads`).
- Initialisers take a ``numpy.random.Generator`` and a dtype and reproduce PyTorch's default distributions
  (not its random streams): ``nn.Linear`` and ``nn.Conv1d`` draw weight and bias from ``U(-1/sqrt(fan_in),
  1/sqrt(fan_in))`` (``kaiming_uniform_(a=sqrt(5))`` reduces to that bound); ``nn.GRU``/``nn.LSTM`` draw every
  parameter from ``U(-1/sqrt(H), 1/sqrt(H))``.

``check_same_dtype``/``get_param`` are the parameters' public-boundary validation shared by all layers in
``refimpl.nn``: they raise ``ValueError`` naming the argument, the expected and the actual shape/dtype/value (the
arrays' own checks are :func:`refimpl.arrays.float_array`).
"""
from __future__ import annotations

from typing import Iterable, Mapping

import numpy as np

from refimpl.arrays import float_array, shape_text

__all__ = [
    "param_name", "subdict", "merge_grads", "accumulate_grads", "count_parameters",
    "init_uniform", "init_normal", "fan_in_bound",
    "check_same_dtype", "get_param",
]

def param_name(prefix: str, name: str) -> str:
    """Full parameter name: ``prefix + "." + name``, or ``name`` when ``prefix`` is empty.

    Parameters
    ----------
    prefix : str
        The layer's prefix inside the model's flat dict (``"rnn"``, ``"fc"``, ``"controls.fc1"``, or ``""``).
    name : str
        The PyTorch parameter name inside the layer (``"weight"``, ``"weight_ih_l0"``, ...).
    """
    return f"{prefix}.{name}" if prefix else name


def subdict(params: Mapping[str, np.ndarray], prefix: str) -> dict[str, np.ndarray]:
    """The entries under ``prefix``, with the prefix (and its dot) removed from the keys.

    ``subdict({"rnn.weight_ih_l0": a, "fc.weight": b}, "rnn") == {"weight_ih_l0": a}``; the empty prefix returns
    a shallow copy of the whole dict. Arrays are not copied.
    """
    if not prefix:
        return dict(params)
    head = prefix + "."
    return {k[len(head):]: v for k, v in params.items() if k.startswith(head)}


def merge_grads(*dicts: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Union of gradient dicts, summing the arrays of keys present in more than one.

    The inputs are never modified. A key present in one dict only is passed through without a copy (so the
    result may share arrays with the inputs); a shared key gets a new array holding the sum.
    """
    out: dict[str, np.ndarray] = {}
    for d in dicts:
        for k, g in d.items():
            if k in out:
                out[k] = out[k] + g
            else:
                out[k] = g
    return out


def accumulate_grads(total: dict, grads: Mapping[str, np.ndarray]) -> dict:
    """``total[k] += grads[k]`` in place (a key seen for the first time is copied), for parameters used at every
    step of a sequence; returns ``total``."""
    for k, v in grads.items():
        if k in total:
            total[k] += v
        else:
            total[k] = np.array(v, copy=True)
    return total


def count_parameters(params: Mapping[str, np.ndarray] | Iterable[np.ndarray]) -> int:
    """Total number of scalar parameters (sum of the arrays' sizes) in a dict or an iterable of arrays."""
    arrays = params.values() if isinstance(params, Mapping) else params
    return int(sum(np.asarray(a).size for a in arrays))


def fan_in_bound(fan_in: int) -> float:
    """PyTorch's default bound ``1/sqrt(fan_in)`` for ``nn.Linear`` / ``nn.Conv1d`` weights and biases
    (and ``1/sqrt(hidden_size)`` for RNN parameters)."""
    if fan_in <= 0:
        raise ValueError(f"fan_in: expected a positive integer, got {fan_in}")
    return 1.0 / float(np.sqrt(fan_in))


def init_uniform(rng: np.random.Generator, shape: tuple[int, ...], bound: float,
                 dtype=np.float64) -> np.ndarray:
    """Draw ``U(-bound, bound)`` of the given shape (drawn in float64, then cast to ``dtype``)."""
    return rng.uniform(-bound, bound, size=shape).astype(dtype, copy=False)


def init_normal(rng: np.random.Generator, shape: tuple[int, ...], std: float, mean: float = 0.0,
                dtype=np.float64) -> np.ndarray:
    """Draw ``N(mean, std^2)`` of the given shape (e.g. QuaterNet's learned initial state, std 0.01)."""
    return rng.normal(mean, std, size=shape).astype(dtype, copy=False)


def check_same_dtype(reference: np.ndarray, reference_name: str, arrays: Mapping[str, np.ndarray | None]) -> None:
    """Raise ``ValueError`` unless every array in ``arrays`` (name -> array; ``None`` entries are skipped) has the
    dtype of ``reference`` (no silent upcast)."""
    for n, a in arrays.items():
        if a is not None and a.dtype != reference.dtype:
            raise ValueError(f"{n}: expected dtype {reference.dtype} (the dtype of {reference_name}), got {a.dtype}")


def get_param(params: Mapping[str, np.ndarray], prefix: str, name: str, shape: tuple,
              dtype=None) -> np.ndarray:
    """Fetch ``params[param_name(prefix, name)]`` and check its shape (and dtype when given).

    Raises
    ------
    ValueError
        Naming the full parameter name when it is missing, or has the wrong shape or dtype.
    """
    full = param_name(prefix, name)
    if full not in params:
        raise ValueError(f"params: missing parameter {full!r} (expected shape {shape_text(shape)})")
    a = float_array(params[full], f"params[{full!r}]", shape, finite=False, cast=False)
    if dtype is not None and a.dtype != np.dtype(dtype):
        raise ValueError(f"params[{full!r}]: expected dtype {np.dtype(dtype)}, got {a.dtype}")
    return a
