"""Tests of refimpl.dualquat (spec/math.md §5-6; paper Eq. 1-3, 6, 8, 13; spec/conventions.md §4).

Rigid transforms are cross-checked against 4×4 homogeneous matrices built independently with scipy.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from refimpl import dualquat as D
from refimpl.dualquat import (_dq_blend_naive, _dq_fix_naive, _dq_transform_point_naive, dq_blend, dq_conj,
                              dq_conj_combined, dq_conj_dual, dq_fix, dq_from_matrix, dq_from_quat_translation,
                              dq_identity, dq_inv, dq_is_unit, dq_mul, dq_norm, dq_normalize, dq_sclerp,
                              dq_transform_point, matrix_from_dq, quat_translation_from_dq, translation_from_dq)
from refimpl.quat import quat_angle, quat_conj, quat_identity, quat_mul, quat_rotate, quat_slerp, quat_xyzw_from_wxyz
from refimpl.rotations import quat_from_axis_angle
from refimpl.strategies import small_shapes, translations, unit_dual_quaternions, unit_quaternions
from refimpl.testing import assert_close

TIGHT = dict(rtol=1e-12, atol=1e-12)


def homogeneous(q: np.ndarray, t: np.ndarray) -> np.ndarray:
    """[[R, t], [0, 1]] with R from scipy (independent of refimpl)."""
    m = np.zeros(q.shape[:-1] + (4, 4))
    m[..., :3, :3] = Rotation.from_quat(quat_xyzw_from_wxyz(q).reshape(-1, 4)).as_matrix().reshape(q.shape[:-1] + (3, 3))
    m[..., :3, 3] = t
    m[..., 3, 3] = 1
    return m


def sign_aligned(a: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """``a`` or ``−a`` (all 8 numbers), whichever real part is in the hemisphere of ``ref``'s."""
    return np.where(np.sum(a[..., :4] * ref[..., :4], axis=-1, keepdims=True) < 0, -a, a)


