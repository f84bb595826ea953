"""Losses of the three systems as pure forward/backward pairs (``spec/losses.md``).

Calling convention (``spec/architecture.md``)::

    value, cache = name_loss_forward(pred, target, ...)   # value: Python float
    dpred = name_loss_backward(dvalue, cache)             # dvalue: float, usually 1.0 (a tuple for 2 inputs)

Only the prediction gets a gradient. Every loss is finite, with a finite gradient, for finite input of
sensible range: zero differences use the subgradient 0 (``sign(0) = 0``, the direction of a zero vector is 0),
means are taken after scaling by the largest entry so sums of huge entries do not overflow, norms are scaled
so denormals and values near 1e300 are handled. float32 inputs are computed in float32.

Shape legend: B batch, T time, J joints, ``...`` any leading axes; the last axis holds the object
(4 quaternion, 8 dual quaternion, 3 position).

=============================  ======================================  =====================================
loss                           source                                  function
=============================  ======================================  =====================================
L_mse                          Andreou et al. Eq. 14 (acRNN MSE)       :func:`mse_loss_forward`
MAE                            QTG (Geleijn et al.)                    :func:`mae_loss_forward`
L_quat (current)               Andreou et al. Eq. 15                   :func:`quat_loss_forward`
L_quat (local)                 Andreou et al. Eq. 15, ``qrl_local``    :func:`local_quat_loss_forward`
L_pos                          Andreou et al. §5.2 (3), Eq. 8          :func:`dq_pos_loss_forward`
L_offset                       Andreou et al. §5.2 (4), Eq. 12, 8      :func:`dq_offset_loss_forward`
L_reg                          Andreou et al. Eq. 16                   :func:`dq_reg_loss_forward`
quaternion norm penalty        QuaterNet §3.3                          :func:`quat_norm_loss_forward`
Euler-angle L1 with 2π wrap    QuaterNet §3.6 (short-term)             :func:`euler_l1_loss_forward`
FK position loss               QuaterNet §3.4 (long-term)              :func:`fk_position_loss_forward`
mean Euclidean distance        building block of the three above       :func:`euclidean_loss_forward`
=============================  ======================================  =====================================
"""
from __future__ import annotations

import math
from types import MappingProxyType

import numpy as np

from refimpl.nn.kinematics_layers import (check_parents, forward_kinematics_backward,
                                          forward_kinematics_forward, offsets_from_dq_backward, offsets_from_dq_forward,
                                          positions_from_dq_backward, positions_from_dq_forward)
from refimpl.arrays import float_array
from refimpl.nn.quat_layers import (normalize, normalize_backward, quat_mul_backward_kernel,
                                    euler_from_quat_backward, euler_from_quat_forward)
from refimpl.quat import quat_conj_kernel, quat_mul_kernel

__all__ = [
    "WEIGHTS_ACRNN_DQ", "WEIGHT_ACRNN_QUAT_FK", "WEIGHTS_QUATERNET_DQ",
    "QUATERNET_PENALTY_WEIGHT", "QUATERNET_EULER_EPS",
    "mse_loss_forward", "mse_loss_backward",
    "mae_loss_forward", "mae_loss_backward",
    "quat_loss_forward", "quat_loss_backward",
    "local_quat_loss_forward", "local_quat_loss_backward",
    "euclidean_loss_forward", "euclidean_loss_backward",
    "dq_pos_loss_forward", "dq_pos_loss_backward",
    "dq_offset_loss_forward", "dq_offset_loss_backward",
    "dq_reg_loss_forward", "dq_reg_loss_backward",
    "quat_norm_loss_forward", "quat_norm_loss_backward",
    "euler_l1_loss_forward", "euler_l1_loss_backward",
    "fk_position_loss_forward", "fk_position_loss_backward",
]

#: Andreou et al. Appendix B, acRNN experiments (the garbled sentence reconciled with the reference code
#: ``dl``, which divides the summed L_pos + L_offset mean by 3): L_pos and L_offset × 1/3, L_quat × 1,
#: L_reg × 0.01; MSE alone is unweighted (1).
WEIGHTS_ACRNN_DQ = MappingProxyType({"mse": 1.0, "quat": 1.0, "pos": 1.0 / 3.0, "offset": 1.0 / 3.0,
                                     "reg": 0.01})
