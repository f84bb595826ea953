"""QuaterNet's input sign rule (the published ``predict``'s canonicalisation of a prefix), in NumPy and as ONNX
nodes (spec/deploy.md §11.1).

A quaternion and its negation are the same rotation, but the recurrent and convolutional QuaterNet read the
numbers: ``refimpl``'s predictor (``refimpl.protocols.prediction.canonical_prefix``) therefore first
maps every prefix to one representative — quaternions → zyx Euler → quaternions (``refimpl.quat``), then
``quat_fix`` over time. This module states that rule without Euler angles, so that a graph (or any consumer)
can apply it:

1. **Unit length**: ``q ← q / |q|`` (the round trip returns unit quaternions).
2. **Frame 0 (Euler branch)**: with ``(w, x, y, z) = q``, ``σ = atan2(z + x, w − y)``,
   ``δ = atan2(z − x, w + y)`` (both in ``(−π, π]``), ``α = σ + δ``, ``γ = σ − δ``; in gimbal lock
   (``hypot(z − x, w + y) ≤ 1.49e-8``: ``α = 2σ, γ = 0``; else ``hypot(z + x, w − y) ≤ 1.49e-8``: ``α = 2δ,
   γ = 0``). The zyx Euler angles are α and γ wrapped to ``[−π, π)``; each wrap negates the round trip's
   quaternion, so frame 0 becomes ``s₀ q₀`` with ``s₀ = (−1)^(n(α) + n(γ))``, ``n(v) = 1`` when ``v ≥ π`` or
   ``v < −π``, else 0.
3. **Continuity** (``quat_fix``): frame ``t ≥ 1`` becomes ``s₀ (−1)^(c_t) q_t``, ``c_t`` = the number of
   ``u ∈ [1, t]`` with ``⟨q_u, q_{u−1}⟩ < 0`` (dot products of the unit inputs): consecutive frames then lie in
   one hemisphere.

Each joint is its own track. The result represents the same rotations; applied twice it changes nothing; any
sign flips of the input give the same output (up to rounding, except exactly on the measure-zero boundaries
``α = ±π``, ``γ = ±π``, a zero dot product, where float32 and float64 may decide differently).

* :func:`canonical_signs` — the rule in NumPy, ``(B, P, J, 4) → (B, P, J, 4)``;
* :func:`canonical_signs_graph` — the same as ONNX nodes on a ``(B, P, 4J)`` tensor (``Atan``, ``CumSum``,
  ``Mod``, ``Where``), used by the QuaterNet ``predict`` model.

Shape legend: B batch, P prefix frames, J joints.
"""
from __future__ import annotations

import numpy as np

from deploy.graph import GraphBuilder

__all__ = ["LOCK_TOL", "canonical_signs", "canonical_signs_graph", "RULE"]

#: Gimbal-lock threshold of ``refimpl.rotations.euler_from_quat`` for a unit quaternion (``sqrt(eps64)``).
LOCK_TOL = float(np.sqrt(np.finfo(np.float64).eps))

#: The rule as metadata text (``input_transform`` of QuaterNet's models).
RULE = [
    "unit length: q <- q / |q| for every joint quaternion (w, x, y, z) of every prefix frame",
    "frame 0, per joint: sigma = atan2(z + x, w - y), delta = atan2(z - x, w + y) (both in (-pi, pi]); "
    "alpha = sigma + delta, gamma = sigma - delta; if hypot(z - x, w + y) <= 1.49e-8: alpha = 2 sigma, gamma = 0; "
    "elif hypot(z + x, w - y) <= 1.49e-8: alpha = 2 delta, gamma = 0; n(v) = 1 if v >= pi or v < -pi else 0; "
    "s0 = (-1)^(n(alpha) + n(gamma)) (this is the sign the quaternion -> zyx Euler -> quaternion round trip "
    "gives)",
    "continuity, per joint: c_t = number of u in [1, t] with dot(q_u, q_{u-1}) < 0 (unit inputs); frame t "
    "becomes s0 * (-1)^c_t * q_t (frame 0: s0 * q_0)",
]


def _atan2_np(y, x):
    return np.arctan2(y, x)


def _wraps(v) -> np.ndarray:
    return ((v >= np.pi) | (v < -np.pi)).astype(np.int64)


