"""Causal dilated 1-D convolution, batch-first, with PyTorch's ``nn.Conv1d`` weight layout (spec/layers.md §6).

PyTorch's ``conv1d`` is a cross-correlation. Made causal by left-padding the time axis with
``P = (K - 1) * d`` zeros (``d`` the dilation), so the output has the input's length and step t sees only
inputs at times ``<= t``::

    y[b, t, o] = bias[o] + sum_{c, k} weight[o, c, k] * xpad[b, t + k d, c]
               = bias[o] + sum_{c, k} weight[o, c, k] * x[b, t - (K - 1 - k) d, c]     (x[b, s < 0] = 0)

so tap ``k = K - 1`` multiplies the current frame and tap ``k = 0`` the frame ``(K - 1) d`` steps back.

Shapes: B batch, T time, C_in / C_out channels, K taps. ``x (B, T, C_in)``, ``weight (C_out, C_in, K)``,
``bias (C_out,)``, ``y (B, T, C_out)``.

Implementation: the K shifted copies of the padded input are laid side by side into ``X_col (B*T, K*C_in)``
(column block k = taps k), the weight is reordered once to ``W_col (K*C_in, C_out)`` with
``W_col[k*C_in + c, o] = weight[o, c, k]``, and the whole convolution is ONE GEMM ``X_col @ W_col``; the
backward is two GEMMs (``dW_col = X_col^T dy``, ``dX_col = dy W_col^T``) and a K-term shifted sum.
``_conv1d_causal_forward_naive`` / ``_conv1d_causal_backward_naive`` are per-(b, t, k) loops (the oracles).

Checks (spec/layers.md §6): the forward validates ``x`` (dtype, shape, finite), ``dilation`` and the parameters
(shape, dtype; not their values); the backward validates ``dy`` (dtype, shape ``(B, T, C_out)``, finite).
"""
from __future__ import annotations

from typing import Mapping

import numpy as np

from refimpl.arrays import float_array
from refimpl.nn.params import check_same_dtype, fan_in_bound, get_param, init_uniform, param_name

__all__ = ["conv1d_causal_forward", "conv1d_causal_backward", "conv1d_init"]


def _check_dilation(dilation) -> int:
    if not (isinstance(dilation, (int, np.integer)) and dilation >= 1):
        raise ValueError(f"dilation: expected an integer >= 1 (1 means no dilation), got {dilation!r}")
    return int(dilation)


def conv1d_init(rng: np.random.Generator, in_channels: int, out_channels: int, kernel_size: int, prefix: str,
                dtype=np.float64) -> dict[str, np.ndarray]:
    """PyTorch-default initialisation of ``nn.Conv1d``: weight and bias ``~ U(±1/sqrt(C_in * K))``.

    Returns
    -------
    dict
        ``{prefix}.weight`` ``(C_out, C_in, K)`` and ``{prefix}.bias`` ``(C_out,)``.
    """
    bound = fan_in_bound(in_channels * kernel_size)
    return {param_name(prefix, "weight"): init_uniform(rng, (out_channels, in_channels, kernel_size), bound, dtype),
            param_name(prefix, "bias"): init_uniform(rng, (out_channels,), bound, dtype)}


def conv1d_causal_forward(x: np.ndarray, params: Mapping[str, np.ndarray], prefix: str, dilation: int = 1):
    """Causal dilated convolution over time.

    Parameters
    ----------
    x : ndarray (B, T, C_in), float32 or float64
    params : dict
        ``{prefix}.weight`` ``(C_out, C_in, K)`` and ``{prefix}.bias`` ``(C_out,)``, same dtype as ``x``.
    prefix : str
    dilation : int
        Spacing of the taps (1: consecutive frames), as PyTorch's ``dilation``.

    Returns
    -------
    y : ndarray (B, T, C_out)
    cache : tuple
        For :func:`conv1d_causal_backward`.
    """
    dilation = _check_dilation(dilation)
    w = get_param(params, prefix, "weight", (None, None, None))  # (C_out, C_in, K)
    c_out, c_in, taps = w.shape
    b = get_param(params, prefix, "bias", (c_out,))
    x = float_array(x, "x", (None, None, c_in), cast=False)
    check_same_dtype(x, "x", {param_name(prefix, "weight"): w, param_name(prefix, "bias"): b})
    batch, t_len, _ = x.shape
    pad = (taps - 1) * dilation
    xpad = np.zeros((batch, t_len + pad, c_in), dtype=x.dtype)  # (B, T + P, C_in)
    xpad[:, pad:] = x
    xcol = np.empty((batch, t_len, taps * c_in), dtype=x.dtype)  # (B, T, K*C_in)
    for k in range(taps):
        xcol[:, :, k * c_in:(k + 1) * c_in] = xpad[:, k * dilation:k * dilation + t_len]
    xcol = xcol.reshape(batch * t_len, taps * c_in)
    wcol = np.ascontiguousarray(w.transpose(2, 1, 0)).reshape(taps * c_in, c_out)  # (K*C_in, C_out)
    y = xcol @ wcol  # (B*T, C_out), one GEMM
    y += b
    return y.reshape(batch, t_len, c_out), (xcol, wcol, (batch, t_len, c_in, c_out, taps, dilation), prefix)


