"""Differentiable quaternion and dual-quaternion layers: forward/backward pairs without parameters.

Every layer is a pure function pair ``y, cache = name_forward(...)`` / ``dx = name_backward(dy, cache)``
(a tuple of gradients when there are several inputs), see ``spec/architecture.md``. The operations:

* ``quat_normalize``      q / max(|q|, eps)  (PyTorch ``F.normalize`` semantics, QuaterNet's output layer)
* ``quat_mul``            Hamilton product a ⊗ b
* ``qmul_velocity``       normalize(Δq ⊗ q_in): QuaterNet's velocity ("QMul") block, network delta on the LEFT
* ``dq_normalize``        dual-quaternion normalisation, Andreou et al. Eq. 13
* ``dq_velocity``         Eq.-13-normalize(ΔD ⊗ D_in): the velocity block of a dual-quaternion QuaterNet
* ``euler_from_quat``     QuaterNet's quaternion → Euler conversion (``qeuler``) for the six orders
* ``euler_to_quat``       q_{o0}(a0) ⊗ q_{o1}(a1) ⊗ q_{o2}(a2): the Euler outputs of the long-term ablation (QN §4.4.2)
* ``axis_angle_to_quat``  (cos θ/2, sin(θ/2)/θ · v): the axis-angle outputs of the same ablation

Conventions: quaternions ``(w, x, y, z)``, Hamilton product, dual quaternions ``(q_r | q_d)`` (8 numbers). All
arrays broadcast over leading axes; the last axis holds the object. Layers work on ``(..., 4)`` / ``(..., 8)``
arrays: a model output ``(B, T, 4·J)`` is reshaped to ``(B, T, J, 4)`` (a view) before the layer.
float32 inputs stay float32.

Specified in ``spec/losses.md`` §2; tested in ``tests/test_nn_quat_layers.py``.

Shape legend: B batch, T time, J joints; ``...`` any leading axes.
"""
from __future__ import annotations

import numpy as np

from refimpl.arrays import float_array, gradient_array, real_number
from refimpl.quat import quat_conj_kernel, quat_mul_kernel  # conjugate, Hamilton product (broadcasting, keep float32)
from refimpl.rotations import quat_elementary_kernel

__all__ = [
    "EULER_ORDERS",
    "quat_normalize_forward", "quat_normalize_backward",
    "quat_mul_forward", "quat_mul_backward",
    "qmul_velocity_forward", "qmul_velocity_backward",
    "dq_normalize_forward", "dq_normalize_backward",
    "dq_velocity_forward", "dq_velocity_backward",
    "euler_from_quat_forward", "euler_from_quat_backward",
    "euler_to_quat_forward", "euler_to_quat_backward",
    "axis_angle_to_quat_forward", "axis_angle_to_quat_backward",
]

#: The Euler orders understood by :func:`euler_from_quat_forward` (QuaterNet's ``qeuler``).
EULER_ORDERS = ("xyz", "yzx", "zxy", "xzy", "yxz", "zyx")


# --------------------------------------------------------------------------------------------------
# validation (public boundaries only)

# --------------------------------------------------------------------------------------------------
# internal kernels (no checks)

def unbroadcast(g: np.ndarray, shape: tuple) -> np.ndarray:
    """Sum ``g`` over the axes that broadcasting added or stretched, so that it has ``shape``."""
    if g.shape == tuple(shape):
        return g
    lead = g.ndim - len(shape)
    if lead > 0:
        g = g.sum(axis=tuple(range(lead)))
    axes = tuple(i for i, n in enumerate(shape) if n == 1 and g.shape[i] != 1)
    if axes:
        g = g.sum(axis=axes, keepdims=True)
    return g