def random_dq(n: int, seed: int = 0, scale_t: float = 3.0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    return dq_from_quat_translation(q, scale_t * rng.normal(size=(n, 3)))


# --------------------------------------------------------------------------------------------------------------
# §5.2 product, §5.3 conjugates and inverse
# --------------------------------------------------------------------------------------------------------------

@given(unit_dual_quaternions(small_shapes()), unit_dual_quaternions(), unit_dual_quaternions())
def test_dq_mul_eq1_associative_closed(a, b, c):
    """spec/math.md §5.2 (Eq. 1): definition by parts, associativity, unit DQs closed under the product."""
    ab = dq_mul(a, b)
    assert_close(ab[..., :4], quat_mul(a[..., :4], b[..., :4]), **TIGHT)
    assert_close(ab[..., 4:], quat_mul(a[..., :4], b[..., 4:]) + quat_mul(a[..., 4:], b[..., :4]), **TIGHT)
    assert_close(dq_mul(ab, c), dq_mul(a, dq_mul(b, c)), rtol=1e-11, atol=1e-11)
    assert np.all(dq_is_unit(ab, atol_norm=1e-12, atol_dot=1e-11))
    assert_close(dq_mul(dq_identity(), a), a, rtol=0, atol=0)


@given(unit_quaternions(), translations(), unit_quaternions(), translations(), translations())
def test_dq_mul_composes_transforms(q1, t1, q2, t2, p):
    """spec/math.md §5.2, §5.9: T(a ⊗ b) = T(a) ∘ T(b), i.e. M(a ⊗ b) = M(a) M(b) (scipy matrices)."""
    a, b = dq_from_quat_translation(q1, t1), dq_from_quat_translation(q2, t2)
    ab = dq_mul(a, b)
    assert_close(matrix_from_dq(ab), homogeneous(q1, t1) @ homogeneous(q2, t2), rtol=1e-12, atol=1e-11)
    assert_close(dq_transform_point(ab, p), dq_transform_point(a, dq_transform_point(b, p)), rtol=1e-12, atol=1e-11)


def test_conjugate_sign_patterns():
    """spec/math.md §5.3: quaternion, dual-number and combined conjugates."""
    a = np.arange(1.0, 9.0)
    assert_close(dq_conj(a), np.array([1, -2, -3, -4, 5, -6, -7, -8.0]), rtol=0, atol=0)
    assert_close(dq_conj_dual(a), np.array([1, 2, 3, 4, -5, -6, -7, -8.0]), rtol=0, atol=0)
    assert_close(dq_conj_combined(a), np.array([1, -2, -3, -4, -5, 6, 7, 8.0]), rtol=0, atol=0)


@given(unit_dual_quaternions(small_shapes()), st.floats(0.5, 2.0), unit_dual_quaternions())
def test_inverse_laws(a, s, b):
    """spec/math.md §5.3: conj = inverse for unit DQs; general inverse of non-unit DQs; (ab)* = b* a*."""
    one = dq_identity(a.shape[:-1])
    assert_close(dq_mul(a, dq_conj(a)), one, **TIGHT)
    assert_close(dq_conj(a), dq_inv(a), **TIGHT)
    g = s * a + 0.1 * np.concatenate([np.zeros(4), np.ones(4)])  # non-unit, does not satisfy Eq. 3
    assert_close(dq_mul(g, dq_inv(g)), one, rtol=1e-12, atol=1e-12)
    assert_close(dq_mul(dq_inv(g), g), one, rtol=1e-12, atol=1e-12)
    assert_close(dq_conj(dq_mul(a, b)), dq_mul(dq_conj(b), dq_conj(a)), **TIGHT)
    with pytest.raises(ValueError, match="real part"):
        dq_inv(np.r_[np.zeros(4), np.ones(4)])


# --------------------------------------------------------------------------------------------------------------
# §5.4 norm and unit test, §5.5 normalisation
# --------------------------------------------------------------------------------------------------------------

@given(unit_dual_quaternions(small_shapes()), st.floats(0.5, 2.0), st.floats(-1.0, 1.0))
def test_dq_norm_eq2(a, s, e):
    """spec/math.md §5.4 (Eq. 2): (|q|)² as a dual number equals q ⊗ q* = (|q_r|², 0,0,0 | 2⟨q_r,q_d⟩, 0,0,0)."""
    g = s * a
    g[..., 4:] += e * g[..., :4]  # add a component along q_r: ⟨q_r, q_d⟩ ≠ 0
    real, dual = dq_norm(g)
    prod = dq_mul(g, dq_conj(g))
    assert_close(real ** 2, prod[..., 0], rtol=1e-12)
    assert_close(2 * real * dual, prod[..., 4], rtol=1e-12, atol=1e-12)
    assert_close(prod[..., [1, 2, 3, 5, 6, 7]], np.zeros(g.shape[:-1] + (6,)), rtol=0, atol=1e-11)
    assert_close(real, s * np.ones(g.shape[:-1]), rtol=1e-12)


def test_dq_is_unit_eq3_absolute():
    """spec/math.md §5.4 (Eq. 3): both conditions with ABSOLUTE comparisons (acRNN's signed test would pass these)."""
    a = random_dq(4)
    assert np.all(dq_is_unit(a))
    assert not np.any(dq_is_unit(0.5 * a))  # | |q_r| − 1 | = 0.5
    bad = a.copy()
    bad[:, 4:] -= 0.01 * a[:, :4]  # ⟨q_r, q_d⟩ = −0.01
    assert not np.any(dq_is_unit(bad))
    assert np.all(dq_is_unit(bad, atol_dot=0.02))
    assert dq_is_unit(a.astype(np.float32)).dtype == bool


@given(unit_dual_quaternions(small_shapes()), st.floats(0.1, 10.0), st.floats(-2.0, 2.0))
def test_dq_normalize_eq13(a, s, e):
    """spec/math.md §5.5 (Eq. 13): output satisfies Eq. 3, keeps the translation, undoes scaling, is idempotent,
    and is the division by the dual magnitude of Eq. 2."""
    g = s * a
    g[..., 4:] += e * g[..., :4]
    n = dq_normalize(g)
    assert np.all(dq_is_unit(n, atol_norm=1e-12, atol_dot=1e-12))
    assert_close(translation_from_dq(n), translation_from_dq(a), rtol=1e-10, atol=1e-10)
    assert_close(n[..., :4], a[..., :4], rtol=1e-12, atol=1e-12)
    assert_close(n, a, rtol=1e-10, atol=1e-10)  # a is unit, so g/|g| = a
    assert_close(dq_normalize(n), n, rtol=1e-12, atol=1e-12)
    real, dual = dq_norm(g)
    mag = np.concatenate([real[..., None], np.zeros(real.shape + (3,)), dual[..., None], np.zeros(real.shape + (3,))],
                         axis=-1)  # the dual number |g| as a DQ
    assert_close(dq_mul(n, mag), g, rtol=1e-10, atol=1e-10)


def test_dq_normalize_zero_real_part_raises():
    """spec/math.md §5.5: |q_r| = 0 has no rigid transform: ValueError (no identity substituted)."""
    a = np.stack([dq_identity(), np.r_[np.zeros(4), 1.0, 2, 3, 4]])
    with pytest.raises(ValueError, match=r"a: zero real part at index \(1,\)"):
        dq_normalize(a)
    for f in (translation_from_dq, matrix_from_dq, quat_translation_from_dq, dq_norm):
        with pytest.raises(ValueError, match="real part"):
            f(a)


# --------------------------------------------------------------------------------------------------------------
# §5.6-5.9 construction, translation, matrices, point transform
# --------------------------------------------------------------------------------------------------------------

@given(unit_quaternions(small_shapes()), translations(), translations())
def test_from_quat_translation_eq6_eq8(q, t, p):
    """spec/math.md §5.6-5.7, §5.9 (Eq. 6 and 8): q_d = ½ (0,t) ⊗ q_r; t = vec(2 q_d q_r*); transform = R p + t."""
    a = dq_from_quat_translation(q, t)
    tb = np.broadcast_to(t, q.shape[:-1] + (3,))
    pure = np.concatenate([np.zeros(q.shape[:-1] + (1,)), tb], axis=-1)
    assert_close(a[..., 4:], 0.5 * quat_mul(pure, q), **TIGHT)
    assert_close(translation_from_dq(a), tb, rtol=1e-12, atol=1e-12)
    assert_close(2 * quat_mul(a[..., 4:], quat_conj(a[..., :4]))[..., 1:], tb, rtol=1e-12, atol=1e-12)
    qq, tt = quat_translation_from_dq(3.0 * a)  # scaled DQ: same transform
    assert_close(qq, q, rtol=1e-12, atol=1e-15)
    assert_close(tt, tb, rtol=1e-12, atol=1e-12)
    expected = quat_rotate(q, p) + t
    assert_close(dq_transform_point(a, p), expected, rtol=1e-12, atol=1e-11)
    assert_close(_dq_transform_point_naive(a, np.broadcast_to(p, a.shape[:-1] + (3,))), expected,
                 rtol=1e-12, atol=1e-11)


def test_pure_translation_and_paper_typo():
    """spec/math.md §5.6, conventions §4: pure translation is (1,0,0,0 | 0, t/2); the right-multiplied variant
    ½ q_r ⊗ (0,t) would translate by R t instead (translate first, then rotate), which we do not use."""
    t = np.array([1.0, -2.0, 0.5])
    assert_close(dq_from_quat_translation(quat_identity(), t), np.r_[1.0, 0, 0, 0, 0, t / 2], rtol=0, atol=0)
    q = quat_from_axis_angle([0.0, 0.0, math.pi / 2])
    a = dq_from_quat_translation(q, t)
    assert_close(dq_transform_point(a, np.zeros(3)), t, **TIGHT)  # origin ↦ t
    other = np.r_[q, 0.5 * quat_mul(q, np.r_[0.0, t])]
    assert_close(translation_from_dq(other), quat_rotate(q, t), **TIGHT)


@given(unit_quaternions(small_shapes()), translations())
def test_matrix_round_trip(q, t):
    """spec/math.md §5.8: dq_from_matrix ∘ matrix_from_dq = identity (up to sign) and matches scipy's [R t]."""
    m = homogeneous(q, np.broadcast_to(t, q.shape[:-1] + (3,)))
    a = dq_from_matrix(m)
    assert np.all(a[..., 0] >= 0)
    assert_close(a, sign_aligned(dq_from_quat_translation(q, t), a), rtol=1e-12, atol=1e-12)
    assert_close(matrix_from_dq(a), m, rtol=1e-12, atol=1e-12)
    assert_close(matrix_from_dq(-a), m, rtol=1e-12, atol=1e-12)


def test_scipy_rigid_transform_dual_quaternion():
    """spec/conventions.md §4, spec/math.md §5.6-5.8: our (q_r | q_d) equals scipy's RigidTransform.as_dual_quat
    with scalar_first=True (an independent implementation), and its matrix."""
    try:
        from scipy.spatial.transform import RigidTransform
    except ImportError:  # scipy < 1.16
        pytest.skip("scipy.spatial.transform.RigidTransform is not available")
    rng = np.random.default_rng(12)
    q = rng.normal(size=(20, 4))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    t = rng.normal(size=(20, 3))
    tf = RigidTransform.from_components(t, Rotation.from_quat(quat_xyzw_from_wxyz(q)))
    ref = tf.as_dual_quat(scalar_first=True)
    ours = dq_from_quat_translation(q, t)
    assert_close(ours, sign_aligned(ref, ours), rtol=1e-12, atol=1e-12)
    assert_close(matrix_from_dq(ours), tf.as_matrix(), rtol=1e-12, atol=1e-12)
    back = RigidTransform.from_dual_quat(ours, scalar_first=True)
    assert_close(back.as_matrix(), tf.as_matrix(), rtol=1e-12, atol=1e-12)


def test_dq_from_matrix_validation():
    """spec/math.md §5.8, §6: last row must be (0,0,0,1); the rotation block must be a rotation."""
    m = np.eye(4)
    m[3, 0] = 0.5
    with pytest.raises(ValueError, match="last row"):
        dq_from_matrix(m)
    m = np.eye(4)
    m[0, 0] = -1
    with pytest.raises(ValueError, match="determinant"):
        dq_from_matrix(m)
    with pytest.raises(ValueError, match=r"\(\.\.\., 4, 4\)"):
        dq_from_matrix(np.eye(3))


# --------------------------------------------------------------------------------------------------------------
# §5.10 fix, §5.11 ScLERP, §5.12 blending
# --------------------------------------------------------------------------------------------------------------

@given(unit_dual_quaternions(st.tuples(st.integers(1, 10), st.integers(1, 3))))
def test_dq_fix(a):
    """spec/math.md §5.10: consecutive real-part dots >= 0, all 8 numbers flipped together, same transforms."""
    f = dq_fix(a)
    assert np.all(np.sum(f[1:, :, :4] * f[:-1, :, :4], axis=-1) >= 0)
    s = np.sign(np.sum(f[..., :4] * a[..., :4], axis=-1, keepdims=True))
    assert_close(f, s * a, rtol=0, atol=0)
    assert_close(matrix_from_dq(f), matrix_from_dq(a), rtol=1e-12, atol=1e-12)
    for j in range(a.shape[1]):
        assert_close(f[:, j], _dq_fix_naive(a[:, j]), rtol=0, atol=0)
    with pytest.raises(ValueError, match="time axis"):
        dq_fix(dq_identity())


@given(unit_dual_quaternions(), unit_dual_quaternions(), st.floats(0, 1))
def test_sclerp_endpoints_midpoint_speed(a, b, t):
    """spec/math.md §5.11: endpoints, (a* ⊗ s(½))² = a* ⊗ b, unit output, rotation angle linear in t, sign-invariant."""
    assert_close(dq_sclerp(a, b, 0.0), a, rtol=1e-12, atol=1e-12)
    end = dq_sclerp(a, b, 1.0)
    bb = sign_aligned(b, end)  # ±b, the sign chosen by the shortest-path rule
    assert_close(end, bb, rtol=1e-10, atol=1e-10)
    assert np.sum(a[:4] * bb[:4]) >= 0
    half = dq_mul(dq_conj(a), dq_sclerp(a, b, 0.5))
    assert_close(dq_mul(half, half), dq_mul(dq_conj(a), bb), rtol=1e-10, atol=1e-10)
    st_ = dq_sclerp(a, b, t)
    assert dq_is_unit(st_, atol_norm=1e-12, atol_dot=1e-10)
    assert_close(quat_angle(a[:4], st_[:4]), t * quat_angle(a[:4], b[:4]), rtol=1e-9, atol=1e-9)
    assert_close(dq_sclerp(a, -b, t), st_, rtol=1e-12, atol=1e-12)  # shortest path: the sign of b is irrelevant


def test_sclerp_translation_rotation_antipodal_broadcast():
    """spec/math.md §5.11: pure translations interpolate linearly; pure rotations follow slerp; b = ±a gives a;
    t broadcasts over leading axes."""
    ta, tb = np.array([1.0, 2, 3]), np.array([-2.0, 0.5, 4])
    a, b = dq_from_quat_translation(quat_identity(), ta), dq_from_quat_translation(quat_identity(), tb)
    ts = np.linspace(-0.5, 1.5, 9)
    assert_close(translation_from_dq(dq_sclerp(a, b, ts)), ta + ts[:, None] * (tb - ta), rtol=1e-12, atol=1e-12)
    q0, q1 = quat_from_axis_angle([0.3, -1.0, 2.0]), quat_from_axis_angle([-1.0, 0.2, 0.4])
    r = dq_sclerp(np.r_[q0, np.zeros(4)], np.r_[q1, np.zeros(4)], ts)
    assert_close(r[:, :4], quat_slerp(q0, q1, ts), rtol=1e-12, atol=1e-12)
    assert_close(r[:, 4:], np.zeros((9, 4)), rtol=0, atol=1e-12)
    c = random_dq(3, seed=2)
    for other in (c, -c):
        assert_close(dq_sclerp(c, other, 0.37), c, rtol=1e-12, atol=1e-12)
    # screw: a rotation by 170° about z through the point (1, 0, 0), sampled at t: the point (1,0,0) stays fixed
    q = quat_from_axis_angle([0, 0, math.radians(170)])
    pivot = np.array([1.0, 0, 0])
    screw = dq_from_quat_translation(q, pivot - quat_rotate(q, pivot))
    mid = dq_sclerp(dq_identity(), screw, ts)
    assert_close(dq_transform_point(mid, pivot), np.broadcast_to(pivot, (9, 3)), rtol=0, atol=1e-12)


@given(unit_dual_quaternions(st.tuples(st.integers(1, 4))), st.data())
def test_dq_blend(dqs, data):
    """spec/math.md §5.12 (DLB): unit output, equals the loop version, invariant to the signs of the inputs."""
    k = dqs.shape[0]
    w = data.draw(st.lists(st.floats(0.05, 1.0), min_size=k, max_size=k).map(np.array))
    out = dq_blend(w, dqs)
    assert dq_is_unit(out, atol_norm=1e-12, atol_dot=1e-12)
    assert_close(out, _dq_blend_naive(w, dqs), rtol=1e-12, atol=1e-12)
    flips = data.draw(st.lists(st.sampled_from([-1.0, 1.0]), min_size=k, max_size=k).map(np.array))
    flipped = dq_blend(w, flips[:, None] * dqs)
    assert_close(flipped, sign_aligned(out, flipped), rtol=1e-12, atol=1e-12)


def test_dq_blend_special_cases():
    """spec/math.md §5.12: one DQ returns it; one-hot weights pick; pure translations blend linearly; batch axes."""
    a = random_dq(3, seed=4)
    assert_close(dq_blend([1.0], a[:1]), a[0], rtol=1e-12, atol=1e-12)
    assert_close(dq_blend([0.7], a[:1]), a[0], rtol=1e-12, atol=1e-12)
    assert_close(dq_blend([0.0, 1.0, 0.0], a), a[1], rtol=1e-12, atol=1e-12)
    ts = np.array([[1.0, 0, 0], [0, 2.0, 0], [0, 0, 3.0]])
    tr = dq_from_quat_translation(quat_identity(), ts)
    w = np.array([0.2, 0.3, 0.5])
    assert_close(translation_from_dq(dq_blend(w, tr)), w @ ts, rtol=1e-12, atol=1e-12)
    batch = dq_blend(np.tile(w, (5, 1)), a)  # weights (5, K), dqs (K, 8) broadcast
    assert batch.shape == (5, 8)
    assert_close(batch, np.broadcast_to(dq_blend(w, a), (5, 8)), rtol=0, atol=0)
    with pytest.raises(ValueError, match="blended real part"):
        dq_blend([1.0, -1.0], np.stack([a[0], a[0]]))
    with pytest.raises(ValueError, match=r"\(\.\.\., K\) and \(\.\.\., K, 8\)"):
        dq_blend([1.0, 1.0], a)


# --------------------------------------------------------------------------------------------------------------
# §6 dtype policy and validation
# --------------------------------------------------------------------------------------------------------------

A8 = random_dq(1, seed=8)[0]
P3 = np.array([0.5, -1.0, 2.0])
CALLS = [
    ("dq_mul", lambda a: dq_mul(a, a)),
    ("dq_conj", dq_conj),
    ("dq_conj_dual", dq_conj_dual),
    ("dq_conj_combined", dq_conj_combined),
    ("dq_inv", dq_inv),
    ("dq_norm", lambda a: dq_norm(a)[1]),
    ("dq_normalize", dq_normalize),
    ("dq_from_quat_translation", lambda a: dq_from_quat_translation(a[:4], a[5:])),
    ("quat_translation_from_dq", lambda a: quat_translation_from_dq(a)[1]),
    ("translation_from_dq", translation_from_dq),
    ("matrix_from_dq", matrix_from_dq),
    ("dq_from_matrix", lambda a: dq_from_matrix(matrix_from_dq(a))),
    ("dq_transform_point", lambda a: dq_transform_point(a, a[5:])),
    ("dq_fix", lambda a: dq_fix(np.stack([a, -a]))),
    ("dq_sclerp", lambda a: dq_sclerp(a, dq_identity(dtype=a.dtype), 0.3)),
    ("dq_blend", lambda a: dq_blend(np.array([0.3, 0.7]), np.stack([a, dq_identity(dtype=a.dtype)]))),
]


@pytest.mark.parametrize("name,f", CALLS, ids=[c[0] for c in CALLS])
def test_dtype_preserved(name, f):
    """spec/math.md §6: float32 stays float32 (close to float64), float64 stays float64."""
    out64 = f(A8.astype(np.float64))
    out32 = f(A8.astype(np.float32))
    assert out64.dtype == np.float64
    assert out32.dtype == np.float32, f"{name} returned {out32.dtype} for float32 input"
    assert_close(out32, out64, rtol=1e-4, atol=1e-5, name=name)


def test_integer_input_becomes_float64():
    """spec/math.md §6: integer arrays are accepted and computed in float64."""
    assert dq_mul(np.arange(8), np.arange(8)).dtype == np.float64
    assert dq_identity().dtype == np.float64
    assert dq_from_quat_translation([1, 0, 0, 0], [1, 2, 3]).dtype == np.float64


BAD = [
    ("dq_mul", lambda x: dq_mul(x, x), (4,)),
    ("dq_conj", dq_conj, (7,)),
    ("dq_inv", dq_inv, (2, 4)),
    ("dq_norm", dq_norm, (9,)),
    ("dq_is_unit", dq_is_unit, (4,)),
    ("dq_normalize", dq_normalize, (3, 4)),
    ("dq_from_quat_translation", lambda x: dq_from_quat_translation(x, np.zeros(3)), (3,)),
    ("translation_from_dq", translation_from_dq, (7,)),
    ("matrix_from_dq", matrix_from_dq, (4, 4)),
    ("dq_transform_point", lambda x: dq_transform_point(x, np.zeros(3)), (4,)),
    ("dq_fix", dq_fix, (3, 4)),
    ("dq_sclerp", lambda x: dq_sclerp(x, x, 0.5), (4,)),
]


@pytest.mark.parametrize("name,f,shape", BAD, ids=[c[0] for c in BAD])
def test_bad_shapes_raise(name, f, shape):
    """spec/math.md §6: wrong trailing shapes raise ValueError with the expected and the actual shape."""
    import re
    with pytest.raises(ValueError, match=r"expected shape .* got " + re.escape(str(shape))):
        f(np.ones(shape))


def test_nan_rejected_and_names():
    """spec/math.md §6: NaN/inf rejected naming the argument; __all__ names exist."""
    with pytest.raises(ValueError, match="a: expected finite values, got NaN"):
        dq_normalize(np.full(8, np.nan))
    with pytest.raises(ValueError, match="p: expected finite values, got NaN or inf"):
        dq_transform_point(dq_identity(), [0, np.inf, 0])
    for name in D.__all__:
        assert hasattr(D, name), name
