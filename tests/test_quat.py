"""Tests of refimpl.quat (spec/math.md §1-4, spec/conventions.md §1-3).

Self-consistency (round trips, algebraic laws) is backed by an independent oracle, scipy.spatial.transform.Rotation
(scalar-last; upper-case Euler sequences are intrinsic), so a convention error cannot hide behind round trips.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation, Slerp

from refimpl import quat as Q
from refimpl import rotations as R
from refimpl.quat import (_quat_fix_naive, _quat_mul_naive, quat_angle, quat_canonical, quat_conj, quat_dot, quat_exp,
                          quat_fix, quat_identity, quat_inv, quat_log, quat_mul, quat_norm, quat_normalize, quat_rotate,
                          quat_slerp, quat_wxyz_from_xyzw, quat_xyzw_from_wxyz)
from refimpl.rotations import (EULER_ORDERS, PROPER_EULER_ORDERS, TAIT_BRYAN_ORDERS, _quat_from_matrix_naive,
                               axis_angle_from_quat, euler_from_matrix, euler_from_quat, matrix_from_euler,
                               matrix_from_ortho6d, matrix_from_quat, ortho6d_from_matrix, quat_from_axis_angle,
                               quat_from_euler, quat_from_matrix)
from refimpl.strategies import (euler_angles, euler_orders, quaternions, rotation_matrices, small_shapes,
                                translations, unit_quaternions)
from refimpl.testing import assert_close, assert_quat_close

TIGHT = dict(rtol=1e-12, atol=1e-12)


def scipy_rot(q: np.ndarray) -> Rotation:
    return Rotation.from_quat(quat_xyzw_from_wxyz(q).reshape(-1, 4))


def elementary(axis: str, a: float) -> np.ndarray:
    """Textbook active rotation matrices about x, y, z (right-handed)."""
    c, s = math.cos(a), math.sin(a)
    return {"x": np.array([[1, 0, 0], [0, c, -s], [0, s, c]]),
            "y": np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]),
            "z": np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])}[axis]


def random_unit(n: int, seed: int = 0) -> np.ndarray:
    q = np.random.default_rng(seed).normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


# --------------------------------------------------------------------------------------------------------------
# §1 algebra
# --------------------------------------------------------------------------------------------------------------

def test_identity_shapes_and_dtypes():
    """spec/math.md §1.1: identity of any leading shape and dtype."""
    assert quat_identity().shape == (4,)
    i = quat_identity((2, 3), np.float32)
    assert i.shape == (2, 3, 4) and i.dtype == np.float32
    assert_close(i[1, 2], np.array([1, 0, 0, 0], dtype=np.float32), rtol=0, atol=0)
    assert quat_identity(5).shape == (5, 4)


def test_float32_euler_and_gimbal():
    """spec/math.md §3.2, §6: float32 round trips to float32 precision, also at gimbal lock (a2 = 0)."""
    rng = np.random.default_rng(6)
    for order in EULER_ORDERS:
        a = np.stack([rng.uniform(-3, 3, 50), rng.uniform(0.2, 1.3, 50), rng.uniform(-3, 3, 50)], -1)
        q = quat_from_euler(a.astype(np.float32), order)
        back = euler_from_quat(q, order)
        assert back.dtype == np.float32
        assert_quat_close(quat_from_euler(back, order), q, atol=1e-5)
        mid = 0.0 if order in PROPER_EULER_ORDERS else math.pi / 2
        a[:, 1] = mid
        q = quat_from_euler(a.astype(np.float32), order)
        back = euler_from_quat(q, order)
        assert np.all(back[:, 2] == 0)
        assert_quat_close(quat_from_euler(back, order), q, atol=1e-3)


def test_quat_mul_basis_and_naive():
    """spec/math.md §1.2: i² = j² = k² = ijk = −1, ij = k, and the vectorised product equals the table version."""
    one, i, j, k = np.eye(4)
    assert_close(quat_mul(i, i), -one)
    assert_close(quat_mul(i, j), k)
    assert_close(quat_mul(j, k), i)
    assert_close(quat_mul(k, i), j)
    assert_close(quat_mul(j, i), -k)
    assert_close(quat_mul(quat_mul(i, j), k), -one)
    rng = np.random.default_rng(3)
    q, r = rng.normal(size=(2, 5, 3, 4))
    assert_close(quat_mul(q, r), _quat_mul_naive(q, r), **TIGHT)


@given(quaternions(small_shapes()), quaternions(), quaternions())
def test_quat_mul_associative_and_norm_multiplicative(q, r, s):
    """spec/math.md §1.2-1.3: (qr)s = q(rs), |qr| = |q||r|, (qr)* = r* q*; leading axes broadcast."""
    assert_close(quat_mul(quat_mul(q, r), s), quat_mul(q, quat_mul(r, s)), rtol=1e-12, atol=1e-12)
    assert_close(quat_norm(quat_mul(q, r)), quat_norm(q) * quat_norm(r), rtol=1e-12)
    assert_close(quat_conj(quat_mul(q, r)), quat_mul(quat_conj(r), quat_conj(q)), **TIGHT)
    assert quat_mul(q, r).shape == q.shape


@given(quaternions(small_shapes()))
def test_conj_inverse_identity(q):
    """spec/math.md §1.1, §1.3: q q⁻¹ = q⁻¹ q = 1, q q* = |q|², identity is neutral."""
    one = quat_identity(q.shape[:-1])
    assert_close(quat_mul(q, quat_inv(q)), one, **TIGHT)
    assert_close(quat_mul(quat_inv(q), q), one, **TIGHT)
    assert_close(quat_mul(q, quat_conj(q)), one * quat_norm(q)[..., None] ** 2, **TIGHT)
    assert_close(quat_mul(one, q), q, rtol=0, atol=0)


def test_inverse_tiny_and_huge():
    """spec/math.md §1.3: the inverse is exact for tiny and huge quaternions (no under/overflow of |q|²)."""
    q = np.array([0.5, -0.5, 0.5, 0.5])
    for s in (1e-170, 1e170):
        assert_close(quat_inv(s * q) * s, quat_conj(q), rtol=1e-15, atol=0)


def test_inverse_normalize_zero_raise():
    """spec/math.md §1.3-1.4: zero quaternions are rejected with ValueError at the public boundary."""
    q = np.array([[1.0, 0, 0, 0], [0, 0, 0, 0]])
    for f in (quat_inv, quat_normalize, quat_log, matrix_from_quat, axis_angle_from_quat):
        with pytest.raises(ValueError, match="q"):
            f(q)
    with pytest.raises(ValueError):
        euler_from_quat(q, "zyx")
    with pytest.raises(ValueError, match="norm <= 0.5"):
        quat_normalize([0.1, 0, 0, 0], eps=0.5)


@given(quaternions(small_shapes()), st.sampled_from([1e-200, 1e-310, 1.0, 1e200]))
def test_quat_normalize(q, scale):
    """spec/math.md §1.4: unit result, same direction, robust to tiny (even subnormal) and huge scales."""
    u = quat_normalize(q * scale)
    assert_close(quat_norm(u), np.ones(q.shape[:-1]), rtol=1e-14, atol=0)
    ref = q / np.linalg.norm(q, axis=-1, keepdims=True)
    assert_close(u, ref, rtol=0, atol=1e-9 if scale == 1e-310 else 1e-15)


@given(unit_quaternions(small_shapes()), translations())
def test_quat_rotate_sandwich_matrix_scipy(q, v):
    """spec/math.md §1.5, §4.1: rotate = vec(q (0,v) q*) = R(q) v = scipy's apply (active rotation)."""
    pv = np.concatenate([np.zeros(q.shape[:-1] + (1,)), np.broadcast_to(v, q.shape[:-1] + (3,))], axis=-1)
    sandwich = quat_mul(quat_mul(q, pv), quat_conj(q))[..., 1:]
    rv = quat_rotate(q, v)
    assert_close(rv, sandwich, rtol=1e-12, atol=1e-12)
    assert_close(rv, np.einsum("...ij,...j->...i", matrix_from_quat(q), v), rtol=1e-12, atol=1e-12)
    assert_close(rv.reshape(-1, 3), scipy_rot(q).apply(np.broadcast_to(v, q.shape[:-1] + (3,)).reshape(-1, 3).copy()),
                 rtol=1e-12, atol=1e-12)


