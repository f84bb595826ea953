"""Element-wise activations as pure forward/backward pairs (spec/layers.md §3).

Convention: ``y, cache = name_forward(x, ...)`` and ``dx = name_backward(dy, cache)``. Arrays of any shape
``(...)``; float32 stays float32. The caches hold what the derivative needs: a boolean mask for the rectifiers
and the output ``y`` for tanh and sigmoid (their derivatives are functions of ``y``).

=============  ======================================  ======================================
activation     forward                                 backward
=============  ======================================  ======================================
leaky_relu     y = x if x > 0 else slope * x           dx = dy if x > 0 else slope * dy
relu           y = max(x, 0)                           dx = dy if x > 0 else 0
tanh           y = tanh(x)                             dx = dy * (1 - y^2)
sigmoid        y = 1 / (1 + exp(-x))                   dx = dy * y * (1 - y)
=============  ======================================  ======================================

At ``x == 0`` the rectifiers take the left derivative (``slope``, resp. 0), as PyTorch does.
QuaterNet's control block uses ``slope = 0.05``; PyTorch's default (``nn.LeakyReLU()``) is 0.01.

Checks (spec/layers.md §3): every ``*_forward`` validates ``x`` (float32/float64, finite; any shape, 0-d
included); every ``*_backward`` validates ``dy`` (float32/float64, the shape of the forward's output, finite) and
raises ``ValueError`` naming it. :func:`sigmoid` is the unchecked kernel used inside the recurrent cells.
"""
from __future__ import annotations

import numpy as np

from refimpl.arrays import float_array

__all__ = [
    "leaky_relu_forward", "leaky_relu_backward", "relu_forward", "relu_backward",
    "tanh_forward", "tanh_backward", "sigmoid_forward", "sigmoid_backward",
]


def sigmoid(x: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Internal kernel (no checks): the logistic function ``1 / (1 + exp(-x))``, elementwise, without overflow warnings.

    Parameters
    ----------
    x : ndarray (...), float32 or float64
    out : ndarray, optional
        Destination (may be ``x`` itself for an in-place update).

    Notes
    -----
    For ``x < -88`` (float32) / ``x < -709`` (float64) ``exp(-x)`` overflows to ``inf`` and the result is
    exactly 0, the correctly rounded value up to the underflow threshold. Accurate to a few ulp elsewhere.
    """
    out = np.negative(x, out=out)
    with np.errstate(over="ignore"):
        np.exp(out, out=out)
    out += 1
    return np.reciprocal(out, out=out)


def leaky_relu_forward(x: np.ndarray, slope: float = 0.01):
    """Leaky rectifier ``y = x (x > 0), slope * x (x <= 0)``.

    Parameters
    ----------
    x : ndarray (...), float32 or float64
    slope : float
        Negative-side slope (PyTorch ``negative_slope``); QuaterNet uses 0.05.

    Returns
    -------
    y : ndarray, same shape and dtype as ``x``
    cache : tuple (mask, slope)
    """
    x = float_array(x, "x", (...,), cast=False)
    mask = x > 0
    y = np.where(mask, x, x * x.dtype.type(slope))
    return y, (mask, slope)


def _check_dy(dy, shape: tuple) -> np.ndarray:
    """The upstream gradient of an activation: a finite float array of the forward output's ``shape``."""
    return float_array(dy, "dy", shape, cast=False)


def leaky_relu_backward(dy: np.ndarray, cache) -> np.ndarray:
    """``dx = dy (x > 0), slope * dy (x <= 0)``; ``dy`` of ``y``'s shape, finite (else ``ValueError``)."""
    mask, slope = cache
    dy = _check_dy(dy, mask.shape)
    return np.where(mask, dy, dy * dy.dtype.type(slope))


def relu_forward(x: np.ndarray):
    """Rectifier ``y = max(x, 0)``; returns ``y, cache`` (cache: the mask ``x > 0``)."""
    x = float_array(x, "x", (...,), cast=False)
    mask = x > 0
    return np.where(mask, x, x.dtype.type(0)), mask


def relu_backward(dy: np.ndarray, cache) -> np.ndarray:
    """``dx = dy`` where ``x > 0``, else 0; ``dy`` of ``y``'s shape, finite (else ``ValueError``)."""
    dy = _check_dy(dy, cache.shape)
    return np.where(cache, dy, dy.dtype.type(0))


def tanh_forward(x: np.ndarray):
    """``y = tanh(x)``; returns ``y, cache`` (cache: ``y``)."""
    x = float_array(x, "x", (...,), cast=False)
    y = np.tanh(x)
    return y, y


def tanh_backward(dy: np.ndarray, cache) -> np.ndarray:
    """``dx = dy * (1 - y^2)``; ``dy`` of ``y``'s shape, finite (else ``ValueError``)."""
    y = cache
    dy = _check_dy(dy, y.shape)
    return dy * (1 - y * y)


def sigmoid_forward(x: np.ndarray):
    """``y = 1 / (1 + exp(-x))``; returns ``y, cache`` (cache: ``y``)."""
    x = float_array(x, "x", (...,), cast=False)
    y = sigmoid(x, out=np.empty_like(x))  # an array out: also a 0-d x gives a 0-d array, not a scalar
    return y, y


def sigmoid_backward(dy: np.ndarray, cache) -> np.ndarray:
    """``dx = dy * y * (1 - y)``; ``dy`` of ``y``'s shape, finite (else ``ValueError``)."""
    y = cache
    dy = _check_dy(dy, y.shape)
    return dy * y * (1 - y)


# Kernel tier (spec/architecture.md; unchecked, not in __all__, imported by other modules under these names): sigmoid.
