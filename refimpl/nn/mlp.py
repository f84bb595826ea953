"""Multi-layer perceptrons: a chain of dense layers with a LeakyReLU after each (the last one optionally linear).

Parameters of layer ``i`` are ``{prefix}.{i}.weight (n_{i+1}, n_i)`` and ``{prefix}.{i}.bias (n_{i+1},)``
(PyTorch ``nn.Sequential`` of ``nn.Linear`` without the activation indices). Used by QTG's encoder and decoder;
the pace network's and acRNN's heads are the same shape.

Shape legend: N leading (batch) axes, n_i width of layer i's input.
"""
from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from refimpl.nn.activations import leaky_relu_backward, leaky_relu_forward
from refimpl.nn.linear import linear_backward, linear_forward, linear_init

__all__ = ["mlp_init", "mlp_forward", "mlp_backward"]


def mlp_init(rng: np.random.Generator, sizes: Sequence[int], prefix: str, dtype=np.float64) -> dict:
    """PyTorch-default initialisation of the dense layers ``sizes[0] -> sizes[1] -> … -> sizes[-1]``.

    Parameters
    ----------
    rng : numpy.random.Generator
    sizes : sequence of int
        Input width, then each layer's output width (at least two entries).
    prefix : str

    Returns
    -------
    dict ``{prefix}.{i}.weight`` ``(sizes[i + 1], sizes[i])``, ``{prefix}.{i}.bias`` ``(sizes[i + 1],)``
    """
    sizes = [int(s) for s in sizes]
    if len(sizes) < 2 or min(sizes) < 1:
        raise ValueError(f"sizes: expected at least two positive widths, got {sizes}")
    params: dict[str, np.ndarray] = {}
    for i, (n_in, n_out) in enumerate(zip(sizes[:-1], sizes[1:])):
        params.update(linear_init(rng, n_in, n_out, f"{prefix}.{i}", dtype=dtype))
    return params


def mlp_forward(x, params: Mapping[str, np.ndarray], prefix: str, num_layers: int, slope: float = 0.01,
                last_linear: bool = False):
    """Dense layers ``{prefix}.0 … {prefix}.{n−1}``: ``x ← LeakyReLU_slope(x Wᵢᵀ + bᵢ)``, the last one without
    the activation when ``last_linear``.

    Parameters
    ----------
    x : ndarray (..., n_0)
    params : dict
    prefix : str
    num_layers : int
    slope : float
        LeakyReLU negative slope.
    last_linear : bool

    Returns
    -------
    y : ndarray (..., n_L)
    cache : list of (linear cache, activation cache or None), one per layer
    """
    caches = []
    for i in range(num_layers):
        x, c_lin = linear_forward(x, params, f"{prefix}.{i}")
        c_act = None
        if not (last_linear and i == num_layers - 1):
            x, c_act = leaky_relu_forward(x, slope)
        caches.append((c_lin, c_act))
    return x, caches


def mlp_backward(dy, cache):
    """Backward of :func:`mlp_forward`: ``(dx (..., n_0), grads)`` with one gradient per parameter."""
    grads: dict[str, np.ndarray] = {}
    for c_lin, c_act in reversed(cache):
        if c_act is not None:
            dy = leaky_relu_backward(dy, c_act)
        dy, g = linear_backward(dy, c_lin)
        grads.update(g)
    return dy, grads