def canonical_signs(prefix) -> np.ndarray:
    """The rule of the module docstring in NumPy (float64).

    Parameters
    ----------
    prefix : array_like, (B, P, J, 4)
        Joint quaternions ``(w, x, y, z)``, non-zero.

    Returns
    -------
    ndarray, (B, P, J, 4)
        Unit quaternions, the same rotations, canonical signs.
    """
    q = np.asarray(prefix, dtype=np.float64)
    if q.ndim != 4 or q.shape[-1] != 4 or q.shape[1] < 1:
        raise ValueError(f"prefix: expected shape (B, P >= 1, J, 4), got {q.shape}")
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q[:, 0], -1, 0)                               # (B, J) each
    m_sum, m_dif = np.hypot(w - y, z + x), np.hypot(w + y, z - x)
    sigma, delta = _atan2_np(z + x, w - y), _atan2_np(z - x, w + y)
    lock_dif = m_dif <= LOCK_TOL
    lock_sum = (m_sum <= LOCK_TOL) & ~lock_dif
    alpha = np.where(lock_dif, 2 * sigma, np.where(lock_sum, 2 * delta, sigma + delta))
    gamma = np.where(lock_dif | lock_sum, 0.0, sigma - delta)
    s0 = 1.0 - 2.0 * ((_wraps(alpha) + _wraps(gamma)) % 2)                  # (B, J)
    d = np.sum(q[:, 1:] * q[:, :-1], axis=-1)                              # (B, P-1, J)
    c = np.cumsum(d < 0, axis=1) % 2
    chain = np.concatenate([np.ones_like(s0)[:, None], 1.0 - 2.0 * c], axis=1)   # (B, P, J)
    return q * (s0[:, None] * chain)[..., None]


def _atan2(g: GraphBuilder, y: str, x: str, *, name: str) -> str:
    """``atan2(y, x)`` in ``(−π, π]``: ``2 atan(y / (hypot(x, y) + x))``, and ``π`` on the negative x axis (and
    0 at the origin, where the caller's lock test takes over)."""
    r = g.node("Sqrt", [g.node("Add", [g.node("Mul", [x, x], f"{name}.xx"), g.node("Mul", [y, y], f"{name}.yy")],
                               f"{name}.r2")], f"{name}.r")
    den = g.node("Add", [r, x], f"{name}.den")
    zero = g.node("LessOrEqual", [den, g.scalar(0.0)], f"{name}.on_axis")
    safe = g.node("Where", [zero, g.scalar(1.0), den], f"{name}.den_safe")
    half = g.node("Atan", [g.node("Div", [y, safe], f"{name}.ratio")], f"{name}.half")
    a = g.node("Mul", [half, g.scalar(2.0)], f"{name}.angle")
    neg_axis = g.node("And", [zero, g.node("Less", [x, g.scalar(0.0)], f"{name}.x_neg")], f"{name}.neg_axis")
    return g.node("Where", [neg_axis, g.scalar(np.pi), a], name)


def _wrap_count(g: GraphBuilder, v: str, *, name: str) -> str:
    hi = g.node("GreaterOrEqual", [v, g.scalar(np.pi)], f"{name}.hi")
    lo = g.node("Less", [v, g.scalar(-np.pi)], f"{name}.lo")
    return g.node("Cast", [g.node("Or", [hi, lo], f"{name}.or")], name, to=g.elem_type)