#: Andreou et al. Appendix B: the FK position loss of acRNN's "quaternions-FK" baseline × 1/4.
WEIGHT_ACRNN_QUAT_FK = 0.25
#: Andreou et al. Appendix B, QuaterNet experiments: L_reg × 0.01, L_pos, L_offset and the rotational loss × 1.
WEIGHTS_QUATERNET_DQ = MappingProxyType({"quat": 1.0, "pos": 1.0, "offset": 1.0, "reg": 0.01})
#: QuaterNet's ``rot_reg``: weight of the quaternion norm penalty.
QUATERNET_PENALTY_WEIGHT = 0.01
#: QuaterNet's asin clip margin in the short-term training loss (``qeuler(..., epsilon=1e-6)``).
QUATERNET_EULER_EPS = 1e-6


# --------------------------------------------------------------------------------------------------
# helpers

def _nonempty(x: np.ndarray, name: str) -> np.ndarray:
    if x.size == 0:
        raise ValueError(f"{name}: expected at least one entry, got shape {x.shape}")
    return x


def _pair(pred, target, last=None, min_ndim: int = 0):
    """Validate a (pred, target) pair of equal shapes."""
    p = _nonempty(float_array(pred, "pred", last=last, min_ndim=min_ndim), "pred")
    t = float_array(target, "target", last=last, min_ndim=min_ndim)
    if p.shape != t.shape:
        raise ValueError(f"target: expected shape {p.shape} (the shape of pred), got {t.shape}")
    return p, t


def _check_dvalue(dvalue) -> float:
    """The upstream gradient of a scalar loss: a finite real number (Python or NumPy scalar, or a 0-d array)."""
    if isinstance(dvalue, (int, float)):  # the usual case (np.float64 is a float)
        d = float(dvalue)
    else:
        a = np.asarray(dvalue)
        if a.ndim != 0 or a.dtype.kind not in "biuf":
            raise ValueError(f"dvalue: expected a finite real scalar (the loss value's gradient), got "
                             f"{type(dvalue).__name__} of shape {a.shape} and dtype {a.dtype}")
        d = float(a)
    if not math.isfinite(d):
        raise ValueError(f"dvalue: expected a finite number, got {dvalue!r}")
    return d


def _mean_abs(a: np.ndarray) -> float:
    """``mean(|a|)`` without overflow of the sum (divided by the largest entry first); ``+inf`` if an entry is
    ``±inf`` (a term that overflowed: the true mean overflows too, or is at least that large)."""
    a = np.abs(a)
    s = a.max()
    if s == 0 or not np.isfinite(s):
        return float(s)
    return float(np.mean(a / s) * s)


def _max_abs(x: np.ndarray) -> float:
    """``max |x_i|`` over a non-empty array (two fast reductions, no temporary)."""
    return max(float(x.max()), -float(x.min()))


