"""ONNX builders for the pointwise activations of ``refimpl/nn/activations.py``.

``LeakyRelu`` stores its slope as a float32 attribute (``alpha = 0.01`` becomes 0.009999999776…), so a float64
reference differs from the export by ~2e-10 relative, harmless at float32 tolerance (``spec/deploy.md`` §2).
With ``g.primitive`` (float64 graphs, or runtimes without LeakyRelu) it is emitted as ``Max(x, α·x)`` for
``0 ≤ α ≤ 1`` (``Min`` for ``α > 1``) with α a graph-dtype constant: exact in float64.

Shape legend: ``...`` any shape (elementwise).
"""
from __future__ import annotations

from deploy.graph import GraphBuilder

__all__ = ["leaky_relu", "relu", "tanh", "sigmoid", "activation"]


def leaky_relu(g: GraphBuilder, x: str, *, name: str, alpha: float = 0.01) -> str:
    """``y = x`` for ``x ≥ 0``, ``α x`` otherwise (PyTorch ``negative_slope`` = ``alpha``); shape of ``x``."""
    if not g.primitive_layers:
        return g.node("LeakyRelu", [x], name, alpha=float(alpha))
    if alpha < 0:
        raise ValueError(f"alpha: primitive LeakyRelu needs alpha >= 0, got {alpha}")
    ax = g.node("Mul", [x, g.scalar(alpha)], f"{name}.ax")
    return g.node("Max" if alpha <= 1 else "Min", [x, ax], name)


def relu(g: GraphBuilder, x: str, *, name: str) -> str:
    """``y = max(x, 0)``; shape of ``x``."""
    return g.node("Relu", [x], name)


def tanh(g: GraphBuilder, x: str, *, name: str) -> str:
    """``y = tanh(x)``; shape of ``x``."""
    return g.node("Tanh", [x], name)


def sigmoid(g: GraphBuilder, x: str, *, name: str) -> str:
    """``y = 1 / (1 + exp(-x))``; shape of ``x``."""
    return g.node("Sigmoid", [x], name)


def activation(g: GraphBuilder, x: str, kind: str, *, name: str, alpha: float = 0.01) -> str:
    """Dispatch on ``kind`` in ``{"leaky_relu", "relu", "tanh", "sigmoid", "identity"}``."""
    if kind == "leaky_relu":
        return leaky_relu(g, x, name=name, alpha=alpha)
    if kind == "identity":
        return x
    table = {"relu": relu, "tanh": tanh, "sigmoid": sigmoid}
    if kind not in table:
        raise ValueError(f"kind: expected one of leaky_relu, relu, tanh, sigmoid, identity; got {kind!r}")
    return table[kind](g, x, name=name)
