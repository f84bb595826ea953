"""Dual quaternions for rigid transforms (layer 1: math), after Andreou et al., "Pose Representations for Deep
Skeletal Animation" (the dual-quaternion paper, Eq. 1-8 and 13) and Kavan et al. 2008 (blending, ScLERP).

Conventions (spec/conventions.md, binding):

* A dual quaternion (DQ) ``q = q_r + ε q_d`` is stored as the 8-vector ``(q_r | q_d)`` =
  ``(rw, rx, ry, rz, dw, dx, dy, dz)`` in the last axis; quaternions are ``(w, x, y, z)``, Hamilton product.
* The DQ of the rigid transform ``p ↦ R(q_r) p + t`` (rotate, then translate) is
  ``q_d = ½ (0, t) ⊗ q_r`` (paper Eq. 6, with its typo corrected: the pure translation quaternion is on the
  LEFT) and ``t = vec(2 q_d ⊗ q_r*)`` (Eq. 8).
* The product ``a ⊗ b`` composes transforms like matrices: ``T(a ⊗ b) = T(a) ∘ T(b)`` (apply ``b`` first).
* Arrays broadcast over leading axes; float64 is the reference dtype and float32 inputs stay float32.
  Public functions validate shapes and finiteness and raise ``ValueError``; private helpers do not.

Shape legend: ``...`` leading (batch) axes, T time (axis 0 for :func:`dq_fix`), K blended transforms.

Each function names the section of spec/math.md that states it.
"""
from __future__ import annotations

import numpy as np

from refimpl.arrays import float_array, real_number
from refimpl.quat import (atan_ratio, hemisphere_sign, prescaled, quat_conj_kernel, quat_mul_kernel,
                          quat_norm_kernel, quat_rotate_kernel, sin_over_x, finite_output, zeros_of)
from refimpl.rotations import check_rotation_matrix, matrix_from_quat_kernel, quat_from_matrix_kernel

__all__ = [
    "dq_identity", "dq_mul", "dq_conj", "dq_conj_dual", "dq_conj_combined", "dq_inv", "dq_norm", "dq_is_unit",
    "dq_normalize", "dq_from_quat_translation", "quat_translation_from_dq", "translation_from_dq",
    "dq_from_matrix", "matrix_from_dq", "dq_transform_point", "dq_fix", "dq_sclerp", "dq_blend",
]


def _split(a: np.ndarray):
    return a[..., :4], a[..., 4:]


def _join(r: np.ndarray, d: np.ndarray) -> np.ndarray:
    return np.concatenate([r, d], axis=-1)


def _dq_prescaled(a: np.ndarray, name: str, what: str = "real part") -> np.ndarray:
    """``a`` times the power of two that :func:`refimpl.quat.prescaled` applies to its real part (where
    needed), for the functions invariant to a common scale of both parts (``a`` and ``c·a``, ``c > 0``, are the
    same rigid transform); ValueError naming ``name`` if some real part is zero."""
    _, e = prescaled(a[..., :4], name, what)
    return a if e is None else np.ldexp(a, -e[..., None])


def dq_identity(shape=(), dtype=np.float64) -> np.ndarray:
    """Identity DQs ``(1, 0, 0, 0 | 0, 0, 0, 0)`` of shape ``shape + (8,)`` (spec/math.md §5.1)."""
    a = zeros_of(shape, dtype, 8)
    a[..., 0] = 1
    return a


