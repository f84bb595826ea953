"""Rotation conversions on NumPy arrays (layer 1: math): axis-angle (exponential map), Euler angles, rotation
matrices and the 6-D representation, to and from quaternions.

Conventions as in :mod:`refimpl.quat` (spec/conventions.md, binding): quaternions ``(w, x, y, z)``, active
rotations, column vectors. Euler ``order`` is a 3-letter string (``"zyx"``, ``"zxy"``, ``"zxz"``...; upper case
accepted); ``angles[..., i]`` is the angle in radians about axis ``order[i]`` and the rotation is
``R_order[0](angles[..., 0]) · R_order[1](angles[..., 1]) · R_order[2](angles[..., 2])`` (intrinsic reading).
A BVH channel list ``Zrotation Xrotation Yrotation`` is order ``"zxy"``; the dual-quaternion paper's Eq. 5 is
order ``"zyx"``. Arrays broadcast over leading axes; dtypes and input checks as in :mod:`refimpl.quat`.

Shape legend: ``...`` any leading (batch) axes.

Each function names the section of spec/math.md that states it.
"""
from __future__ import annotations

import math

import numpy as np

from refimpl.arrays import float_array
from refimpl.quat import (atan_ratio, check_nonzero, finite_output, prescaled, quat_canonical_kernel,
                          quat_mul_kernel, quat_norm_kernel, sin_over_x)

__all__ = [
    "quat_from_axis_angle", "axis_angle_from_quat",
    "quat_from_euler", "euler_from_quat", "matrix_from_euler", "euler_from_matrix",
    "matrix_from_quat", "quat_from_matrix", "ortho6d_from_matrix", "matrix_from_ortho6d",
    "EULER_ORDERS", "TAIT_BRYAN_ORDERS", "PROPER_EULER_ORDERS",
]

TAIT_BRYAN_ORDERS = ("xyz", "xzy", "yxz", "yzx", "zxy", "zyx")
PROPER_EULER_ORDERS = ("xyx", "xzx", "yxy", "yzy", "zxz", "zyz")
EULER_ORDERS = TAIT_BRYAN_ORDERS + PROPER_EULER_ORDERS

_AXIS_INDEX = {"x": 0, "y": 1, "z": 2}


def _parse_order(order) -> str:
    """Validate an Euler order string and return it in lower case."""
    if not isinstance(order, str):
        raise ValueError(f"order: expected a 3-letter string such as 'zyx', got {order!r}")
    o = order.lower()
    if len(o) != 3 or any(c not in _AXIS_INDEX for c in o) or o[0] == o[1] or o[1] == o[2]:
        raise ValueError(f"order: expected one of {', '.join(EULER_ORDERS)} (any case), got {order!r}")
    return o


def _eps(dtype) -> float:
    return float(np.finfo(dtype).eps)

# ----------------------------------------------------------------------------------------------------------------
# axis-angle (exponential map)
# ----------------------------------------------------------------------------------------------------------------

@finite_output
def quat_from_axis_angle(v) -> np.ndarray:
    """Unit quaternion of the rotation vector ``v = θ n`` (exponential map) (spec/math.md §2.1).

    ``q = (cos(θ/2), sin(θ/2)/θ · v)``; ``sin(θ/2)/θ`` uses its Taylor series ``½ − θ²/48 + θ⁴/3840`` near 0,
    so ``v = 0`` gives the identity. ``θ = 2π`` gives ``(−1, 0, 0, 0)`` (the identity rotation); no sign is
    canonicalised. Every finite ``v`` gives a finite unit quaternion: ``θ`` is computed without overflow (exact
    power-of-two rescaling, spec/math.md §6) and ``cos``/``sin`` reduce ``θ/2`` exactly modulo ``2π``; for
    ``θ > 2^53`` the float ``θ`` itself is coarser than a turn, so such a rotation is defined but not meaningful.

    Parameters
    ----------
    v : array_like, (..., 3)

    Returns
    -------
    ndarray, (..., 4)
    """
    v = float_array(v, "v", (..., 3))
    vs, e = prescaled(v)  # v = 2^e vs where θ² could under/overflow: exact
    if e is None:
        half = 0.5 * np.sqrt(np.sum(v * v, axis=-1))  # (...) θ/2
        return np.concatenate([np.cos(half)[..., None], (0.5 * sin_over_x(half))[..., None] * v], axis=-1)
    ns = quat_norm_kernel(vs)  # (...) |vs|
    half = np.ldexp(ns, e - 1)  # θ/2 = 2^(e-1) |vs|: finite for every finite v (θ/2 <= 0.87 max|v_i|)
    axis = vs / np.where(ns == 0, 1, ns)[..., None]  # (..., 3) unit axis (0 for v = 0)
    vec = np.where((half < 1)[..., None], (0.5 * sin_over_x(half))[..., None] * v, np.sin(half)[..., None] * axis)
    return np.concatenate([np.cos(half)[..., None], vec], axis=-1)


