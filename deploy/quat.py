"""ONNX builders for the quaternion and dual-quaternion operations of ``refimpl/quat.py``/``refimpl/dualquat.py``.

Conventions as in ``refimpl`` (``spec/conventions.md``): quaternions ``(w, x, y, z)`` in the last axis, Hamilton
product, active rotations; dual quaternions ``(q_r | q_d)`` in an 8-vector; leading axes broadcast.

Few, coarse nodes (each extra ONNX node costs ~0.5 µs in onnxruntime): the Hamilton product is written as a
matrix product ``q ⊗ r = L(q) r`` with ``L(q) = sign ⊙ q[index]`` built by one ``Gather``; the rotation
``v + 2 (w (u × v) + u × (u × v))`` as ``(I + 2 w K + 2 K²) v`` with the cross-product matrix ``K = [u]×``.
A graph cannot raise, so normalisations divide by ``max(|q|, eps)`` (``eps`` defaults to 1e-8) where the
NumPy functions reject a zero quaternion with ``ValueError``.

Shape legend: ``...`` leading axes (e.g. B, T, J).
"""
from __future__ import annotations

import numpy as np

from deploy.graph import GraphBuilder

__all__ = ["quat_normalize", "quat_mul", "quat_rotate", "quat_rotation_matrix", "dq_normalize"]

# L(q)[i, j] = _MUL_SIGN[i, j] * q[_MUL_INDEX[i, j]], so that (q ⊗ r)_i = Σ_j L(q)[i, j] r_j
_MUL_INDEX = np.array([[0, 1, 2, 3], [1, 0, 3, 2], [2, 3, 0, 1], [3, 2, 1, 0]], dtype=np.int64)
_MUL_SIGN = np.array([[1, -1, -1, -1], [1, 1, -1, 1], [1, 1, 1, -1], [1, -1, 1, 1]], dtype=np.float64)
# K = [u]x for u = (x, y, z) = q[1:4]: K[i, j] = _CROSS_SIGN[i, j] * q[_CROSS_INDEX[i, j]]
_CROSS_INDEX = np.array([[0, 3, 2], [3, 0, 1], [2, 1, 0]], dtype=np.int64)
_CROSS_SIGN = np.array([[0, -1, 1], [1, 0, -1], [-1, 1, 0]], dtype=np.float64)


def quat_normalize(g: GraphBuilder, q: str, *, name: str, eps: float = 1e-8) -> str:
    """``q / max(|q|, eps)`` over the last axis; ``q`` ``(..., 4)`` (or any ``(..., n)``) → same shape.

    Equals ``refimpl.quat.quat_normalize`` wherever ``|q| > eps`` (spec/math.md §1.4).
    """
    n2 = g.reduce("ReduceSumSquare", q, [-1], f"{name}.n2")             # (..., 1)
    n = g.node("Sqrt", [n2], f"{name}.norm")                             # (..., 1)
    n = g.node("Max", [n, g.scalar(eps)], f"{name}.norm_eps")            # (..., 1)
    return g.node("Div", [q, n], name)                                   # (..., 4)


def quat_mul(g: GraphBuilder, q: str, r: str, *, name: str) -> str:
    """Hamilton product ``q ⊗ r`` of ``(..., 4)`` tensors (leading axes broadcast), as ``refimpl.quat.quat_mul``.

    Equations
    ---------
    ``w = w1w2 − x1x2 − y1y2 − z1z2``, ``x = w1x2 + x1w2 + y1z2 − z1y2``,
    ``y = w1y2 − x1z2 + y1w2 + z1x2``, ``z = w1z2 + x1y2 − y1x2 + z1w2``; computed as ``L(q) r`` with
    ``L(q)[i, j] = sign[i, j] q[index[i, j]]``.
    """
    lq = g.node("Gather", [q, g.shared("const.quat_mul.index", _MUL_INDEX)], f"{name}.gather", axis=-1)  # (..., 4, 4)
    lq = g.node("Mul", [lq, g.shared("const.quat_mul.sign", _MUL_SIGN)], f"{name}.L")   # (..., 4, 4)
    rc = g.node("Unsqueeze", [r, g.ints([-1])], f"{name}.r_col")         # (..., 4, 1)
    out = g.node("MatMul", [lq, rc], f"{name}.matmul")                   # (..., 4, 1)
    return g.node("Squeeze", [out, g.ints([-1])], name)                  # (..., 4)