def _pow2_limit(dtype, root: int) -> float:
    """``2^(maxexp/root)`` of ``dtype``: below it, products of ``root`` such numbers cannot overflow."""
    return 2.0 ** (np.finfo(dtype).maxexp // root)


def _difference(p: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, float]:
    """``(d, f)`` with ``p − t = f·d``: ``d = p − t`` (``f = 1``) unless that overflows (finite inputs of
    opposite signs near the float range); then ``d = p/2 − t/2`` (exact halving) and ``f = 2``."""
    with np.errstate(over="ignore", invalid="ignore"):  # detected here (inf, or inf − inf in the sum)
        d = p - t
        if math.isfinite(d.sum()):  # one fast reduction; a sum that overflows merely takes the (exact) 2nd path
            return d, 1.0
    return 0.5 * p - 0.5 * t, 2.0


def _rows_scaled(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(u, k)`` with ``x = 2^k u`` per object (last axis): ``k >= 0`` is the binary exponent of the largest
    component where that exceeds 1 (exact power-of-two scaling into ``[0.5, 1)``) and 0 elsewhere, so
    polynomials of the raw output can be evaluated on ``u`` without overflow and rescaled once at the end.
    Used only where the direct evaluation could overflow."""
    k = np.maximum(np.frexp(np.max(np.abs(x), axis=-1))[1], 0)  # (...)
    return np.ldexp(x, -k[..., None]), k


def _norm_and_direction(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Euclidean norms over the last axis and unit directions (0 for a zero vector), overflow/underflow-safe."""
    s = np.max(np.abs(d), axis=-1, keepdims=True)
    nz = s > 0
    u = d / np.where(nz, s, 1)  # entries in [-1, 1]
    r = np.sqrt(np.sum(u * u, axis=-1, keepdims=True))  # in [1, sqrt(3)] where nz
    direction = np.where(nz, u / np.where(nz, r, 1), 0)
    return (s * r)[..., 0], direction


# --------------------------------------------------------------------------------------------------
# MSE and MAE

def mse_loss_forward(pred, target):
    """L_mse (Andreou et al. Eq. 14; acRNN's ``nn.MSELoss``): ``mean((pred - target)²)`` over all entries.

    Parameters
    ----------
    pred, target : ndarray, same shape, e.g. (B, T, F)

    Returns
    -------
    value : float
        ``+inf`` only when the true mean square exceeds the float range (e.g. differences ~1e300); a difference
        that itself overflows (``pred = 1.5e308``, ``target = −1.5e308``) gives ``+inf`` and a finite gradient.
    cache : tuple
    """
    p, t = _pair(pred, target)
    d, f = _difference(p, t)  # pred - target = f d
    s = float(np.max(np.abs(d)))
    if s == 0.0:
        return 0.0, (d, f)
    rms = f * s * float(np.sqrt(np.mean((d / s) ** 2)))  # root mean square, no overflow of the sum
    return rms * rms, (d, f)


def mse_loss_backward(dvalue, cache):
    """Gradient of :func:`mse_loss_forward`: ``dpred = 2 (pred - target) dvalue / N``."""
    d, f = cache
    scale = 2.0 * f * _check_dvalue(dvalue) / d.size
    if not math.isfinite(scale):  # |dvalue| near the float maximum: keep 0 · inf out of the result
        return (2.0 * f / d.size) * d * _check_dvalue(dvalue)
    return scale * d


def mae_loss_forward(pred, target):
    """Mean absolute error (QTG's training loss, PyTorch ``L1Loss``): ``mean(|pred - target|)``.

    Parameters
    ----------
    pred, target : ndarray, same shape, e.g. (B, T, 91)

    Returns
    -------
    value : float
    cache : tuple
    """
    p, t = _pair(pred, target)
    d, f = _difference(p, t)  # pred - target = f d
    return f * _mean_abs(d), (np.sign(d),)


def mae_loss_backward(dvalue, cache):
    """Gradient of :func:`mae_loss_forward`: ``sign(pred - target) dvalue / N`` (0 where equal)."""
    (sg,) = cache
    return sg * (_check_dvalue(dvalue) / sg.size)


# --------------------------------------------------------------------------------------------------
# rotational losses

def _embed(grad_q: np.ndarray, full_shape: tuple) -> np.ndarray:
    """Put a ``(..., 4)`` gradient into an array of ``full_shape`` (zeros in a dual part)."""
    if grad_q.shape == full_shape:
        return grad_q
    out = np.zeros(full_shape, dtype=grad_q.dtype)
    out[..., :4] = grad_q
    return out


def quat_loss_forward(pred, target):
    """L_quat on current rotations (Andreou et al. Eq. 15; reference ``qrl_curr``): ``mean |1 - <q, q̃>|``.

    The mean runs over all leading axes (B, T, J). The absolute value is a no-op for unit quaternions; there is
    no sign handling (the data is made hemisphere-continuous in preprocessing).

    Parameters
    ----------
    pred, target : ndarray, shape (..., 4) or (..., 8)
        Quaternions, or dual quaternions of which the real part (first 4 numbers) is used.

    Returns
    -------
    value : float
    cache : tuple
    """
    p, t = _pair(pred, target, (4, 8))
    pq, tq = p[..., :4], t[..., :4]
    if _max_abs(pq) * _max_abs(tq) <= _pow2_limit(pq.dtype, 2):  # the usual case: no product can overflow
        e = 1.0 - np.sum(pq * tq, axis=-1)  # (...)
    else:  # sum scaled quaternions, rescale once: ±inf where <q, q̃> overflows, never inf − inf
        (up, kp), (ut, kt) = _rows_scaled(pq), _rows_scaled(tq)
        e = 1.0 - np.ldexp(np.sum(up * ut, axis=-1), kp + kt)
    return _mean_abs(e), (np.sign(e), tq, p.shape)


def quat_loss_backward(dvalue, cache):
    """Gradient of :func:`quat_loss_forward`: ``dq = -sign(1 - <q, q̃>) q̃ dvalue / N`` (0 in a dual part)."""
    sg, tq, shape = cache
    g = (-_check_dvalue(dvalue) / sg.size) * sg[..., None] * tq
    return _embed(g, shape)


def _local_rotations(q: np.ndarray, par: np.ndarray, eps: float):
    """``normalize(q_p* ⊗ q_j)`` per joint, root: ``normalize(q_0)``; returns (local, raw product, parent conj)."""
    qp = np.empty_like(q)
    qp[..., 0, :] = 0.0
    qp[..., 0, 0] = 1.0
    qp[..., 1:, :] = quat_conj_kernel(q[..., par[1:], :])
    raw = quat_mul_kernel(qp, q)
    loc, n = normalize(raw, eps)
    return loc, n, qp


def local_quat_loss_forward(pred, target, parents, eps: float = 1e-12):
    """L_quat on local rotations (Andreou et al. Eq. 15 variant; reference ``qrl_local``).

    ``l_j = normalize(q_p* ⊗ q_j)`` (root: parent = identity) for prediction and target, then
    ``mean |1 - <l, l̃>|`` over the leading axes and joints.

    Parameters
    ----------
    pred, target : ndarray, shape (..., J, 4) or (..., J, 8)
        Current rotations (or current dual quaternions, of which the real parts are used).
    parents : sequence of int, length J
        ``parents[0] == -1``, ``0 <= parents[j] < j``.
    eps : float
        Normalisation clamp (``q / max(|q|, eps)``).

    Returns
    -------
    value : float
    cache : tuple
    """
    p, t = _pair(pred, target, (4, 8), min_ndim=2)
    par = check_parents(parents, p.shape[-2])
    q = p[..., :4]
    loc, n, qp = _local_rotations(q, par, eps)
    tloc, _, _ = _local_rotations(t[..., :4], par, eps)
    e = 1.0 - np.sum(loc * tloc, axis=-1)
    return _mean_abs(e), (np.sign(e), tloc, loc, n, qp, q, par, eps, p.shape)


def local_quat_loss_backward(dvalue, cache):
    """Gradient of :func:`local_quat_loss_forward` through the normalisation and both factors of
    ``q_p* ⊗ q_j`` (each parent collects from all its children)."""
    sg, tloc, loc, n, qp, q, par, eps, shape = cache
    gl = (-_check_dvalue(dvalue) / sg.size) * sg[..., None] * tloc
    graw = normalize_backward(gl, loc, n, eps)
    gqp, gq = quat_mul_backward_kernel(graw, qp, q)
    gpar = quat_conj_kernel(gqp[..., 1:, :])  # gradient w.r.t. q_p from the conjugated factor
    np.add.at(gq, (Ellipsis, par[1:], slice(None)), gpar)
    return _embed(gq, shape)


# --------------------------------------------------------------------------------------------------
# positional losses

def euclidean_loss_forward(pred, target):
    """Mean Euclidean distance ``mean ‖p - p̃‖₂`` over the leading axes (NOT squared).

    Parameters
    ----------
    pred, target : ndarray, shape (..., 3) (any last size works)

    Returns
    -------
    value : float
    cache : tuple
    """
    p, t = _pair(pred, target, None, min_ndim=1)
    d, f = _difference(p, t)  # pred - target = f d
    n, direction = _norm_and_direction(d)
    return f * _mean_abs(n), (direction,)


def euclidean_loss_backward(dvalue, cache):
    """Gradient of :func:`euclidean_loss_forward`: ``(p - p̃) / ‖p - p̃‖ · dvalue / N``, 0 where ``p = p̃``."""
    (direction,) = cache
    count = direction.size // direction.shape[-1]
    return direction * (_check_dvalue(dvalue) / count)


def dq_pos_loss_forward(pred, target):
    """L_pos (Andreou et al. §5.2): ``mean ‖p - p̃‖₂`` with ``p = vec(2 q_d ⊗ q_r*)`` (Eq. 8) per joint.

    Parameters
    ----------
    pred, target : ndarray, shape (..., J, 8)
        Unit current dual quaternions (the prediction after :func:`refimpl.nn.quat_layers.dq_normalize_forward`).

    Returns
    -------
    value : float
    cache : tuple
    """
    p, t = _pair(pred, target, 8)
    pp, pcache = positions_from_dq_forward(p)
    tp, _ = positions_from_dq_forward(t)
    value, ecache = euclidean_loss_forward(pp, tp)
    return value, (pcache, ecache)


def dq_pos_loss_backward(dvalue, cache):
    """Gradient of :func:`dq_pos_loss_forward` (through Eq. 8)."""
    pcache, ecache = cache
    return positions_from_dq_backward(euclidean_loss_backward(dvalue, ecache), pcache)


def dq_offset_loss_forward(pred, target, parents):
    """L_offset (Andreou et al. §5.2): ``mean ‖o - õ‖₂`` over (..., J), ``o`` the translation of
    ``C_p⁻¹ ⊗ C_j`` (Eq. 12 then Eq. 8; root offset 0, so the root contributes 0 to the sum but counts in J).

    Parameters
    ----------
    pred, target : ndarray, shape (..., J, 8)
        Unit current dual quaternions.
    parents : sequence of int, length J

    Returns
    -------
    value : float
    cache : tuple
    """
    p, t = _pair(pred, target, 8)
    po, ocache = offsets_from_dq_forward(p, parents)
    to, _ = offsets_from_dq_forward(t, parents)
    value, ecache = euclidean_loss_forward(po, to)
    return value, (ocache, ecache)


def dq_offset_loss_backward(dvalue, cache):
    """Gradient of :func:`dq_offset_loss_forward`."""
    ocache, ecache = cache
    return offsets_from_dq_backward(euclidean_loss_backward(dvalue, ecache), ocache)


# --------------------------------------------------------------------------------------------------
# unit-norm regularisers

def dq_reg_loss_forward(raw):
    """L_reg (Andreou et al. Eq. 16) on the RAW network output, before normalisation.

    ``mean over (...) of (|q_r|² - 1)² + <q_r, q_d>²`` for dual quaternions ``(..., 8)``; for plain quaternions
    ``(..., 4)`` only the first term (then it equals :func:`quat_norm_loss_forward`).

    Parameters
    ----------
    raw : ndarray, shape (..., 8) or (..., 4)

    Returns
    -------
    value : float
    cache : tuple
    """
    x = _nonempty(float_array(raw, "raw", last=(4, 8)), "raw")
    if _max_abs(x) <= _pow2_limit(x.dtype, 8):  # the usual case: 4th powers (and the gradient) cannot overflow
        terms, a, b = _dq_reg_terms(x, 1)
        return _mean_abs(terms), (x, None, a, b)
    u, k = _rows_scaled(x)  # x = 2^k u: a, b of u are 2^-2k times the true ones; terms 2^-4k
    terms, a, b = _dq_reg_terms(u, np.ldexp(u.dtype.type(1), -2 * k))
    return _mean_abs(np.ldexp(terms, 4 * k)), (u, k, a, b)


def _dq_reg_terms(x: np.ndarray, one):
    """``(a² + b², a, b)`` with ``a = |q_r|² − one``, ``b = ⟨q_r, q_d⟩`` (``b = None`` for ``(..., 4)``)."""
    r = x[..., :4]
    a = np.sum(r * r, axis=-1) - one
    if x.shape[-1] == 4:
        return a * a, a, None
    b = np.sum(r * x[..., 4:], axis=-1)
    return a * a + b * b, a, b


def dq_reg_loss_backward(dvalue, cache):
    """Gradient of :func:`dq_reg_loss_forward`: ``dq_r = (4 a q_r + 2 b q_d) c``, ``dq_d = 2 b q_r c`` with
    ``a = |q_r|² - 1``, ``b = <q_r, q_d>``, ``c = dvalue / N`` (after an overflow in the forward, evaluated on
    the scaled output and rescaled by ``2^3k``: ``±inf`` only where the true gradient overflows, never NaN)."""
    u, k, a, b = cache
    c = _check_dvalue(dvalue) / a.size
    r = u[..., :4]
    g = np.empty_like(u)
    g[..., :4] = 4.0 * a[..., None] * r
    if b is not None:
        g[..., :4] += 2.0 * b[..., None] * u[..., 4:]
        g[..., 4:] = 2.0 * b[..., None] * r
    g *= c  # last, so a zero stays zero (no 0 · inf for huge dvalue)
    return g if k is None else np.ldexp(g, 3 * k[..., None])


def quat_norm_loss_forward(raw):
    """QuaterNet's quaternion norm penalty ``mean((Σ q² - 1)²)`` over all quaternions of the raw (pre-normalised,
    pre-QMul) output; weighted by :data:`QUATERNET_PENALTY_WEIGHT` = 0.01 in training.

    Parameters
    ----------
    raw : ndarray, shape (..., 4)
        e.g. (B, T, J, 4).

    Returns
    -------
    value : float
    cache : tuple
    """
    x = _nonempty(float_array(raw, "raw", last=4), "raw")
    if _max_abs(x) <= _pow2_limit(x.dtype, 8):  # the usual case, as in dq_reg_loss_forward
        terms, a, _ = _dq_reg_terms(x, 1)
        return _mean_abs(terms), (x, None, a)
    u, k = _rows_scaled(x)  # x = 2^k u, as in dq_reg_loss_forward
    terms, a, _ = _dq_reg_terms(u, np.ldexp(u.dtype.type(1), -2 * k))
    return _mean_abs(np.ldexp(terms, 4 * k)), (u, k, a)


def quat_norm_loss_backward(dvalue, cache):
    """Gradient of :func:`quat_norm_loss_forward`: ``4 (|q|² - 1) q dvalue / N`` (after an overflow in the
    forward, on the scaled output rescaled by ``2^3k``: ``±inf`` only where the true gradient overflows)."""
    u, k, a = cache
    g = 4.0 * a[..., None] * u
    g *= _check_dvalue(dvalue) / a.size  # last, so a zero stays zero
    return g if k is None else np.ldexp(g, 3 * k[..., None])


# --------------------------------------------------------------------------------------------------
# QuaterNet short-term: Euler-angle L1 with 2π wrap

def euler_l1_loss_forward(pred, target, order: str = "zyx", eps: float = QUATERNET_EULER_EPS):
    """QuaterNet's short-term loss: L1 distance of Euler angles with the 2π wrap.

    ``e = euler(pred, order, eps)`` (QuaterNet ``qeuler``, asin argument clipped to ``[-1+eps, 1-eps]``),
    ``d = (e - ẽ + π) mod 2π - π`` (floor-based ``mod`` as ``torch.remainder``, so ``d ∈ [-π, π)``),
    value ``= mean |d|`` over all angles (all joints including the root, 3 per joint).

    Parameters
    ----------
    pred : ndarray, shape (..., J, 4) or (..., 4)
        Predicted unit quaternions (after normalisation / QMul).
    target : ndarray, shape (..., 4) or (..., 3)
        Ground-truth quaternions (converted with ``eps = 0``, as QuaterNet's precomputed Euler targets) or
        ground-truth Euler angles ``(x, y, z)`` in radians.
    order : str
        Euler order, QuaterNet short-term: ``'zyx'``.
    eps : float
        asin clip margin for the prediction (QuaterNet: 1e-6; must be > 0 for a bounded gradient).

    Returns
    -------
    value : float
    cache : tuple
    """
    p = _nonempty(float_array(pred, "pred", last=4), "pred")
    t = float_array(target, "target", last=(3, 4))
    if t.shape[:-1] != p.shape[:-1]:
        raise ValueError(f"target: expected shape {p.shape[:-1] + (4,)} or {p.shape[:-1] + (3,)}, got {t.shape}")
    e, ecache = euler_from_quat_forward(p, order, eps)
    te = euler_from_quat_forward(t, order, 0.0)[0] if t.shape[-1] == 4 else t.astype(e.dtype, copy=False)
    d = np.remainder(e - te + np.pi, 2.0 * np.pi) - np.pi
    return _mean_abs(d), (np.sign(d), ecache)


def euler_l1_loss_backward(dvalue, cache):
    """Gradient of :func:`euler_l1_loss_forward` into the predicted quaternions: ``sign(d) dvalue / N``
    (the wrap has derivative 1) back through the Euler conversion."""
    sg, ecache = cache
    return euler_from_quat_backward(sg * (_check_dvalue(dvalue) / sg.size), ecache)


# --------------------------------------------------------------------------------------------------
# QuaterNet long-term: FK position loss

def fk_position_loss_forward(pred_rotations, pred_translations, target_positions, target_translations,
                             offsets, parents, up_axis: int = 1):
    """QuaterNet's long-term loss: FK positions plus the longitudinal-offset term.

    Positions are ``FK(pred_rotations)`` with root position ``(0, h, 0)`` (h = ``pred_translations[..., 1]``,
    the predicted root height, added to the up coordinate of every joint); with the offset
    ``o = pred_translations[..., 0]``::

        value = mean over (..., J) of ( ‖p_j - p̃_j‖₂ + |o - õ| )
              = mean_{..., J} ‖p_j - p̃_j‖₂ + mean_{...} |o - õ|

    Parameters
    ----------
    pred_rotations : ndarray, shape (..., J, 4)
        Predicted (normalised) local rotations.
    pred_translations : ndarray, shape (..., 2)
        Predicted ``[offset, height]``.
    target_positions : ndarray, shape (..., J, 3)
        Ground-truth positions with the root's horizontal coordinates set to 0 (QuaterNet ``positions_local``).
    target_translations : ndarray, shape (..., 2)
        Ground-truth ``[offset, height]``; only the offset is used (the height is in the target positions).
    offsets : ndarray, shape (J, 3)
    parents : sequence of int, length J
    up_axis : int
        The vertical axis (1 = y, QuaterNet's locomotion data).

    Returns
    -------
    value : float
    cache : tuple
    """
    rot = _nonempty(float_array(pred_rotations, "pred_rotations", last=4, min_ndim=2), "pred_rotations")
    tr = float_array(pred_translations, "pred_translations", last=2)
    lead = rot.shape[:-2]
    if tr.shape != lead + (2,):
        raise ValueError(f"pred_translations: expected shape {lead + (2,)}, got {tr.shape}")
    tpos = float_array(target_positions, "target_positions", last=3, min_ndim=2)
    if tpos.shape != rot.shape[:-1] + (3,):
        raise ValueError(f"target_positions: expected shape {rot.shape[:-1] + (3,)}, got {tpos.shape}")
    ttr = float_array(target_translations, "target_translations", last=2)
    if ttr.shape != tr.shape:
        raise ValueError(f"target_translations: expected shape {tr.shape}, got {ttr.shape}")
    if up_axis not in (0, 1, 2):
        raise ValueError(f"up_axis: expected 0, 1 or 2, got {up_axis!r}")
    root = np.zeros(lead + (3,), dtype=np.result_type(rot, tr))
    root[..., up_axis] = tr[..., 1]
    pos, fk_cache = forward_kinematics_forward(rot, root, offsets, parents)
    pos_value, ecache = euclidean_loss_forward(pos, tpos.astype(pos.dtype, copy=False))
    do, f = _difference(tr[..., 0], ttr[..., 0])  # o - õ = f do
    return pos_value + f * _mean_abs(do), (fk_cache, ecache, np.sign(do), up_axis, tr.dtype)


def fk_position_loss_backward(dvalue, cache):
    """Gradients of :func:`fk_position_loss_forward`.

    Returns
    -------
    drotations : ndarray, shape (..., J, 4)
    dtranslations : ndarray, shape (..., 2)
        ``[sign(o - õ) dvalue / N_frames, Σ_j dp_j[up_axis]]``.
    """
    fk_cache, ecache, sg, up_axis, tdtype = cache
    dvalue = _check_dvalue(dvalue)
    dpos = euclidean_loss_backward(dvalue, ecache)
    drot, droot, _ = forward_kinematics_backward(dpos, fk_cache)
    dtr = np.empty(sg.shape + (2,), dtype=np.result_type(tdtype, droot))
    dtr[..., 0] = sg * (dvalue / sg.size)
    dtr[..., 1] = droot[..., up_axis]
    return drot, dtr