@given(unit_quaternions(), unit_quaternions(), translations())
def test_rotation_composition_is_matrix_product(q, r, v):
    """spec/math.md §1.5, §4.1: R(q ⊗ r) = R(q) R(r); rotate(q ⊗ r, v) = rotate(q, rotate(r, v))."""
    assert_close(matrix_from_quat(quat_mul(q, r)), matrix_from_quat(q) @ matrix_from_quat(r), **TIGHT)
    assert_close(quat_rotate(quat_mul(q, r), v), quat_rotate(q, quat_rotate(r, v)), rtol=1e-12, atol=1e-12)


@given(unit_quaternions(), unit_quaternions())
def test_dot_and_angle(q, r):
    """spec/math.md §1.6: angle is the geodesic angle, sign-invariant, equals scipy's magnitude of r q⁻¹ ..."""
    assert_close(quat_dot(q, r), np.sum(q * r), **TIGHT)
    ang = quat_angle(q, r)
    assert 0 <= ang <= math.pi
    assert_close(quat_angle(-q, r), ang, **TIGHT)
    assert_close(quat_angle(q, -r), ang, **TIGHT)
    assert_close(ang, (scipy_rot(q).inv() * scipy_rot(r)).magnitude()[0], rtol=1e-9, atol=1e-9)
    assert_close(quat_angle(q), scipy_rot(q).magnitude()[0], rtol=1e-9, atol=1e-12)