@finite_output
def axis_angle_from_quat(q) -> np.ndarray:
    """Rotation vector ``θ n`` with ``θ ∈ [0, π]`` of a non-zero quaternion (logarithm map) (spec/math.md §2.1).

    ``v = 2 atan2(|u|, w) u/|u|`` after replacing ``q`` by :func:`quat_canonical` ``(q)`` (so ``w >= 0`` and ``q``,
    ``−q`` give the same vector), with the series of ``atan2(s, w)/s`` for small ``|u|``. Scale-invariant: ``q``
    need not be unit. At exactly ``θ = π`` (``w = 0``) the canonical sign makes the first non-zero component of
    ``v`` positive.

    Raises
    ------
    ValueError
        If some quaternion is zero.
    """
    q = float_array(q, "q", (..., 4))
    q, _ = prescaled(q, "q")
    q = quat_canonical_kernel(q)
    u = q[..., 1:]
    s = np.sqrt(np.sum(u * u, axis=-1))
    return (2 * atan_ratio(s, q[..., 0]))[..., None] * u


# ----------------------------------------------------------------------------------------------------------------
# Euler angles
# ----------------------------------------------------------------------------------------------------------------

def quat_elementary_kernel(axis: int, angle: np.ndarray) -> np.ndarray:
    """The rotation by ``angle`` (...) about axis ``axis`` (0, 1, 2 = x, y, z): ``(cos a/2, sin a/2 e_axis)`` (...) 4."""
    q = np.zeros(angle.shape + (4,), dtype=angle.dtype)
    q[..., 0] = np.cos(0.5 * angle)
    q[..., 1 + axis] = np.sin(0.5 * angle)
    return q


@finite_output
def quat_from_euler(angles, order: str) -> np.ndarray:
    """Quaternion ``q_{order[0]}(a0) ⊗ q_{order[1]}(a1) ⊗ q_{order[2]}(a2)`` (spec/math.md §3.1; paper Eq. 4-5).

    ``q_x(a) = (cos a/2, sin a/2, 0, 0)`` and likewise for y, z. No sign is canonicalised.

    Parameters
    ----------
    angles : array_like, (..., 3)
        Radians; ``angles[..., i]`` is the angle about axis ``order[i]``.
    order : str
        One of the 12 orders (Tait-Bryan ``xyz``... or proper ``zxz``...), any case.

    Returns
    -------
    ndarray, (..., 4)
    """
    o = _parse_order(order)
    a = float_array(angles, "angles", (..., 3))
    q = quat_elementary_kernel(_AXIS_INDEX[o[0]], a[..., 0])
    q = quat_mul_kernel(q, quat_elementary_kernel(_AXIS_INDEX[o[1]], a[..., 1]))
    return quat_mul_kernel(q, quat_elementary_kernel(_AXIS_INDEX[o[2]], a[..., 2]))


def _wrap_angle(a: np.ndarray) -> np.ndarray:
    """Wrap to ``[−π, π)``."""
    return np.mod(a + np.pi, 2 * np.pi) - np.pi