def quat_rotation_matrix(g: GraphBuilder, q: str, *, name: str) -> str:
    """``M(q) = I + 2 w K + 2 K²`` ``(..., 3, 3)`` with ``K = [u]×``, so that ``M(q) v = quat_rotate(q, v)``.

    For unit ``q`` this is the rotation matrix ``R(q)``; for other ``q`` it reproduces the formula of
    ``refimpl.quat.quat_rotate`` (QuaterNet's ``qrot``), which does not normalise.
    """
    k = g.node("Gather", [q, g.shared("const.cross.index", _CROSS_INDEX)], f"{name}.gather", axis=-1)  # (..., 3, 3)
    k = g.node("Mul", [k, g.shared("const.cross.sign", _CROSS_SIGN)], f"{name}.K")   # (..., 3, 3)
    k2 = g.node("MatMul", [k, k], f"{name}.K2")                          # (..., 3, 3)
    w = g.node("Slice", [q, g.ints([0]), g.ints([1]), g.ints([-1])], f"{name}.w")  # (..., 1)
    w = g.node("Unsqueeze", [w, g.ints([-1])], f"{name}.w11")            # (..., 1, 1)
    wk = g.node("Mul", [w, k], f"{name}.wK")                             # (..., 3, 3)
    s = g.node("Add", [wk, k2], f"{name}.wK_K2")                         # (..., 3, 3)
    s = g.node("Mul", [s, g.scalar(2.0)], f"{name}.2s")                  # (..., 3, 3)
    return g.node("Add", [s, g.shared("const.eye3", np.eye(3))], name)    # (..., 3, 3)


def quat_rotate(g: GraphBuilder, q: str, v: str, *, name: str) -> str:
    """Rotate ``v`` ``(..., 3)`` by ``q`` ``(..., 4)``: ``v + 2 (w (u × v) + u × (u × v))`` (spec/math.md §1.5).

    Leading axes of ``q`` and ``v`` broadcast (through ``MatMul``).
    """
    m = quat_rotation_matrix(g, q, name=f"{name}.M")                     # (..., 3, 3)
    vc = g.node("Unsqueeze", [v, g.ints([-1])], f"{name}.v_col")         # (..., 3, 1)
    out = g.node("MatMul", [m, vc], f"{name}.matmul")                    # (..., 3, 1)
    return g.node("Squeeze", [out, g.ints([-1])], name)                  # (..., 3)


def dq_normalize(g: GraphBuilder, a: str, *, name: str, eps: float = 1e-8) -> str:
    """Unit dual quaternion (paper Eq. 13), as ``refimpl.dualquat.dq_normalize``; ``a`` ``(..., 8)`` → ``(..., 8)``.

    Equations
    ---------
    ``n = max(|q_r|, eps)``, ``q̂_r = q_r / n``, ``q̂_d = q_d / n − q̂_r ⟨q_r, q_d⟩ / n²``.
    """
    r, d = g.node("Split", [a, g.ints([4, 4])], f"{name}.split", axis=-1, outputs=("r", "d"))  # (..., 4) each
    n2 = g.reduce("ReduceSumSquare", r, [-1], f"{name}.n2")             # (..., 1)
    n = g.node("Max", [g.node("Sqrt", [n2], f"{name}.norm"), g.scalar(eps)], f"{name}.n")  # (..., 1)
    rh = g.node("Div", [r, n], f"{name}.r_hat")                          # (..., 4)
    dot = g.reduce("ReduceSum", g.node("Mul", [r, d], f"{name}.rd"), [-1], f"{name}.dot")  # (..., 1)
    coef = g.node("Div", [dot, g.node("Mul", [n, n], f"{name}.nn")], f"{name}.coef")  # (..., 1)
    dh = g.node("Sub", [g.node("Div", [d, n], f"{name}.d_n"),
                        g.node("Mul", [rh, coef], f"{name}.proj")], f"{name}.d_hat")  # (..., 4)
    return g.node("Concat", [rh, dh], name, axis=-1)                     # (..., 8)