def test_angle_accurate_small_and_near_pi():
    """spec/math.md §1.6: atan2 form keeps tiny angles and angles near π accurate (acos would not)."""
    for a in (1e-12, 1e-7, math.pi - 1e-9, math.pi):
        q = quat_from_axis_angle([0.0, a, 0.0])
        assert_close(quat_angle(q), np.float64(a), rtol=1e-14, atol=0)
        assert_close(quat_angle(quat_identity(), q), np.float64(a), rtol=1e-14, atol=0)


@given(quaternions(small_shapes()))
def test_exp_log_inverse(q):
    """spec/math.md §1.7: exp(log q) = q for non-zero q; log(exp p) = p when |vec p| < π."""
    assert_close(quat_exp(quat_log(q)), q, rtol=1e-12, atol=1e-12)
    p = np.concatenate([q[..., :1], 0.9 * q[..., 1:]], axis=-1)  # |vec p| <= 0.9 · 2 < π
    assert_close(quat_log(quat_exp(p)), p, rtol=1e-12, atol=1e-12)


def test_exp_log_special_values():
    """spec/math.md §1.7: exp of pure (0, v/2) is the axis-angle quaternion; log at u = 0 for both signs of w."""
    v = np.array([0.3, -1.2, 2.0])
    assert_close(quat_exp(np.r_[0.0, v / 2]), quat_from_axis_angle(v), **TIGHT)
    assert_close(quat_log([2.0, 0, 0, 0]), np.array([math.log(2), 0, 0, 0]), **TIGHT)
    assert_close(quat_log([-2.0, 0, 0, 0]), np.array([math.log(2), math.pi, 0, 0]), **TIGHT)
    assert_close(quat_exp([0.0, 1e-20, 0, 0]), np.array([1, 1e-20, 0, 0]), rtol=1e-15, atol=0)
    assert_close(quat_log([1.0, 1e-20, 0, 0]), np.array([0, 1e-20, 0, 0]), rtol=1e-15, atol=0)


def test_quat_canonical():
    """spec/math.md §1.8: the first non-zero component is positive; q and −q map to the same representative."""
    q = np.array([[-0.5, 0.5, 0.5, 0.5], [0, -1.0, 0, 0], [0, 0, 0.6, -0.8], [0, 0, -0.6, 0.8], [0, 0, 0, -1.0]])
    c = quat_canonical(q)
    assert_close(c, np.array([[0.5, -0.5, -0.5, -0.5], [0, 1.0, 0, 0], [0, 0, 0.6, -0.8], [0, 0, 0.6, -0.8],
                              [0, 0, 0, 1.0]]), rtol=0, atol=0)
    r = random_unit(50)
    assert_close(quat_canonical(-r), quat_canonical(r), rtol=0, atol=0)
    assert np.all(quat_canonical(r)[:, 0] >= 0)


@given(unit_quaternions(st.tuples(st.integers(1, 12), st.integers(1, 3))))
def test_quat_fix(q):
    """spec/math.md §1.8: consecutive dots >= 0, every frame ±input, frame 0 unchanged, equals the loop version."""
    f = quat_fix(q)
    assert np.all(np.sum(f[1:] * f[:-1], axis=-1) >= 0)
    assert np.all(np.isclose(np.abs(np.sum(f * q, axis=-1)), 1.0))
    assert_close(f[0], q[0], rtol=0, atol=0)
    for j in range(q.shape[1]):
        assert_close(f[:, j], _quat_fix_naive(q[:, j]), rtol=0, atol=0)
    with pytest.raises(ValueError, match=r"\(T, \.\.\., 4\)"):
        quat_fix(np.array([1.0, 0, 0, 0]))


# --------------------------------------------------------------------------------------------------------------
# §1.9 slerp
# --------------------------------------------------------------------------------------------------------------

