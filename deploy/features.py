"""ONNX builders for feature standardisation (``refimpl/preprocess.py``): ``(x − mean) / std`` and its inverse.

The statistics are constants of the graph (and also written to the model's metadata, ``deploy/metadata.py``),
so a consumer feeds raw features and reads raw features. ``Div`` (not multiplication by ``1/std``) keeps the
float64 variant bit-identical to NumPy's ``(x - mean) / std``.

Shape legend: ``...`` leading axes, F features.
"""
from __future__ import annotations

import numpy as np

from deploy.graph import GraphBuilder

__all__ = ["standardize", "destandardize"]


def _stats(mean, std):
    mean = np.asarray(mean, dtype=np.float64)
    std = np.asarray(std, dtype=np.float64)
    if mean.ndim != 1 or std.shape != mean.shape:
        raise ValueError(f"mean, std: expected two arrays of shape (F,), got {mean.shape} and {std.shape}")
    if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(std)) and np.all(std > 0)):
        raise ValueError("std: expected finite, strictly positive values (and a finite mean)")
    return mean, std


def standardize(g: GraphBuilder, x: str, mean, std, *, name: str, wname: str | None = None) -> str:
    """``z = (x − mean) / std`` over the last axis; ``x`` ``(..., F)``, ``mean``/``std`` ``(F,)``."""
    mean, std = _stats(mean, std)
    xc = g.node("Sub", [x, g.weight(f"{wname or name}.mean", mean)], f"{name}.centered")  # (..., F)
    return g.node("Div", [xc, g.weight(f"{wname or name}.std", std)], name)               # (..., F)


def destandardize(g: GraphBuilder, z: str, mean, std, *, name: str, wname: str | None = None) -> str:
    """``x = z · std + mean`` over the last axis; ``z`` ``(..., F)``."""
    mean, std = _stats(mean, std)
    zs = g.node("Mul", [z, g.weight(f"{wname or name}.std", std)], f"{name}.scaled")      # (..., F)
    return g.node("Add", [zs, g.weight(f"{wname or name}.mean", mean)], name)             # (..., F)