def quat_mul_backward_kernel(dy: np.ndarray, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gradients of ``y = a ⊗ b``: ``da = dy ⊗ b*``, ``db = a* ⊗ dy`` (summed back to the input shapes)."""
    da = quat_mul_kernel(dy, quat_conj_kernel(b))
    db = quat_mul_kernel(quat_conj_kernel(a), dy)
    return unbroadcast(da, a.shape), unbroadcast(db, b.shape)


def _norm_last(x: np.ndarray) -> np.ndarray:
    """Euclidean norm over the last axis, keepdims, without overflow/underflow (scaled by the largest entry)."""
    s = np.max(np.abs(x), axis=-1, keepdims=True)
    safe = np.where(s > 0, s, 1)
    return s * np.sqrt(np.sum((x / safe) ** 2, axis=-1, keepdims=True))


def normalize(q: np.ndarray, eps: float) -> tuple[np.ndarray, np.ndarray]:
    """``(q / max(|q|, eps), |q|)``, norm keepdims."""
    n = _norm_last(q)
    return q / np.maximum(n, eps), n


def normalize_backward(dy: np.ndarray, y: np.ndarray, n: np.ndarray, eps: float) -> np.ndarray:
    """Gradient of ``y = q / max(|q|, eps)``: ``(dy - y <y, dy>) / |q|`` where ``|q| >= eps``, else ``dy / eps``."""
    radial = np.where(n >= eps, np.sum(y * dy, axis=-1, keepdims=True), 0)  # no radial part under the clamp
    return (dy - y * radial) / np.maximum(n, eps)


# --------------------------------------------------------------------------------------------------
# quaternion normalisation

def quat_normalize_forward(q, eps: float = 1e-12):
    """Normalise quaternions: ``y = q / max(|q|, eps)`` (PyTorch ``F.normalize``; QuaterNet's output layer).

    Parameters
    ----------
    q : ndarray, shape (..., 4)
        Quaternions ``(w, x, y, z)`` (any norm, zero allowed). For a network output ``(B, T, 4·J)`` pass the
        view ``(B, T, J, 4)``.
    eps : float
        Lower bound of the divisor (default 1e-12 as PyTorch).

    Returns
    -------
    y : ndarray, shape (..., 4)
        Unit quaternions (``q / eps`` when ``|q| < eps``; the zero quaternion maps to zero).
    cache : tuple
    """
    q = float_array(q, "q", last=4)
    eps = real_number(eps, "eps", 0.0, low_open=True)
    y, n = normalize(q, eps)  # (..., 4), (..., 1)
    return y, (y, n, eps)


def quat_normalize_backward(dy, cache):
    """Gradient of :func:`quat_normalize_forward`.

    ``dq = (dy - y <y, dy>) / |q|`` where ``|q| >= eps`` (the tangential part of ``dy``), ``dq = dy / eps``
    where the clamp is active.

    Returns
    -------
    dq : ndarray, shape (..., 4)
    """
    y, n, eps = cache
    dy = gradient_array(dy, y.shape)
    return normalize_backward(dy, y, n, eps)


# --------------------------------------------------------------------------------------------------
# Hamilton product

def quat_mul_forward(a, b):
    """Hamilton product ``y = a ⊗ b`` (broadcasting over leading axes).

    ``w = a0 b0 - a1 b1 - a2 b2 - a3 b3``, ``x = a0 b1 + a1 b0 + a2 b3 - a3 b2``,
    ``y = a0 b2 - a1 b3 + a2 b0 + a3 b1``, ``z = a0 b3 + a1 b2 - a2 b1 + a3 b0``.

    Parameters
    ----------
    a, b : ndarray, shape (..., 4)
        Quaternions ``(w, x, y, z)``; leading axes broadcast.

    Returns
    -------
    y : ndarray, shape broadcast(a, b)
    cache : tuple
    """
    a = float_array(a, "a", last=4)
    b = float_array(b, "b", last=4)
    try:
        np.broadcast_shapes(a.shape, b.shape)
    except ValueError:
        raise ValueError(f"a and b: shapes {a.shape} and {b.shape} do not broadcast") from None
    return quat_mul_kernel(a, b), (a, b)


def quat_mul_backward(dy, cache):
    """Gradients of :func:`quat_mul_forward`: ``da = dy ⊗ b*``, ``db = a* ⊗ dy``.

    (The product is bilinear; right multiplication by ``b`` has the matrix ``R(b)`` with ``R(b)ᵀ = R(b*)``,
    left multiplication by ``a`` has ``L(a)ᵀ = L(a*)``.) Gradients are summed over broadcast axes.

    Returns
    -------
    da : ndarray, shape of ``a``
    db : ndarray, shape of ``b``
    """
    a, b = cache
    dy = gradient_array(dy, np.broadcast_shapes(a.shape, b.shape))
    return quat_mul_backward_kernel(dy, a, b)


# --------------------------------------------------------------------------------------------------
# QuaterNet velocity block

def qmul_velocity_forward(delta, q_in, eps: float = 1e-12):
    """QuaterNet's velocity mode: ``y = normalize(Δq ⊗ q_in)``, the network's delta on the LEFT.

    Parameters
    ----------
    delta : ndarray, shape (..., 4)
        Raw (un-normalised) network output per joint, ``Δq``.
    q_in : ndarray, shape (..., 4)
        The input quaternion of the same step and joint (ground truth under teacher forcing, otherwise the
        fed-back prediction).
    eps : float
        Normalisation clamp, as :func:`quat_normalize_forward`.

    Returns
    -------
    y : ndarray, shape (..., 4)
        Unit quaternions.
    cache : tuple
    """
    delta = float_array(delta, "delta", last=4)
    q_in = float_array(q_in, "q_in", last=4)
    if delta.shape != q_in.shape:
        raise ValueError(f"q_in: expected shape {delta.shape} (the shape of delta), got {q_in.shape}")
    eps = real_number(eps, "eps", 0.0, low_open=True)
    p = quat_mul_kernel(delta, q_in)  # (..., 4)
    y, n = normalize(p, eps)
    return y, (delta, q_in, y, n, eps)


def qmul_velocity_backward(dy, cache):
    """Gradients of :func:`qmul_velocity_forward` into both inputs.

    Returns
    -------
    ddelta : ndarray, shape (..., 4)
    dq_in : ndarray, shape (..., 4)
    """
    delta, q_in, y, n, eps = cache
    dy = gradient_array(dy, y.shape)
    dp = normalize_backward(dy, y, n, eps)
    return quat_mul_backward_kernel(dp, delta, q_in)


# --------------------------------------------------------------------------------------------------
# dual-quaternion normalisation (Eq. 13)

def dq_normalize_forward(dq, eps: float = 1e-12):
    """Normalise dual quaternions (Andreou et al. Eq. 13).

    With ``n = max(|q_r|, eps)`` and ``r̂ = q_r / n``::

        q̂_r = q_r / n
        q̂_d = q_d / n - r̂ <q_r, q_d> / n²  =  (q_d - r̂ <r̂, q_d>) / n

    i.e. the dual part loses its component along the real part and is divided by the real norm, so that
    ``|q̂_r| = 1`` and ``<q̂_r, q̂_d> = 0`` (the unit conditions, Eq. 3) whenever ``|q_r| >= eps``.

    Parameters
    ----------
    dq : ndarray, shape (..., 8)
        Dual quaternions ``(q_r | q_d)``, each part ``(w, x, y, z)``.
    eps : float
        Lower bound of the real-part norm (the paper has none; the reference code divides by ``|q_r|``).

    Returns
    -------
    y : ndarray, shape (..., 8)
    cache : tuple
    """
    dq = float_array(dq, "dq", last=8)
    eps = real_number(eps, "eps", 0.0, low_open=True)
    r, d = dq[..., :4], dq[..., 4:]
    n = _norm_last(r)  # (..., 1)
    nc = np.maximum(n, eps)
    rh = r / nc  # (..., 4)
    a = np.sum(rh * d, axis=-1, keepdims=True)  # <r̂, q_d>
    dh = (d - rh * a) / nc
    y = np.concatenate([rh, dh], axis=-1)
    return y, (d, rh, dh, a, n, eps)


def dq_normalize_backward(dy, cache):
    """Gradient of :func:`dq_normalize_forward`.

    With ``g_r``, ``g_d`` the halves of ``dy`` and ``P = I - r̂ r̂ᵀ``::

        dq_d = P g_d / n
        g_r̂  = g_r - (a g_d + q_d <r̂, g_d>) / n           (a = <r̂, q_d>)
        g_n  = -<g_d, q̂_d> / n
        dq_r = (g_r̂ - r̂ <r̂, g_r̂>) / n + g_n r̂             where |q_r| >= eps
        dq_r = g_r̂ / eps                                     where the clamp is active (n = eps constant)

    Returns
    -------
    ddq : ndarray, shape (..., 8)
    """
    d, rh, dh, a, n, eps = cache
    dy = gradient_array(dy, rh.shape[:-1] + (8,))
    gr, gd = dy[..., :4], dy[..., 4:]
    big = n >= eps
    nc = np.maximum(n, eps)
    rgd = np.sum(rh * gd, axis=-1, keepdims=True)
    dd = (gd - rh * rgd) / nc
    g_rh = gr - (a * gd + d * rgd) / nc
    g_n = -np.sum(gd * dh, axis=-1, keepdims=True) / nc
    radial = np.sum(rh * g_rh, axis=-1, keepdims=True)
    dr = (g_rh - rh * np.where(big, radial, 0)) / nc + rh * np.where(big, g_n, 0)  # n = eps const under the clamp
    return np.concatenate([dr, dd], axis=-1)


# --------------------------------------------------------------------------------------------------
# dual-quaternion velocity block (QuaterNet with dual quaternions, spec/quaternet.md §9)

def _dq_mul_parts(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Dual-quaternion product ``a ⊗ b = (a_r ⊗ b_r | a_r ⊗ b_d + a_d ⊗ b_r)`` on ``(..., 8)`` arrays."""
    r = quat_mul_kernel(a[..., :4], b[..., :4])
    d = quat_mul_kernel(a[..., :4], b[..., 4:]) + quat_mul_kernel(a[..., 4:], b[..., :4])
    return np.concatenate([r, d], axis=-1)


def dq_velocity_forward(delta, d_in, eps: float = 1e-12):
    """Velocity mode for dual quaternions: ``y = N(ΔD ⊗ D_in)``, the network's delta on the LEFT.

    ``⊗`` is the dual-quaternion product ``(a_r ⊗ b_r | a_r ⊗ b_d + a_d ⊗ b_r)`` and ``N`` the Eq. 13
    normalisation (:func:`dq_normalize_forward`). With ``D_in`` a joint's current (root-relative) transform, ``ΔD``
    is a rigid motion applied in the root frame; ``ΔD`` = identity keeps the joint where it was. The paper does not
    say how QuaterNet's velocity mode was adapted to dual quaternions (reference notes §1.5); this is the direct
    analogue of :func:`qmul_velocity_forward` (spec/quaternet.md §9).

    Parameters
    ----------
    delta : ndarray, shape (..., 8)
        Raw network output per joint ``(Δ_r | Δ_d)``.
    d_in : ndarray, shape (..., 8)
        The input dual quaternion of the same step and joint.
    eps : float
        Clamp of the real-part norm in Eq. 13.

    Returns
    -------
    y : ndarray, shape (..., 8)
        Unit dual quaternions.
    cache : tuple
    """
    delta = float_array(delta, "delta", last=8)
    d_in = float_array(d_in, "d_in", last=8)
    if delta.shape != d_in.shape:
        raise ValueError(f"d_in: expected shape {delta.shape} (the shape of delta), got {d_in.shape}")
    y, nc = dq_normalize_forward(_dq_mul_parts(delta, d_in), eps)
    return y, (delta, d_in, nc)


def dq_velocity_backward(dy, cache):
    """Gradients of :func:`dq_velocity_forward` into both inputs.

    With ``p = ΔD ⊗ D_in`` and ``g = ∂L/∂p`` (from :func:`dq_normalize_backward`), by the bilinearity of the three
    Hamilton products: ``dΔ_r = g_r ⊗ D_r* + g_d ⊗ D_d*``, ``dΔ_d = g_d ⊗ D_r*``, ``dD_r = Δ_r* ⊗ g_r + Δ_d* ⊗ g_d``,
    ``dD_d = Δ_r* ⊗ g_d``.

    Returns
    -------
    ddelta : ndarray, shape (..., 8)
    dd_in : ndarray, shape (..., 8)
    """
    delta, d_in, nc = cache
    g = dq_normalize_backward(dy, nc)
    gr, gd = g[..., :4], g[..., 4:]
    ar, ad, br, bd = delta[..., :4], delta[..., 4:], d_in[..., :4], d_in[..., 4:]
    da_r1, db_r1 = quat_mul_backward_kernel(gr, ar, br)  # r = a_r ⊗ b_r
    da_r2, db_d = quat_mul_backward_kernel(gd, ar, bd)  # d ∋ a_r ⊗ b_d
    da_d, db_r2 = quat_mul_backward_kernel(gd, ad, br)  # d ∋ a_d ⊗ b_r
    return (np.concatenate([da_r1 + da_r2, da_d], axis=-1),
            np.concatenate([db_r1 + db_r2, db_d], axis=-1))


# --------------------------------------------------------------------------------------------------
# quaternion -> Euler angles (QuaterNet qeuler)

# For each order and each output angle (x, y, z): ("atan2", num, den) or ("asin", num), where
# num = (s1, i1, j1, s2, i2, j2) means 2 (s1 q_i1 q_j1 + s2 q_i2 q_j2) and den = (k1, k2) means
# 1 - 2 (q_k1² + q_k2²). Quaternion components q0..q3 = w, x, y, z.
_EULER_TABLE = {
    "xyz": (("atan2", (1, 0, 1, -1, 2, 3), (1, 2)), ("asin", (1, 1, 3, 1, 0, 2)),
            ("atan2", (1, 0, 3, -1, 1, 2), (2, 3))),
    "yzx": (("atan2", (1, 0, 1, -1, 2, 3), (1, 3)), ("atan2", (1, 0, 2, -1, 1, 3), (2, 3)),
            ("asin", (1, 1, 2, 1, 0, 3))),
    "zxy": (("asin", (1, 0, 1, 1, 2, 3)), ("atan2", (1, 0, 2, -1, 1, 3), (1, 2)),
            ("atan2", (1, 0, 3, -1, 1, 2), (1, 3))),
    "xzy": (("atan2", (1, 0, 1, 1, 2, 3), (1, 3)), ("atan2", (1, 0, 2, 1, 1, 3), (2, 3)),
            ("asin", (1, 0, 3, -1, 1, 2))),
    "yxz": (("asin", (1, 0, 1, -1, 2, 3)), ("atan2", (1, 1, 3, 1, 0, 2), (1, 2)),
            ("atan2", (1, 1, 2, 1, 0, 3), (1, 3))),
    "zyx": (("atan2", (1, 0, 1, 1, 2, 3), (1, 2)), ("asin", (1, 0, 2, -1, 1, 3)),
            ("atan2", (1, 0, 3, 1, 1, 2), (2, 3))),
}


def _euler_num(q, num):
    s1, i1, j1, s2, i2, j2 = num
    return 2.0 * (s1 * q[..., i1] * q[..., j1] + s2 * q[..., i2] * q[..., j2])


def _euler_den(q, den):
    k1, k2 = den
    return 1.0 - 2.0 * (q[..., k1] ** 2 + q[..., k2] ** 2)


def _euler_from_quat(q: np.ndarray, order: str, eps: float) -> np.ndarray:
    out = np.empty(q.shape[:-1] + (3,), dtype=q.dtype)
    for axis, entry in enumerate(_EULER_TABLE[order]):
        if entry[0] == "atan2":
            out[..., axis] = np.arctan2(_euler_num(q, entry[1]), _euler_den(q, entry[2]))
        else:
            out[..., axis] = np.arcsin(np.clip(_euler_num(q, entry[1]), -1.0 + eps, 1.0 - eps))
    return out


def euler_from_quat_forward(q, order: str = "zyx", eps: float = 0.0):
    """Euler angles ``(x, y, z)`` from quaternions, exactly as QuaterNet's ``qeuler(q, order, epsilon)``.

    The order string gives the multiplication order from left to right (``'zyx'``: ``q = q_z ⊗ q_y ⊗ q_x``,
    ``R = Rz Ry Rx``). Two angles come from ``atan2``, one from ``asin`` of an argument clipped to
    ``[-1 + eps, 1 - eps]``; e.g. for ``'zyx'``::

        x = atan2(2 (q0 q1 + q2 q3), 1 - 2 (q1² + q2²))
        y = asin(clip(2 (q0 q2 - q1 q3), -1 + eps, 1 - eps))
        z = atan2(2 (q0 q3 + q1 q2), 1 - 2 (q2² + q3²))

    The formulas assume unit quaternions and are invariant to ``q → -q``. QuaterNet uses ``eps = 1e-6`` in its
    short-term training loss and ``eps = 0`` elsewhere.

    Parameters
    ----------
    q : ndarray, shape (..., 4)
        Unit quaternions ``(w, x, y, z)``.
    order : str
        One of :data:`EULER_ORDERS`.
    eps : float
        Clip margin of the ``asin`` argument, ``0 <= eps < 1``.

    Returns
    -------
    angles : ndarray, shape (..., 3)
        Radians, always ordered ``(x, y, z)`` whatever the order.
    cache : tuple
    """
    q = float_array(q, "q", last=4)
    if order not in _EULER_TABLE:
        raise ValueError(f"order: expected one of {EULER_ORDERS}, got {order!r}")
    eps = float(eps)
    if not (0.0 <= eps < 1.0):
        raise ValueError(f"eps: expected 0 <= eps < 1, got {eps!r}")
    return _euler_from_quat(q, order, eps), (q, order, eps)


def euler_from_quat_backward(dangles, cache):
    """Gradient of :func:`euler_from_quat_forward` with respect to the quaternions.

    ``d atan2(a, b) = (b da - a db) / (a² + b²)`` (0 where ``a² + b² = 0``, the gimbal-lock points);
    ``d asin(c) = dc / sqrt(1 - c²)`` passed through the clip where ``-1 + eps <= arg <= 1 - eps`` (as PyTorch's
    ``clamp``) and 0 where ``1 - c² = 0`` (only possible with ``eps = 0``), so the gradient is always finite.

    Returns
    -------
    dq : ndarray, shape (..., 4)
    """
    q, order, eps = cache
    g = gradient_array(dangles, q.shape[:-1] + (3,), "dangles")
    dq = np.zeros(q.shape, dtype=np.result_type(q, g))
    for axis, entry in enumerate(_EULER_TABLE[order]):
        ga = g[..., axis]
        s1, i1, j1, s2, i2, j2 = entry[1]
        a = _euler_num(q, entry[1])
        if entry[0] == "atan2":
            b = _euler_den(q, entry[2])
            r2 = a * a + b * b
            ok = r2 > 0
            inv = np.where(ok, 1.0 / np.where(ok, r2, 1.0), 0.0)
            ga_num = ga * b * inv  # dL/da
            ga_den = -ga * a * inv  # dL/db
            k1, k2 = entry[2]
            dq[..., k1] += -4.0 * q[..., k1] * ga_den
            dq[..., k2] += -4.0 * q[..., k2] * ga_den
        else:
            c = np.clip(a, -1.0 + eps, 1.0 - eps)
            inside = (a >= -1.0 + eps) & (a <= 1.0 - eps)
            s = 1.0 - c * c
            ok = inside & (s > 0)
            ga_num = np.where(ok, ga / np.sqrt(np.where(ok, s, 1.0)), 0.0)
        dq[..., i1] += 2.0 * s1 * q[..., j1] * ga_num
        dq[..., j1] += 2.0 * s1 * q[..., i1] * ga_num
        dq[..., i2] += 2.0 * s2 * q[..., j2] * ga_num
        dq[..., j2] += 2.0 * s2 * q[..., i2] * ga_num
    return dq



# --------------------------------------------------------------------------------------------------
# Euler angles and axis-angle vectors to quaternions (the long-term QuaterNet's ablation outputs, QN §4.4.2)

_AXIS = {"x": 0, "y": 1, "z": 2}


def euler_to_quat_forward(angles, order: str):
    """``q = q_{o0}(a0) ⊗ q_{o1}(a1) ⊗ q_{o2}(a2)`` (:func:`refimpl.rotations.quat_from_euler`), with a cache.

    angles : (..., 3) radians, ``angles[..., i]`` about axis ``order[i]``; order : one of :data:`EULER_ORDERS`.
    Returns q (..., 4) and the cache for :func:`euler_to_quat_backward`."""
    if order not in EULER_ORDERS:
        raise ValueError(f"order: expected one of {EULER_ORDERS}, got {order!r}")
    angles = float_array(angles, "angles", last=3)
    e = [quat_elementary_kernel(_AXIS[order[i]], angles[..., i]) for i in range(3)]
    ab, c1 = quat_mul_forward(e[0], e[1])
    q, c2 = quat_mul_forward(ab, e[2])
    return q, (angles, order, c1, c2)


def euler_to_quat_backward(dq, cache) -> np.ndarray:
    """Gradient of :func:`euler_to_quat_forward` w.r.t. the angles (..., 3): ``dq/da_i`` of the elementary
    quaternion is ``½ (−sin a/2, cos a/2 e_axis)``."""
    angles, order, c1, c2 = cache
    dq = gradient_array(dq, angles.shape[:-1] + (4,), "dq")
    dab, de2 = quat_mul_backward(dq, c2)
    de0, de1 = quat_mul_backward(dab, c1)
    out = np.empty_like(angles)
    for i, de in enumerate((de0, de1, de2)):
        a = angles[..., i]
        out[..., i] = 0.5 * (-np.sin(a / 2) * de[..., 0] + np.cos(a / 2) * de[..., 1 + _AXIS[order[i]]])
    return out


_SMALL_ANGLE = 1e-4


def axis_angle_to_quat_forward(v):
    """``q = (cos θ/2, sin(θ/2)/θ · v)``, θ = ‖v‖ (:func:`refimpl.rotations.quat_from_axis_angle`); below θ = 1e-4
    the series ``sin(θ/2)/θ ≈ ½ − θ²/48``. v : (..., 3); returns q (..., 4) and the cache."""
    v = float_array(v, "v", last=3)
    th = np.linalg.norm(v, axis=-1)
    small = th < _SMALL_ANGLE
    ts = np.where(small, 1.0, th)
    s = np.where(small, 0.5 - th * th / 48.0, np.sin(ts / 2) / ts)
    q = np.concatenate([np.cos(th / 2)[..., None], s[..., None] * v], axis=-1)
    return q, (v, th, ts, small, s)


def axis_angle_to_quat_backward(dq, cache) -> np.ndarray:
    """Gradient of :func:`axis_angle_to_quat_forward`: ``dw/dv = −½ sin(θ/2) v/θ`` (→ −v/4 at 0),
    ``d(s v)/dv = s I + v (s'(θ)/θ) vᵀ`` with ``s'(θ)/θ = (½ θ cos θ/2 − sin θ/2)/θ³`` (→ −1/24 at 0)."""
    v, th, ts, small, s = cache
    dq = gradient_array(dq, v.shape[:-1] + (4,), "dq")
    hw = np.where(small, 0.25 - th * th / 96.0, np.sin(ts / 2) / (2 * ts))       # ½ sin(θ/2)/θ
    ds = np.where(small, -1.0 / 24.0, (0.5 * ts * np.cos(ts / 2) - np.sin(ts / 2)) / ts ** 3)
    dxyz = dq[..., 1:]
    return (-hw * dq[..., 0])[..., None] * v + s[..., None] * dxyz + (ds * np.sum(dxyz * v, -1))[..., None] * v


# Kernel tier (spec/architecture.md; unchecked, not in __all__, imported by other modules under these names):
# normalize, normalize_backward, quat_mul_backward_kernel, unbroadcast.