@given(unit_quaternions(), unit_quaternions(), st.floats(0, 1))
def test_slerp_endpoints_speed_shortest(q0, q1, t):
    """spec/math.md §1.9: endpoints, constant angular speed along the shortest arc, unit result, scipy's Slerp."""
    assert_quat_close(quat_slerp(q0, q1, 0.0), q0, atol=1e-12)
    assert_quat_close(quat_slerp(q0, q1, 1.0), q1, atol=1e-12)
    qt = quat_slerp(q0, q1, t)
    assert_close(quat_norm(qt), np.float64(1), rtol=1e-12)
    assert_close(quat_slerp(q0, -q1, t), qt, **TIGHT)  # shortest path: the stored sign of q1 is irrelevant
    assert_close(quat_slerp(-q0, q1, t), -qt, **TIGHT)
    total = quat_angle(q0, q1)  # <= π: the shortest rotation between them
    assert_close(quat_angle(q0, qt), t * total, rtol=1e-9, atol=1e-9)
    assert_close(quat_angle(qt, q1), (1 - t) * total, rtol=1e-9, atol=1e-9)
    assume(total < math.pi - 1e-6)  # scipy's path is ambiguous at exactly 180°
    ref = Slerp([0, 1], Rotation.from_quat(np.stack([quat_xyzw_from_wxyz(q0), quat_xyzw_from_wxyz(q1)])))([t])
    assert_close(matrix_from_quat(qt), ref.as_matrix()[0], rtol=1e-9, atol=1e-9)


def test_slerp_near_zero_antipodal_and_broadcast():
    """spec/math.md §1.9: identical/nearly identical/antipodal inputs are stable; t broadcasts over leading axes."""
    q = random_unit(3, seed=5)
    for other in (q, -q, quat_normalize(q + 1e-13)):
        for t in (0.0, 0.3, 1.0, 1.7):
            assert_quat_close(quat_slerp(q, other, t), q, atol=1e-12)
    q0, q1 = random_unit(2, seed=7)
    ts = np.linspace(0, 1, 5)
    out = quat_slerp(q0, q1, ts)
    assert out.shape == (5, 4)
    for k, t in enumerate(ts):
        assert_close(out[k], quat_slerp(q0, q1, t), **TIGHT)
    # rotations exactly 180° apart (⟨q0, q1⟩ = 0): the tie is broken by the canonical relative rotation, so the
    # stored sign of q1 does not matter and the sign of q0 only flips the result
    a, b = quat_identity(), np.array([0.0, 0, 0, 1])
    half = np.array([math.sqrt(0.5), 0, 0, math.sqrt(0.5)])
    for sb in (1, -1):
        assert_close(quat_slerp(a, sb * b, 0.5), half, **TIGHT)
        assert_close(quat_slerp(-a, sb * b, 0.5), -half, **TIGHT)
    a, b = np.array([0.0, 1, 0, 0]), np.array([1.0, 0, 0, 0])  # relative rotation (0, −1, 0, 0) → −b is used
    assert_close(quat_slerp(a, b, 1.0), -b, **TIGHT)


# --------------------------------------------------------------------------------------------------------------
# §2 axis-angle
# --------------------------------------------------------------------------------------------------------------

@given(unit_quaternions(small_shapes()))
def test_axis_angle_round_trip_and_scipy(q):
    """spec/math.md §2.1: log map ∘ exp map, against scipy's rotvec in both directions."""
    v = axis_angle_from_quat(q)
    assert np.all(np.linalg.norm(v, axis=-1) <= math.pi + 1e-12)
    assert_quat_close(quat_from_axis_angle(v), q, atol=1e-12)
    ref = scipy_rot(q).as_rotvec()
    at_pi = np.abs(q.reshape(-1, 4)[:, 0]) < 1e-12  # θ = π: v and −v are the same rotation
    ref[at_pi] *= np.where(np.sum(ref[at_pi] * v.reshape(-1, 3)[at_pi], axis=-1) < 0, -1, 1)[:, None]
    assert_close(v.reshape(-1, 3), ref, rtol=1e-9, atol=1e-12)
    assert_close(axis_angle_from_quat(-q), v, rtol=0, atol=0)
    assert_quat_close(quat_from_axis_angle(v).reshape(-1, 4), quat_wxyz_from_xyzw(Rotation.from_rotvec(
        v.reshape(-1, 3)).as_quat()), atol=1e-12)


