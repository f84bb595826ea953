"""ONNX builder for the causal dilated 1-D convolution of ``refimpl/nn/conv1d.py`` (PyTorch ``nn.Conv1d``).

Equation (cross-correlation, no kernel flip; ``x`` left-padded with ``(K − 1)·d`` zeros so the output keeps
length ``T`` and ``y_t`` sees only ``x_{t − (K−1)d} … x_t``)::

    y[b, t, o] = bias[o] + Σ_{k=0}^{K−1} Σ_c weight[o, c, k] · x[b, t − (K − 1 − k)·d, c]

Fused form: ``Transpose`` ``(B, T, C)`` → ``(N, C, L)``, ``Conv`` with ``pads = [(K−1)·d, 0]``,
``dilations = [d]``, ``strides = [1]`` (``auto_pad`` unset), ``Transpose`` back (``spec/deploy.md`` §2.5).
Primitive form (``g.primitive``; onnxruntime has no float64 ``Conv``): ``Pad`` the time axis, gather the K taps
with ``Slice`` and ``Concat`` them into ``(B, T, K·C_in)`` (im2col), one ``MatMul`` with the weight reshaped to
``(K·C_in, C_out)``, ``Add`` the bias; batch-first throughout.

Shape legend: B batch, T time, C_in / C_out channels, K kernel taps, d dilation.
"""
from __future__ import annotations

from typing import Mapping

import numpy as np

from deploy.graph import GraphBuilder, get_param

__all__ = ["conv1d_causal"]

_INT64_MAX = 2 ** 63 - 1


def conv1d_causal(g: GraphBuilder, x: str, params: Mapping[str, np.ndarray], prefix: str, *, name: str,
                  dilation: int = 1, wname: str | None = None) -> str:
    """Append a causal dilated convolution over time.

    Parameters
    ----------
    x : str
        Input ``(B, T, C_in)``, batch-first.
    params : dict
        ``{prefix}.weight`` ``(C_out, C_in, K)`` and ``{prefix}.bias`` ``(C_out,)`` (optional).
    name : str
        Graph path: initializers ``{name}.W``, ``{name}.b``.
    dilation : int
        ``d ≥ 1``.
    wname : str, optional
        Path of the initializers (default ``name``).

    Returns
    -------
    str
        Output ``(B, T, C_out)``.
    """
    weight = get_param(params, prefix, "weight")
    if weight.ndim != 3:
        raise ValueError(f"params[{prefix!r}.weight]: expected shape (C_out, C_in, K), got {weight.shape}")
    if int(dilation) < 1:
        raise ValueError(f"dilation: expected >= 1, got {dilation}")
    c_out, c_in, k = weight.shape
    d = int(dilation)
    full_b = f"{prefix}.bias" if prefix else "bias"
    bias = np.asarray(params[full_b]) if full_b in params else None
    pad = (k - 1) * d
    wname = wname or name
    if not g.primitive_layers:
        xc = g.node("Transpose", [x], f"{name}.x_ncl", perm=[0, 2, 1])  # (B, C_in, T)
        inputs = [xc, g.weight(f"{wname}.W", weight)] + ([g.weight(f"{wname}.b", bias)] if bias is not None else [])
        y = g.node("Conv", inputs, f"{name}.conv", pads=[pad, 0], dilations=[d], strides=[1],
                   kernel_shape=[k])                                     # (B, C_out, T)
        return g.node("Transpose", [y], f"{name}.y", perm=[0, 2, 1])     # (B, T, C_out)
    if pad:
        xp = g.node("Pad", [x, g.ints([0, pad, 0, 0, 0, 0])], f"{name}.pad")  # (B, T + pad, C_in)
    else:
        xp = x
    taps = []
    for j in range(k):
        start, stop = j * d, j * d - pad                                  # tap j covers [j d, j d + T)
        taps.append(g.node("Slice", [xp, g.ints([start]), g.ints([stop if stop < 0 else _INT64_MAX]),
                                     g.ints([1])], f"{name}.tap{j}"))    # (B, T, C_in)
    cols = taps[0] if k == 1 else g.node("Concat", taps, f"{name}.im2col", axis=-1)  # (B, T, K·C_in)
    w_col = np.transpose(weight, (2, 1, 0)).reshape(k * c_in, c_out)     # (K·C_in, C_out), row k·C_in + c
    y = g.node("MatMul", [cols, g.weight(f"{wname}.W", w_col)], f"{name}.matmul")  # (B, T, C_out)
    if bias is None:
        return y
    return g.node("Add", [y, g.weight(f"{wname}.b", bias)], f"{name}.y")  # (B, T, C_out)
