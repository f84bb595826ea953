"""Quaternion algebra on NumPy arrays (layer 1: math); the conversions to and from axis-angle, Euler angles,
matrices and 6-D are in :mod:`refimpl.rotations`.

Conventions (spec/conventions.md, binding):

* A quaternion is stored as ``(w, x, y, z)`` in the last axis (real part first).
* Products are Hamilton products, ``quat_mul(q, r) = q ⊗ r``.
* Rotations are active: a unit quaternion ``q`` maps a vector ``v`` to ``q ⊗ (0, v) ⊗ q*``; the matrix of
  ``q ⊗ r`` is ``R(q) R(r)`` (column vectors, right-handed frames).
* Arrays broadcast over leading axes. float64 is the reference dtype; float32 (and other floating) inputs keep
  their dtype; integer inputs become float64.
* Public functions validate the trailing shape and finiteness and raise ``ValueError`` naming the argument and
  the expected and actual shapes. Private helpers (``_name``) do not check.

Shape legend: ``...`` any leading (batch) axes, T time (axis 0 for :func:`quat_fix`).

Each function names the section of spec/math.md that states it.
"""
from __future__ import annotations

import functools
import math
import numbers

import numpy as np

from refimpl.arrays import float_array, real_number

__all__ = [
    "quat_identity", "quat_mul", "quat_conj", "quat_inv", "quat_norm", "quat_normalize", "quat_rotate",
    "quat_dot", "quat_angle", "quat_exp", "quat_log", "quat_slerp", "quat_canonical", "quat_fix",
    "quat_xyzw_from_wxyz", "quat_wxyz_from_xyzw",
]



# ----------------------------------------------------------------------------------------------------------------
# validation helpers (shared with refimpl.rotations, refimpl.dualquat)
# ----------------------------------------------------------------------------------------------------------------

def finite_output(fn):
    """Public-boundary guard (spec/math.md §6, spec/robustness.md §8): run ``fn`` with NumPy's floating-point
    warnings silenced and raise ``ValueError`` if a floating result is not finite.

    Inputs are checked finite by :func:`refimpl.arrays.float_array`, so a non-finite result can only come from a result (or an
    intermediate of it) beyond the float range: e.g. ``quat_mul`` of components near ``1e308``, ``quat_exp`` with
    ``w > 709``, ``dq_inv`` of a real part near ``1e-310``. One vectorised ``isfinite`` pass over the output.
    """
    @functools.wraps(fn)
    def guarded(*args, **kwargs):
        with np.errstate(over="ignore", invalid="ignore", divide="ignore", under="ignore"):
            out = fn(*args, **kwargs)
        for o in (out if isinstance(out, tuple) else (out,)):
            if isinstance(o, (np.ndarray, np.floating)) and o.dtype.kind == "f" and not np.isfinite(o).all():
                raise ValueError(f"{fn.__name__}: the result is not representable in {o.dtype} for this input "
                                 f"(a value beyond the float range, from an input too large or, for an inverse, "
                                 f"too small; output shape {o.shape})")
        return out
    return guarded


def check_nonzero(norm: np.ndarray, name: str, what: str = "quaternion") -> None:
    """Raise ValueError if any entry of ``norm`` is zero (an undefined normalisation)."""
    if np.any(norm == 0):
        idx = tuple(int(i) for i in np.argwhere(norm == 0)[0])
        raise ValueError(f"{name}: zero {what} at index {idx} (norm 0); the operation is undefined there")


def prescaled(q: np.ndarray, name: str | None = None, what: str = "quaternion"):
    """``(q_s, e)`` with ``q = 2^e · q_s`` per object (last axis), for the public functions that only depend on
    the direction of ``q`` (or whose result scales with ``|q|``).

    Usual inputs take the fast path: when every ``|q|²`` lies in ``[2^-k, 2^k]`` (``k = maxexp/4`` of the dtype:
    ``2^±256`` for float64, ``2^±32`` for float32) no sum of squares, nor of products of two such quaternions,
    can under/overflow, and ``(q, None)`` is returned. Otherwise every object is multiplied by ``2^-e``, ``e`` the
    binary exponent of its largest component, so that component lies in ``[0.5, 1)``: exact (a power of two), so
    results do not change, only under/overflow disappears. With ``name``, a zero object raises ValueError naming
    it. Hot kernels (``quat_mul_kernel``, ``quat_rotate_kernel``) never pay for this.
    """
    with np.errstate(over="ignore", under="ignore"):  # detected here
        n2 = np.sum(q * q, axis=-1)  # (...)
    low, high = _scale_limits(q.dtype)
    if np.all((n2 >= low) & (n2 <= high)):
        return q, None
    m = np.max(np.abs(q), axis=-1)  # (...)
    if name is not None:
        check_nonzero(m, name, what)
    e = np.frexp(m)[1]  # (...) int, 0 for a zero object
    return np.ldexp(q, -e[..., None]), e