def test_axis_angle_zero_tiny_and_two_pi():
    """spec/math.md §2.1: exact identity at 0, full relative precision for tiny vectors, correct at and near 2π."""
    assert_close(quat_from_axis_angle(np.zeros(3)), quat_identity(), rtol=0, atol=0)
    assert_close(axis_angle_from_quat(quat_identity()), np.zeros(3), rtol=0, atol=0)
    v = np.array([1e-9, -2e-9, 3e-10])
    q = quat_from_axis_angle(v)
    assert_close(q, np.r_[1.0, v / 2], rtol=1e-15, atol=0)
    assert_close(axis_angle_from_quat(q), v, rtol=1e-15, atol=0)
    n = np.array([2.0, -1.0, 2.0]) / 3
    for d in (1e-3, 1e-9, 0.0):
        q = quat_from_axis_angle((2 * math.pi - d) * n)
        assert q[0] < 0  # no canonicalisation in the exponential map
        assert_close(matrix_from_quat(q), matrix_from_quat(quat_from_axis_angle(-d * n)), rtol=0, atol=1e-14)
        assert_close(axis_angle_from_quat(q), -d * n, rtol=1e-6, atol=1e-15)
    # angle exactly π: q and −q give the same vector, first non-zero component positive
    for s in (1, -1):
        v = axis_angle_from_quat(s * np.array([0.0, 0, -0.6, 0.8]))
        assert_close(v, math.pi * np.array([0, 0.6, -0.8]), **TIGHT)


# --------------------------------------------------------------------------------------------------------------
# §3 Euler angles
# --------------------------------------------------------------------------------------------------------------

@given(st.data(), euler_orders())
def test_euler_round_trip_and_scipy(data, order):
    """spec/math.md §3.1-3.2, conventions §2: round trip away from gimbal lock; scipy's intrinsic (upper-case)."""
    a = data.draw(euler_angles(order, small_shapes()))
    q = quat_from_euler(a, order)
    assert_close(euler_from_quat(q, order), a, rtol=1e-9, atol=1e-9)
    ref = Rotation.from_euler(order.upper(), a.reshape(-1, 3))
    assert_quat_close(q.reshape(-1, 4), quat_wxyz_from_xyzw(ref.as_quat()), atol=1e-12)
    assert_close(matrix_from_euler(a, order).reshape(-1, 3, 3), ref.as_matrix(), rtol=1e-12, atol=1e-12)
    assert_close(euler_from_matrix(matrix_from_euler(a, order), order), a, rtol=1e-9, atol=1e-9)
    assert_close(euler_from_quat(q, order.upper()), euler_from_quat(q, order), rtol=0, atol=0)


@pytest.mark.parametrize("order", EULER_ORDERS)
def test_euler_from_quat_matches_scipy(order):
    """spec/math.md §3.2: on random rotations the angles (and their ranges) equal scipy's as_euler (intrinsic)."""
    q = random_unit(300, seed=11)
    ours = euler_from_quat(q, order)
    ref = scipy_rot(q).as_euler(order.upper())
    diff = np.angle(np.exp(1j * (ours - ref)))  # equal modulo 2π (the ±π wrap)
    assert np.max(np.abs(diff)) < 1e-9
    assert np.all(ours[:, [0, 2]] >= -math.pi) and np.all(ours[:, [0, 2]] < math.pi)
    lo, hi = (0, math.pi) if order in PROPER_EULER_ORDERS else (-math.pi / 2, math.pi / 2)
    assert np.all(ours[:, 1] >= lo) and np.all(ours[:, 1] <= hi)


@pytest.mark.parametrize("order", EULER_ORDERS)
def test_euler_gimbal_lock(order):
    """spec/math.md §3.2: at gimbal lock the last angle is 0 and the angles reproduce the rotation."""
    rng = np.random.default_rng(2)
    locks = (0.0, math.pi) if order in PROPER_EULER_ORDERS else (-math.pi / 2, math.pi / 2)
    for mid in locks:
        for eps in (0.0, 1e-12):
            a = np.stack([rng.uniform(-3, 3, 20), np.full(20, mid + (eps if mid <= 0 else -eps)),
                          rng.uniform(-3, 3, 20)], axis=-1)
            q = quat_from_euler(a, order)
            back = euler_from_quat(q, order)
            assert_close(back[:, 2], np.zeros(20), rtol=0, atol=0)
            assert_quat_close(quat_from_euler(back, order), q, atol=1e-8)
            assert_close(matrix_from_euler(back, order), matrix_from_quat(q), rtol=0, atol=1e-8)


