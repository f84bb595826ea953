"""Helpers shared by the model modules: parameter-dict validation against a config's shapes, and gradient
accumulation for parameters used at every step (spec/architecture.md, "Models")."""
from __future__ import annotations

from typing import Mapping

import numpy as np

__all__ = ["check_param_dict"]


def check_param_dict(params: Mapping[str, np.ndarray], shapes: Mapping[str, tuple[int, ...]]) -> np.dtype:
    """Validate ``params`` against ``shapes`` (name -> shape): no missing, extra or mis-shaped entry, one float
    dtype (float32 or float64) for all. Returns that dtype.

    Raises
    ------
    ValueError
        Naming the unexpected, missing or mis-shaped parameter, or the dtype.
    """
    extra = sorted(set(params) - set(shapes))
    if extra:
        raise ValueError(f"params: unexpected parameter(s) {extra} for this config (expected {sorted(shapes)})")
    dtype = None
    for name, shape in shapes.items():
        if name not in params:
            raise ValueError(f"params: missing parameter {name!r} (expected shape {shape})")
        a = params[name]
        if not isinstance(a, np.ndarray) or a.shape != shape:
            raise ValueError(f"params[{name!r}]: expected shape {shape}, got {np.shape(a)}")
        if dtype is None:
            dtype = a.dtype
        elif a.dtype != dtype:
            raise ValueError(f"params[{name!r}]: expected dtype {dtype} like the other parameters, got {a.dtype}")
    if dtype not in (np.dtype(np.float32), np.dtype(np.float64)):
        raise ValueError(f"params: expected float32 or float64 arrays, got {dtype}")
    return dtype


