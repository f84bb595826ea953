"""Dual-quaternion pieces of the QuaterNet export (``QuaterNetConfig(representation="dual_quaternion")``;
spec/quaternet.md §9, spec/deploy.md §11): the dual-quaternion product.

``deploy/models/quaternet.py`` builds the whole graph; its head, for a dual-quaternion network::

    o  = fc(top) = [ΔD (8J) | τ (O)]                        Gemm, Slice
    D̂  = N(ΔD_j ⊗ D_in,j) (velocity) or N(ΔD_j) (absolute)  dq_mul (Gather, Mul, MatMul), dq_normalize (Eq. 13)
    y  = [D̂ (8J) | τ]                                       Concat

The dual-quaternion product ``a ⊗ b = (a_r ⊗ b_r | a_r ⊗ b_d + a_d ⊗ b_r)`` is one 8 × 8 matrix product
``L₈(a) b`` with ``L₈(a) = [[L(a_r), 0], [L(a_d), L(a_r)]]``, gathered from ``a`` in one node as the quaternion
product of ``deploy.quat.quat_mul``. Inputs and outputs of the exported models are the network's own frames:
current (root-relative) unit dual quaternions ``(q_r | q_d)`` per joint, joint-major.

Shape legend: B batch, J joints, H hidden size, O translations, G = 8J + O.
"""
from __future__ import annotations

import numpy as np

from deploy.graph import GraphBuilder

__all__ = ["dq_mul"]

# L(q)[i, j] = _MUL_SIGN[i, j] * q[_MUL_INDEX[i, j]] (the Hamilton product q ⊗ r = L(q) r, as deploy.quat.quat_mul)
_MUL_INDEX = np.array([[0, 1, 2, 3], [1, 0, 3, 2], [2, 3, 0, 1], [3, 2, 1, 0]], dtype=np.int64)
_MUL_SIGN = np.array([[1, -1, -1, -1], [1, 1, -1, 1], [1, 1, 1, -1], [1, -1, 1, 1]], dtype=np.float64)
# L8(a)[i, j] = _DQ_SIGN[i, j] * a[_DQ_INDEX[i, j]], so that (a ⊗ b)_i = Σ_j L8(a)[i, j] b_j
_DQ_INDEX = np.zeros((8, 8), dtype=np.int64)
_DQ_SIGN = np.zeros((8, 8), dtype=np.float64)
_DQ_INDEX[:4, :4], _DQ_SIGN[:4, :4] = _MUL_INDEX, _MUL_SIGN          # real part: L(a_r) b_r
_DQ_INDEX[4:, 4:], _DQ_SIGN[4:, 4:] = _MUL_INDEX, _MUL_SIGN          # dual part: L(a_r) b_d
_DQ_INDEX[4:, :4], _DQ_SIGN[4:, :4] = _MUL_INDEX + 4, _MUL_SIGN      #          + L(a_d) b_r


def dq_mul(g: GraphBuilder, a: str, b: str, *, name: str) -> str:
    """Dual-quaternion product ``a ⊗ b`` of ``(..., 8)`` tensors, as ``refimpl.dualquat.dq_mul``:
    ``(a_r ⊗ b_r | a_r ⊗ b_d + a_d ⊗ b_r)``, computed as ``L₈(a) b``."""
    la = g.node("Gather", [a, g.shared("const.dq_mul.index", _DQ_INDEX)], f"{name}.gather", axis=-1)  # (..., 8, 8)
    la = g.node("Mul", [la, g.shared("const.dq_mul.sign", _DQ_SIGN)], f"{name}.L8")   # (..., 8, 8)
    bc = g.node("Unsqueeze", [b, g.ints([-1])], f"{name}.b_col")         # (..., 8, 1)
    out = g.node("MatMul", [la, bc], f"{name}.matmul")                   # (..., 8, 1)
    return g.node("Squeeze", [out, g.ints([-1])], name)                  # (..., 8)