def _euler_from_quat(q: np.ndarray, o: str) -> np.ndarray:
    i, j = _AXIS_INDEX[o[0]], _AXIS_INDEX[o[1]]
    proper = o[0] == o[2]
    k = 3 - i - j
    sign = 1 if (j - i) % 3 == 1 else -1  # e_i e_j = sign · e_k
    w, qi, qj, qk = q[..., 0], q[..., 1 + i], q[..., 1 + j], sign * q[..., 1 + k]
    tol = math.sqrt(_eps(q.dtype)) * quat_norm_kernel(q)
    if proper:
        # q = (c cosσ, [i] c sinσ, [j] s cosδ, [k] sign·s sinδ), c = cos(b/2), s = sin(b/2), σ=(a+g)/2, δ=(a−g)/2
        m_sum, m_dif = np.hypot(w, qi), np.hypot(qj, qk)
        ang_sum, ang_dif = np.arctan2(qi, w), np.arctan2(qk, qj)
        beta = 2 * np.arctan2(m_dif, m_sum)  # [0, π]
    else:
        # P = (w + qj, qi + qk) = (c + s)(cos, sin)(φ_P), M = (w − qj, qi − qk) = (c − s)(cos, sin)(φ_M)
        # sign +1: φ_P = σ, φ_M = δ; sign −1: φ_P = δ, φ_M = σ
        m_p, m_m = np.hypot(w + qj, qi + qk), np.hypot(w - qj, qi - qk)
        ang_p, ang_m = np.arctan2(qi + qk, w + qj), np.arctan2(qi - qk, w - qj)
        beta = 2 * np.arctan2(m_p, m_m) - 0.5 * np.pi  # [−π/2, π/2]
        if sign > 0:
            m_sum, m_dif, ang_sum, ang_dif = m_p, m_m, ang_p, ang_m
        else:
            m_sum, m_dif, ang_sum, ang_dif = m_m, m_p, ang_m, ang_p
    alpha = ang_sum + ang_dif
    gamma = ang_sum - ang_dif
    # gimbal lock: only a0 ± a2 is defined; convention a2 = 0
    lock_dif = m_dif <= tol  # δ undefined → a0 = 2σ
    lock_sum = (m_sum <= tol) & ~lock_dif  # σ undefined → a0 = 2δ
    alpha = np.where(lock_dif, 2 * ang_sum, np.where(lock_sum, 2 * ang_dif, alpha))
    gamma = np.where(lock_dif | lock_sum, 0, gamma)
    return np.stack([_wrap_angle(alpha), beta, _wrap_angle(gamma)], axis=-1)


@finite_output
def euler_from_quat(q, order: str) -> np.ndarray:
    """Euler angles (radians) in ``order`` of a non-zero quaternion (spec/math.md §3.2; paper Eq. 7 for ``zyx``).

    Direct quaternion method (no matrix): ``angles[..., i]`` is the angle about ``order[i]`` and
    ``quat_from_euler(angles, order) = ±q/|q|``. Ranges: first and last angle in ``[−π, π)``; middle angle in
    ``[−π/2, π/2]`` (Tait-Bryan) or ``[0, π]`` (proper). Gimbal lock (middle angle at a range end, detected when
    the relevant half-angle pair has magnitude ``<= sqrt(eps)|q|``): only the sum or difference of the outer
    angles is defined and we set the LAST angle to 0.

    Note: unlike QuaterNet's ``qeuler``, which always returns ``(x, y, z)``, the angles come in ``order``.

    Raises
    ------
    ValueError
        For a bad order or a zero quaternion.
    """
    o = _parse_order(order)
    q = float_array(q, "q", (..., 4))
    q, _ = prescaled(q, "q")
    return _euler_from_quat(q, o)


@finite_output
def matrix_from_euler(angles, order: str) -> np.ndarray:
    """Rotation matrix ``R_{order[0]}(a0) R_{order[1]}(a1) R_{order[2]}(a2)``, ``(..., 3, 3)`` (spec/math.md §3.3)."""
    return matrix_from_quat_kernel(quat_from_euler(angles, order))


@finite_output
def euler_from_matrix(m, order: str) -> np.ndarray:
    """Euler angles in ``order`` of rotation matrices ``(..., 3, 3)``, via :func:`quat_from_matrix` (spec/math.md §3.3)."""
    o = _parse_order(order)
    return _euler_from_quat(quat_from_matrix(m), o)


# ----------------------------------------------------------------------------------------------------------------
# matrices and 6-D
# ----------------------------------------------------------------------------------------------------------------