def test_euler_paper_eq7_and_eq5():
    """spec/math.md §3.1-3.2: the paper's Eq. 5 (q = q_z q_y q_x) and Eq. 7 (x, y, z angles) for order zyx."""
    rng = np.random.default_rng(4)
    z, y, x = rng.uniform(-1.2, 1.2, size=(3, 50))
    q = quat_from_euler(np.stack([z, y, x], -1), "zyx")
    qx = np.stack([np.cos(x / 2), np.sin(x / 2), 0 * x, 0 * x], -1)
    qy = np.stack([np.cos(y / 2), 0 * y, np.sin(y / 2), 0 * y], -1)
    qz = np.stack([np.cos(z / 2), 0 * z, 0 * z, np.sin(z / 2)], -1)
    assert_close(q, quat_mul(quat_mul(qz, qy), qx), **TIGHT)
    w, qi, qj, qk = q.T
    alpha = np.arctan2(2 * (w * qi + qj * qk), 1 - 2 * (qi ** 2 + qj ** 2))
    beta = np.arcsin(2 * (w * qj - qk * qi))
    gamma = np.arctan2(2 * (w * qk + qi * qj), 1 - 2 * (qj ** 2 + qk ** 2))
    assert_close(euler_from_quat(q, "zyx"), np.stack([gamma, beta, alpha], -1), rtol=1e-9, atol=1e-12)


def test_bvh_channel_order_zxy():
    """spec/conventions.md §2: BVH 'Zrotation Xrotation Yrotation' = order 'zxy' = Rz·Rx·Ry (explicit matrices)."""
    z, x, y = 0.7, -0.4, 1.9  # values in channel order
    expected = elementary("z", z) @ elementary("x", x) @ elementary("y", y)
    assert_close(matrix_from_euler([z, x, y], "zxy"), expected, **TIGHT)
    assert_close(matrix_from_euler([z, x, y], "ZXY"), expected, **TIGHT)
    assert_close(matrix_from_quat(quat_from_euler([z, x, y], "zxy")), expected, **TIGHT)
    # the dual-quaternion paper's zyx: R = Rz Ry Rx, x applied first to column vectors
    assert_close(matrix_from_euler([z, y, x], "zyx"), elementary("z", z) @ elementary("y", y) @ elementary("x", x),
                 **TIGHT)
    # proper order
    assert_close(matrix_from_euler([z, x, y], "zxz"), elementary("z", z) @ elementary("x", x) @ elementary("z", y),
                 **TIGHT)


@pytest.mark.parametrize("bad", ["zzx", "xy", "xyzx", "abc", "xyy", 3, None])
def test_bad_euler_order(bad):
    """spec/math.md §3.1: invalid orders raise ValueError naming `order`."""
    with pytest.raises(ValueError, match="order"):
        quat_from_euler(np.zeros(3), bad)
    with pytest.raises(ValueError, match="order"):
        euler_from_quat(quat_identity(), bad)


# --------------------------------------------------------------------------------------------------------------
# §4 matrices and 6-D
# --------------------------------------------------------------------------------------------------------------

@given(quaternions(small_shapes()))
def test_matrix_quat_round_trip_and_scipy(q):
    """spec/math.md §4.1-4.2: R(q) = R(q/|q|) = scipy; quat_from_matrix inverts it (w >= 0) = naive Shepperd."""
    m = matrix_from_quat(q)
    assert_close(m.reshape(-1, 3, 3), scipy_rot(q).as_matrix(), rtol=1e-12, atol=1e-12)
    back = quat_from_matrix(m)
    assert np.all(back[..., 0] >= 0)
    assert_quat_close(back, quat_normalize(q), atol=1e-12)
    assert_close(back, _quat_from_matrix_naive(m), rtol=1e-12, atol=1e-14)


def test_quat_from_matrix_180_degrees():
    """spec/math.md §4.2: 180° rotations (w = 0, trace = −1), about coordinate axes and random axes."""
    rng = np.random.default_rng(9)
    axes = np.concatenate([np.eye(3), -np.eye(3), rng.normal(size=(30, 3))])
    axes /= np.linalg.norm(axes, axis=-1, keepdims=True)
    m = 2 * axes[:, :, None] * axes[:, None, :] - np.eye(3)  # R(π, n) = 2nnᵀ − I
    q = quat_from_matrix(m)
    assert_quat_close(q, np.concatenate([np.zeros((len(axes), 1)), axes], axis=-1), atol=1e-15)
    assert_close(matrix_from_quat(q), m, rtol=0, atol=1e-15)
    assert_close(q, _quat_from_matrix_naive(m), rtol=0, atol=1e-15)
    # near 180°
    q2 = quat_from_matrix(matrix_from_quat(quat_from_axis_angle((math.pi - 1e-10) * axes)))
    assert_quat_close(q2, quat_from_axis_angle((math.pi - 1e-10) * axes), atol=1e-14)