_SCALE_LIMITS = {np.dtype(t): (2.0 ** -(np.finfo(t).maxexp // 4), 2.0 ** (np.finfo(t).maxexp // 4))
                 for t in (np.float16, np.float32, np.float64)}


def _scale_limits(dtype) -> tuple:
    """``(2^-k, 2^k)``, ``k = maxexp/4`` of ``dtype``, as numbers of that dtype's range (long double included:
    ``2.0 ** 4096`` would overflow a Python float, so it is built with ``ldexp``)."""
    lim = _SCALE_LIMITS.get(np.dtype(dtype))
    if lim is None:
        k = np.finfo(dtype).maxexp // 4
        one = np.ones((), dtype=dtype)
        lim = (np.ldexp(one, -k), np.ldexp(one, k))
    return lim




# ----------------------------------------------------------------------------------------------------------------
# algebra
# ----------------------------------------------------------------------------------------------------------------

def quat_identity(shape=(), dtype=np.float64) -> np.ndarray:
    """Identity quaternions ``(1, 0, 0, 0)`` of shape ``shape + (4,)`` (spec/math.md §1.1)."""
    q = zeros_of(shape, dtype, 4)
    q[..., 0] = 1
    return q


def zeros_of(shape, dtype, size: int) -> np.ndarray:
    """``np.zeros(shape + (size,), dtype)`` for :func:`quat_identity` / ``dq_identity``; ValueError unless
    ``shape`` is a non-negative int or a sequence of them and ``dtype`` a floating dtype, or if the array would
    not fit in memory."""
    sides = (shape,) if isinstance(shape, (numbers.Integral, np.integer)) else shape
    try:
        sides = tuple(sides)
    except TypeError:
        raise ValueError(f"shape: expected an int or a sequence of ints, got {shape!r:.60}") from None
    if any(isinstance(n, (bool, np.bool_)) or not isinstance(n, (numbers.Integral, np.integer)) or n < 0
           for n in sides):
        raise ValueError(f"shape: expected non-negative ints, got {shape!r:.60}")
    try:
        dt = np.dtype(dtype)
    except TypeError:
        raise ValueError(f"dtype: expected a floating dtype, got {dtype!r:.60}") from None
    if dt.kind != "f":
        raise ValueError(f"dtype: expected a floating dtype (float32, float64...), got {dt}")
    try:
        return np.zeros(tuple(int(n) for n in sides) + (size,), dtype=dt)
    except (MemoryError, ValueError) as exc:
        raise ValueError(f"shape: {shape!r:.60} is too large ({exc})") from None


def quat_mul_kernel(q: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Hamilton product kernel (broadcasting; dtype ``result_type(q, r)``), shared with refimpl.nn.quat_layers.

    Each component is written into a preallocated output: 2.5× faster than ``np.stack`` of the four components
    on (B, T, J, 4) batches (the stack copies through a size-1 inner axis), the same on small arrays.
    """
    w1, x1, y1, z1 = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    w2, x2, y2, z2 = r[..., 0], r[..., 1], r[..., 2], r[..., 3]
    out = np.empty(np.broadcast_shapes(q.shape, r.shape), dtype=np.result_type(q, r))  # (..., 4)
    out[..., 0] = w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2
    out[..., 1] = w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2
    out[..., 2] = w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2
    out[..., 3] = w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2
    return out


def _quat_mul_naive(q: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Slow loop version of :func:`quat_mul` (same-shape inputs), through the basis-product table i² = −1, ij = k."""
    # table[a][b] = (sign, index) of e_a e_b for the basis (1, i, j, k)
    table = [[(1, 0), (1, 1), (1, 2), (1, 3)],
             [(1, 1), (-1, 0), (1, 3), (-1, 2)],
             [(1, 2), (-1, 3), (-1, 0), (1, 1)],
             [(1, 3), (1, 2), (-1, 1), (-1, 0)]]
    qf = q.reshape(-1, 4)
    rf = r.reshape(-1, 4)
    out = np.zeros_like(qf)
    for n in range(qf.shape[0]):
        for a in range(4):
            for b in range(4):
                s, c = table[a][b]
                out[n, c] += s * qf[n, a] * rf[n, b]
    return out.reshape(q.shape)


@finite_output
def quat_mul(q, r) -> np.ndarray:
    """Hamilton product ``q ⊗ r`` (spec/math.md §1.2).

    Parameters
    ----------
    q, r : array_like, (..., 4)
        Quaternions ``(w, x, y, z)``; leading axes broadcast.

    Returns
    -------
    ndarray, (..., 4)
        ``w = w1w2 − x1x2 − y1y2 − z1z2``, ``x = w1x2 + x1w2 + y1z2 − z1y2``,
        ``y = w1y2 − x1z2 + y1w2 + z1x2``, ``z = w1z2 + x1y2 − y1x2 + z1w2``.
    """
    q = float_array(q, "q", (..., 4))
    r = float_array(r, "r", (..., 4))
    try:
        return quat_mul_kernel(q, r)
    except ValueError:
        raise ValueError(f"q, r: leading axes do not broadcast: shapes {q.shape} and {r.shape}") from None


def quat_conj_kernel(q: np.ndarray) -> np.ndarray:
    return q * np.array([1, -1, -1, -1], dtype=q.dtype)


@finite_output
def quat_conj(q) -> np.ndarray:
    """Conjugate ``q* = (w, −x, −y, −z)`` (spec/math.md §1.3). Equals the inverse for a unit quaternion."""
    return quat_conj_kernel(float_array(q, "q", (..., 4)))


def quat_norm_kernel(q: np.ndarray) -> np.ndarray:
    return np.sqrt(np.sum(q * q, axis=-1))  # (...)


@finite_output
def quat_norm(q) -> np.ndarray:
    """Euclidean norm ``|q| = sqrt(w² + x² + y² + z²)``, shape ``(...)`` (spec/math.md §1.3).

    Computed as ``2^e |q 2^-e|`` (exact power-of-two scaling by the largest component), so it is accurate for
    tiny and huge quaternions; ``inf`` only when ``|q|`` exceeds the float range.
    """
    qs, e = prescaled(float_array(q, "q", (..., 4)))
    n = quat_norm_kernel(qs)
    return n if e is None else np.ldexp(n, e)


@finite_output
def quat_inv(q) -> np.ndarray:
    """Inverse ``q⁻¹ = q* / |q|²`` of a non-zero quaternion (spec/math.md §1.3).

    Raises
    ------
    ValueError
        If some quaternion is exactly zero.
    """
    q = float_array(q, "q", (..., 4))
    scale = np.max(np.abs(q), axis=-1, keepdims=True)  # (..., 1); scaling avoids under/overflow of |q|²
    check_nonzero(scale[..., 0], "q")
    qs = q / scale
    return quat_conj_kernel(qs) / (np.sum(qs * qs, axis=-1, keepdims=True) * scale)


@finite_output
def quat_normalize(q, eps: float = 0.0) -> np.ndarray:
    """Unit quaternion ``q / |q|`` (spec/math.md §1.4).

    The norm is computed after scaling by ``max |q_i|``, so tiny (even subnormal) and huge inputs normalise
    correctly.

    Parameters
    ----------
    q : array_like, (..., 4)
    eps : float
        Quaternions with ``|q| <= eps`` are rejected. The default 0 rejects exactly-zero quaternions only.

    Raises
    ------
    ValueError
        If some ``|q| <= eps`` (the direction of a zero quaternion is undefined; no identity is substituted).
    """
    q = float_array(q, "q", (..., 4))
    eps = real_number(eps, "eps", 0.0)
    scale = np.max(np.abs(q), axis=-1, keepdims=True)  # (..., 1)
    bad = scale[..., 0] == 0
    if eps > 0:
        with np.errstate(divide="ignore", invalid="ignore"):  # zero rows are already bad
            bad |= quat_norm_kernel(q / scale) * scale[..., 0] <= eps  # scaled: no under/overflow of |q|²
    if np.any(bad):
        idx = tuple(int(i) for i in np.argwhere(bad)[0])
        raise ValueError(f"q: quaternion with norm <= {eps} at index {idx}; normalisation is undefined")
    qs = q / scale  # max |component| = 1: no under/overflow in the norm
    return qs / quat_norm_kernel(qs)[..., None]


def quat_rotate_kernel(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    w = q[..., :1]  # (..., 1)
    u = q[..., 1:]  # (..., 3)
    uv = np.cross(u, v)
    uuv = np.cross(u, uv)
    return v + 2 * (w * uv + uuv)  # (..., 3)


@finite_output
def quat_rotate(q, v) -> np.ndarray:
    """Rotate vectors: ``vec(q ⊗ (0, v) ⊗ q*) = v + 2 (w (u × v) + u × (u × v))``, ``u = (x, y, z)`` (spec/math.md §1.5).

    Parameters
    ----------
    q : array_like, (..., 4)
        Unit quaternions (not normalised here, as QuaterNet's ``qrot``; for non-unit ``q`` the result is the
        formula above, which is not a rotation).
    v : array_like, (..., 3)
        Vectors; leading axes broadcast with ``q``.

    Returns
    -------
    ndarray, (..., 3)
    """
    q = float_array(q, "q", (..., 4))
    v = float_array(v, "v", (..., 3))
    lead = np.broadcast_shapes(q.shape[:-1], v.shape[:-1])
    return quat_rotate_kernel(np.broadcast_to(q, lead + (4,)), np.broadcast_to(v, lead + (3,)))


@finite_output
def quat_dot(q, r) -> np.ndarray:
    """Four-dimensional dot product ``⟨q, r⟩ = w1w2 + x1x2 + y1y2 + z1z2``, shape ``(...)`` (spec/math.md §1.6)."""
    q = float_array(q, "q", (..., 4))
    r = float_array(r, "r", (..., 4))
    return np.sum(q * r, axis=-1)


@finite_output
def quat_angle(q, r=None) -> np.ndarray:
    """Geodesic angle in ``[0, π]`` of the rotation ``q`` (or of ``q* ⊗ r`` when ``r`` is given) (spec/math.md §1.6).

    ``θ = 2 atan2(|vec(p)|, |w(p)|)`` with ``p = q`` or ``p = q* ⊗ r``: invariant to the sign of either input,
    to their scale, and accurate for small and near-π angles (no ``acos``).

    Returns
    -------
    ndarray, (...)
    """
    q, _ = prescaled(float_array(q, "q", (..., 4)))  # exact rescaling where needed: no under/overflow below
    if r is not None:
        r, _ = prescaled(float_array(r, "r", (..., 4)))
        q = quat_mul_kernel(quat_conj_kernel(q), r)
    return 2 * np.arctan2(np.sqrt(np.sum(q[..., 1:] ** 2, axis=-1)), np.abs(q[..., 0]))


def sin_over_x(x: np.ndarray) -> np.ndarray:
    """``sin(x)/x`` with its Taylor series ``1 − x²/6 + x⁴/120`` for small ``|x|``."""
    small = np.abs(x) < 1e-3
    xs = np.where(small, 1, x)
    x2 = x * x
    return np.where(small, 1 - x2 / 6 + x2 * x2 / 120, np.sin(xs) / xs)


@finite_output
def quat_exp(q) -> np.ndarray:
    """Quaternion exponential ``exp(w, u) = e^w (cos|u|, sin|u| u/|u|)`` (spec/math.md §1.7).

    Stable at ``|u| = 0`` (Taylor series of ``sin|u|/|u|``). For a pure quaternion ``(0, u)`` the result is the
    unit quaternion of the rotation by angle ``2|u|`` about ``u``. Any finite ``u`` is accepted: ``|u|`` is
    computed without overflow and ``cos``, ``sin`` reduce it exactly modulo ``2π`` (for ``|u| > 2^53`` the float
    ``|u|`` is no longer meaningful modulo ``2π``, but the result is a finite quaternion of norm ``e^w``).
    ``w > log(max float) ≈ 709.78`` (float64) overflows ``e^w``, and ``|u|`` itself can exceed the float range
    (components near ``1e308``): both give ``ValueError`` (spec/math.md §1.7).

    Parameters
    ----------
    q : array_like, (..., 4)

    Returns
    -------
    ndarray, (..., 4)
    """
    q = float_array(q, "q", (..., 4))
    u = q[..., 1:]
    us, e = prescaled(u)  # u = 2^e us where |u|² could under/overflow: exact
    a = quat_norm_kernel(us) if e is None else np.ldexp(quat_norm_kernel(us), e)  # (...) |u|, finite (<= 2 max|u_i|)
    ew = np.exp(q[..., 0])
    if e is None:
        vec = (ew * sin_over_x(a))[..., None] * u
    else:  # sin|u| · u/|u| with the unit axis us/|us|: no overflow of a and no underflow of sin|u|/|u|
        axis = us / np.where(a == 0, 1, quat_norm_kernel(us))[..., None]
        vec = np.where((a < 1)[..., None], (ew * sin_over_x(a))[..., None] * u, (ew * np.sin(a))[..., None] * axis)
    return np.concatenate([(ew * np.cos(a))[..., None], vec], axis=-1)


def atan_ratio(s: np.ndarray, w: np.ndarray) -> np.ndarray:
    """``atan2(s, w) / s`` for ``s >= 0``; the series ``(1/w)(1 − r²/3 + r⁴/5)``, ``r = s/w``, when ``0 <= s <= 1e-4 w``.

    For ``w < 0`` the direct quotient is used (``≈ π/s``, large but exact); ``s = 0, w < 0`` gives inf·0 issues,
    so callers handle that case (the negative real axis) themselves.
    """
    small = (w > 0) & (s <= 1e-4 * w)
    ss = np.where(small | (s == 0), 1, s)
    ws = np.where(small, w, 1)
    r2 = (np.where(small, s, 0) / ws) ** 2
    return np.where(small, (1 - r2 / 3 + r2 * r2 / 5) / ws, np.arctan2(ss, w) / ss)


@finite_output
def quat_log(q) -> np.ndarray:
    """Quaternion logarithm ``log q = (log|q|, atan2(|u|, w) u/|u|)`` (spec/math.md §1.7).

    Stable for ``|u| → 0`` (series of ``atan2(s, w)/s``). For a negative real quaternion (``u = 0``, ``w < 0``)
    the axis is undefined; we return the x axis: ``(log|w|, π, 0, 0)``.

    Raises
    ------
    ValueError
        If some quaternion is zero (``log 0`` is undefined).
    """
    q = float_array(q, "q", (..., 4))
    q, e = prescaled(q, "q")  # input = 2^e q: log|input| = log|q| + e log 2
    log_n = np.log(quat_norm_kernel(q))
    if e is not None:
        log_n = log_n + (e * math.log(2)).astype(q.dtype)
    w = q[..., 0]
    u = q[..., 1:]
    s = np.sqrt(np.sum(u * u, axis=-1))
    neg_real = (s == 0) & (w < 0)
    f = np.where(neg_real, 0, atan_ratio(s, w))
    vec = f[..., None] * u
    vec[..., 0] = np.where(neg_real, np.pi, vec[..., 0])
    return np.concatenate([log_n[..., None], vec], axis=-1)


@finite_output
def quat_canonical(q) -> np.ndarray:
    """The representative of ``±q`` whose first non-zero component is positive (spec/math.md §1.8).

    So ``w >= 0``; when ``w = 0`` the sign is fixed by x, then y, then z. Unique for every non-zero ``q``.
    """
    return quat_canonical_kernel(float_array(q, "q", (..., 4)))


def quat_canonical_kernel(q: np.ndarray) -> np.ndarray:
    """Unchecked :func:`quat_canonical` (the first non-zero component made positive), (..., 4) -> (..., 4)."""
    first = np.argmax(q != 0, axis=-1)  # index of the first non-zero component (0 if all zero)
    lead = np.take_along_axis(q, first[..., None], axis=-1)  # (..., 1)
    return np.where(lead < 0, -q, q)


def _quat_fix(q: np.ndarray) -> np.ndarray:
    dots = np.sum(q[1:] * q[:-1], axis=-1)  # (T-1, ...)
    flips = np.cumsum(dots < 0, axis=0) % 2  # (T-1, ...)
    out = q.copy()
    out[1:][flips.astype(bool)] *= -1
    return out


def _quat_fix_naive(q: np.ndarray) -> np.ndarray:
    """Slow loop version of :func:`quat_fix` for ``(T, 4)``: running parity of negative input dot products."""
    out = q.copy()
    flip = False
    for t in range(1, q.shape[0]):
        flip ^= bool(np.dot(q[t], q[t - 1]) < 0)
        if flip:
            out[t] = -q[t]
    return out


@finite_output
def quat_fix(q) -> np.ndarray:
    """Antipodal continuity over time, axis 0 (QuaterNet's ``qfix``) (spec/math.md §1.8).

    Frame 0 is kept; frame ``t`` is negated when it lies in the other hemisphere than the (already corrected)
    frame ``t−1``: with ``d_t = ⟨q_t, q_{t−1}⟩`` on the input, frame ``t`` is flipped when the number of
    ``d_s < 0`` for ``s <= t`` is odd. Afterwards every consecutive dot product is ``>= 0`` and each quaternion
    represents the same rotation. Returns a copy.

    Parameters
    ----------
    q : array_like, (T, ..., 4)
        T >= 1 frames; any further axes (e.g. joints) are independent tracks.
    """
    q = float_array(q, "q", (..., 4))
    if q.ndim < 2:
        raise ValueError(f"q: expected shape (T, ..., 4) with a time axis, got {q.shape}")
    return _quat_fix(q)


def hemisphere_sign(q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
    """``±1`` of shape ``(..., 1)`` making ``q0* ⊗ (±q1)`` canonical (first non-zero component > 0).

    Away from ties this is ``sign⟨q0, q1⟩`` (the w of ``q0* ⊗ q1`` is ``⟨q0, q1⟩``); when ``⟨q0, q1⟩ = 0`` the
    x, y, z of the relative rotation break the tie, so the choice does not depend on the stored sign of ``q1``.
    """
    rel = quat_mul_kernel(quat_conj_kernel(q0), q1)
    first = np.argmax(rel != 0, axis=-1)
    lead = np.take_along_axis(rel, first[..., None], axis=-1)  # (..., 1)
    return np.where(lead < 0, -1, 1).astype(rel.dtype)


@finite_output
def quat_slerp(q0, q1, t) -> np.ndarray:
    """Spherical linear interpolation along the shortest arc (spec/math.md §1.9).

    ``q1`` is negated where ``⟨q0, q1⟩ < 0`` (ties ``⟨q0, q1⟩ = 0``, rotations exactly 180° apart, are broken
    by making the relative rotation ``q0* ⊗ q1`` canonical, see :func:`quat_canonical`, so the result never
    depends on the stored sign of ``q1``); with ``Ω = 2 atan2(|q0 − q1|, |q0 + q1|)`` (the 4-D angle, in
    ``[0, π/2]`` after the flip) the result is ``(sin((1−t)Ω) q0 + sin(tΩ) q1) / sin Ω``, with the Taylor
    series of the coefficients for ``Ω → 0`` (so equal inputs give ``q0``). Antipodal inputs (the same rotation)
    interpolate to that rotation. ``slerp(−q0, q1, t) = −slerp(q0, q1, t)`` and ``slerp(q0, −q1, t) =
    slerp(q0, q1, t)``.

    Parameters
    ----------
    q0, q1 : array_like, (..., 4)
        Unit quaternions (not normalised here).
    t : array_like, broadcastable to the leading shape ``(...)``
        Interpolation parameter; 0 gives ``q0``, 1 gives ``q1`` (up to sign); values outside [0, 1] extrapolate.

    Returns
    -------
    ndarray, (..., 4)
    """
    q0 = float_array(q0, "q0", (..., 4))
    q1 = float_array(q1, "q1", (..., 4))
    t = float_array(t, "t", (..., )).astype(np.result_type(q0, q1), copy=False)  # t does not change the dtype
    q1 = hemisphere_sign(q0, q1) * q1
    omega = 2 * np.arctan2(quat_norm_kernel(q0 - q1), quat_norm_kernel(q0 + q1))  # (...)
    omega, t = np.broadcast_arrays(omega, t)
    c0 = sin_over_x((1 - t) * omega) * (1 - t) / sin_over_x(omega)
    c1 = sin_over_x(t * omega) * t / sin_over_x(omega)
    return c0[..., None] * q0 + c1[..., None] * q1


# ----------------------------------------------------------------------------------------------------------------
# layout converters
# ----------------------------------------------------------------------------------------------------------------

@finite_output
def quat_xyzw_from_wxyz(q) -> np.ndarray:
    """``(w, x, y, z) → (x, y, z, w)`` (scalar-last, as scipy and ROS) (spec/conventions.md)."""
    q = float_array(q, "q", (..., 4))
    return np.concatenate([q[..., 1:], q[..., :1]], axis=-1)


@finite_output
def quat_wxyz_from_xyzw(q) -> np.ndarray:
    """``(x, y, z, w) → (w, x, y, z)`` (spec/conventions.md)."""
    q = float_array(q, "q", (..., 4))
    return np.concatenate([q[..., 3:], q[..., :3]], axis=-1)


# Kernel tier (spec/architecture.md; unchecked, not in __all__, imported by other modules under these names):
# atan_ratio, check_nonzero, finite_output, hemisphere_sign, prescaled, quat_canonical_kernel,
# quat_conj_kernel, quat_mul_kernel, quat_norm_kernel, quat_rotate_kernel, sin_over_x, zeros_of.
