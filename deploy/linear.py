"""ONNX builder for the fully connected layer ``y = x Wᵀ + b`` (PyTorch ``nn.Linear``).

Mirrors ``refimpl/nn/linear.py``: parameters ``{prefix}.weight`` ``(F_out, F_in)`` and ``{prefix}.bias``
``(F_out,)`` (optional). The initializer ``{name}.W`` holds ``weightᵀ`` ``(F_in, F_out)`` so the product is a
plain ``MatMul`` (or ``Gemm`` for 2-D input), and ``{name}.b`` holds the bias.

Shape legend: B batch, F_in / F_out features; ``...`` any leading axes.
"""
from __future__ import annotations

from typing import Mapping

import numpy as np

from deploy.graph import GraphBuilder, get_param

__all__ = ["linear"]


def linear(g: GraphBuilder, x: str, params: Mapping[str, np.ndarray], prefix: str, *, name: str,
           rank2: bool = False, wname: str | None = None) -> str:
    """Append ``y = x Wᵀ + b`` to ``g``.

    Parameters
    ----------
    g : GraphBuilder
    x : str
        Input tensor ``(..., F_in)``.
    params : dict
        ``{prefix}.weight`` ``(F_out, F_in)``; ``{prefix}.bias`` ``(F_out,)`` if present.
    prefix : str
        Parameter prefix (``"fc"`` reads ``fc.weight``).
    name : str
        Graph path of this layer (``"enc.fc0"``): initializers ``{name}.W``, ``{name}.b``, output ``{name}``.
    rank2 : bool
        ``x`` is 2-D ``(B, F_in)``: emit one ``Gemm`` node instead of ``MatMul`` + ``Add``.
    wname : str, optional
        Path of the initializers (default ``name``); layers applied several times (the steps of an unrolled
        rollout) pass one ``wname`` and distinct ``name`` s, and share the weights.

    Returns
    -------
    str
        Output tensor ``(..., F_out)``.

    Equations
    ---------
    ``y = x Wᵀ + b``  (``W = weight``).
    """
    weight = get_param(params, prefix, "weight")
    if weight.ndim != 2:
        raise ValueError(f"params[{prefix!r}.weight]: expected shape (F_out, F_in), got {weight.shape}")
    full_b = f"{prefix}.bias" if prefix else "bias"
    bias = np.asarray(params[full_b]) if full_b in params else None
    if bias is not None and bias.shape != (weight.shape[0],):
        raise ValueError(f"params[{full_b!r}]: expected shape ({weight.shape[0]},), got {bias.shape}")
    wname = wname or name
    w = g.weight(f"{wname}.W", weight.T)                                  # (F_in, F_out)
    b = g.weight(f"{wname}.b", bias) if bias is not None else None        # (F_out,)
    if rank2:
        return g.node("Gemm", [x, w] + ([b] if b else []), f"{name}.gemm")  # (B, F_out)
    y = g.node("MatMul", [x, w], f"{name}.matmul")                       # (..., F_out)
    if b is None:
        return y
    return g.node("Add", [y, b], f"{name}.add")                          # (..., F_out)