def canonical_signs_graph(g: GraphBuilder, prefix: str, J: int, *, name: str = "canon") -> str:
    """The rule as ONNX nodes: ``prefix (B, P, 4J)`` → ``(B, P, 4J)`` (joint-major quaternions)."""
    q = g.node("Reshape", [prefix, g.ints([0, 0, J, 4])], f"{name}.joints")                     # (B, P, J, 4)
    n = g.node("Sqrt", [g.reduce("ReduceSum", g.node("Mul", [q, q], f"{name}.sq"), [-1], f"{name}.n2")],
               f"{name}.norm")
    q = g.node("Div", [q, g.node("Max", [n, g.scalar(1e-30)], f"{name}.norm_safe")], f"{name}.unit")
    f0 = g.node("Gather", [q, g.constant(f"{name}.zero", np.array(0, dtype=np.int64))], f"{name}.f0", axis=1)
    w, x, y, z = g.node("Split", [f0, g.ints([1, 1, 1, 1])], f"{name}.wxyz", axis=-1,
                        outputs=("w", "x", "y", "z"))                                          # (B, J, 1) each
    a_y, a_x = g.node("Add", [z, x], f"{name}.zpx"), g.node("Sub", [w, y], f"{name}.wmy")      # sigma's pair
    b_y, b_x = g.node("Sub", [z, x], f"{name}.zmx"), g.node("Add", [w, y], f"{name}.wpy")      # delta's pair
    sigma = _atan2(g, a_y, a_x, name=f"{name}.sigma")
    delta = _atan2(g, b_y, b_x, name=f"{name}.delta")

    def hyp(u, v, tag):
        return g.node("Sqrt", [g.node("Add", [g.node("Mul", [u, u], f"{name}.{tag}.uu"),
                                              g.node("Mul", [v, v], f"{name}.{tag}.vv")], f"{name}.{tag}.s")],
                      f"{name}.{tag}")

    lock_dif = g.node("LessOrEqual", [hyp(b_y, b_x, "m_dif"), g.scalar(LOCK_TOL)], f"{name}.lock_dif")
    lock_sum = g.node("And", [g.node("LessOrEqual", [hyp(a_y, a_x, "m_sum"), g.scalar(LOCK_TOL)],
                                     f"{name}.sum_small"), g.node("Not", [lock_dif], f"{name}.not_dif")],
                      f"{name}.lock_sum")
    two = g.scalar(2.0)
    alpha = g.node("Where", [lock_dif, g.node("Mul", [sigma, two], f"{name}.2sigma"),
                             g.node("Where", [lock_sum, g.node("Mul", [delta, two], f"{name}.2delta"),
                                              g.node("Add", [sigma, delta], f"{name}.sum")], f"{name}.alpha_s")],
                   f"{name}.alpha")
    locked = g.node("Or", [lock_dif, lock_sum], f"{name}.locked")
    gamma = g.node("Where", [locked, g.scalar(0.0), g.node("Sub", [sigma, delta], f"{name}.dif")], f"{name}.gamma")
    wraps = g.node("Add", [_wrap_count(g, alpha, name=f"{name}.n_alpha"),
                           _wrap_count(g, gamma, name=f"{name}.n_gamma")], f"{name}.wraps")   # (B, J, 1)
    s0 = g.node("Sub", [g.scalar(1.0), g.node("Mul", [g.node("Mod", [wraps, two], f"{name}.wraps2", fmod=1), two],
                                              f"{name}.s0x2")], f"{name}.s0")                    # (B, J, 1)
    # continuity: parity of the negative dot products up to t (a cumulative sum, mod 2)
    cur = g.node("Slice", [q, g.ints([1]), g.ints([2 ** 62]), g.ints([1])], f"{name}.cur")       # (B, P-1, J, 4)
    prev = g.node("Slice", [q, g.ints([0]), g.ints([-1]), g.ints([1])], f"{name}.prev")
    d = g.reduce("ReduceSum", g.node("Mul", [cur, prev], f"{name}.dp"), [-1], f"{name}.dot")    # (B, P-1, J, 1)
    neg = g.node("Cast", [g.node("Less", [d, g.scalar(0.0)], f"{name}.neg_b")], f"{name}.neg", to=g.elem_type)
    c = g.node("CumSum", [neg, g.constant(f"{name}.axis1", np.array(1, dtype=np.int64))], f"{name}.count")
    flips = g.node("Sub", [g.scalar(1.0), g.node("Mul", [g.node("Mod", [c, two], f"{name}.parity", fmod=1), two],
                                                 f"{name}.parity2")], f"{name}.flips")           # (B, P-1, J, 1)
    ones = g.node("Slice", [g.node("Mul", [n, g.scalar(0.0)], f"{name}.zeros"), g.ints([0]), g.ints([1]),
                            g.ints([1])], f"{name}.zero0")                                       # (B, 1, J, 1)
    chain = g.node("Concat", [g.node("Add", [ones, g.scalar(1.0)], f"{name}.one0"), flips], f"{name}.chain",
                   axis=1)                                                                       # (B, P, J, 1)
    s = g.node("Mul", [chain, g.node("Unsqueeze", [s0, g.ints([1])], f"{name}.s0_t")], f"{name}.sign")
    out = g.node("Mul", [q, s], f"{name}.signed")                                                # (B, P, J, 4)
    return g.node("Reshape", [out, g.ints([0, 0, 4 * J])], name)