def dq_mul_kernel(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ar, ad = _split(a)
    br, bd = _split(b)
    return _join(quat_mul_kernel(ar, br), quat_mul_kernel(ar, bd) + quat_mul_kernel(ad, br))


@finite_output
def dq_mul(a, b) -> np.ndarray:
    """DQ product ``a ⊗ b = a_r b_r + ε (a_r b_d + a_d b_r)`` (paper Eq. 1; spec/math.md §5.2).

    Parameters
    ----------
    a, b : array_like, (..., 8)
        Leading axes broadcast.

    Returns
    -------
    ndarray, (..., 8)
    """
    a = float_array(a, "a", (..., 8))
    b = float_array(b, "b", (..., 8))
    return dq_mul_kernel(a, b)


_SIGN_CONJ = (1, -1, -1, -1, 1, -1, -1, -1)
_SIGN_DUAL = (1, 1, 1, 1, -1, -1, -1, -1)
_SIGN_COMBINED = (1, -1, -1, -1, -1, 1, 1, 1)


def dq_conj_kernel(a: np.ndarray) -> np.ndarray:
    return a * np.array(_SIGN_CONJ, dtype=a.dtype)


@finite_output
def dq_conj(a) -> np.ndarray:
    """Quaternion conjugate of both parts ``(q_r*, q_d*)`` = inverse of a UNIT DQ (spec/math.md §5.3).

    This is the paper's "conjugate" (§3.1) and acRNN/PoseRepresentation's ``dqinv``.
    """
    a = float_array(a, "a", (..., 8))
    return dq_conj_kernel(a)


@finite_output
def dq_conj_dual(a) -> np.ndarray:
    """Dual-number conjugate ``(q_r, −q_d)`` (spec/math.md §5.3)."""
    a = float_array(a, "a", (..., 8))
    return a * np.array(_SIGN_DUAL, dtype=a.dtype)


@finite_output
def dq_conj_combined(a) -> np.ndarray:
    """Combined conjugate ``(q_r*, −q_d*)`` (used in point transforms ``σ (1 + ε p) σ†``) (spec/math.md §5.3).

    This is acRNN/PoseRepresentation's ``dqconj``.
    """
    a = float_array(a, "a", (..., 8))
    return a * np.array(_SIGN_COMBINED, dtype=a.dtype)


@finite_output
def dq_inv(a) -> np.ndarray:
    """General inverse ``(q_r⁻¹, −q_r⁻¹ q_d q_r⁻¹)`` of a DQ with non-zero real part (spec/math.md §5.3).

    ``dq_mul(a, dq_inv(a)) = dq_mul(dq_inv(a), a) = identity``; equals :func:`dq_conj` for unit DQs.

    Raises
    ------
    ValueError
        If some real part is zero.
    """
    a = float_array(a, "a", (..., 8))
    r, d = _split(a)
    rs, e = prescaled(r, "a", "real part")  # r = 2^e rs where needed: no under/overflow of |r|²
    rs_inv = quat_conj_kernel(rs) / np.sum(rs * rs, axis=-1, keepdims=True)
    real, dual = rs_inv, -quat_mul_kernel(quat_mul_kernel(rs_inv, d), rs_inv)
    if e is not None:  # r⁻¹ = 2^-e rs⁻¹ and r⁻¹ d r⁻¹ = 2^-2e rs⁻¹ d rs⁻¹
        real, dual = np.ldexp(real, -e[..., None]), np.ldexp(dual, -2 * e[..., None])
    return _join(real, dual)


@finite_output
def dq_norm(a):
    """Dual-number magnitude ``|q| = |q_r| + ε ⟨q_r, q_d⟩/|q_r|`` (paper Eq. 2; spec/math.md §5.4).

    Returns
    -------
    (real, dual) : tuple of ndarray, each (...)

    Raises
    ------
    ValueError
        If some real part is zero (the dual part is undefined).
    """
    a = float_array(a, "a", (..., 8))
    r, d = _split(a)
    rs, e = prescaled(r, "a", "real part")  # r = 2^e rs where needed, exact
    ns = quat_norm_kernel(rs)
    return (ns if e is None else np.ldexp(ns, e)), np.sum(rs * d, axis=-1) / ns


@finite_output
def dq_is_unit(a, atol_norm: float | None = None, atol_dot: float | None = None) -> np.ndarray:
    """Unit test (paper Eq. 3): ``| |q_r| − 1 | <= atol_norm`` and ``|⟨q_r, q_d⟩| <= atol_dot`` (spec/math.md §5.4).

    ``q_r* q_d + q_d* q_r = (2⟨q_r, q_d⟩, 0, 0, 0)``, so Eq. 3 is the dot-product condition. Both comparisons use
    absolute values (unlike acRNN's ``is_unit``, which compares signed differences).

    Parameters
    ----------
    a : array_like, (..., 8)
    atol_norm, atol_dot : float, optional
        Default ``1e-6`` for float64 and ``1e-4`` for lower precision.

    Returns
    -------
    ndarray of bool, (...)
    """
    a = float_array(a, "a", (..., 8))
    default = 1e-6 if a.dtype.itemsize >= 8 else 1e-4
    atol_norm = default if atol_norm is None else real_number(atol_norm, "atol_norm", 0.0)
    atol_dot = default if atol_dot is None else real_number(atol_dot, "atol_dot", 0.0)
    r, d = _split(a)
    return (np.abs(quat_norm_kernel(r) - 1) <= atol_norm) & (np.abs(np.sum(r * d, axis=-1)) <= atol_dot)


def _dq_normalize(a: np.ndarray) -> np.ndarray:
    r, d = _split(a)
    n = quat_norm_kernel(r)[..., None]  # (..., 1)
    rh = r / n
    return _join(rh, d / n - rh * (np.sum(r * d, axis=-1, keepdims=True) / (n * n)))


@finite_output
def dq_normalize(a) -> np.ndarray:
    """Unit DQ ``q / |q|`` (paper Eq. 13; spec/math.md §5.5).

    ``q̂_r = q_r/|q_r|``, ``q̂_d = q_d/|q_r| − q̂_r ⟨q_r, q_d⟩/|q_r|²``. Afterwards ``|q̂_r| = 1`` and
    ``⟨q̂_r, q̂_d⟩ = 0`` (exactly in exact arithmetic, to rounding in floating point), i.e. Eq. 3 holds. The
    translation ``vec(2 q_d q_r*)/|q_r|²`` is unchanged. Idempotent on unit DQs.

    Raises
    ------
    ValueError
        If some real part is exactly zero (no rigid transform; no identity is substituted).
    """
    a = float_array(a, "a", (..., 8))
    return _dq_normalize(_dq_prescaled(a, "a"))


def _pure(t: np.ndarray) -> np.ndarray:
    return np.concatenate([np.zeros_like(t[..., :1]), t], axis=-1)


def dq_from_quat_translation_kernel(q: np.ndarray, t: np.ndarray) -> np.ndarray:
    return _join(q, 0.5 * quat_mul_kernel(_pure(t), q))


@finite_output
def dq_from_quat_translation(q, t) -> np.ndarray:
    """DQ of ``p ↦ R(q) p + t``: ``(q | ½ (0, t) ⊗ q)`` (paper Eq. 6, typo corrected; spec/math.md §5.6).

    Parameters
    ----------
    q : array_like, (..., 4)
        Rotation quaternion, used as given (pass a unit quaternion to get a unit DQ).
    t : array_like, (..., 3)
        Translation; leading axes broadcast with ``q``.

    Returns
    -------
    ndarray, (..., 8)
    """
    q = float_array(q, "q", (..., 4))
    t = float_array(t, "t", (..., 3))
    lead = np.broadcast_shapes(q.shape[:-1], t.shape[:-1])
    q = np.broadcast_to(q, lead + (4,))
    t = np.broadcast_to(t, lead + (3,))
    return dq_from_quat_translation_kernel(q, t)


def _translation_from_dq(a: np.ndarray) -> np.ndarray:
    r, d = _split(a)
    return 2 * quat_mul_kernel(d, quat_conj_kernel(r))[..., 1:] / np.sum(r * r, axis=-1, keepdims=True)


@finite_output
def translation_from_dq(a) -> np.ndarray:
    """Translation ``t = vec(2 q_d ⊗ q_r*) / |q_r|²`` (paper Eq. 8; spec/math.md §5.7).

    For unit DQs this is Eq. 8; the division by ``|q_r|²`` makes it exact for any DQ that is a scaled unit DQ and
    equal to Eq. 8 applied after Eq. 13 normalisation for any DQ.

    Returns
    -------
    ndarray, (..., 3)

    Raises
    ------
    ValueError
        If some real part is zero.
    """
    a = float_array(a, "a", (..., 8))
    return _translation_from_dq(_dq_prescaled(a, "a"))


@finite_output
def quat_translation_from_dq(a):
    """Rotation and translation of a DQ: ``(q_r/|q_r|, translation_from_dq(a))`` (spec/math.md §5.7).

    Returns
    -------
    q : ndarray, (..., 4)
        Unit rotation quaternion (sign as stored).
    t : ndarray, (..., 3)
    """
    a = _dq_prescaled(float_array(a, "a", (..., 8)), "a")
    return a[..., :4] / quat_norm_kernel(a[..., :4])[..., None], _translation_from_dq(a)


@finite_output
def dq_from_matrix(m) -> np.ndarray:
    """Unit DQ of homogeneous rigid transforms ``[[R, t], [0, 1]]``, ``(..., 4, 4) → (..., 8)`` (spec/math.md §5.8).

    ``q_r = quat_from_matrix(R)`` (so ``w >= 0``), ``q_d = ½ (0, t) ⊗ q_r``.

    Raises
    ------
    ValueError
        If ``m`` is not ``(..., 4, 4)``, its rotation block is not a rotation (see ``quat_from_matrix``) or its
        last row is not ``(0, 0, 0, 1)`` (tolerance 1e-6 for float64, 1e-3 for float32).
    """
    m = float_array(m, "m", (..., 4, 4))
    tol = 1e-6 if m.dtype.itemsize >= 8 else 1e-3
    if np.any(np.abs(m[..., 3, :] - np.array([0, 0, 0, 1], dtype=m.dtype)) > tol):
        raise ValueError(f"m: last row of a homogeneous transform must be (0, 0, 0, 1); got shape {m.shape} "
                         f"with max deviation {float(np.max(np.abs(m[..., 3, :] - np.array([0, 0, 0, 1])))):.3g}")
    rot = m[..., :3, :3]
    check_rotation_matrix(rot, "m[..., :3, :3]")
    return dq_from_quat_translation_kernel(quat_from_matrix_kernel(rot), m[..., :3, 3])


@finite_output
def matrix_from_dq(a) -> np.ndarray:
    """Homogeneous matrix ``[[R(q_r), t], [0, 1]]`` of a DQ with non-zero real part, ``(..., 4, 4)`` (spec/math.md §5.8).

    ``R`` is the rotation of ``q_r/|q_r|`` and ``t = translation_from_dq(a)``.
    """
    a = _dq_prescaled(float_array(a, "a", (..., 8)), "a")
    out = np.zeros(a.shape[:-1] + (4, 4), dtype=a.dtype)
    out[..., :3, :3] = matrix_from_quat_kernel(a[..., :4])
    out[..., :3, 3] = _translation_from_dq(a)
    out[..., 3, 3] = 1
    return out


def _dq_transform_point_naive(a: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Point transform as the sandwich ``σ ⊗ (1 + ε (0, p)) ⊗ σ†`` with the combined conjugate (unit ``σ``)."""
    pdq = _join(np.broadcast_to(np.array([1, 0, 0, 0], dtype=p.dtype), p.shape[:-1] + (4,)), _pure(p))
    out = dq_mul_kernel(dq_mul_kernel(a, pdq), a * np.array(_SIGN_COMBINED, dtype=a.dtype))
    return out[..., 5:]


@finite_output
def dq_transform_point(a, p) -> np.ndarray:
    """Apply a unit DQ to points: ``R(q_r) p + t`` with ``t = vec(2 q_d q_r*)`` (spec/math.md §5.9).

    Equals the dual-vector part of ``σ ⊗ (1 + ε (0, p)) ⊗ σ†`` (``σ†`` the combined conjugate) for unit ``σ``.

    Parameters
    ----------
    a : array_like, (..., 8)
        Unit DQs (``q_r`` is used as given in the rotation; normalise first with :func:`dq_normalize`).
    p : array_like, (..., 3)
        Points; leading axes broadcast with ``a``.

    Returns
    -------
    ndarray, (..., 3)
    """
    a = float_array(a, "a", (..., 8))
    p = float_array(p, "p", (..., 3))
    lead = np.broadcast_shapes(a.shape[:-1], p.shape[:-1])
    a = np.broadcast_to(a, lead + (8,))
    p = np.broadcast_to(p, lead + (3,))
    r, d = _split(a)
    return quat_rotate_kernel(r, p) + 2 * quat_mul_kernel(d, quat_conj_kernel(r))[..., 1:]


def _dq_fix(a: np.ndarray) -> np.ndarray:
    dots = np.sum(a[1:, ..., :4] * a[:-1, ..., :4], axis=-1)  # (T-1, ...)
    flips = np.cumsum(dots < 0, axis=0) % 2
    out = a.copy()
    out[1:][flips.astype(bool)] *= -1
    return out


def _dq_fix_naive(a: np.ndarray) -> np.ndarray:
    """Slow version of :func:`dq_fix` for ``(T, 8)``."""
    out = a.copy()
    flip = False
    for t in range(1, a.shape[0]):
        flip ^= bool(np.dot(a[t, :4], a[t - 1, :4]) < 0)
        if flip:
            out[t] = -a[t]
    return out


@finite_output
def dq_fix(a) -> np.ndarray:
    """Antipodal continuity over time, axis 0 (paper §5.1; spec/math.md §5.10).

    Frame ``t`` is negated (all 8 numbers) when the running parity of ``⟨r_s, r_{s−1}⟩ < 0`` (real parts, input
    frames, ``s <= t``) is odd, so every consecutive real-part dot product is ``>= 0``. Each DQ keeps its
    transform (``q`` and ``−q`` are the same rigid transform). Returns a copy.

    Parameters
    ----------
    a : array_like, (T, ..., 8)
    """
    a = float_array(a, "a", (..., 8))
    if a.ndim < 2:
        raise ValueError(f"a: expected shape (T, ..., 8) with a time axis, got {a.shape}")
    return _dq_fix(a)


def _dq_log(a: np.ndarray):
    """Logarithm of unit DQs with ``w(q_r) >= 0``: the dual 3-vector ``(u, v)`` with ``exp(u + ε v) = a``.

    ``u = (θ/2) l`` (rotation axis ``l``, angle θ); ``v`` solves ``D exp(u)[v] = q_d``.
    """
    r, d = _split(a)
    u3 = r[..., 1:]
    s = np.sqrt(np.sum(u3 * u3, axis=-1))  # sin φ
    phi = np.arctan2(s, r[..., 0])  # (...) in [0, π/2]
    u = atan_ratio(s, r[..., 0])[..., None] * u3  # (φ / sin φ) u3, series near φ = 0
    sinc = sin_over_x(phi)[..., None]
    c = _dsinc_over_x(phi)[..., None]
    uv = -d[..., :1] / sinc  # ⟨u, v⟩
    v = (d[..., 1:] - u * c * uv) / sinc
    return u, v


def _dsinc_over_x(x: np.ndarray) -> np.ndarray:
    """``(d/dx)(sin x / x) / x = (x cos x − sin x)/x³``, series ``−1/3 + x²/30 − x⁴/840 + x⁶/45360`` for ``|x| < 0.05``."""
    small = np.abs(x) < 0.05
    xs = np.where(small, 1, x)
    x2 = x * x
    return np.where(small, -1 / 3 + x2 / 30 - x2 * x2 / 840 + x2 * x2 * x2 / 45360,
                    (xs * np.cos(xs) - np.sin(xs)) / xs ** 3)


def _dq_exp(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``exp(u + ε v)`` for pure dual vectors: ``(cos φ, sinc φ u | −sinc φ ⟨u,v⟩, sinc φ v + c(φ) ⟨u,v⟩ u)``."""
    phi = np.sqrt(np.sum(u * u, axis=-1))
    sinc = sin_over_x(phi)[..., None]
    c = _dsinc_over_x(phi)[..., None]
    uv = np.sum(u * v, axis=-1, keepdims=True)
    real = np.concatenate([np.cos(phi)[..., None], sinc * u], axis=-1)
    dual = np.concatenate([-sinc * uv, sinc * v + c * uv * u], axis=-1)
    return _join(real, dual)


@finite_output
def dq_sclerp(a, b, t) -> np.ndarray:
    """Screw linear interpolation ``a ⊗ (a* ⊗ b)^t`` along the shortest path (spec/math.md §5.11).

    ``b`` is negated where ``⟨a_r, b_r⟩ < 0`` (ties at 0 broken as in :func:`refimpl.quat.quat_slerp`, so the
    result never depends on the stored sign of ``b``). The power of the unit DQ ``d = a* ⊗ b`` is
    ``exp(t log d)``: the screw motion of ``d`` with angle and slide scaled by ``t`` about the same axis line.
    A pure translation interpolates linearly; equal inputs return ``a``. Stable near 0 (series) and near
    180° (the shortest-path flip keeps the relative half-angle in ``[0, π/2]``).

    Parameters
    ----------
    a, b : array_like, (..., 8)
        Unit DQs (normalise first with :func:`dq_normalize`).
    t : array_like, broadcastable to the leading shape ``(...)``

    Returns
    -------
    ndarray, (..., 8)
    """
    a = float_array(a, "a", (..., 8))
    b = float_array(b, "b", (..., 8))
    t = float_array(t, "t", (..., )).astype(np.result_type(a, b), copy=False)  # t does not change the dtype
    b = hemisphere_sign(a[..., :4], b[..., :4]) * b
    a, b = np.broadcast_arrays(a, b)
    rel = dq_mul_kernel(dq_conj_kernel(a), b)  # (..., 8)
    u, v = _dq_log(rel)
    tt = t[..., None]
    return dq_mul_kernel(a, _dq_exp(tt * u, tt * v))


def _dq_blend_naive(weights: np.ndarray, dqs: np.ndarray) -> np.ndarray:
    """Slow version of :func:`dq_blend` for ``weights (K,)`` and ``dqs (K, 8)``."""
    pivot = int(np.argmax(weights))
    acc = np.zeros(8, dtype=dqs.dtype)
    for k in range(len(weights)):
        rel = quat_mul_kernel(quat_conj_kernel(dqs[pivot, :4]), dqs[k, :4])  # w = ⟨r_p, r_k⟩
        first = next(c for c in rel if c != 0)
        acc += weights[k] * (-1 if first < 0 else 1) * dqs[k]
    return _dq_normalize(acc)


@finite_output
def dq_blend(weights, dqs) -> np.ndarray:
    """Dual quaternion linear blending (DLB, Kavan et al. 2008) (spec/math.md §5.12).

    ``b = Σ_k w_k s_k q_k`` with ``s_k = sign⟨r_k, r_p⟩`` aligning every DQ with the hemisphere of the pivot
    ``p = argmax_k w_k`` (the first one on ties), then ``b / |b|`` by Eq. 13. When ``⟨r_k, r_p⟩ = 0`` the sign
    makes ``r_p* ⊗ r_k`` canonical (as in :func:`refimpl.quat.quat_slerp`), so the result depends only on the
    sign of the pivot, which it shares.

    Parameters
    ----------
    weights : array_like, (..., K)
    dqs : array_like, (..., K, 8)
        Unit DQs; leading axes broadcast with ``weights``.

    Returns
    -------
    ndarray, (..., 8)

    Raises
    ------
    ValueError
        On shape mismatch, or when the blended real part is zero (e.g. weights summing to 0).
    """
    dqs = float_array(dqs, "dqs", (..., 8))
    weights = float_array(weights, "weights", (..., )).astype(dqs.dtype, copy=False)  # the DQs set the dtype
    if dqs.ndim < 2 or weights.ndim < 1 or weights.shape[-1] != dqs.shape[-2]:
        raise ValueError(f"weights, dqs: expected shapes (..., K) and (..., K, 8), got {weights.shape} and {dqs.shape}")
    lead = np.broadcast_shapes(weights.shape[:-1], dqs.shape[:-2])
    k = dqs.shape[-2]
    weights, _ = prescaled(weights)  # only the ratios matter: exact power-of-two rescaling where Σ could overflow
    weights = np.broadcast_to(weights, lead + (k,))
    dqs = np.broadcast_to(dqs, lead + (k, 8))
    pivot = np.argmax(weights, axis=-1)  # (...)
    pr = np.take_along_axis(dqs[..., :4], pivot[..., None, None], axis=-2)  # (..., 1, 4)
    sign = hemisphere_sign(pr, dqs[..., :4])[..., 0]  # (..., K)
    acc = np.sum((weights * sign)[..., None] * dqs, axis=-2)  # (..., 8)
    return _dq_normalize(_dq_prescaled(acc, "weights, dqs", "blended real part"))


# Kernel tier (spec/architecture.md; unchecked, not in __all__, imported by other modules under these names):
# dq_from_quat_translation_kernel, dq_conj_kernel, dq_mul_kernel.