def matrix_from_quat_kernel(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    s = 2 / np.sum(q * q, axis=-1)
    xx, yy, zz = s * x * x, s * y * y, s * z * z
    xy, xz, yz = s * x * y, s * x * z, s * y * z
    wx, wy, wz = s * w * x, s * w * y, s * w * z
    m = np.stack([
        1 - (yy + zz), xy - wz, xz + wy,
        xy + wz, 1 - (xx + zz), yz - wx,
        xz - wy, yz + wx, 1 - (xx + yy),
    ], axis=-1)
    return m.reshape(q.shape[:-1] + (3, 3))


@finite_output
def matrix_from_quat(q) -> np.ndarray:
    """Rotation matrix of a non-zero quaternion (of ``q/|q|``), ``(..., 3, 3)`` (spec/math.md §4.1).

    ``R = I + 2/|q|² [[−(y²+z²), xy − wz, xz + wy], [xy + wz, −(x²+z²), yz − wx], [xz − wy, yz + wx, −(x²+y²)]]``
    so that ``R v = quat_rotate(q, v)`` for unit ``q``.

    Raises
    ------
    ValueError
        If some quaternion is zero.
    """
    q = float_array(q, "q", (..., 4))
    q, _ = prescaled(q, "q")
    return matrix_from_quat_kernel(q)


def _orthonormality_tol(dtype) -> float:
    return 1e-6 if np.dtype(dtype).itemsize >= 8 else 1e-3


def check_rotation_matrix(m: np.ndarray, name: str) -> None:
    """Raise ValueError unless ``m`` is orthonormal with det +1 (to the dtype's tolerance)."""
    if not isinstance(m, np.ndarray) or m.dtype.kind != "f" or m.shape[-2:] != (3, 3):
        raise ValueError(f"{name}: expected a floating array of rotation matrices (..., 3, 3), got "
                         f"{getattr(m, 'dtype', type(m).__name__)} of shape {getattr(m, 'shape', None)}")
    tol = _orthonormality_tol(m.dtype)
    with np.errstate(over="ignore", invalid="ignore"):  # huge entries: inf/NaN, refused below
        mtm = np.einsum("...ki,...kj->...ij", m, m)  # (..., 3, 3) MᵀM (any float dtype, unlike matmul/linalg)
        err = np.abs(mtm - np.eye(3, dtype=m.dtype))
        bad = ~(err <= tol)  # NaN counts as bad
        if np.any(bad):
            idx = np.unravel_index(int(np.argmax(np.where(bad, np.inf, err))), err.shape)[:-2]
            raise ValueError(f"{name}: not orthonormal at index {tuple(int(i) for i in idx)} "
                             f"(max |MᵀM − I| = {float(np.nanmax(np.where(bad, np.inf, err))):.3g} > {tol}); "
                             "expected rotation matrices (..., 3, 3)")
    # det = m0 · (m1 × m2) (rows): no LAPACK, so float16 and long double work too
    det = np.sum(m[..., 0, :] * np.cross(m[..., 1, :], m[..., 2, :]), axis=-1)  # (...)
    if np.any(~(det > 0)):
        idx = tuple(int(i) for i in np.argwhere(~(det > 0))[0])
        raise ValueError(f"{name}: determinant <= 0 at index {idx} (a reflection, not a rotation)")


def quat_from_matrix_kernel(m: np.ndarray) -> np.ndarray:
    m00, m01, m02 = m[..., 0, 0], m[..., 0, 1], m[..., 0, 2]
    m10, m11, m12 = m[..., 1, 0], m[..., 1, 1], m[..., 1, 2]
    m20, m21, m22 = m[..., 2, 0], m[..., 2, 1], m[..., 2, 2]
    tr = m00 + m11 + m22
    # the four columns of 4 q qᵀ (scaled by 4w, 4x, 4y, 4z respectively)
    cand = np.stack([
        np.stack([1 + tr, m21 - m12, m02 - m20, m10 - m01], axis=-1),
        np.stack([m21 - m12, 1 + m00 - m11 - m22, m01 + m10, m02 + m20], axis=-1),
        np.stack([m02 - m20, m01 + m10, 1 - m00 + m11 - m22, m12 + m21], axis=-1),
        np.stack([m10 - m01, m02 + m20, m12 + m21, 1 - m00 - m11 + m22], axis=-1),
    ], axis=-2)  # (..., 4, 4)
    best = np.argmax(np.stack([tr, m00, m11, m22], axis=-1), axis=-1)  # (...)
    q = np.take_along_axis(cand, best[..., None, None], axis=-2)[..., 0, :]  # (..., 4)
    q = q / quat_norm_kernel(q)[..., None]
    return np.where(q[..., :1] < 0, -q, q)


def _quat_from_matrix_naive(m: np.ndarray) -> np.ndarray:
    """Slow scalar version of :func:`quat_from_matrix` (Shepperd's four branches written out)."""
    flat = m.reshape(-1, 3, 3)
    out = np.empty((flat.shape[0], 4), dtype=m.dtype)
    for n, r in enumerate(flat):
        tr = r[0, 0] + r[1, 1] + r[2, 2]
        k = int(np.argmax([tr, r[0, 0], r[1, 1], r[2, 2]]))
        if k == 0:
            w = math.sqrt(1 + tr) / 2
            q = [w, (r[2, 1] - r[1, 2]) / (4 * w), (r[0, 2] - r[2, 0]) / (4 * w), (r[1, 0] - r[0, 1]) / (4 * w)]
        elif k == 1:
            x = math.sqrt(1 + r[0, 0] - r[1, 1] - r[2, 2]) / 2
            q = [(r[2, 1] - r[1, 2]) / (4 * x), x, (r[0, 1] + r[1, 0]) / (4 * x), (r[0, 2] + r[2, 0]) / (4 * x)]
        elif k == 2:
            y = math.sqrt(1 - r[0, 0] + r[1, 1] - r[2, 2]) / 2
            q = [(r[0, 2] - r[2, 0]) / (4 * y), (r[0, 1] + r[1, 0]) / (4 * y), y, (r[1, 2] + r[2, 1]) / (4 * y)]
        else:
            z = math.sqrt(1 - r[0, 0] - r[1, 1] + r[2, 2]) / 2
            q = [(r[1, 0] - r[0, 1]) / (4 * z), (r[0, 2] + r[2, 0]) / (4 * z), (r[1, 2] + r[2, 1]) / (4 * z), z]
        q = np.array(q) / np.linalg.norm(q)
        out[n] = -q if q[0] < 0 else q
    return out.reshape(m.shape[:-2] + (4,))


@finite_output
def quat_from_matrix(m) -> np.ndarray:
    """Unit quaternion with ``w >= 0`` of rotation matrices ``(..., 3, 3)`` (spec/math.md §4.2).

    Shepperd's method in Markley's form: of the four columns of ``4 q qᵀ`` (computable from ``R``), take the one
    with the largest diagonal entry (``1 + tr R`` or ``1 + 2R_ii − tr R``) and normalise it. Accurate for every
    rotation, including 180° rotations (where ``w = 0``).

    Raises
    ------
    ValueError
        If ``m`` is not ``(..., 3, 3)``, not finite, not orthonormal (``max |MᵀM − I|`` above 1e-6 for float64,
        1e-3 for float32) or has det <= 0.
    """
    m = float_array(m, "m", (..., 3, 3))
    check_rotation_matrix(m, "m")
    return quat_from_matrix_kernel(m)


@finite_output
def ortho6d_from_matrix(m) -> np.ndarray:
    """6-D rotation representation (Zhou et al. 2019): the first two COLUMNS of ``R`` (spec/math.md §4.3).

    Layout: ``(R00, R10, R20, R01, R11, R21)`` = column 0 then column 1. ``m`` is not checked for
    orthonormality (the map is defined for any matrix).

    Returns
    -------
    ndarray, (..., 6)
    """
    m = float_array(m, "m", (..., 3, 3))
    return np.concatenate([m[..., :, 0], m[..., :, 1]], axis=-1)


@finite_output
def matrix_from_ortho6d(x) -> np.ndarray:
    """Rotation matrix from 6 numbers by Gram-Schmidt (Zhou et al. 2019) (spec/math.md §4.3).

    With ``a1 = x[..., 0:3]``, ``a2 = x[..., 3:6]``: ``b1 = a1/|a1|``, ``b2 = (a2 − ⟨b1, a2⟩ b1)/|…|``,
    ``b3 = b1 × b2``; ``R = [b1 b2 b3]`` (columns). ``matrix_from_ortho6d(ortho6d_from_matrix(R)) = R``.

    Raises
    ------
    ValueError
        If ``a1`` is zero or ``a2`` is parallel to ``a1`` (relative residual ``<= eps``).
    """
    x = float_array(x, "x", (..., 6))
    a1, a2 = x[..., :3], x[..., 3:]
    a1, _ = prescaled(a1)  # exact rescaling of each column where needed (the result is invariant to it):
    a2, _ = prescaled(a2)  # no under/overflow of the norms
    n1 = np.sqrt(np.sum(a1 * a1, axis=-1))
    check_nonzero(n1, "x", "first column x[..., 0:3]")
    b1 = a1 / n1[..., None]
    r = a2 - np.sum(b1 * a2, axis=-1, keepdims=True) * b1
    n2 = np.sqrt(np.sum(r * r, axis=-1))
    bad = n2 <= _eps(x.dtype) * np.sqrt(np.sum(a2 * a2, axis=-1))
    if np.any(bad):
        idx = tuple(int(i) for i in np.argwhere(bad)[0])
        raise ValueError(f"x: second column parallel to the first (or zero) at index {idx}; Gram-Schmidt is undefined")
    b2 = r / n2[..., None]
    b3 = np.cross(b1, b2)
    return np.stack([b1, b2, b3], axis=-1)  # (..., 3, 3), columns b1 b2 b3

# Kernel tier (spec/architecture.md; unchecked, not in __all__, imported by other modules under these names):
# check_rotation_matrix, matrix_from_quat_kernel, quat_elementary_kernel, quat_from_matrix_kernel.