def conv1d_causal_backward(dy: np.ndarray, cache):
    """Gradients of :func:`conv1d_causal_forward`.

    ``dW_col = X_col^T dy`` and ``dX_col = dy W_col^T`` (one GEMM each); ``dx[:, t] = sum_k
    dX_col[:, t + (K - 1 - k) d, block k]`` (terms past the end are 0), ``dbias = sum dy``.

    Parameters
    ----------
    dy : ndarray (B, T, C_out), float32 or float64, finite
    cache : tuple
        From :func:`conv1d_causal_forward`.

    Returns
    -------
    dx : ndarray (B, T, C_in)
    grads : dict
        ``{prefix}.weight`` ``(C_out, C_in, K)``, ``{prefix}.bias`` ``(C_out,)``.

    Raises
    ------
    ValueError
        When ``dy`` is not a float array of ``y``'s shape, or holds NaN/inf.
    """
    xcol, wcol, (batch, t_len, c_in, c_out, taps, dilation), prefix = cache
    dy = float_array(dy, "dy", (batch, t_len, c_out), cast=False)
    dy2 = dy.reshape(batch * t_len, c_out)  # (B*T, C_out)
    dwcol = xcol.T @ dy2  # (K*C_in, C_out)
    dxcol = (dy2 @ wcol.T).reshape(batch, t_len, taps * c_in)  # (B, T, K*C_in)
    pad = (taps - 1) * dilation
    dxpad = np.zeros((batch, t_len + pad, c_in), dtype=dxcol.dtype)
    for k in range(taps):
        dxpad[:, k * dilation:k * dilation + t_len] += dxcol[:, :, k * c_in:(k + 1) * c_in]
    grads = {param_name(prefix, "weight"): np.ascontiguousarray(dwcol.reshape(taps, c_in, c_out).transpose(2, 1, 0)),
             param_name(prefix, "bias"): dy2.sum(axis=0)}
    return dxpad[:, pad:].copy(), grads


# ----------------------------------------------------------------------------------------------------------
# slow oracles


def _conv1d_causal_forward_naive(x, params, prefix, dilation=1):
    """Per (b, t, k) loop of ``y[b, t] = bias + sum_k weight[:, :, k] @ x[b, t - (K-1-k) d]``."""
    w = params[param_name(prefix, "weight")]
    b = params[param_name(prefix, "bias")]
    c_out, _, taps = w.shape
    batch, t_len, _ = x.shape
    y = np.zeros((batch, t_len, c_out), dtype=x.dtype)
    for bi in range(batch):
        for t in range(t_len):
            y[bi, t] = b
            for k in range(taps):
                s = t - (taps - 1 - k) * dilation
                if s >= 0:
                    y[bi, t] += w[:, :, k] @ x[bi, s]
    return y


def _conv1d_causal_backward_naive(dy, x, params, prefix, dilation=1):
    """Per (b, t, k) loop; returns ``(dx, grads)``."""
    w = params[param_name(prefix, "weight")]
    taps = w.shape[2]
    batch, t_len, _ = x.shape
    dx = np.zeros_like(x)
    dw = np.zeros_like(w)
    for bi in range(batch):
        for t in range(t_len):
            for k in range(taps):
                s = t - (taps - 1 - k) * dilation
                if s >= 0:
                    dx[bi, s] += w[:, :, k].T @ dy[bi, t]
                    dw[:, :, k] += np.outer(dy[bi, t], x[bi, s])
    return dx, {param_name(prefix, "weight"): dw, param_name(prefix, "bias"): dy.sum(axis=(0, 1))}
