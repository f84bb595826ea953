"""Fully connected (affine) layer with PyTorch's ``nn.Linear`` parameter names and layout (spec/layers.md §2).

    y = x W^T + b

Shapes: ``x (..., I)`` with any leading axes (``(B, F)``, ``(B, T, F)``, ...), ``weight (O, I)``,
``bias (O,)``, ``y (..., O)``. All leading axes are flattened into one GEMM ``(N, I) @ (I, O)``.
Parameters are read from the model's flat dict under ``prefix`` (``"fc"`` -> ``"fc.weight"``, ``"fc.bias"``).

Checks (spec/layers.md §2): :func:`linear_forward` validates ``x`` (dtype, last axis, finite) and the parameters
(shape, dtype; not their values); :func:`linear_backward` validates ``dy`` (dtype, shape ``(..., O)`` of ``y``,
finite). :func:`matmul_wt` is the unchecked kernel the recurrent layers call inside their step loops.
"""
from __future__ import annotations

from typing import Mapping

import numpy as np

from refimpl.arrays import float_array
from refimpl.nn.params import (check_same_dtype, fan_in_bound, get_param, init_uniform,
                               param_name)

__all__ = ["linear_forward", "linear_backward", "linear_init"]


def matmul_wt(a: np.ndarray, w: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """``a @ w.T`` for a PyTorch-layout weight ``w (O, I)`` and ``a (N, I)``, into a C-contiguous ``(N, O)``.

    Internal kernel: no checks (called inside the recurrent layers' step loops; the public functions validate).

    Computed as ``(w @ a.T)`` written into the transposed view of the result, i.e. the BLAS call reads ``w`` in
    its stored row-major layout. With OpenBLAS this is markedly faster for small ``N`` (e.g. a batch-32 RNN step)
    than ``a @ w.T``, which makes the GEMM transpose ``w`` on the fly, and it needs no transposed copy of ``w``.

    Parameters
    ----------
    a : ndarray (N, I)
    w : ndarray (O, I), C-contiguous
    out : ndarray (N, O), C-contiguous, optional
    """
    if out is None:
        out = np.empty((a.shape[0], w.shape[0]), dtype=np.result_type(a, w))
    np.matmul(w, a.T, out=out.T)
    return out


def linear_forward(x: np.ndarray, params: Mapping[str, np.ndarray], prefix: str, bias: bool = True):
    """Affine map ``y = x W^T + b`` over the last axis.

    Parameters
    ----------
    x : ndarray (..., I), float32 or float64
    params : dict
        Holds ``{prefix}.weight`` ``(O, I)`` and, when ``bias``, ``{prefix}.bias`` ``(O,)``, same dtype as ``x``.
    prefix : str
        The layer's name in ``params`` (``""`` for no prefix).
    bias : bool
        Whether the layer has a bias (PyTorch ``bias=True``, the default).

    Returns
    -------
    y : ndarray (..., O), dtype of ``x``
    cache : tuple
        ``(x2d (N, I), weight, lead_shape, prefix, bias)`` for :func:`linear_backward`.
    """
    w = get_param(params, prefix, "weight", (None, None))  # (O, I)
    out_f, in_f = w.shape
    x = float_array(x, "x", (..., in_f), cast=False)
    b = get_param(params, prefix, "bias", (out_f,)) if bias else None
    check_same_dtype(x, "x", {param_name(prefix, "weight"): w, param_name(prefix, "bias"): b})
    lead = x.shape[:-1]
    x2 = x.reshape(-1, in_f)  # (N, I)
    y = matmul_wt(x2, w)  # (N, O)
    if bias:
        y += b
    return y.reshape(*lead, out_f), (x2, w, lead, prefix, bias)


def linear_backward(dy: np.ndarray, cache):
    """Gradients of the affine map.

    ``dx = dy W``, ``dW = dy^T x`` (summed over all leading axes), ``db = sum(dy)``.

    Parameters
    ----------
    dy : ndarray (..., O), float32 or float64, finite
        Cotangent of ``y``, of ``y``'s shape.
    cache : tuple
        From :func:`linear_forward`.

    Returns
    -------
    dx : ndarray (..., I)
    grads : dict
        ``{prefix}.weight`` ``(O, I)`` and ``{prefix}.bias`` ``(O,)`` (when the layer has a bias).

    Raises
    ------
    ValueError
        When ``dy`` is not a float array of ``y``'s shape, or holds NaN/inf.
    """
    x2, w, lead, prefix, bias = cache
    out_f, in_f = w.shape
    dy = float_array(dy, "dy", (*lead, out_f), cast=False)
    dy2 = dy.reshape(-1, out_f)  # (N, O)
    dx = (dy2 @ w).reshape(*lead, in_f)  # (..., I)
    grads = {param_name(prefix, "weight"): dy2.T @ x2}  # (O, I)
    if bias:
        grads[param_name(prefix, "bias")] = dy2.sum(axis=0)  # (O,)
    return dx, grads


def linear_init(rng: np.random.Generator, in_features: int, out_features: int, prefix: str,
                dtype=np.float64, bias: bool = True) -> dict[str, np.ndarray]:
    """PyTorch-default initialisation of ``nn.Linear(in_features, out_features)``.

    ``weight (O, I)`` and ``bias (O,)`` are drawn from ``U(-1/sqrt(I), 1/sqrt(I))``.

    Returns
    -------
    dict
        ``{prefix}.weight`` and (when ``bias``) ``{prefix}.bias``.
    """
    bound = fan_in_bound(in_features)
    out = {param_name(prefix, "weight"): init_uniform(rng, (out_features, in_features), bound, dtype)}
    if bias:
        out[param_name(prefix, "bias")] = init_uniform(rng, (out_features,), bound, dtype)
    return out


# Kernel tier (spec/architecture.md; unchecked, not in __all__, imported by other modules under these names):
# matmul_wt.