def test_quat_from_matrix_rejects_non_rotations():
    """spec/math.md §4.2, §6: non-orthonormal matrices and reflections raise ValueError."""
    with pytest.raises(ValueError, match="orthonormal"):
        quat_from_matrix(np.eye(3) * 1.1)
    with pytest.raises(ValueError, match="determinant"):
        quat_from_matrix(np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(ValueError, match=r"\(\.\.\., 3, 3\)"):
        quat_from_matrix(np.eye(4))
    quat_from_matrix(np.eye(3) + 1e-8)  # within the float64 tolerance


@given(rotation_matrices(small_shapes()))
def test_ortho6d(m):
    """spec/math.md §4.3: layout = first two columns; Gram-Schmidt inverts it; noisy input gives a rotation."""
    x = ortho6d_from_matrix(m)
    assert_close(x[..., :3], m[..., :, 0], rtol=0, atol=0)
    assert_close(x[..., 3:], m[..., :, 1], rtol=0, atol=0)
    assert_close(matrix_from_ortho6d(x), m, rtol=1e-12, atol=1e-12)
    noisy = 2.5 * x + 0.1 * np.cos(np.arange(6))  # a different 6-vector, still non-degenerate
    r = matrix_from_ortho6d(noisy)
    assert_close(np.swapaxes(r, -1, -2) @ r, np.broadcast_to(np.eye(3), r.shape), rtol=0, atol=1e-12)
    assert_close(np.linalg.det(r), np.ones(r.shape[:-2]), rtol=1e-12)


def test_ortho6d_zhou_cross_product_form_and_degenerate():
    """spec/math.md §4.3: equals Zhou et al.'s cross-product construction; parallel columns raise ValueError."""
    x = np.random.default_rng(1).normal(size=(20, 6))
    a1, a2 = x[:, :3], x[:, 3:]
    bx = a1 / np.linalg.norm(a1, axis=-1, keepdims=True)
    bz = np.cross(bx, a2)
    bz /= np.linalg.norm(bz, axis=-1, keepdims=True)
    by = np.cross(bz, bx)
    assert_close(matrix_from_ortho6d(x), np.stack([bx, by, bz], axis=-1), rtol=1e-12, atol=1e-12)
    with pytest.raises(ValueError, match="parallel"):
        matrix_from_ortho6d([1.0, 2, 3, 2, 4, 6])
    with pytest.raises(ValueError, match="zero"):
        matrix_from_ortho6d([0.0, 0, 0, 2, 4, 6])


def test_layout_converters():
    """spec/conventions.md §1: (w,x,y,z) ↔ (x,y,z,w) as scipy expects."""
    q = random_unit(10)
    assert_close(quat_wxyz_from_xyzw(quat_xyzw_from_wxyz(q)), q, rtol=0, atol=0)
    assert_close(quat_xyzw_from_wxyz([1.0, 2, 3, 4]), np.array([2.0, 3, 4, 1]), rtol=0, atol=0)
    assert_close(Rotation.from_quat(quat_xyzw_from_wxyz(q)).as_matrix(), matrix_from_quat(q), **TIGHT)


# --------------------------------------------------------------------------------------------------------------
# §6 dtype policy and validation
# --------------------------------------------------------------------------------------------------------------

Q4 = np.array([0.5, 0.5, -0.5, 0.5])
CALLS = [
    ("quat_mul", lambda a: quat_mul(a, a), Q4),
    ("quat_conj", quat_conj, Q4),
    ("quat_inv", quat_inv, Q4),
    ("quat_norm", quat_norm, Q4),
    ("quat_normalize", quat_normalize, Q4),
    ("quat_rotate", lambda a: quat_rotate(a, a[..., 1:]), Q4),
    ("quat_dot", lambda a: quat_dot(a, a), Q4),
    ("quat_angle", quat_angle, Q4),
    ("quat_exp", quat_exp, Q4),
    ("quat_log", quat_log, Q4),
    ("quat_canonical", quat_canonical, Q4),
    ("quat_fix", quat_fix, np.stack([Q4, -Q4])),
    ("quat_slerp", lambda a: quat_slerp(a, quat_conj(a), 0.25), Q4),
    ("quat_from_axis_angle", quat_from_axis_angle, Q4[1:]),
    ("axis_angle_from_quat", axis_angle_from_quat, Q4),
    ("quat_from_euler", lambda a: quat_from_euler(a, "zxy"), Q4[1:]),
    ("euler_from_quat", lambda a: euler_from_quat(a, "zxz"), Q4),
    ("matrix_from_euler", lambda a: matrix_from_euler(a, "xyz"), Q4[1:]),
    ("euler_from_matrix", lambda a: euler_from_matrix(a, "xyz"), np.eye(3)),
    ("matrix_from_quat", matrix_from_quat, Q4),
    ("quat_from_matrix", quat_from_matrix, np.eye(3)),
    ("ortho6d_from_matrix", ortho6d_from_matrix, np.eye(3)),
    ("matrix_from_ortho6d", matrix_from_ortho6d, np.array([1.0, 0, 0, 0, 1, 0])),
    ("quat_xyzw_from_wxyz", quat_xyzw_from_wxyz, Q4),
    ("quat_wxyz_from_xyzw", quat_wxyz_from_xyzw, Q4),
]


@pytest.mark.parametrize("name,f,x", CALLS, ids=[c[0] for c in CALLS])
def test_dtype_preserved(name, f, x):
    """spec/math.md §6: float32 stays float32 (and agrees with float64), float64 stays float64, ints → float64."""
    out64 = f(x.astype(np.float64))
    out32 = f(x.astype(np.float32))
    assert out64.dtype == np.float64
    assert out32.dtype == np.float32, f"{name} returned {out32.dtype} for float32 input"
    assert_close(out32, out64, rtol=1e-5, atol=1e-6, name=name)
    if name not in ("quat_slerp",):
        xi = np.rint(x * 2).astype(np.int64)  # integer input
        if name in ("euler_from_matrix", "quat_from_matrix", "ortho6d_from_matrix"):
            xi = np.eye(3, dtype=np.int64)
        if name == "matrix_from_ortho6d":
            xi = np.array([1, 0, 0, 0, 1, 0])
        if name == "quat_fix":
            xi = np.array([[1, 0, 0, 0], [-1, 0, 0, 0]])
        assert f(xi).dtype == np.float64


BAD_SHAPES = [
    ("quat_mul", lambda a: quat_mul(a, a), (3,)),
    ("quat_conj", quat_conj, (5,)),
    ("quat_inv", quat_inv, (2, 3)),
    ("quat_normalize", quat_normalize, (4, 3)),
    ("quat_rotate", lambda a: quat_rotate(a, np.zeros(3)), (3,)),
    ("quat_angle", quat_angle, (3,)),
    ("quat_log", quat_log, (3,)),
    ("quat_fix", quat_fix, (5, 3)),
    ("quat_slerp", lambda a: quat_slerp(a, a, 0.5), (3,)),
    ("quat_from_axis_angle", quat_from_axis_angle, (4,)),
    ("axis_angle_from_quat", axis_angle_from_quat, (3,)),
    ("quat_from_euler", lambda a: quat_from_euler(a, "zyx"), (4,)),
    ("euler_from_quat", lambda a: euler_from_quat(a, "zyx"), (3,)),
    ("matrix_from_quat", matrix_from_quat, (3, 3)),
    ("quat_from_matrix", quat_from_matrix, (3, 4)),
    ("ortho6d_from_matrix", ortho6d_from_matrix, (4, 4)),
    ("matrix_from_ortho6d", matrix_from_ortho6d, (9,)),
]


@pytest.mark.parametrize("name,f,shape", BAD_SHAPES, ids=[c[0] for c in BAD_SHAPES])
def test_bad_shapes_raise(name, f, shape):
    """spec/math.md §6: wrong trailing shapes raise ValueError giving the expected and the actual shape."""
    with pytest.raises(ValueError, match=r"expected shape .* got " + re_escape_shape(shape)):
        f(np.ones(shape))


def re_escape_shape(shape) -> str:
    import re
    return re.escape(str(tuple(shape)))


def test_nan_and_non_float_rejected():
    """spec/math.md §6: NaN/inf and complex inputs raise ValueError naming the argument."""
    with pytest.raises(ValueError, match="q: expected finite values, got NaN"):
        quat_normalize([np.nan, 0, 0, 1])
    with pytest.raises(ValueError, match="v: expected finite values, got NaN or inf"):
        quat_rotate(quat_identity(), [np.inf, 0, 0])
    with pytest.raises(ValueError, match="real floating"):
        quat_conj(np.ones(4, dtype=complex))
    with pytest.raises(ValueError, match="t"):
        quat_slerp(quat_identity(), quat_identity(), np.nan)


def test_public_names_exist():
    """spec/math.md: every name in __all__ of refimpl.quat and refimpl.rotations is defined."""
    for mod in (Q, R):
        for name in mod.__all__:
            assert hasattr(mod, name), name
    assert len(EULER_ORDERS) == 12 and len(set(EULER_ORDERS)) == 12 and len(TAIT_BRYAN_ORDERS) == 6
